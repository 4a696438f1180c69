"""The light-field stage's method registries: the CLI's ``--method`` names
and the functions they call.

Every refocusing method takes ``(lf, slopes, **options)`` and returns the
photographs refocused at ``slopes`` as one ``(N, H, W, C)`` float32 array on
the centre view's grid, so a method that pays a one-time cost (the 4-D FFT of
Fourier slice refocusing) pays it once per stack.

Examples
--------
>>> REFOCUS_METHODS.names
('shift-add', 'fourier')
>>> REFOCUS_METHODS["shift-add"].options
('kernel',)

Every depth method takes ``(lf, slopes, **options)`` (candidate disparities,
px per view step) and returns a
:class:`~lumigraph.lightfield.refocus.DisparityEstimate` (disparity and
confidence of the centre view).

>>> DEPTH_METHODS.names
('wang2015', 'variance')
"""

from __future__ import annotations

from lumigraph.capture.registry import Method, Registry

REFOCUS_METHODS = Registry("refocus", [
    Method("shift-add", "lumigraph.lightfield.refocus:shift_and_add_stack",
           "shift-and-add of the views (Ng 2005 eq. 5.9): one pass over the views per value",
           options=("kernel",)),
    Method("fourier", "lumigraph.lightfield.ng2005:refocus_stack",
           "Fourier slice photography (Ng 2005 eqs. 5.10-5.11): one 4-D FFT, then a 2-D "
           "slice per value",
           options=("max_slope", "oversample", "kernel_width", "interpolation")),
])

DEPTH_METHODS = Registry("depth", [
    Method("wang2015", "lumigraph.lightfield.wang2015:estimate_disparity",
           "occlusion-aware: least cost over half-apertures (Wang et al. 2015), guided-filter "
           "cost aggregation, weighted-median refinement; keeps silhouettes (default)",
           options=("views", "radius", "median_radius", "soft_edges")),
    Method("variance", "lumigraph.lightfield.refocus:estimate_disparity",
           "angular variance of the refocused views in a box window (the earlier default; "
           "fattens silhouettes)",
           options=("window",)),
])
