"""Hard cases and bad input for Façade's photogrammetric modelling (issue 17):
a mis-marked edge, a photograph with only two marks, a parameter no mark
constrains, marks made on the wrong image, automatic marking from four hand
marks per photograph. Marks are exact (capture/scenes/facade_edges.py)
unless noise is injected, so a solve on the good marks is judged at
round-off (1e-8 relative) and a noisy one in units of its reported σ."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from cli_catalog import run_cli
from facade_checks import fixture_cameras, fixture_model

from lumigraph.capture.errors import EstimationError, InputError
from lumigraph.capture.scenes.facade_edges import (
    paint_facade,
    project_edges,
    ring_cameras,
    write_facade_folder,
)
from lumigraph.stereo.bench_facade import four_hand_marks
from lumigraph.stereo.debevec1996.automark import automark
from lumigraph.stereo.debevec1996.edges import EdgeMarks
from lumigraph.stereo.debevec1996.solve import solve_facade


@pytest.fixture(scope="module")
def model():
    return fixture_model()


@pytest.fixture(scope="module")
def cams():
    return fixture_cameras()


def marks_of(model, cams, photographs=None, **kw):
    marks = project_edges(model, cams, **kw)
    return marks, lambda m: EdgeMarks.from_dict({"photographs": m}, model=model,
                                                photographs=list(cams))


def K(cams):
    return {p: c["K"] for p, c in cams.items()}


def exact(sol, model):
    return max(abs(sol.params[n] - v) / v for n, v in model.named_values().items())


def test_a_mis_marked_edge_is_found_and_reported(model, cams):
    raw, mk = marks_of(model, cams)
    entry = next(e for e in raw["photo_02.png"] if e["edge"] == "house/top-front")
    entry["edge"] = "house/bottom-front"          # the user clicked the wrong edge's name
    raw["photo_02.png"] = [e for e in raw["photo_02.png"]
                           if e is entry or e["edge"] != "house/bottom-front"]
    sol = solve_facade(model, mk(raw), K(cams))
    assert [(p, e) for p, e, _ in sol.outliers] == [("photo_02.png", "house/bottom-front")]
    assert any("mis-marked" in w for w in sol.warnings)
    assert exact(sol, model) < 1e-8                # the other marks are exact


def test_a_photograph_with_two_marks_is_left_out(model, cams):
    raw, mk = marks_of(model, cams)
    raw["photo_03.png"] = raw["photo_03.png"][:2]
    sol = solve_facade(model, mk(raw), K(cams))
    assert sol.dropped == ["photo_03.png"] and "photo_03.png" not in sol.poses
    assert any("photo_03.png" in w and "2 marked edge" in w for w in sol.warnings)
    assert exact(sol, model) < 1e-8


def test_an_unconstrained_parameter_is_refused_and_named(model, cams):
    raw, mk = marks_of(model, cams)
    raw = {p: [e for e in v if not e["edge"].startswith("spire/")] for p, v in raw.items()}
    with pytest.raises(EstimationError) as e:
        solve_facade(model, mk(raw), K(cams))
    assert "spire/height" in e.value.problem
    assert "house/depth" not in e.value.problem   # only the unconstrained one is named
    # automatic marking's rough solve holds it instead
    sol = solve_facade(model.with_values({"spire/height": 2.5}), mk(raw), K(cams),
                       hold_unconstrained=True)
    assert sol.params["spire/height"] == 2.5 and abs(sol.params["tower/height"] - 9) < 1e-7


def test_the_rank_test_runs_again_at_the_solution(model, cams, monkeypatch):
    """The start's rank test sees the Jacobian at the linear initialisation;
    a solve can end where a direction it held is free (a marking-eval run,
    seed 205, ended 8e3 off). Here the start's test is made to miss
    ``spire/height``, which no mark constrains: the test at the solution
    refuses, naming it and saying where it was found; a rough solve
    (``hold_unconstrained``) holds it instead and says why."""
    import lumigraph.stereo.debevec1996.solve as S

    raw, mk = marks_of(model, cams)
    raw = {p: [e for e in v if not e["edge"].startswith("spire/")] for p, v in raw.items()}
    real, calls = S._rank_deficient, []

    def start_misses(J, names, **kw):
        calls.append(len(J))
        return [] if len(calls) == 1 else real(J, names, **kw)

    monkeypatch.setattr(S, "_rank_deficient", start_misses)
    with pytest.raises(S.Unconstrained) as e:
        solve_facade(model, mk(raw), K(cams), robust=False)
    assert len(calls) == 2 and e.value.at_solution
    assert e.value.unknowns == ("spire/height",)
    assert "at the solution" in e.value.problem
    calls.clear()
    sol = solve_facade(model.with_values({"spire/height": 2.5}), mk(raw), K(cams),
                       robust=False, hold_unconstrained=True)
    assert sol.held == ("spire/height",) and sol.params["spire/height"] == 2.5
    assert any("free at the solution" in w for w in sol.warnings)
    assert abs(sol.params["tower/height"] - 9) < 1e-7


def test_a_rough_solve_leaves_out_a_photograph_free_at_the_solution(model, cams, monkeypatch):
    """A rough pose can end with a marked edge through its camera's centre
    (a marking-eval run, seed 226: a Jacobian column 10¹⁰ times the
    others', the photograph's pose free at the solution). Made to happen
    here by the rank test at the first solution naming ``photo_03.png``'s
    pose: the rough solve leaves that photograph out, says so, and the
    rest solves exactly."""
    import lumigraph.stereo.debevec1996.solve as S

    raw, mk = marks_of(model, cams)
    real, calls = S._rank_deficient, []

    def pose_free_at_first_solution(J, names, **kw):
        calls.append(len(J))
        if len(calls) == 2:         # the first call is the start's, the second the solution's
            return ["photo_03.png:rotation", "photo_03.png:position"]
        return real(J, names, **kw)

    monkeypatch.setattr(S, "_rank_deficient", pose_free_at_first_solution)
    sol = solve_facade(model, mk(raw), K(cams), hold_unconstrained=True)
    assert "photo_03.png" in sol.dropped and "photo_03.png" not in sol.poses
    assert any("photo_03.png" in w and "at the solution" in w for w in sol.warnings)
    assert exact(sol, model) < 1e-8
    calls.clear()
    with pytest.raises(S.Unconstrained) as e:      # a final solve refuses instead
        # (from given rotations: no other candidate to start the photograph from)
        solve_facade(model, mk(raw), K(cams), rough_rotations={p: c["R"] for p, c in cams.items()})
    assert e.value.at_solution and e.value.unknowns[0] == "photo_03.png:rotation"


def test_a_vanishing_direction_from_two_nearly_coincident_marks(model, cams):
    """Two vertical edges seen nearly one behind the other (a tower along its
    side, seed 226 of the marking eval) give interpretation planes a
    fraction of a degree apart; a 0.5 px error then moves their own
    intersection anywhere (the directions fitted separately were 5-71° off
    over these five draws). Fitted perpendicular to the well-seen
    horizontal direction, the vertical is one angle, and the best candidate
    must be a start the solve converges from: within the ±15° of rotation
    that the bench's random starts show it reaches the minimum from."""
    from scipy.spatial.transform import Rotation

    from lumigraph.stereo.debevec1996.solve import _rotation_from_vanishing

    R, t = (np.asarray(cams["photo_03.png"][k], float) for k in "Rt")
    for seed in range(5):
        rng = np.random.default_rng(seed)

        def normal(X0, X1, rng=rng):
            # the image segment's interpretation plane, endpoints off by 0.5 px at f = 700
            u = [(R @ X + t) / (R @ X + t)[2] + np.r_[rng.normal(0, 0.5 / 700, 2), 0]
                 for X in (X0, X1)]
            n = np.cross(u[0], u[1])
            return n / np.linalg.norm(n)

        N = [normal(np.array([-5, -3, z]), np.array([5, -3, z])) for z in (0, 6, 3)]
        N += [normal(np.array([8, -3, 0]), np.array([8, -3, 9])),
              normal(np.array([8.05, -2.9, 0]), np.array([8.05, -2.9, 9]))]
        ax = np.array([0, 0, 0, 2, 2])
        err = min(np.degrees(Rotation.from_matrix(c.T @ R).magnitude())
                  for c in _rotation_from_vanishing(np.array(N), ax))
        assert err < 15.0, (seed, err)


