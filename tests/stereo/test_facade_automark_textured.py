"""Automatic marking on textured walls (stereo/debevec1996/automark.py):
the checks that keep window frames, brick joints and a flush edge seen
from behind its wall from giving proposals, and the search for an edge
the line detector misses, unit by unit on images whose edges are known
exactly, then on the rendered building."""

from __future__ import annotations

import numpy as np
import pytest

from lumigraph.stereo.debevec1996.automark import (
    _continues,
    _grey,
    _opponent,
    _search_edge,
    _strongest,
    _visible_near_flush,
    detect_segments,
    refine_segment,
)
from lumigraph.stereo.debevec1996.model import BlockModel

STEP = 40.0          # grey levels across the edges below


def _wall(*, rows=120, cols=120, edge_x=60.5, rng=None, noise=0.0):
    """A vertical step of STEP grey levels at x = ``edge_x`` (pixel centres
    at integers: the step lies between columns), plus Gaussian ``noise``."""
    x = np.arange(cols)[None, :].repeat(rows, 0).astype(float)
    g = 100.0 + STEP * np.clip(x - edge_x + 0.5, 0.0, 1.0)
    if rng is not None:
        g = g + rng.normal(0.0, noise, g.shape)
    return g


def test_a_step_along_the_whole_edge_continues():
    g = _wall()
    seg = refine_segment(g, np.array([60.3, 20.0, 60.3, 50.0]))
    assert seg is not None and abs(seg[0] - 60.5) < 0.05
    # the detection covers a third of the edge; the step runs all along it
    assert _continues(g, seg, np.array([60.5, 5.0, 60.5, 115.0]))


def _isoluminant(edge_x=60.5, rows=120, cols=120):
    """Brick red left of x = ``edge_x``, a greyer, bluer tile right of it,
    of one luminance (0.299 R + 0.587 G + 0.114 B equal to 1e-9): the
    rendered spire over its tower wall, as 8-bit codes (no rounding)."""
    left = np.array([90.0, 40.0, 30.0])
    # right = left + a step orthogonal to the luminance weights
    w = np.array([0.299, 0.587, 0.114])
    step = np.array([-20.0, 8.0, 0.0])
    step[2] = -(w[:2] @ step[:2]) / w[2]
    x = np.arange(cols)[None, :].repeat(rows, 0).astype(float)
    t = np.clip(x - edge_x + 0.5, 0.0, 1.0)[..., None]
    return left + t * step, w @ step


def test_an_edge_of_one_luminance_is_found_in_the_colour_opponent_channels():
    img, dlum = _isoluminant()
    assert abs(dlum) < 1e-9
    grey = _grey(img)
    assert np.ptp(grey) < 1e-9                     # nothing to see in grey
    assert len(detect_segments(grey, min_length_px=15)) == 0
    chans = [grey] + _opponent(img)
    det = np.vstack([detect_segments(c, min_length_px=15) for c in chans])
    assert len(det) and np.all(np.abs(det[:, [0, 2]] - 60.5) < 1.0)
    ch = _strongest(chans, np.array([60.0, 10.0, 60.0, 110.0]))
    assert ch is not grey
    seg = refine_segment(ch, np.array([60.0, 10.0, 60.0, 110.0]))
    # a noise-free step between pixel columns is refined to the boundary
    assert seg is not None and np.all(np.abs(seg[[0, 2]] - 60.5) < 0.05)


def test_a_grey_photograph_has_no_opponent_channels():
    assert _opponent(np.zeros((10, 10))) == []
    assert _opponent(np.zeros((10, 10, 1))) == []
    g = _wall()
    assert _strongest([g], np.array([60.0, 10.0, 60.0, 110.0])) is g


def test_a_step_along_a_third_of_the_edge_does_not_continue():
    # a window frame beside a wall's corner: the step stops where the window
    # does, two thirds of the corner's length show no step on its line
    g = np.full((120, 120), 100.0)
    g[20:55, 61:] += STEP
    seg = refine_segment(g, np.array([60.3, 22.0, 60.3, 52.0]))
    assert seg is not None
    assert not _continues(g, seg, np.array([60.5, 5.0, 60.5, 115.0]))


def test_a_window_column_beside_a_seam_does_not_continue_at_a_seams_share():
    # two windows one above the other beside a flush corner (a seam): their
    # frames step over 60 % of the corner's stretch, enough for an edge of
    # the model that shows as a corner (half), not for a seam, which shows
    # only as a change of material and so runs along all of it
    from lumigraph.stereo.debevec1996.automark import SEAM_SHARE

    edge = np.array([60.5, 5.0, 60.5, 115.0])
    g = np.full((120, 120), 100.0)
    g[8:41, 61:] += STEP
    g[63:96, 61:] += STEP                  # 66 of the stretch's 110 rows
    seg = refine_segment(g, np.array([60.3, 10.0, 60.3, 38.0]))
    assert seg is not None
    assert _continues(g, seg, edge, share=0.5)
    assert not _continues(g, seg, edge, share=SEAM_SHARE)
    # a change of material along the whole seam passes either way
    full = _wall()
    seg = refine_segment(full, np.array([60.3, 10.0, 60.3, 38.0]))
    assert _continues(full, seg, edge, share=SEAM_SHARE)


def test_a_step_of_the_other_sign_does_not_continue_it():
    # the same line, but the wall beyond the window is darker on the other
    # side: a different boundary, not the detection's step running on
    g = np.full((120, 120), 100.0)
    g[:40, 61:] += STEP
    g[40:, :61] += STEP
    seg = refine_segment(g, np.array([60.3, 5.0, 60.3, 35.0]))
    assert not _continues(g, seg, np.array([60.5, 5.0, 60.5, 115.0]))


def test_a_faint_step_in_noise_is_found_along_the_projected_edge():
    # a step of 40 under noise of sd 15: each profile's own peak is
    # unreliable, their average along the edge is not; the projected edge is
    # 2.5 px off
    rng = np.random.default_rng(3)
    g = _wall(rng=rng, noise=15.0, edge_x=60.3)
    seg = _search_edge(g, np.array([62.8, 5.0, 62.8, 115.0]), gate_px=6.0)
    assert seg is not None
    # ~20 profile peaks within ±0.5 px each fix the line to ~0.2 px
    assert abs(seg[0] - 60.3) < 0.25 and abs(seg[2] - 60.3) < 0.25


def test_two_steps_in_the_gate_are_not_searched():
    # a second step as strong 3 px away: either could be the edge
    g = _wall() + STEP * (np.arange(120)[None, :] >= 64)
    assert _search_edge(g, np.array([62.0, 5.0, 62.0, 115.0]), gate_px=6.0) is None


def test_a_neighbouring_projected_edge_in_the_gate_stops_the_search():
    g = _wall()
    edge = np.array([61.0, 5.0, 61.0, 115.0])
    assert _search_edge(g, edge, gate_px=6.0) is not None
    # another model edge 4 px away and parallel: the step could be its
    other = np.array([[65.0, 0.0, 65.0, 120.0]])
    assert _search_edge(g, edge, gate_px=6.0, others=other) is None
    # one on the same line (a flush neighbour) does not
    flush = np.array([[61.3, 0.0, 61.3, 60.0]])
    assert _search_edge(g, edge, gate_px=6.0, others=flush) is not None
    assert _search_edge(g, edge, gate_px=6.0, others=flush, same_line=[True]) is not None
    # unless it is on the image line only (another block's silhouette in
    # front of a corner it hides): the step could be its
    assert _search_edge(g, edge, gate_px=6.0, others=flush, same_line=[False]) is None


TWO = {"blocks": [
    {"name": "house", "kind": "box",
     "params": {"width": {"value": 10.0, "fixed": True}, "depth": 6.0, "height": 6.0}},
    # the wing against the house's left wall, set back: its front-right
    # corner lies on that wall; the wing here reaches 0.05 m into the house
    {"name": "wing", "kind": "box", "parent": "house", "on": "base", "x": "offset", "y": "back",
     "params": {"width": 4.1, "depth": 4.0, "height": 4.0, "offset_x": -7.0}}]}


def _camera(centre, target=(0.0, 0.0, 2.0)):
    c = np.asarray(centre, float)
    z = np.asarray(target, float) - c
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return {"K": np.array([[700.0, 0, 320], [0, 700.0, 240], [0, 0, 1]]), "R": R,
            "t": -R @ c, "image_size": [640, 480]}


