"""Automatic marking on textured walls (stereo/debevec1996/automark.py):
the checks that keep window frames, brick joints and a flush edge seen
from behind its wall from giving proposals, unit by unit on images whose
edges are known exactly, then on the rendered building."""

from __future__ import annotations

import numpy as np
import pytest

from lumigraph.stereo.debevec1996.automark import (
    _continues,
    _visible_near_flush,
    refine_segment,
)
from lumigraph.stereo.debevec1996.model import BlockModel

STEP = 40.0          # grey levels across the edges below


def _wall(*, rows=120, cols=120, edge_x=60.5):
    """A vertical step of STEP grey levels at x = ``edge_x`` (pixel centres
    at integers: the step lies between columns)."""
    x = np.arange(cols)[None, :].repeat(rows, 0).astype(float)
    return 100.0 + STEP * np.clip(x - edge_x + 0.5, 0.0, 1.0)


def test_a_step_along_the_whole_edge_continues():
    g = _wall()
    seg = refine_segment(g, np.array([60.3, 20.0, 60.3, 50.0]))
    assert seg is not None and abs(seg[0] - 60.5) < 0.05
    # the detection covers a third of the edge; the step runs all along it
    assert _continues(g, seg, np.array([60.5, 5.0, 60.5, 115.0]))


def test_a_step_along_a_third_of_the_edge_does_not_continue():
    # a window frame beside a wall's corner: the step stops where the window
    # does, two thirds of the corner's length show no step on its line
    g = np.full((120, 120), 100.0)
    g[20:55, 61:] += STEP
    seg = refine_segment(g, np.array([60.3, 22.0, 60.3, 52.0]))
    assert seg is not None
    assert not _continues(g, seg, np.array([60.5, 5.0, 60.5, 115.0]))


def test_a_step_of_the_other_sign_does_not_continue_it():
    # the same line, but the wall beyond the window is darker on the other
    # side: a different boundary, not the detection's step running on
    g = np.full((120, 120), 100.0)
    g[:40, 61:] += STEP
    g[40:, :61] += STEP
    seg = refine_segment(g, np.array([60.3, 5.0, 60.3, 35.0]))
    assert not _continues(g, seg, np.array([60.5, 5.0, 60.5, 115.0]))


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


def test_on_the_rendered_building_no_proposal_is_off_its_edge(rendered):
    """Window frames, brick courses and a buried flush edge: with the checks
    of this module switched off, a dozen proposals sit on them and the
    solve lands 20x the fully marked error off; with them, none does and
    the error is within the issue's 1.2x of the fully marked solve's."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo.debevec1996.solve import solve_facade

    c = rendered
    switches = ("_CONTINUES", "_ON_NEAREST_FACE")

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
    assert len(_far(c, before.marks)) >= 5 and err_before > 1.2 * err_full     # the premise
    assert not _far(c, after.marks)
    assert err <= 1.2 * err_full, (err, err_full)
