"""The flow methods by CLI name (``lumigraph flow --method``): one registry,
so the choices the command offers cannot drift from what exists.

Each entry maps a name to ``fn(image0, image1, *, levels, **knobs) -> FlowResult``.

Examples
--------
>>> sorted(FLOW_METHODS)
['pyramid', 'pyramid-dense', 'video-matching']
"""

from __future__ import annotations


def _pyramid(i0, i1, *, levels="auto", window=9, iterations=3, finest_level=0, median_radius=0,
             **_):
    from lumigraph.stereo.pyramid_flow import pyramid_flow

    return pyramid_flow(i0, i1, levels=levels, window=window, iterations=iterations,
                        finest_level=finest_level, median_radius=median_radius, method="local")


def _pyramid_dense(i0, i1, *, levels="auto", window=9, iterations=3, finest_level=0,
                   median_radius=0, **_):
    from lumigraph.stereo.pyramid_flow import pyramid_flow

    return pyramid_flow(i0, i1, levels=levels, window=window, iterations=iterations,
                        finest_level=finest_level, median_radius=median_radius, method="dense")


def _video_matching(i0, i1, *, levels="auto", **_):
    from lumigraph.stereo.sand2004 import video_matching

    return video_matching(i0, i1, levels=levels)


FLOW_METHODS = {
    "pyramid": (_pyramid, "coarse-to-fine Lucas-Kanade pyramid flow (reference 5.1.3, Fig. 5.5)"),
    "pyramid-dense": (_pyramid_dense, "pyramid flow with a smoothness term (combined "
                                      "local-global) that fills textureless areas"),
    "video-matching": (_video_matching, "Sand & Teller 2004: robust to lighting change, added/"
                                        "removed objects, small camera shifts"),
}