@pytest.mark.parametrize("side, seen", [("left", True), ("right", False)])
def test_an_edge_just_inside_a_wall_is_seen_from_its_front_only(side, seen):
    model = BlockModel.from_dict(TWO, where="test")
    p0, p1 = model.edges()["wing/front-right"]
    assert p0[0] == pytest.approx(-4.95)        # 0.05 m inside the house's wall at x = -5
    mid = (p0 + p1) / 2
    # from the left the wall faces the camera: the edge is on it, seen; from
    # the right the house's front and right walls stand in front of it
    cam = _camera((-30.0, -30.0, 5.0) if side == "left" else (30.0, -30.0, 5.0))
    vis = _visible_near_flush(model, cam, tol_px=6.0)
    assert bool(vis("p", mid[None])[0]) is seen


def _painted_step(seg, step, *, rng, half=6.0, blur=1.0, shape=(480, 640)):
    """A grey image (100, noise σ 2) with ``step`` added over the band
    ``half`` px wide on the left of ``seg`` ((2, 2) px) along its extent,
    blurred by a Gaussian of σ ``blur`` px: a crease's edge within a pixel
    of the line (the band covers whole pixels)."""
    from scipy.ndimage import gaussian_filter

    a, b = (np.asarray(x, float) for x in seg)
    L = float(np.hypot(*(b - a)))
    u = (b - a) / L
    n = np.array([-u[1], u[0]])
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    P = np.stack([xx, yy], -1) - a
    t, h = P @ u, P @ n
    band = ((t >= 0) & (t <= L) & (h >= 0) & (h <= half)).astype(float)
    return 100.0 + rng.normal(0.0, 2.0, shape) + step * gaussian_filter(band, blur)


# the wing's right end alone: its offset and width together, the left end still
_WING_END = (["wing/offset_x", "wing/width"], np.array([1.0, 2.0]) / np.sqrt(5.0))


def _crease_cameras():
    """Photographs a and b: the crease of ``TWO``'s wing front against the
    house's wall seen from the front left, moving 10-16 px per metre of
    the wing's end."""
    return {"a": _camera((-22.0, -30.0, 2.0), (-6.0, 0.0, 2.0)),
            "b": _camera((-36.0, -22.0, 2.0), (-6.0, 0.0, 2.0))}


def _scanned_without_then_with(switch, start, names, v, cams, greys, *, sigma):
    """``_crease`` along ``v`` from ``start``, first with the automark
    module's ``switch`` off, where it finds nothing (the premise), then on:
    its proposals."""
    import lumigraph.stereo.debevec1996.automark as am

    def run():
        return am._crease(start, names, v, cams, greys, rough=start, trust=0.3, sigma=sigma)

    setattr(am, switch, False)
    try:
        assert run() == []                                                       # the premise
    finally:
        setattr(am, switch, True)
    return run()


def _found_in_a_and_b_within_a_pixel(found, true_lines):
    """The crease proposed in photographs a and b, each within a pixel of
    its true line (the painted band covers whole pixels)."""
    assert sorted((m.photo, m.edge) for m in found) == [("a", "wing/front-right"),
                                                        ("b", "wing/front-right")]
    for m in found:
        a, b = true_lines[m.photo][m.edge]
        n = np.array([-(b - a)[1], (b - a)[0]]) / np.hypot(*(b - a))
        assert max(abs((m.segment[:2] - a) @ n), abs((m.segment[2:] - a) @ n)) <= 1.0


@pytest.mark.parametrize("seed", range(6))
def test_a_line_the_scan_barely_moves_is_no_rival_to_the_crease(seed):
    """``_crease`` along the wing's right end (offset and width together, the
    left end still), the start 0.4 m short. Photographs a and b see the
    crease of the wing's front against the house's wall (a faint step, 5
    grey levels in noise of 2), which moves 10-16 px per metre there;
    photograph c looks along the wing from high up, where its top's end
    moves 2 px per metre: 2.7 px over the scan (±4 σ, σ 0.15 m), less than
    ``CREASE_APART_PX``. Its step is strong and blurred over 8 px, so it
    scores every move alike (the rendered building's seed 118: a roofline
    seen end-on scored z 19-26 at every move, and its crease's peak, 45,
    was refused for a rival at 0.505 of it). Scanned, it makes the moves
    away from the crease rivals of its peak and nothing is found (the
    premise); left out, the crease is found in a and b, within a pixel of
    its true line (the painted band covers whole pixels)."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo.debevec1996.solve import project_model_edges

    truth = BlockModel.from_dict(TWO, where="test")
    start = truth.with_values({"wing/width": 3.7, "wing/offset_x": -7.2})
    assert start.edges()["wing/front-left"][0][0] == pytest.approx(-9.05)   # the left end still
    cams = {**_crease_cameras(), "c": _camera((-60.0, 1.0, 15.0), (-5.0, 1.0, 4.0))}
    rng = np.random.default_rng(seed)
    true_lines = {p: project_model_edges(truth, c["K"], c["R"], c["t"]) for p, c in cams.items()}
    greys = {"a": _painted_step(true_lines["a"]["wing/front-right"], 5.0, rng=rng),
             "b": _painted_step(true_lines["b"]["wing/front-right"], 5.0, rng=rng),
             "c": _painted_step(true_lines["c"]["wing/top-right"], 150.0, rng=rng, half=40.0,
                                  blur=8.0)}
    names, v = _WING_END
    slots = np.array([start.slot_of(n) for n in names])
    rates = {(p, start.edge_names[i]): r for (p, i), (_, _, r) in am._crease_lines(
        start, slots, v, 0.0, cams, tol_px=1e9).items()}
    assert rates[("c", "wing/top-right")] * 8 * 0.15 < am.CREASE_APART_PX          # the premise
    assert min(rates[("a", "wing/front-right")], rates[("b", "wing/front-right")]) * 8 * 0.15 \
        >= am.CREASE_APART_PX

    found = _scanned_without_then_with("_CREASE_MOVING", start, names, v, cams, greys, sigma=0.15)
    _found_in_a_and_b_within_a_pixel(found, true_lines)


@pytest.mark.parametrize("seed", range(4))
def test_a_scan_too_short_for_a_rival_leaves_no_line_out(seed):
    """``_crease`` along the wing's right end as above, the start 0.08 m
    short, the marks placing it to σ 0.03 m: the scan's ±4 σ moves the
    fastest line, photograph b's crease, 3.8 px, less than
    ``CREASE_APART_PX``, so no move can have a rival. Leaving out every
    line that moves less than that over the scan left none, and nothing
    was found (the premise; the rendered building's seed 263, second draw
    from ``blocks.json``: the wing's end 4 cm short, 2.4 σ, where the scan
    moved its lines 3.8 px). With no line left out, the crease is found in
    a and b, within a pixel of its true line."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo.debevec1996.solve import project_model_edges

    truth = BlockModel.from_dict(TWO, where="test")
    start = truth.with_values({"wing/width": 4.02, "wing/offset_x": -7.04})
    assert start.edges()["wing/front-left"][0][0] == pytest.approx(-9.05)   # the left end still
    cams = _crease_cameras()
    rng = np.random.default_rng(seed)
    true_lines = {p: project_model_edges(truth, c["K"], c["R"], c["t"]) for p, c in cams.items()}
    greys = {p: _painted_step(true_lines[p]["wing/front-right"], 5.0, rng=rng) for p in cams}
    names, v = _WING_END
    slots = np.array([start.slot_of(n) for n in names])
    sigma = 0.03
    rates = [r for _, _, r in am._crease_lines(start, slots, v, 0.0, cams, tol_px=1e9).values()]
    assert max(rates) * 8 * sigma < am.CREASE_APART_PX                         # the premise

    found = _scanned_without_then_with("_NO_RIVALS", start, names, v, cams, greys, sigma=sigma)
    _found_in_a_and_b_within_a_pixel(found, true_lines)


