"""Build the optional C kernels of stereo matching (everything else is in pyproject.toml).

``stereo/_ssd.c`` (block matching) and ``stereo/_sgm.c`` (semi-global
matching) are plain C: no numpy headers, so building needs only a C
compiler and the Python headers. ``optional=True``: without a compiler the
install still succeeds and ``lumigraph.stereo.block_matching`` and
``lumigraph.stereo.hirschmuller2008`` fall back to numpy (with a warning).
``-ffp-contract=off``: no fused multiply-add, so the SSD kernel's float32
decision rounds exactly as numpy's does.
"""

from setuptools import Extension, setup

setup(ext_modules=[
    Extension("lumigraph.stereo._ssd", sources=["stereo/_ssd.c"],
              define_macros=[("LUMIGRAPH_PYMODULE", "1")], libraries=["m"],
              extra_compile_args=["-O3", "-ffp-contract=off"], optional=True),
    # integers only: the numpy twin gives the same results at any optimisation;
    # -fno-wrapv undoes the interpreter's -fwrapv, which kept the int16 path
    # loops from vectorising (8x slower); no value overflows (checked by the caller)
    Extension("lumigraph.stereo._sgm", sources=["stereo/_sgm.c"],
              define_macros=[("LUMIGRAPH_PYMODULE", "1")], extra_compile_args=["-O3", "-fno-wrapv"],
              optional=True)])
