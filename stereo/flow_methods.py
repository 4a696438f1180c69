"""The flow methods by name (``lumigraph flow --method``): one
:class:`~lumigraph.capture.registry.Registry`, so the choices and the help the
command offers cannot drift from what exists.

Each method is called as ``method(reference, moving, **options) -> FlowResult``
(:class:`lumigraph.stereo.pyramid_flow.FlowResult`), ``options`` among its
``Method.options``; ``pyramid`` and ``pyramid-dense`` are one function in two
modes (``bound``).

Examples
--------
>>> FLOW_METHODS.names
('pyramid', 'pyramid-dense', 'video-matching')
>>> FLOW_METHODS["video-matching"].options
('levels',)
"""

from __future__ import annotations

from lumigraph.capture.registry import Method, Registry

PYRAMID_OPTIONS = ("levels", "window", "iterations", "finest_level", "median_radius")

FLOW_METHODS = Registry("flow", [
    Method("pyramid", "lumigraph.stereo.pyramid_flow:pyramid_flow",
           "coarse-to-fine Lucas-Kanade pyramid flow (reference 5.1.3, Fig. 5.5)",
           options=PYRAMID_OPTIONS, bound={"method": "local"}),
    Method("pyramid-dense", "lumigraph.stereo.pyramid_flow:pyramid_flow",
           "pyramid flow with a smoothness term (combined local-global) that fills textureless "
           "areas", options=PYRAMID_OPTIONS, bound={"method": "dense"}),
    Method("video-matching", "lumigraph.stereo.sand2004:video_matching",
           "Sand & Teller 2004: robust to lighting change, added/removed objects, small camera "
           "shifts", options=("levels",)),
])
