"""The flow methods by name (``lumigraph flow --method``): one
:class:`~lumigraph.capture.registry.Registry`, so the choices and the help the
command offers cannot drift from what exists.

Each method is called as ``method(reference, moving, **options) -> FlowResult``
(:class:`lumigraph.stereo.pyramid_flow.FlowResult`), ``options`` among its
``Method.options``; ``pyramid`` and ``pyramid-dense`` are one function in two
modes (``bound``). ``dis`` (dense inverse search, the default) takes a
``preset`` (``fast``/``default``/``accurate``), the others none.

:func:`check_options` checks a method's options before any image is read.

Examples
--------
>>> FLOW_METHODS.names
('dis', 'pyramid', 'pyramid-dense', 'video-matching')
>>> FLOW_METHODS["dis"].options
('preset',)
>>> FLOW_METHODS["video-matching"].options
('levels',)
>>> check_options("video-matching", levels=2, window=9, median_radius=0)
{'levels': 2}
"""

from __future__ import annotations

from lumigraph.capture.errors import InputError
from lumigraph.capture.registry import Method, Registry

PYRAMID_OPTIONS = ("levels", "window", "iterations", "finest_level", "median_radius")

FLOW_METHODS = Registry("flow", [
    Method("dis", "lumigraph.stereo.kroeger2016:dense_inverse_search",
           "dense inverse search (Kroeger et al. 2016; OpenCV's DIS as inner solver) at full size, "
           "median-filtered (accurate: occlusions filled, variational refinement); --preset picks "
           "speed or accuracy (default)",
           options=("preset",)),
    Method("pyramid", "lumigraph.stereo.pyramid_flow:pyramid_flow",
           "coarse-to-fine Lucas-Kanade pyramid flow (reference 5.1.3, Fig. 5.5)",
           options=PYRAMID_OPTIONS, bound={"method": "local"}),
    Method("pyramid-dense", "lumigraph.stereo.pyramid_flow:pyramid_flow",
           "pyramid flow with a smoothness term (combined local-global) that fills textureless "
           "areas", options=PYRAMID_OPTIONS, bound={"method": "dense"}),
    Method("video-matching", "lumigraph.stereo.sand2004:video_matching",
           "Sand & Teller 2004: robust to lighting change, added/removed objects, small camera "
           "shifts (dense inverse search on contrast-normalised frames; --levels: the paper's "
           "pyramid search)", options=("levels",)),
])

# Refinements only the pyramid methods have; 0 is "off".
PYRAMID_ONLY = ("finest_level", "median_radius")


def check_options(method: str, *, preset: str | None = None, **options) -> dict:
    """Check the options of flow ``method`` before any image is read; returns
    those the method takes.

    Every option among :data:`PYRAMID_OPTIONS` given is checked against its
    range (:func:`stereo.pyramid_flow.check_options`, whichever the method),
    and a method without the pyramid-only refinements (:data:`PYRAMID_ONLY`)
    must be given them off (0).

    Raises
    ------
    InputError
        Naming the option out of range, or ``method`` when it takes no
        ``finest_level``/``median_radius`` and one was given; ``preset`` out
        of its choices, or given to a method without presets.

    Examples
    --------
    >>> check_options("dis", preset="fast", window=9)
    {'preset': 'fast'}
    >>> check_options("pyramid", levels="auto", finest_level=1)
    {'levels': 'auto', 'finest_level': 1}
    >>> try:
    ...     check_options("video-matching", median_radius=5)
    ... except InputError as e:
    ...     print(e.where)
    method
    """
    from lumigraph.stereo.pyramid_flow import check_options as check_pyramid_options

    m = FLOW_METHODS.resolve(method)
    if preset is not None:
        if "preset" not in m.options:
            raise InputError("preset", f"{method} has no presets (dis only)")
        from lumigraph.stereo.kroeger2016 import check_options as check_dis

        check_dis(preset=preset)
    levels = check_pyramid_options(**options)
    if "levels" in options:
        options["levels"] = levels
    if any(options.get(k) and k not in m.options for k in PYRAMID_ONLY):
        raise InputError("method", f"{method} takes no median_radius or finest_level "
                                   "(pyramid methods only)")
    out = {k: v for k, v in options.items() if k in m.options}
    return {**out, "preset": preset} if preset is not None else out
