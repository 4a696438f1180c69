"""Method registries: the CLI's ``--method`` names and the functions they call.

Values are ``"module:function"`` strings, imported on use, so listing the
choices (``--help``) stays cheap and cannot drift from what exists.

Examples
--------
>>> sorted(RESPONSE_METHODS)
['debevec', 'linear', 'mitsunaga-nayar', 'robertson']
>>> resolve(RESPONSE_METHODS, "debevec").__name__
'response_debevec1997'
"""

from __future__ import annotations

import importlib

RESPONSE_METHODS = {
    "debevec": "lumigraph.hdr.debevec1997:response_debevec1997",
    "mitsunaga-nayar": "lumigraph.hdr.mitsunaga1999:response_mitsunaga1999",
    "robertson": "lumigraph.hdr.robertson2003:response_robertson2003",
    "linear": "lumigraph.hdr.methods:linear_response",
}
TONEMAP_METHODS = {
    "reinhard": "lumigraph.hdr.reinhard2002:tonemap",
    "reinhard-local": "lumigraph.hdr.reinhard2002:tonemap",
}
ALIGN_METHODS = {"mtb": "lumigraph.hdr.ward2003:align"}


def resolve(registry: dict, name: str):
    """The function registered under ``name`` (ValueError listing the choices)."""
    if name not in registry:
        raise ValueError(f"method: expected one of {', '.join(sorted(registry))}, got {name!r}")
    mod, fn = registry[name].split(":")
    return getattr(importlib.import_module(mod), fn)


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
