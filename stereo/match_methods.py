"""The dense-stereo methods by name (``lumigraph stereo match --method``): one
:class:`~lumigraph.capture.registry.Registry`, so the choices and the help the
command offers cannot drift from what exists.

Each is called as ``method(left, right, max_disp=..., **options) ->
DisparityMap`` (:class:`lumigraph.stereo.block_matching.DisparityMap`).

Examples
--------
>>> MATCH_METHODS.names
('sgm', 'ssd')
"""

from __future__ import annotations

from lumigraph.capture.registry import Method, Registry

MATCH_METHODS = Registry("stereo matching", [
    Method("sgm", "lumigraph.stereo.hirschmuller2008:match",
           "semi-global matching on a census cost (Hirschmueller 2008; default)",
           options=("cost", "uniqueness", "lr_tolerance", "texture_snr")),
    Method("ssd", "lumigraph.stereo.block_matching:match",
           "SSD block matching (reference eq. 5.1)",
           options=("window", "texture_snr", "uniqueness", "lr_tolerance", "channels",
                    "prefilter")),
])