def test_a_camera_on_a_marked_edges_line_is_found():
    """A camera on the line of one of its marked edges sees the edge as a
    point: eq. 5.3's projected line is undefined there and a solve can end
    on it with small residuals (seed 226 of the marking eval: 20 m off, on
    the corner where two of its marked edges meet). The check on one
    photograph's projected edges: a 120-px mark whose edge projects to
    0.4 px is named with both lengths; a 190-px edge under its 190-px mark
    is not (the solve's refusal path is the next test's)."""
    import lumigraph.stereo.debevec1996.solve as S

    uv = np.array([[[100.0, 50.0], [100.4, 50.0]], [[10.0, 10.0], [200.0, 10.0]]])
    z = np.ones((2, 2))
    e, why = S._unseen_edge(["house/top-front", "house/bottom-front"], uv, z,
                            np.array([120.0, 190.0]))
    assert e == "house/top-front" and "on the edge's line" in why and "0.4 px" in why
    assert S._unseen_edge(["house/bottom-front"], uv[1:], z[1:], np.array([190.0])) is None


def test_a_pose_that_cannot_see_its_marks_is_solved_again_from_the_next_candidate(
        model, cams, monkeypatch):
    """The solve from a photograph's best-fitting vanishing candidate can end
    on a pose that cannot see its marks (the mirror image); the solver then
    starts that photograph from its next candidate, once, and says so.
    Made to happen here by the check failing once for ``photo_02.png``."""
    import lumigraph.stereo.debevec1996.solve as S

    raw, mk = marks_of(model, cams)
    starts, real = [], S._solve_facade

    def spy(*a, **kw):
        starts.append(dict(kw.get("rough_rotations") or {}))
        return real(*a, **kw)

    real_unseen, flagged = S._unseen_edge, []

    def once(edges, *a):
        if not flagged and "house/top-front" in edges:
            flagged.append(1)
            return "house/top-front", "made to fail"
        return real_unseen(edges, *a)

    monkeypatch.setattr(S, "_solve_facade", spy)
    monkeypatch.setattr(S, "_unseen_edge", once)
    try:
        sol = solve_facade(model, mk(raw), K(cams), robust=False)
    except S.CannotSeeMarks:
        sol = None          # the next candidate did not solve either: refused, not silent
    flagged_photo = next(p for p in cams if p in starts[1])
    assert len(starts) == 2 and starts[0] == {} and list(starts[1]) == [flagged_photo]
    if sol is not None:
        assert any(flagged_photo in w and "next candidate" in w for w in sol.warnings)


