"""Build the optional C kernel of stereo block matching (everything else is in pyproject.toml).

``stereo/_ssd.c`` is plain C: no numpy headers, so building needs only a C
compiler and the Python headers. ``optional=True``: without a compiler the
install still succeeds and ``lumigraph.stereo.block_matching`` falls back to numpy
(with a warning). ``-ffp-contract=off``: no fused multiply-add, so the
kernel's float32 decision rounds exactly as numpy's does.
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension(
    "lumigraph.stereo._ssd", sources=["stereo/_ssd.c"], define_macros=[("LUMIGRAPH_PYMODULE", "1")],
    libraries=["m"], extra_compile_args=["-O3", "-ffp-contract=off"], optional=True)])
