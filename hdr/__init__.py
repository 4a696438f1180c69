"""HDR imaging: camera-response recovery (one module per method), radiance
merge, exposure alignment, tone mapping and HDR file formats.

``from lumigraph.hdr import response_debevec1997, response_mitsunaga1999,
response_robertson2003, tonemap, ResponseCurve`` works (and ``hdr_video``,
``tonemap_video`` for HDR video); the names load their modules on first use so
``import lumigraph.hdr`` stays cheap. The merge is ``from lumigraph.hdr.merge
import merge``: ``lumigraph.hdr.merge`` is the module's name,
and a package attribute of the same name would be the function or the module
depending on what had been imported before.
"""

from __future__ import annotations

from lumigraph.capture.lazy import attach

_LAZY = {
    "ResponseCurve": "lumigraph.hdr.response",
    "response_debevec1997": "lumigraph.hdr.debevec1997",
    "response_mitsunaga1999": "lumigraph.hdr.mitsunaga1999",
    "response_robertson2003": "lumigraph.hdr.robertson2003",
    "RadianceMap": "lumigraph.hdr.merge",
    "tonemap": "lumigraph.hdr.reinhard2002",
    "align": "lumigraph.hdr.ward2003",
    "mtb_shift": "lumigraph.hdr.ward2003",
    "read_rgbe": "lumigraph.hdr.formats",
    "write_rgbe": "lumigraph.hdr.formats",
    "read_logluv_tiff": "lumigraph.hdr.formats",
    "write_logluv_tiff": "lumigraph.hdr.formats",
    "hdr_video": "lumigraph.hdr.kang2003",
    "unaligned_merge": "lumigraph.hdr.kang2003",
    "tonemap_video": "lumigraph.hdr.kang2003",
    "HDRVideo": "lumigraph.hdr.kang2003",
    "TonemappedVideo": "lumigraph.hdr.kang2003",
    "Radiometry": "lumigraph.hdr.kang2003",
}
__getattr__, __dir__, __all__ = attach(__name__, _LAZY)