def test_marks_from_another_photograph_are_reported(model, cams):
    raw, mk = marks_of(model, cams)
    # four of photo_01's segments pasted into photo_04's list under their own names
    raw["photo_04.png"] = raw["photo_04.png"] + raw["photo_01.png"][:4]
    sol = solve_facade(model, mk(raw), K(cams))
    assert {p for p, _, _ in sol.outliers} == {"photo_04.png"} and len(sol.outliers) >= 3
    assert exact(sol, model) < 1e-6


def _cli_folder(tmp_path, model):
    cams = ring_cameras(4, target=[1.5, 0, 4], radius=30, height=4, focal_px=120,
                        image_size=(128, 96), arc_deg=(-130.0, -50.0))
    return write_facade_folder(tmp_path / "f", model, cams)


def _one_error_line(rc, err):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("error: "), (rc, err)
    return lines[0]


def test_cli_segment_outside_its_photograph(tmp_path, model):
    folder = _cli_folder(tmp_path, model)
    d = json.loads((folder / "edges.json").read_text())
    d["photographs"]["photo_02.png"][1]["segment"] = [10, 10, 400, 300]   # 128x96 photograph
    (folder / "edges.json").write_text(json.dumps(d))
    rc, _, err = run_cli(["stereo", "facade", "solve", str(folder), "--out", str(tmp_path / "o")])
    line = _one_error_line(rc, err)
    assert "edges.json" in line and "photo_02.png[1]" in line and "another image" in line


def test_cli_unknown_photograph_and_unconstrained(tmp_path, model):
    folder = _cli_folder(tmp_path, model)
    d = json.loads((folder / "edges.json").read_text())
    d["photographs"]["photo_09.png"] = []
    (folder / "edges.json").write_text(json.dumps(d))
    rc, _, err = run_cli(["stereo", "facade", "solve", str(folder), "--out", str(tmp_path / "o")])
    assert "unknown photograph 'photo_09.png'" in _one_error_line(rc, err)
    del d["photographs"]["photo_09.png"]
    d["photographs"] = {p: [e for e in v if not e["edge"].startswith("spire/")]
                        for p, v in d["photographs"].items()}
    (folder / "edges.json").write_text(json.dumps(d))
    rc, _, err = run_cli(["stereo", "facade", "solve", str(folder), "--out", str(tmp_path / "o")])
    # one error line, then (indented) the edges that would constrain each unknown
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and lines[0].startswith("error: "), (rc, err)
    assert "spire/height" in lines[0] and "do not constrain" in lines[0]
    assert all(ln.startswith("  ") for ln in lines[1:]) and any(
        ln.strip().startswith("spire/height: ") for ln in lines[1:]), err
    assert not (tmp_path / "o").exists()


