"""Light fields: the 4-D container, camera-array and lenslet import,
refocusing (shift-and-add, Fourier slice) and light-slab rendering.

==========================  ====================================================
module                      what
==========================  ====================================================
``lightfield.field``        :class:`LightField` (U, V, H, W, C), folder format
``lightfield.lenslet``      plenoptic raw decoding (grid fit, devignette, slice)
``lightfield.refocus``      shift-and-add (eq. 5.9), focal stack, depth,
                            all-in-focus; ``refocus(lf, s, method=...)``
``lightfield.ng2005``       Fourier slice digital refocusing (eqs. 5.10-5.11)
``lightfield.levoy1996``    light-slab rendering of novel views (§5.4.3)
``lightfield.methods``      ``REFOCUS_METHODS``: the ``--method`` registry
==========================  ====================================================
"""

from lumigraph.lightfield.field import LightField

__all__ = ["LightField"]
