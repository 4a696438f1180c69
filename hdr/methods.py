"""The stage's method registries: the CLI's ``--method`` names, the functions
they call, a one-line help and the options each understands.

Every registry is a :class:`capture.registry.Registry` of
:class:`capture.registry.Method` entries (targets are ``"module:function"``
strings, imported on use, so listing the choices for ``--help`` stays cheap
and cannot drift from what exists). The CLI's ``choices`` and help lines are
generated from them, and the CLI dispatches through them.

Examples
--------
>>> RESPONSE_METHODS.names
('debevec', 'mitsunaga-nayar', 'robertson', 'linear')
>>> RESPONSE_METHODS.resolve("debevec").load().__name__
'response_debevec1997'
>>> TONEMAP_METHODS["reinhard-local"].bound["method"]
'reinhard-local'
"""

from __future__ import annotations

from lumigraph.capture.registry import Method, Registry

RESPONSE_METHODS = Registry("response", [
    Method("debevec", "lumigraph.hdr.debevec1997:response_debevec1997",
           "Debevec & Malik 1997: g = ln f^-1 per code, smoothness from the L-curve",
           options=("bit_depth", "smoothness", "samples", "rng", "noise")),
    Method("mitsunaga-nayar", "lumigraph.hdr.mitsunaga1999:response_mitsunaga1999",
           "Mitsunaga & Nayar 1999: polynomial response, refined exposure ratios",
           options=("bit_depth", "order", "samples", "rng")),
    Method("robertson", "lumigraph.hdr.robertson2003:response_robertson2003",
           "Robertson et al. 2003: alternating maximum likelihood, run to convergence",
           options=("bit_depth", "samples", "rng")),
    Method("linear", "lumigraph.hdr.methods:linear_response",
           "identity response for RAW or linear data (no fit)", options=("bit_depth",)),
])
TONEMAP_METHODS = Registry("tone-mapping", [
    Method("reinhard", "lumigraph.hdr.reinhard2002:tonemap",
           "Reinhard et al. 2002 global operator", options=("key", "white", "bit_depth"),
           bound={"method": "reinhard"}),
    Method("reinhard-local", "lumigraph.hdr.reinhard2002:tonemap",
           "Reinhard et al. 2002 local operator (dodging and burning)",
           options=("key", "bit_depth"), bound={"method": "reinhard-local"}),
])
ALIGN_METHODS = Registry("alignment", [
    Method("mtb", "lumigraph.hdr.ward2003:align",
           "Ward 2003 median threshold bitmaps (integer translation)",
           options=("reference", "levels")),
])


def linear_response(images, exposure_times_s=None, *, bit_depth=None, **_ignored):
    """The identity response for RAW/linear data (no fit: nothing to model)."""
    import numpy as np

    from lumigraph.hdr.response import ResponseCurve

    z = np.asarray(images)
    bd = int(bit_depth) if bit_depth is not None else 8 * z.dtype.itemsize
    c = z.shape[-1] if z.ndim == 4 else 1
    r = ResponseCurve.linear(bd, c, reason="linear data (RAW or declared linear): the response "
                                           "is the identity, no curve was fitted")
    times = None if exposure_times_s is None else tuple(float(t) for t in exposure_times_s)
    return ResponseCurve(r.method, r.bit_depth, r.g, times, r.selection, r.warnings, r.fit)