def test_automatic_marking_from_four_hand_marks(model, cams):
    rng = np.random.default_rng(7)
    raw, mk = marks_of(model, cams, noise_px=0.5, rng=rng)
    hand = mk({p: four_hand_marks(model, v) for p, v in raw.items()})
    images = {p: paint_facade(model, c, rng=rng) for p, c in cams.items()}
    start = model.with_values(model.values[~model.fixed] * 1.1)
    res = automark(start, hand, images, K(cams), noise_px=0.5)
    assert res.proposed >= 0.5 * sum(len(v) for v in raw.values()) - len(hand.marks)
    sol = solve_facade(start, res.marks, K(cams), noise_px=0.5)
    for n, v in model.named_values().items():
        if sol.std[n] > 0:
            assert abs(sol.params[n] - v) < 5 * sol.std[n], (n, sol.params[n], v, sol.std[n])
    assert replace(res.marks, marks=()).photographs == tuple(cams)


def test_a_rough_solve_holds_only_the_direction_the_marks_leave_free():
    """The tower's right-hand side unmarked (and its back hidden): its width
    and offset are free together (the right side moves), while the marks
    fix the left side, ``offset - width / 2``; its depth no mark sees.
    Held along that direction only (the default), the left side and every
    other parameter come out exact from a start 0.6 m off; held parameter
    by parameter (``"parameters"``, automatic marking's own rough solves),
    width and offset stay at their start and the left side with them, and
    the marks that see it call themselves mis-marked. Exact marks: judged
    at round-off."""
    import copy

    from lumigraph.stereo.debevec1996.model import BlockModel
    from lumigraph.stereo.debevec1996.solve import FIXTURE

    d = copy.deepcopy(FIXTURE)
    d["blocks"][2]["params"]["depth"] = 3.0          # the tower's depth its own
    model = BlockModel.from_dict(d)
    cams = ring_cameras(6, target=[1.5, 0, 4], radius=30, height=4, focal_px=700)
    raw = {p: [e for e in v if not e["edge"].endswith("-right") or not e["edge"].startswith("tower/")]
           for p, v in project_edges(model, cams).items()}
    marks = EdgeMarks.from_dict({"photographs": raw}, model=model, photographs=list(cams))
    with pytest.raises(EstimationError, match="tower/width"):
        solve_facade(model, marks, K(cams))
    start = model.with_values({"tower/width": 3.6, "tower/offset_x": 6.2})   # left side at 4.4, not 5
    truth = model.named_values()
    left = lambda p: p["tower/offset_x"] - p["tower/width"] / 2     # noqa: E731
    sol = solve_facade(start, marks, K(cams), hold_unconstrained=True)
    assert set(sol.held) == {"tower/width", "tower/offset_x", "tower/depth"}
    assert any("along the direction" in w for w in sol.warnings) and not sol.outliers
    assert sol.params["tower/depth"] == 3.0                  # a zero column: held outright
    assert abs(left(sol.params) - 5.0) < 1e-8
    others = [n for n in truth if n not in sol.held]
    assert max(abs(sol.params[n] - truth[n]) / truth[n] for n in others) < 1e-8
    # what stays free stays where the start put it: the held direction's
    # component (over width and offset, in metres) is the start's
    dw, do = sol.params["tower/width"] - 3.6, sol.params["tower/offset_x"] - 6.2
    free = np.array([1.0, 0.5]) / np.hypot(1.0, 0.5)          # (width, offset): the right side
    assert abs(free @ [dw, do]) < 1e-8
    held = solve_facade(start, marks, K(cams), hold_unconstrained="parameters")
    assert (held.params["tower/width"], held.params["tower/offset_x"]) == (3.6, 6.2)
    assert abs(left(held.params) - 5.0) > 0.5 and held.outliers
    with pytest.raises(InputError, match="hold_unconstrained"):
        solve_facade(start, marks, K(cams), hold_unconstrained="both")