@pytest.mark.parametrize("seed", range(4))
def test_a_loose_wing_end_takes_a_crease_only_one_photograph_shows(seed):
    """``_creases`` on a solve of ``TWO`` from four photographs whose marks
    (σ 0.5 px) miss every edge of the wing's right end but a 20 px piece of
    ``wing/back-right`` in photograph c, drawn 1 px off its edge: the end is
    placed loosely (σ about 6 cm) and off the truth. Only photograph a
    sees the end's crease against the house's wall (a faint step, 5 grey
    levels in noise of 2); the others show plain noise. The loose scan
    (within 4 σ of where the marks put the end) finds it in a alone, and a
    crease seen in one photograph was no proposal (the premise; the
    rendered building's seed 21, second draw from ``blocks.json``: the end
    placed by two short ``wing/top-right`` proposals, one on a mortar joint
    0.66 px off, 1.8x the fully marked error, nothing said). Proposed from
    one photograph where the scan is loose, the crease lies within a pixel
    of its true line (the painted band covers whole pixels) and puts the
    end within that pixel's move of the truth."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.capture.scenes.facade_edges import project_edges
    from lumigraph.stereo.debevec1996.edges import EdgeMarks, Mark
    from lumigraph.stereo.debevec1996.solve import project_model_edges, solve_facade

    truth = BlockModel.from_dict(TWO, where="test")
    cams = {"a": _crease_cameras()["a"], "c": _camera((-40.0, 12.0, 9.0), (-6.0, 1.0, 2.0)),
            "d": _camera((25.0, -30.0, 8.0), (-2.0, 0.0, 2.0)),
            "e": _camera((-15.0, 30.0, 10.0), (-3.0, 1.0, 2.0))}
    rng = np.random.default_rng(seed)
    seen = {p: {v["edge"]: np.array(v["segment"], float) for v in project_edges(
        truth, {p: c}, min_length_px=15, samples=41)[p]} for p, c in cams.items()}
    marks = [Mark(p, e, s + rng.normal(0.0, 0.5, 4)) for p, es in seen.items()
             for e, s in es.items() if not (e.startswith("wing/") and "right" in e)]
    a, b = np.split(seen["c"]["wing/back-right"], 2)
    u = (b - a) / np.hypot(*(b - a))
    n = np.array([-u[1], u[0]])
    marks.append(Mark("c", "wing/back-right", np.r_[a + n, a + 20.0 * u + n]))
    marks = EdgeMarks(tuple(marks), tuple(cams))
    K = {p: c["K"] for p, c in cams.items()}
    start = truth.with_values({"wing/width": 4.2, "wing/offset_x": -6.95})
    sol = solve_facade(start, marks, K, noise_px=0.5, hold_unconstrained=am.ROUGH_HOLD)
    assert not sol.held
    true_lines = project_model_edges(truth, cams["a"]["K"], cams["a"]["R"], cams["a"]["t"])
    greys = {p: 100.0 + rng.normal(0.0, 2.0, (480, 640)) for p in "cde"}
    greys["a"] = _painted_step(true_lines["wing/front-right"], 5.0, rng=rng)

    def creases():
        return am._creases(sol, {}, current=start, marks=marks, K=K, images=greys, greys=greys,
                           rough=start, trust=0.3, rough_rotations=None, noise_px=0.5,
                           where="test")

    am._ONE_PHOTO_LOOSE = False
    try:
        assert creases()[1] == {}                                               # the premise
    finally:
        am._ONE_PHOTO_LOOSE = True
    got, kept, said = creases()
    assert list(kept) == [("a", "wing/front-right")] and said
    p, q = true_lines["wing/front-right"]
    nl = np.array([-(q - p)[1], (q - p)[0]]) / np.hypot(*(q - p))
    seg = kept["a", "wing/front-right"].segment
    assert max(abs((seg[:2] - p) @ nl), abs((seg[2:] - p) @ nl)) <= 1.0
    # the end's move per pixel across the crease in a: the painting's resolution
    names, v = _WING_END
    rate = max(r for (ph, i), (_, _, r) in am._crease_lines(
        truth, np.array([truth.slot_of(nm) for nm in names]), v, 0.0, {"a": cams["a"]},
        tol_px=1e9).items() if truth.edge_names[i] == "wing/front-right")
    # the direction v moves the end (offset_x + width / 2) by v_offset + v_width / 2 per unit
    per_unit = v[0] + v[1] / 2.0
    end = got.params["wing/offset_x"] + got.params["wing/width"] / 2.0
    assert abs(end - (-4.95)) <= per_unit / rate


@pytest.fixture(scope="module")
def rendered():
    """The bench's rendered building, seed 4 (a tuning layout): the start 4.9 %
    small, textured walls (stereo/bench_facade.py, ``rendered_case``)."""
    from lumigraph.stereo import bench_facade as BF

    return BF.rendered_case(4)


def _far(c, marks, limit=1.5):
    """The proposals with an end more than ``limit`` px (3 sigma of a hand
    mark) from their true edge."""
    from lumigraph.stereo.debevec1996.solve import project_model_edges

    out = set()
    for m in marks.marks:
        cam = c["cameras"][m.photo]
        a, b = project_model_edges(c["model"], np.array(cam["K"]), np.array(cam["R"]),
                                   np.array(cam["t"]).ravel())[m.edge]
        d = b - a
        n = np.array([-d[1], d[0]]) / np.hypot(*d)
        if m.proposed and max(abs((m.segment[:2] - a) @ n), abs((m.segment[2:] - a) @ n)) > limit:
            out.add((m.photo, m.edge))
    return out


@pytest.mark.slow
def test_on_the_rendered_building_no_proposal_is_off_its_edge(rendered):
    """Window frames, brick courses, a buried flush edge and a seam: with the checks
    of this module switched off, proposals sit on them and the solve lands
    beyond 1.2x the fully marked error (a dozen and 20x before the colour
    channels were searched too, four and more since); with them, none does and
    the error is within the issue's 1.2x of the fully marked solve's."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo.debevec1996.solve import solve_facade

    c = rendered
    switches = ("_CONTINUES", "_ON_NEAREST_FACE", "_SEARCH_UNDETECTED", "_NO_SEAMS")

    def run():
        res = am.automark(c["start"], c["hand"], c["images"], c["K"], noise_px=0.5,
                          rough_rotations=c["rotations"])
        sol = solve_facade(c["start"], res.marks, c["K"], noise_px=0.5, hold_unconstrained=True)
        err = np.sqrt(np.mean([((sol.params[n] - v) / v) ** 2 for n, v in c["truth"].items()]))
        return res, err

    for s in switches:
        setattr(am, s, False)
    try:
        before, err_before = run()
    finally:
        for s in switches:
            setattr(am, s, True)
    after, err = run()
    full = solve_facade(c["start"], c["full"], c["K"], noise_px=0.5)
    err_full = np.sqrt(np.mean([((full.params[n] - v) / v) ** 2 for n, v in c["truth"].items()]))
    assert _far(c, before.marks) and err_before > 1.2 * err_full, (err_before, err_full)  # premise
    assert not _far(c, after.marks)
    assert err <= 1.2 * err_full, (err, err_full)


THREE = {"blocks": [
    *TWO["blocks"],
    # a tower on the house's right, its front aligned with the house's: the
    # two fronts are one plane, and the house's front-right corner between
    # them is no line in a photograph
    {"name": "tower", "kind": "box", "parent": "house", "on": "base", "x": "offset",
     "y": "front", "params": {"width": 3.0, "depth": 3.0, "height": 9.0, "offset_x": 6.6}}]}


@pytest.mark.parametrize("edge, seam", [
    ("house/front-right", True),      # house front | (0.1 m gap) | tower front: one plane
    ("wing/front-right", False),      # the wing's front against the house's left wall
    ("house/front-left", False),      # a corner: front and left walls
    ("tower/top-front", False),       # the tower's front against the sky
])
def test_an_edge_between_faces_in_one_plane_is_a_seam(edge, seam):
    from lumigraph.capture.scenes.facade_edges import project_edges
    from lumigraph.stereo.debevec1996.automark import _seam

    model = BlockModel.from_dict(THREE, where="test")
    cam = _camera((-12.0, -30.0, 5.0))
    # the gap the tower's offset leaves (0.1 m, 3 px here) makes the house's
    # corner a visible edge of the model, seen through it on the tower's side
    vis = {v["edge"]: np.array(v["segment"]) for v in project_edges(
        model, {"p": cam}, min_length_px=15, samples=41,
        visible=_visible_near_flush(model, cam, tol_px=6.0))["p"]}
    assert edge in vis
    assert _seam(model, cam, vis[edge], tol_px=6.0) is seam


def test_the_same_corner_with_the_tower_set_back_is_no_seam():
    from lumigraph.capture.scenes.facade_edges import project_edges
    from lumigraph.stereo.debevec1996.automark import _seam

    spec = {"blocks": [*TWO["blocks"], {**THREE["blocks"][-1], "y": "back"}]}
    model = BlockModel.from_dict(spec, where="test")
    cam = _camera((-12.0, -30.0, 5.0))
    vis = {v["edge"]: np.array(v["segment"]) for v in project_edges(
        model, {"p": cam}, min_length_px=15, samples=41,
        visible=_visible_near_flush(model, cam, tol_px=6.0))["p"]}
    # the house's front, then (3 m behind) the tower's: two planes
    assert not _seam(model, cam, vis["house/front-right"], tol_px=6.0)



@pytest.mark.slow
def test_on_the_rendered_building_a_seam_takes_no_line_beside_it():
    """Seed 37 (a tuning layout): the tower's front is aligned with the
    house's, so the house's front-right corner is no line in the
    photographs; the rough model's gap makes it an edge of the model, and
    without the seam rule window columns 6-11 px beside it became its
    proposals. With it, no proposal is more than 3 sigma of a hand mark off."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo import bench_facade as BF

    c = BF.rendered_case(37)

    def run():
        return am.automark(c["start"], c["hand"], c["images"], c["K"], noise_px=0.5,
                           rough_rotations=c["rotations"]).marks

    # the premise on the grey channel alone, where the rule was found (the
    # colour channels find the corner's window columns less often)
    am._NO_SEAMS = am._COLOUR = False
    try:
        before = run()
    finally:
        am._NO_SEAMS = am._COLOUR = True
    assert sum(e == "house/front-right" for _, e in _far(c, before)) >= 2      # the premise
    assert not _far(c, run())


def test_a_suggested_seam_is_flagged_and_not_assumed_marked():
    """A refusal's suggestions (``unconstrained_spots``): with the tower
    (its front aligned with the house's, flush against its right wall)
    unmarked, its offset is free; the tower's front-left corner is a seam
    (the house's front runs on into the tower's), flagged as such, and the
    tower's far corners are not."""
    from lumigraph.capture.scenes.facade_edges import project_edges, ring_cameras
    from lumigraph.stereo.debevec1996.automark import refusal_lines, unconstrained_spots
    from lumigraph.stereo.debevec1996.edges import EdgeMarks

    spec = {"blocks": [*TWO["blocks"][:1], {**THREE["blocks"][-1], "params": {
        **THREE["blocks"][-1]["params"], "offset_x": 6.5}}]}         # flush: 5 + 3/2
    model = BlockModel.from_dict(spec, where="test")
    cams = ring_cameras(6, target=[1.5, 0, 4], radius=30, height=4, focal_px=700,
                        arc_deg=(-160.0, -70.0))
    seen = {p: [e for e in v if not e["edge"].startswith("tower/")]
            for p, v in project_edges(model, cams).items()}
    marks = EdgeMarks.from_dict({"photographs": seen}, model=model, photographs=list(cams))
    spots = unconstrained_spots(model, marks, {p: c["K"] for p, c in cams.items()},
                                {p: c["image_size"] for p, c in cams.items()},
                                ["tower/offset_x"], suggestions=12)
    sug = spots[0]["suggest"]
    flags = {q["edge"]: q["seam"] for q in sug}
    assert flags.get("tower/front-left") is True, sug
    assert all(not f for e, f in flags.items() if e in ("tower/front-right", "tower/top-right"))
    line = refusal_lines(spots)[1]
    assert "(a seam: a line only where the blocks differ in colour)" in line


def test_the_free_direction_moves_only_the_end_no_mark_holds():
    """The wing's left end and its long edges marked: width and offset may
    still move its right end (offset by half what the width gains), and
    only that; with the right end's corner marked too, nothing is free."""
    from lumigraph.stereo.debevec1996.automark import _free_direction

    model = BlockModel.from_dict(TWO, where="test")
    names = ["wing/width", "wing/offset_x"]
    left = ["wing/front-left", "wing/top-left", "wing/top-front", "wing/bottom-front"]
    N = _free_direction(model, names, left)
    assert N.shape == (1, 2)
    v = N[0] * np.sign(N[0][0])
    np.testing.assert_allclose(v, np.array([1.0, 0.5]) / np.hypot(1.0, 0.5), atol=1e-12)
    assert _free_direction(model, names, [*left, "wing/front-right"]).shape == (0, 2)


def _bricks(rng, *, crease_x=60.5, joint_x=None, rows=160, cols=120):
    """Brick courses 8 px high (dark bed joints, staggered head joints every
    16 px, each brick's grey drawn around 110 with σ 8, image noise σ 2),
    the wall right of ``crease_x`` lit 30 grey levels brighter (a crease
    between two walls of one brick), and optionally a head-joint column at
    ``joint_x`` running the whole height (a joint line parallel to the crease)."""
    y, x = np.mgrid[:rows, :cols].astype(float)
    course = (y // 8).astype(int)
    brick = ((x + 8 * (course % 2)) // 16).astype(int)
    g = 110.0 + rng.normal(0.0, 8.0, (rows // 8 + 1, cols // 16 + 2))[course, brick]
    g[(y % 8) < 1.0] = 70.0
    g[((x + 8 * (course % 2)) % 16) < 1.0] = 70.0
    if joint_x is not None:
        g[:, int(joint_x)] = 70.0
    g = g + 30.0 * (x > crease_x)
    return g + rng.normal(0.0, 2.0, g.shape)


@pytest.mark.parametrize("seed", range(4))
def test_the_band_step_peaks_on_a_crease_between_brick_walls_with_a_joint_beside_it(seed):
    """``_band_steps`` and ``_robust_z`` over vertical candidate lines across
    a crease with a joint column 4.5 px beside it: the z peaks within the
    1.5 px that ``_crease`` refines over (the joint darkens one band and
    pulls the peak towards it), passes the acceptance (``CREASE_Z``) on
    its own, and on the walls, 5 px or more from crease and joint, stays
    under ``CREASE_SECOND`` of the peak."""
    from lumigraph.stereo.debevec1996.automark import (
        CREASE_SECOND,
        CREASE_Z,
        _band_steps,
        _robust_z,
    )

    g = _bricks(np.random.default_rng(seed), joint_x=56)
    xs = np.arange(20.5, 100.0, 0.25)
    # drawn upwards: the left normal points to +x, the brighter wall
    z = np.array([_robust_z(_band_steps(g, np.array([x, 150.0]), np.array([x, 10.0])))
                  for x in xs])
    k = int(np.argmax(np.abs(z)))
    assert abs(xs[k] - 60.5) <= 1.5
    assert z[k] >= CREASE_Z
    walls = (np.abs(xs - 60.5) >= 5.0) & (np.abs(xs - 56.0) >= 5.0)
    assert np.abs(z[walls]).max() <= CREASE_SECOND * z[k]


def test_the_crease_refinement_reaches_the_band_steps_peak_from_the_scans_line():
    """Synthetic bricks, 8 seeds, with a joint column 4.5 px either side of
    the crease or none beyond the bricks' own head joints. The scan's line
    is the peak of the robust z; where it lies within the 1.5 px that a
    joint pulls it (the test above), the refinement from it lands on the
    crease to the same 1.5 px. The z and the mean band step are pulled
    differently (the z by the joint's effect on the spread, the mean by its
    darkening one band), so the refinement must reach past the 1.5 px
    itself: at the old reach of 1.5 px some of these creases were dropped."""
    from lumigraph.stereo.debevec1996.automark import _band_steps, _refine_crease, _robust_z

    xs = np.arange(20.5, 100.0, 0.25)
    dropped_before = 0
    for joint in (56, 65, None):
        for seed in range(8):
            g = _bricks(np.random.default_rng(seed), joint_x=joint)
            z = np.array([_robust_z(_band_steps(g, np.array([x, 150.0]), np.array([x, 10.0])))
                          for x in xs])
            x0 = xs[int(np.argmax(np.abs(z)))]
            if abs(x0 - 60.5) > 1.5:
                continue        # a scan this far off is not the refinement's to mend
            a, b = np.array([x0, 150.0]), np.array([x0, 10.0])
            o = _refine_crease(g, a, b, sign=1.0)
            assert o is not None and abs(x0 + o - 60.5) <= 1.5, (joint, seed, x0, o)
            dropped_before += _refine_crease(g, a, b, sign=1.0, reach_px=1.5) is None
    assert dropped_before >= 1          # the premise: the old reach fell short


@pytest.mark.parametrize("seed", range(4))
def test_a_course_inside_a_brick_wall_is_a_textures_line_and_the_walls_top_is_not(seed):
    """``_in_texture`` on horizontal brick courses (bed joints every 8 px,
    12 px reach: the joints above and below are within it) under a flat
    sky from row 41: a bed joint's edge inside the wall has a parallel step
    of its sign, at least ``RIVAL_RATIO`` as strong, on each side; the
    wall's top edge against the sky has courses below it only, and the sky
    side none at all."""
    from lumigraph.stereo.debevec1996.automark import _in_texture

    g = _bricks(np.random.default_rng(seed), crease_x=1e9)
    g[:41] = 180.0 + np.random.default_rng(100 + seed).normal(0.0, 2.0, (41, g.shape[1]))
    joint = refine_segment(g, np.array([10.0, 79.6, 110.0, 79.6]))   # the joint at row 80
    # on the joint: between its two edges (79.5, 80.5), to a tenth of a pixel
    assert joint is not None and np.all(np.abs(joint[[1, 3]] - 80.0) <= 0.6)
    assert _in_texture(g, joint, reach_px=12.0)
    top = refine_segment(g, np.array([10.0, 40.6, 110.0, 40.6]))
    assert top is not None and abs(top[1] - 40.5) < 0.5
    assert not _in_texture(g, top, reach_px=12.0)
    # with the reach under the course height, the joint has no neighbour either
    assert not _in_texture(g, joint, reach_px=6.0)


@pytest.mark.parametrize("seed", range(4))
def test_a_step_along_a_third_of_the_line_counts_little_in_the_robust_z(seed):
    """A window frame on the wall, twice the crease's step, reaches along a
    third of a candidate line: the t statistic of the mean step counts it
    (the premise), the median's z does not (a quarter of t or less), while
    a crease of half that step along the whole line passes ``CREASE_Z``."""
    from lumigraph.stereo.debevec1996.automark import CREASE_Z, _band_steps, _robust_z

    a, b = np.array([60.5, 150.0]), np.array([60.5, 10.0])
    g = _bricks(np.random.default_rng(seed), crease_x=1e9)
    g[10:60, 61:] += 60.0                             # the frame's step, rows 10-60 only
    d = _band_steps(g, a, b)
    t = d.mean() / (d.std(ddof=1) / np.sqrt(len(d)))
    assert t >= 4.0                                   # the premise
    assert abs(_robust_z(d)) <= t / 4
    assert _robust_z(_band_steps(_bricks(np.random.default_rng(seed)), a, b)) >= CREASE_Z


@pytest.mark.slow
@pytest.mark.parametrize("seed, held", [(19, True), (49, False)])
def test_on_the_rendered_building_the_wings_crease_is_found(seed, held):
    """Two tuning layouts. The marks fix the wing's left end, and its right
    end meets the house's left wall in a concave crease, brick against
    brick, which the line detector misses. Without the crease search, seed
    19 holds the wing's width and offset at the rough values, and seed 49
    places its right end from one 20 px proposal (σ of the width 6 %). With
    it, the crease is proposed, every proposal on it within 1.5 px (3 σ of
    a hand mark) of its true edge and nothing is held. On seed 49 the error
    is then within the issue's 1.2x of the fully marked solve's. On seed 19
    it is not (1.48x: the wing's width 1 % off with the crease's proposals
    within 0.4 px), and the solve holding the wing's free direction at the
    rough values happens to be nearer (1.33x): a crease found is a measured
    edge, a held direction a guess that can land well. Seed 42, the held
    layout until session 31, now finds the crease's line without the
    search (the association's 3-D line test). The premise and the search
    run on the grey channel, where they were found; the colour-opponent
    channels (session 32) often see the crease's line themselves, so the
    last run, as automatic marking runs, checks the outcome: nothing held,
    no proposal off its edge, and on seed 49 the 1.2x. The first-round vote
    (session 33) is off in the premise and the search too: with it, seed
    19 holds nothing even without the crease search, so the premise is
    not there to test."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo import bench_facade as BF
    from lumigraph.stereo.debevec1996.solve import solve_facade

    c = BF.rendered_case(seed)

    def run():
        return am.automark(c["start"], c["hand"], c["images"], c["K"], noise_px=0.5,
                           rough_rotations=c["rotations"])

    # the premise on the grey channel alone: the colour-opponent channels
    # often find the crease's line (the two walls face different ways, so
    # their shading differs in colour as well), which the search is for
    am._CREASE = am._COLOUR = am._VOTE_FIRST = False
    try:
        before = run()
    finally:
        am._CREASE = am._COLOUR = am._VOTE_FIRST = True
    # the premise
    assert (set(before.solution.held) == {"wing/width", "wing/offset_x"}) is held
    assert not any(m.edge == "wing/front-right" for m in before.marks.marks)
    # the search on the grey channel: the crease is found
    am._COLOUR = am._VOTE_FIRST = False
    try:
        grey = run()
    finally:
        am._COLOUR = am._VOTE_FIRST = True
    assert not grey.solution.held
    creases = {(m.photo, m.edge) for m in grey.marks.marks
               if m.proposed and m.edge == "wing/front-right"}
    assert creases and not _far(c, grey.marks) & creases
    # and as it runs: the wing placed, nothing held, no proposal off its edge
    after = run()
    assert not after.solution.held
    assert not _far(c, after.marks)
    sol = solve_facade(c["start"], after.marks, c["K"], noise_px=0.5, hold_unconstrained=True)
    full = solve_facade(c["start"], c["full"], c["K"], noise_px=0.5)
    err = [np.sqrt(np.mean([((s.params[n] - v) / v) ** 2 for n, v in c["truth"].items()]))
           for s in (sol, full)]
    if not held:
        assert err[0] <= 1.2 * err[1], err


@pytest.mark.slow
def test_from_the_renderers_rough_model_the_held_parameters_are_voted_first():
    """Seed 5 (a tuning layout), its first noise draw, started from the
    renderer's own rough ``blocks.json`` (each parameter off by its own
    amount, up to 15 %). The four hand marks per photograph fix no
    parameter to the trust test, so the first round holds all eleven.
    Proposed against that model under the first round's wide gates, the
    wing's top edges take lines a face away and the wing ends 39 % too wide
    with a σ under 1 %: silently wrong (the start as given alone). With
    what the hand marks leave free set first by the detected length it
    explains, the two starts' ends are recorded and the voted one is kept
    (neither rejects a hand mark or holds a parameter; the voted end found
    more edges on detected lines, 88 proposals against 82). Every
    parameter then lands within 3 σ of the truth, σ as the solve reports
    it. Two later rules rescue this start without the vote as well:
    session 37's replacement of proposals on edges the solved model hides
    (the wing's width then 0.1 σ off) and session 38's seam share
    (``SEAM_SHARE``: 1.0 σ off, the start as given then ends with 89
    proposals and is kept), and session 39's refusal of a texture's lines
    (``_in_texture``: 0.9 σ off), and session 42's restart of a run whose
    marks do not fit the noise (``_RESTART``: 0.4 σ off). So the premise
    and the vote's own case run with none of them, and the last run, with
    everything, asks only that the result be right and both starts be
    recorded (first, before any restart)."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo import bench_facade as BF
    from lumigraph.stereo.debevec1996.solve import solve_facade

    c = BF.rendered_case(5)
    draws = BF.rendered_draws(5, draws=1)
    _, hand = draws[0]

    def z(*, vote):
        am._VOTE_FIRST = vote
        am._UNSEEN_CREASE, share, am.SEAM_SHARE = False, am.SEAM_SHARE, am.CONTINUES_SHARE
        am._IN_TEXTURE = am._RESTART = False
        try:
            return z_all()
        finally:
            am._VOTE_FIRST = am._UNSEEN_CREASE = am._IN_TEXTURE = am._RESTART = True
            am.SEAM_SHARE = share

    def z_all():
        res = am.automark(draws.rough, hand, c["images"], c["K"], noise_px=0.5,
                          rough_rotations=c["rotations"])
        sol = solve_facade(draws.rough, res.marks, c["K"], noise_px=0.5, hold_unconstrained=True)
        return res, {n: abs(sol.params[n] - v) / sol.std[n] for n, v in c["truth"].items()}

    res, before = z(vote=False)
    assert before["wing/width"] > 10, before          # the premise: far beyond its σ
    assert [x["start"] for x in res.candidates] == ["rough model"]
    res, voted_only = z(vote=True)
    assert max(voted_only.values()) <= 3.0, voted_only
    voted, rough = res.candidates
    assert voted["chosen"] and not rough["chosen"]
    assert voted["proposed"] > rough["proposed"], res.candidates
    res, after = z_all()
    assert max(after.values()) <= 3.0, after
    starts = [x["start"] for x in res.candidates]
    assert starts[:2] == ["held parameters voted first", "rough model"], starts
    assert starts[2:] in ([], ["restarted from the first solve"]), starts
    assert sum(x["chosen"] for x in res.candidates) == 1


@pytest.mark.slow
def test_hand_marks_the_proposals_push_out_are_not_blamed_alone():
    """Seed 0 (a tuning layout), its third noise draw, from the renderer's
    rough ``blocks.json``: the proposals hold the wing 36 % too shallow and
    the final solve leaves out five hand marks, each called "mis-marked?"
    by the solve's own lines. Automatic marking says as well that the
    proposals may be at fault, naming each left-out mark (not yet fixed:
    docs/decisions/facade.md, session 33). Session 42's restart of a run
    whose marks do not fit the noise (``_RESTART``) keeps here an end that
    rejects none of them, so the warning's case runs without it."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo import bench_facade as BF

    c = BF.rendered_case(0)
    draws = BF.rendered_draws(0, draws=3)
    _, hand = draws[2]
    am._RESTART = False
    try:
        res = am.automark(draws.rough, hand, c["images"], c["K"], noise_px=0.5,
                          rough_rotations=c["rotations"])
    finally:
        am._RESTART = True
    out = am._hand_outliers(res.solution, hand)
    said = [w for w in res.warnings if w.startswith("the solve with the proposals leaves out")]
    assert out and len(said) == 1, res.warnings
    assert all(f"{e!r} on {p!r}" in said[0] for p, e in out), said
    assert "solve the hand marks alone" in said[0]


@pytest.mark.slow
def test_a_start_whose_marks_do_not_fit_the_noise_is_restarted_from_its_solve():
    """Seed 124 (seen in session 40, this rule designed on it in sessions
    41-42), its second noise draw, started from the renderer's rough
    ``blocks.json``: each parameter 3-14 % off, each its own way, so the
    poses the hand marks give put edges 20-45 px from their lines, and the
    first round's wide gates take a neighbour's (11 of its 33 proposals
    more than 2 px off). The run ended with its marks fitting at σ̂ twice
    the 0.5 px noise given and an RMS parameter error 23x the fully marked
    solve's. What its solve fixed is nearer the truth than the start was
    (the house's depth 14 % → 2 % off; the wing's width, held and voted
    round after round, ran to 4x and is not carried over): started again
    from those values, the marks fit the noise and every parameter lands
    within 3 σ of the truth. The
    premise is read from the record: the first run's end does not fit the
    noise; the restart's does and is kept."""
    from lumigraph.stereo import bench_facade as BF
    from lumigraph.stereo.debevec1996.automark import automark
    from lumigraph.stereo.debevec1996.solve import solve_facade

    c = BF.rendered_case(124)
    draws = BF.rendered_draws(124, draws=2)
    _, hand = draws[1]
    res = automark(draws.rough, hand, c["images"], c["K"], noise_px=0.5,
                   rough_rotations=c["rotations"])
    *first, again = res.candidates
    assert first and not any(x["fits_noise"] for x in first), res.candidates     # the premise
    assert again["start"] == "restarted from the first solve", res.candidates
    assert again["chosen"] and again["fits_noise"], res.candidates
    sol = solve_facade(draws.rough, res.marks, c["K"], noise_px=0.5, hold_unconstrained=True)
    z = {n: abs(sol.params[n] - v) / sol.std[n] for n, v in c["truth"].items()}
    assert max(z.values()) <= 3.0, z


def _wing_crease_taken(c, start, full, hand, constant, old):
    """Automatic marking from ``start`` on ``c``'s photographs, first with
    the automark module's ``constant`` at its ``old`` value (the premise: no
    ``wing/front-right`` proposed, the error beyond the issue's 1.2x of the
    fully marked solve's), then as it stands: the crease proposed in two
    photographs or more, no proposal off its true edge, the error within
    1.2x. Returns the first run's result."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo.debevec1996.solve import solve_facade

    def err(marks):
        sol = solve_facade(start, marks, c["K"], noise_px=0.5, hold_unconstrained=True)
        return np.sqrt(np.mean([((sol.params[n] - v) / v) ** 2 for n, v in c["truth"].items()]))

    def run():
        res = am.automark(start, hand, c["images"], c["K"], noise_px=0.5,
                          rough_rotations=c["rotations"])
        return res, err(res.marks)

    sf = solve_facade(start, full, c["K"], noise_px=0.5)
    err_full = np.sqrt(np.mean([((sf.params[n] - v) / v) ** 2 for n, v in c["truth"].items()]))
    now = getattr(am, constant)
    setattr(am, constant, old)
    try:
        before, err_before = run()
    finally:
        setattr(am, constant, now)
    assert not any(m.edge == "wing/front-right" for m in before.marks.marks)
    assert err_before > 1.2 * err_full, (err_before, err_full)
    after, err_after = run()
    creases = {(m.photo, m.edge) for m in after.marks.marks
               if m.proposed and m.edge == "wing/front-right"}
    assert len({p for p, _ in creases}) >= 2, after.warnings
    assert not _far(c, after.marks)
    assert err_after <= 1.2 * err_full, (err_after, err_full)
    return before


@pytest.mark.slow
def test_a_loosely_fixed_wing_end_takes_the_crease_a_short_scan_finds():
    """Seed 148 (seen in session 42, where this rule was designed), its
    second noise draw, from one factor off. The wing's right end meets the
    house's back wall in a concave crease (brick against brick); no
    detection on it passes the continuity test (its step holds along 40-45
    % of the edge), so one proposal on ``wing/top-right`` places the end,
    loosely (σ of the width 1 %), and it lands 0.12 m inside the truth, 2.7
    σ: 4.8x the fully marked solve's error. The crease search along the
    wing's least-determined direction peaks near the truth (summed |z|
    16.1, nothing 5 px away above 2), under ``CREASE_Z`` (20, set on held
    blocks scanned over the whole trust region), over ``CREASE_Z_LOOSE``
    (10, a scan of 4 σ). With it the crease is proposed, no proposal is off
    its true edge, and the error is within the issue's 1.2x of the fully
    marked solve's."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo import bench_facade as BF

    c = BF.rendered_case(148)
    full, hand = BF.rendered_draws(148, draws=2)[1]
    _wing_crease_taken(c, c["start"], full, hand, "CREASE_Z_LOOSE", am.CREASE_Z)


@pytest.mark.slow
def test_a_wing_end_the_marks_place_to_a_pixel_still_takes_its_crease():
    """Seed 163 (seen in session 42, where this rule was designed in
    session 43), its first noise draw, from the renderer's own rough
    ``blocks.json``. Every start ends fitting the noise (σ̂ 0.50 px for 0.5
    given) with no proposal on ``wing/front-right``; the wing's right end
    sits 0.07 m inside the truth, 2.2 σ, which moves its edges 1.4 px: the
    fully marked solve's error 3.2 times over. 1 σ of that direction moves
    an edge by 0.66 px, under the one pixel the loose crease scan first
    asked for, so it never ran. The crease's own proposals lie 0.30 px RMS
    from their true lines (``CREASE_PLACED_PX``): scanned, it is proposed in
    two photographs or more, no proposal is off its true edge, and the error
    is within the issue's 1.2x."""
    from lumigraph.stereo import bench_facade as BF

    c = BF.rendered_case(163)
    draws = BF.rendered_draws(163, draws=1)
    full, hand = draws[0]
    before = _wing_crease_taken(c, draws.rough, full, hand, "CREASE_PLACED_PX", 1.0)
    # the premise too: without the change every start's marks fit the noise
    assert all(x["fits_noise"] for x in before.candidates), before.candidates


def _at(c, model):
    """A solve's stand-in for :func:`_runs_on`: ``model`` seen from the
    true cameras of the rendered case ``c``."""
    from types import SimpleNamespace

    return SimpleNamespace(model=model, unknowns=tuple(model.parameter_names),
                           K={p: np.array(cm["K"]) for p, cm in c["cameras"].items()},
                           poses={p: (np.array(cm["R"]), np.array(cm["t"]).ravel())
                                  for p, cm in c["cameras"].items()})


def test_the_image_lines_run_on_past_a_tower_top_set_short_and_not_past_the_true_one():
    """Seed 176 (seen in session 43; this test designed on it in session 44),
    the true cameras. At the true model no parameter's ends have image lines
    running on past them. With the tower's height set 16 % short (where its
    automatic marking locked it: the top edges on a line 1.5 m below the
    top), the steps of its vertical edges go on past the model's top in every
    photograph that shows them, and the move to where they end puts the top
    back within the run's own resolution (places every 3 px, and the run's
    end is the last place the step shows: 3 px at the edges' median rate)."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo import bench_facade as BF

    c = BF.rendered_case(176)
    chans = {p: [am._grey(im)] + am._opponent(im) for p, im in c["images"].items()}
    assert am._runs_on(_at(c, c["model"]), c["images"], chans, min_length_px=15.0) == {}
    true = c["truth"]["tower/height"]
    short = c["model"].with_values({"tower/height": 0.84 * true})
    got = am._runs_on(_at(c, short), c["images"], chans, min_length_px=15.0)
    assert set(got) == {"tower/height"}, got
    share, move, pairs, rate = got["tower/height"]
    assert share >= am.RUN_ON_SHARE and pairs >= am.RUN_ON_PAIRS
    assert abs(0.84 * true + move - true) <= 3.0 / rate, (move, rate)


@pytest.mark.slow
def test_a_tower_locked_short_of_its_top_is_restarted_where_its_edges_end():
    """Seed 176, its first noise draw, from the renderer's rough
    ``blocks.json`` (seen in session 43; the rule designed on it in session
    44). Every start locked the tower's top edges on an image line 1.5 m
    below the top (``tower/height`` 16 % short at a small σ) and left
    ``spire/height`` to no proposal: 22.8x the fully marked solve's error.
    The steps of the tower's vertical edges run on past that top
    (:func:`_runs_on`); started again with the height moved to where they
    end, the rounds lock the top where it is, and the restart is kept. The
    premise is read from the record: the restart was tried, so the first
    ends' lines ran on; it is chosen, and every parameter lands within 3 σ
    of the truth."""
    from lumigraph.stereo import bench_facade as BF
    from lumigraph.stereo.debevec1996.automark import automark
    from lumigraph.stereo.debevec1996.solve import solve_facade

    c = BF.rendered_case(176)
    draws = BF.rendered_draws(176, draws=1)
    _, hand = draws[0]
    res = automark(draws.rough, hand, c["images"], c["K"], noise_px=0.5,
                   rough_rotations=c["rotations"])
    *first, again = res.candidates
    assert first and again["start"] == "restarted where the image lines past its corners end"
    assert again["chosen"], res.candidates
    assert not any("run on past" in w for w in res.warnings), res.warnings
    sol = solve_facade(draws.rough, res.marks, c["K"], noise_px=0.5, hold_unconstrained=True)
    z = {n: abs(sol.params[n] - v) / sol.std[n] for n, v in c["truth"].items()}
    assert max(z.values()) <= 3.0, z


def test_the_image_lines_run_on_past_a_wing_end_set_short_and_not_past_the_true_one():
    """Seed 233 (fresh in session 45, the rule designed on it in session
    46), the true cameras. Along the direction that moves the wing's right
    end alone (width and half of it in the offset), the steps of the edges
    whose right ends it slides stop at the true end in the median pair. With
    the end 0.8 m short (where a lone proposal on a window's edge put it),
    they run on past it by :data:`RUN_ON_ALONE_PX` or more, and the move to
    where they end puts it back within the run's resolution (places every
    3 px: 3 px at the median rate)."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo import bench_facade as BF

    c = BF.rendered_case(233)
    model = c["model"]
    chans = {p: [am._grey(im)] + am._opponent(im) for p, im in c["images"].items()}
    d = np.zeros(len(model.values))
    d[model.slot_of("wing/width")], d[model.slot_of("wing/offset_x")] = 1.0, 0.5

    def run(m):
        sol = _at(c, m)
        return am._direction_run(sol, d, am._end_views(sol, c["images"], min_length_px=15.0),
                                 chans, min_length_px=15.0)

    at_truth = run(model)
    assert at_truth is not None and at_truth[0] < am.RUN_ON_ALONE_PX, at_truth
    t = c["truth"]
    short = model.with_values({"wing/width": t["wing/width"] - 0.8,
                               "wing/offset_x": t["wing/offset_x"] - 0.4})
    median, move, pairs, rate = run(short)
    assert median >= am.RUN_ON_ALONE_PX and pairs >= am.RUN_ON_PAIRS
    assert abs(move - 0.8) <= 3.0 / rate, (move, rate)


@pytest.mark.slow
def test_a_wing_end_one_proposal_places_short_of_its_corner_is_restarted_where_its_lines_end():
    """Seed 233, its second noise draw, from the renderer's rough
    ``blocks.json`` (fresh in session 45, the rule designed on it in session
    46). One proposal of ``wing/front-right``, on a window's edge 36 px in
    from the corner in one photograph, alone placed the wing's right end:
    ``wing/width`` 40 % short at a σ of 0.2 %, 52x the fully marked solve's
    error, and only the lone-proposal warning said anything. The steps of
    the wing's horizontal edges run on past that end; started again with
    the end moved to where they stop, the rounds find the corner, the
    restart is kept, and the error is within the issue's 1.2x of the fully
    marked solve's, with nothing left to warn of."""
    from lumigraph.stereo import bench_facade as BF

    c, start, hand, err, _, err_full = _crease_draw(233, 1)
    before = _automark_with(c, start, hand, _RUN_ON_ALONE=False)
    # the premise: beyond 1.2x, and the one proposal that alone placed the end is named
    assert err(before.marks, hold_unconstrained=True) > 1.2 * err_full
    lone = [w for w in before.warnings if w.startswith("proposals that alone")]
    assert lone and "'wing/front-right'" in lone[0], before.warnings
    after = _automark_with(c, start, hand)
    assert [x["start"] for x in after.candidates if x["chosen"]] == [
        "restarted where the image lines past its corners end"], after.candidates
    assert err(after.marks, hold_unconstrained=True) <= 1.2 * err_full
    assert not any(w.startswith(BF.DOUBTS) for w in after.warnings), after.warnings


@pytest.mark.slow
def test_a_start_that_leaves_the_hand_marks_beyond_their_noise_is_not_kept():
    """Seed 64, its fourth noise draw, from the renderer's rough
    ``blocks.json`` (a reported seed until session 46, where this rule was
    designed on it). The start with the held parameters voted first ends
    with the most proposals (88 against the rough model's 83) and was kept
    for them, but its model leaves the user's own marks beyond their noise
    (0.73 px RMS for 0.5 px given): every parameter came out 5 % small, 22x
    the fully marked solve's error. The hand marks are the same in every
    start, so their fit ranks before the proposals' count: the record shows
    the voted start ahead by its proposals and misfitting its hand marks,
    the kept end fits them, and the error is within the issue's 1.2x of
    the fully marked solve's."""
    from lumigraph.stereo.debevec1996.automark import automark

    c, start, hand, err, _, err_full = _crease_draw(64, 3)
    res = automark(start, hand, c["images"], c["K"], noise_px=0.5, rough_rotations=c["rotations"])
    by = {x["start"]: x for x in res.candidates}
    voted, rough = by["held parameters voted first"], by["rough model"]
    assert voted["proposed"] > rough["proposed"] and not voted["hand_marks_fit_noise"], by
    assert (voted["hand_marks_rejected"], voted["held"]) == (rough["hand_marks_rejected"],
                                                             rough["held"]), by
    kept = [x for x in res.candidates if x["chosen"]]
    assert len(kept) == 1 and kept[0]["hand_marks_fit_noise"], res.candidates
    assert err(res.marks, hold_unconstrained=True) <= 1.2 * err_full


def _automark_with(c, start, hand, **switches):
    """Automatic marking of a rendered draw with the module's ``switches``
    (name=value) set for this call alone: the code a test's premise ran."""
    import lumigraph.stereo.debevec1996.automark as am

    was = {k: getattr(am, k) for k in switches}
    for k, v in switches.items():
        setattr(am, k, v)
    try:
        return am.automark(start, hand, c["images"], c["K"], noise_px=0.5,
                           rough_rotations=c["rotations"])
    finally:
        for k, v in was.items():
            setattr(am, k, v)


def _crease_draw(seed, k):
    """The rendered case ``seed``'s noise draw ``k`` from the renderer's
    rough model: ``(c, start, hand, err, creases, err_full)``, ``err`` the
    RMS relative parameter error of a solve of some marks, ``creases`` the
    photographs of an automatic marking's ``wing/front-right`` proposals."""
    from lumigraph.stereo import bench_facade as BF
    from lumigraph.stereo.debevec1996.solve import solve_facade

    c = BF.rendered_case(seed)
    draws = BF.rendered_draws(seed, draws=k + 1)
    full, hand = draws[k]
    start = draws.rough

    def err(marks, **kw):
        sol = solve_facade(start, marks, c["K"], noise_px=0.5, **kw)
        return np.sqrt(np.mean([((sol.params[n] - v) / v) ** 2 for n, v in c["truth"].items()]))

    def creases(res):
        return {m.photo for m in res.marks.marks if m.proposed and m.edge == "wing/front-right"}

    return c, start, hand, err, creases, err(full)


def _crease_taken(c, start, hand, err, creases, err_full):
    """Automatic marking of the draw as it stands: the crease proposed in two
    photographs or more, no proposal off its true edge, and the error within
    the issue's 1.2x of the fully marked solve's (``_crease_draw``'s
    measures). Returns the result."""
    after = _automark_with(c, start, hand)
    assert len(creases(after)) >= 2, after.warnings
    assert not _far(c, after.marks)
    assert err(after.marks, hold_unconstrained=True) <= 1.2 * err_full
    return after


@pytest.mark.slow
def test_a_wing_end_placed_by_one_crease_proposal_takes_the_crease_in_the_others():
    """Seed 193 (seen in session 44, where this rule was designed), its
    second noise draw, from the renderer's rough ``blocks.json``. The wing's
    right end is placed by three proposals, each within 1.1 px of its true
    edge: ``wing/top-right`` in two photographs and the crease
    ``wing/front-right`` in one; the end lands 0.09 m inside the truth,
    about 2.5 σ, the fully marked solve's error four times over, and nothing
    is warned. The loose crease scan along the end's direction peaks within
    a few centimetres of the truth, but it was allowed to propose only edges
    marked in no photograph, and ``wing/front-right`` was marked in one.
    Allowed to propose it in the others, it does (two photographs or more),
    no proposal is off its true edge, and the error is within the issue's
    1.2x of the fully marked solve's."""
    from lumigraph.stereo import bench_facade as BF

    c, start, hand, err, creases, err_full = _crease_draw(193, 1)
    before = _automark_with(c, start, hand, _CREASE_MARKED=False)
    # the premise: one photograph's crease proposal, the error beyond 1.2x, no doubt said
    assert len(creases(before)) == 1, creases(before)
    assert err(before.marks, hold_unconstrained=True) > 1.2 * err_full
    assert not any(w.startswith(BF.DOUBTS) for w in before.warnings), before.warnings
    _crease_taken(c, start, hand, err, creases, err_full)


@pytest.mark.slow
def test_a_wing_crease_a_pixel_and_more_off_the_scans_line_is_refined_in_both_photographs():
    """Seed 66, its second noise draw, from the renderer's rough model
    (a reported seed until session 45, seen since: this rule was designed on
    it and on seed 27). The wing's right end meets the house in a crease of
    brick against brick. The scan along the end's loose direction peaks in
    photographs 02 and 03, but its line lies 0.8 and 1.3 px short of the
    true crease (its robust z is pulled by a joint column), and photograph
    03's refinement, reaching 1.5 px, peaked on its window's edge and was
    dropped; a crease in one photograph is no proposal, and the width
    stayed 1.5 % short (3.2x the fully marked solve's error), placed by one
    proposal on ``wing/top-right`` alone (said since session 45; silent
    before). Reaching :data:`CREASE_REACH_PX`, both photographs take the
    crease, no proposal is off its true edge, and the error is within the
    issue's 1.2x of the fully marked solve's."""
    from lumigraph.stereo import bench_facade as BF

    c, start, hand, err, creases, err_full = _crease_draw(66, 1)
    # (a crease in one photograph is proposed by a loose scan since session
    # 48: photograph 02's here; the premise is that of the rule's design)
    before = _automark_with(c, start, hand, CREASE_REACH_PX=1.5, _ONE_PHOTO_LOOSE=False)
    # the premise: no crease proposal, the error beyond 1.2x; the one
    # proposal that placed the end alone is named (before session 45,
    # nothing was said)
    assert not creases(before), creases(before)
    assert err(before.marks, hold_unconstrained=True) > 1.2 * err_full
    lone = [w for w in before.warnings if w.startswith("proposals that alone")]
    assert lone and "'wing/top-right'" in lone[0] and "wing/width" in lone[0], before.warnings
    after = _crease_taken(c, start, hand, err, creases, err_full)
    assert not any(w.startswith(BF.DOUBTS) for w in after.warnings), after.warnings


@pytest.mark.slow
def test_a_wing_end_the_marks_place_to_a_few_pixels_takes_the_crease_its_short_scan_finds():
    """Seed 263 (fresh in session 47, where this rule was designed), its
    second noise draw, from the renderer's rough ``blocks.json``. Two short
    proposals on ``wing/top-right`` place the wing's right end, 4 cm inside
    the truth (2.4 σ), 1.4x the fully marked solve's error, and nothing is
    warned. The loose crease scan runs along the end's direction, but its
    ±4 σ move the fastest line 3.8 px, less than ``CREASE_APART_PX``, and
    every line moving less than that was left out: none was scanned. With
    no line left out where no rival can rise, the crease is proposed in two
    photographs or more, no proposal is off its true edge, and the error is
    within the issue's 1.2x of the fully marked solve's."""
    from lumigraph.stereo import bench_facade as BF

    c, start, hand, err, creases, err_full = _crease_draw(263, 1)
    before = _automark_with(c, start, hand, _NO_RIVALS=False)
    # the premise: no crease proposal, the error beyond 1.2x, no doubt said
    assert not creases(before), creases(before)
    assert err(before.marks, hold_unconstrained=True) > 1.2 * err_full
    assert not any(w.startswith(BF.DOUBTS) for w in before.warnings), before.warnings
    _crease_taken(c, start, hand, err, creases, err_full)


@pytest.mark.slow
def test_a_hidden_proposal_is_replaced_only_by_a_crease_of_the_block_it_held():
    """Seed 289 (fresh in session 48, where this rule was designed), its
    second noise draw, from the renderer's rough ``blocks.json``. One start
    ends with the tower's top 25 % low, held by a ``tower/top-left``
    proposal on photograph 03 that the solved model hides. Left out, it
    frees ``tower/height``; the crease search then ran over every block,
    found nothing along the tower's height but took the spire's hips, 16 %
    high, as the spire's crease, and they fixed the tower's top 14 % high:
    the replacement was kept, that start ranked first, and the result was
    32x the fully marked solve's error with no doubt said (the premise).
    Searched along the freed block's own direction only, nothing replaces
    the hidden proposal, that start keeps its doubt, and the start that
    ends on the true lines is chosen: within the issue's 1.2x."""
    from lumigraph.stereo import bench_facade as BF

    c, start, hand, err, _, err_full = _crease_draw(289, 1)
    before = _automark_with(c, start, hand, _UNSEEN_OWN_BLOCK=False)
    assert any(w.startswith("a crease found for spire/height") for w in before.warnings), \
        before.warnings
    assert err(before.marks, hold_unconstrained=True) > 10 * err_full
    assert not any(w.startswith(BF.DOUBTS) for w in before.warnings), before.warnings
    after = _automark_with(c, start, hand)
    assert not any("spire" in w for w in after.warnings), after.warnings
    assert err(after.marks, hold_unconstrained=True) <= 1.2 * err_full
