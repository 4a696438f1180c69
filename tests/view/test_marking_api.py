"""Marking mode of ``lumigraph view`` through its JSON API (Flask's test
client): every edit leaves a valid ``edges.json``, a kill mid-save leaves the
old or the new file, solve answers residuals, bad requests are one-line 4xx
answers and the server keeps answering; and the done-when of issue 18:
marking the rendered Façade scene from scratch, with Propose, solves within
the Façade bound (automatic marking's: RMS parameter error within 1.2x the
fully marked solve, ``lumigraph bench facade``).

The scene: ``lumigraph render facade`` at 320x240, six photographs, marks
with σ = 0.5 px endpoint noise (its ``edges.json`` is the "fully marked"
reference and the ground truth of which line each edge is).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from facade_helpers import (  # noqa: E402
    EDGE_NOISE_PX,
    distance,
    four_hand_marks,
    onto_line,
    refusal_marks,
    truth_lines,
)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from lumigraph.capture.render import render

    s = render("facade", size=(320, 240), seed=2, photos=6, novel=0, supersample=2,
               edge_noise=EDGE_NOISE_PX)
    return s.save(tmp_path_factory.mktemp("facade") / "scene"), s


def _session(folder: Path, edges: Path):
    from lumigraph.view.marking import FacadeSession

    return FacadeSession.open(folder, edges=edges)


def _client(folder: Path, edges: Path):
    from lumigraph.view.app import create_app

    s = _session(folder, edges)
    return create_app(artifacts=[], facade=s).test_client(), s


def _valid(path: Path, folder: Path | None = None):
    """The saved file read back as the solver reads it (and its unassigned key);
    ``folder``: the scene (default: the file's folder)."""
    from lumigraph.stereo.debevec1996.edges import load_edges
    from lumigraph.stereo.debevec1996.model import load_blocks

    folder = path.parent if folder is None else folder
    model = load_blocks(folder / "blocks.json")
    photos = json.loads((folder / "stack.json").read_text())["images"]
    marks = load_edges(path, model=model, photographs=photos)
    return marks, json.loads(path.read_text())["unassigned"]


def test_every_edit_leaves_a_valid_edges_json(scene, tmp_path):
    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    edges = work / "mine.json"
    c, _ = _client(work, edges)
    full = json.loads((work / "edges.json").read_text())["photographs"]
    mark = full["photo_00.png"][0]

    r = c.post("/api/facade/marks", json={"photo": "photo_00.png", "segment": mark["segment"]})
    assert r.status_code == 200, r.get_json()
    mid = r.get_json()["id"]
    marks, un = _valid(edges)
    assert len(marks.marks) == 0 and len(un["photo_00.png"]) == 1

    r = c.post(f"/api/facade/marks/{mid}", json={"edge": mark["edge"]})
    assert r.status_code == 200 and r.get_json()["edge"] == mark["edge"]
    marks, un = _valid(edges)
    assert [m.edge for m in marks.marks] == [mark["edge"]] and un == {}

    second = full["photo_01.png"][0]
    r = c.post("/api/facade/marks", json={"photo": 1, "segment": second["segment"],
                                          "edge": second["edge"]})
    assert r.status_code == 200
    marks, _ = _valid(edges)
    assert sorted(m.photo for m in marks.marks) == ["photo_00.png", "photo_01.png"]

    # a segment moved by hand (no snapping) is saved where it was put
    moved = [v + 0.25 for v in second["segment"]]
    sid = c.get("/api/facade/state").get_json()["marks"][-1]["id"]
    assert c.post(f"/api/facade/marks/{sid}", json={"segment": moved}).get_json()["segment"] == moved
    marks, _ = _valid(edges)
    assert marks.of("photo_01.png")[0].segment.tolist() == moved

    assert c.delete(f"/api/facade/marks/{mid}").status_code == 200
    marks, _ = _valid(edges)
    assert [m.photo for m in marks.marks] == ["photo_01.png"]

    # a new session reads the file back: the same marks
    _, s2 = _client(work, edges)
    assert [(m["photo"], m["edge"]) for m in s2.marks.values()] == [("photo_01.png",
                                                                     second["edge"])]


def test_the_photographs_and_their_detected_lines_are_served(scene, tmp_path):
    import cv2

    folder, s = scene
    c, _ = _client(folder, tmp_path / "e.json")
    r = c.get("/api/facade/photo/1")
    assert r.status_code == 200 and r.mimetype == "image/png"
    img = cv2.imdecode(np.frombuffer(r.data, np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
    assert np.array_equal(img, s.images[1])   # the photograph itself, RGB, lossless
    segs = np.array(c.get("/api/facade/detected/1").get_json()["segments"])
    assert segs.ndim == 2 and segs.shape[1] == 4 and len(segs) > 10


def test_a_dragged_segment_snaps_onto_the_edge(scene, tmp_path):
    folder, _ = scene
    truth = truth_lines(folder)
    c, _ = _client(folder, tmp_path / "e.json")
    full = json.loads((folder / "edges.json").read_text())["photographs"]
    # the longest marked edge of photo_00, dragged 1.5 px off its line and 1° turned
    m = max(full["photo_00.png"], key=lambda e: np.hypot(e["segment"][2] - e["segment"][0],
                                                       e["segment"][3] - e["segment"][1]))
    a, b = np.asarray(m["segment"][:2]), np.asarray(m["segment"][2:])
    d = (b - a) / np.hypot(*(b - a))
    n = np.array([-d[1], d[0]])
    drag = np.r_[a + 1.5 * n, b + 1.5 * n + 0.017 * np.hypot(*(b - a)) * n]
    before = distance(drag, truth["photo_00.png"][m["edge"]])
    r = c.post("/api/facade/marks", json={"photo": "photo_00.png", "segment": drag.tolist()})
    got = r.get_json()
    assert got["snapped"], got
    after = distance(got["segment"], truth["photo_00.png"][m["edge"]])
    # the photographs are rendered one sample per pixel: an edge is located to
    # within half a pixel
    assert before > 1.5 and after <= 0.5, (before, after)
    # the page is told how far the snap moved the drag (the farther end) and
    # what was drawn: moving the drag onto the snapped line moved each end
    # by its distance from that line, at least before - after
    assert got["dragged"] == pytest.approx(drag.tolist())
    assert got["jump_px"] >= before - after
    # "Keep as drawn": the mark goes back to the drag, unsnapped
    r = c.post(f"/api/facade/marks/{got['id']}", json={"segment": got["dragged"]})
    assert r.get_json()["segment"] == pytest.approx(drag.tolist())


def test_a_snapped_mark_carries_its_step_spread_and_one_moved_by_hand_none(scene, tmp_path,
                                                                           monkeypatch):
    import lumigraph.view.marking as marking
    from lumigraph.stereo.debevec1996.edges import load_edges

    monkeypatch.setattr(marking, "WEIGH_BY_SPREAD", True)
    folder, _ = scene
    c, s = _client(folder, tmp_path / "e.json")
    full = json.loads((folder / "edges.json").read_text())["photographs"]
    m = max(full["photo_00.png"], key=lambda e: np.hypot(e["segment"][2] - e["segment"][0],
                                                       e["segment"][3] - e["segment"][1]))
    got = c.post("/api/facade/marks", json={"photo": "photo_00.png", "segment": m["segment"],
                                            "edge": m["edge"]}).get_json()
    assert got["snapped"]
    # the scatter of the image's steps about the snapped segment, as step_spread measures it
    assert got["spread_px"] == pytest.approx(
        marking.step_spread(s.grey("photo_00.png"), np.asarray(got["segment"])))
    saved = load_edges(tmp_path / "e.json", model=s.model, photographs=s.photos).marks
    assert [k.spread_px for k in saved] == [pytest.approx(got["spread_px"])]
    # moved by hand: the user's own placement, no measured scatter
    moved = c.post(f"/api/facade/marks/{got['id']}", json={"segment": got["dragged"]}).get_json()
    assert "spread_px" not in moved
    saved = load_edges(tmp_path / "e.json", model=s.model, photographs=s.photos).marks
    assert [k.spread_px for k in saved] == [None]
    # drawn with snapping off: none either
    got = c.post("/api/facade/marks", json={"photo": "photo_01.png", "segment": m["segment"],
                                            "snap": False}).get_json()
    assert "spread_px" not in got


def test_the_weak_list_names_a_side_marked_once_and_the_edges_that_hold_it(scene, tmp_path):
    """The scene's own marks (σ = 0.5 px) with the wing's right side kept in
    one mark only: its width is then held by that mark alone (its left side
    by many), so the solve lists wing/width as weak, and the first edge it
    suggests lies on the wing's right side (the only unmarked edges that
    carry its width). Adding the first one the photographs show lowers the
    width's σ, to near the σ predicted (closer to it than to the σ before)."""
    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    body = json.loads((work / "edges.json").read_text())
    full = {p: list(v) for p, v in body["photographs"].items()}
    kept = None
    for p, ms in body["photographs"].items():
        right = [m for m in ms if m["edge"].startswith("wing/") and m["edge"].endswith("-right")]
        if kept is None and right:
            kept, right = (p, right[0]["edge"]), right[1:]
        body["photographs"][p] = [m for m in ms if m not in right]
    (work / "edges.json").write_text(json.dumps(body))
    c, s = _client(work, work / "edges.json")
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 200, r.get_json()
    weak = r.get_json()["weak"]
    assert [w["parameter"] for w in weak][:1] == ["wing/width"], weak
    w = weak[0]
    assert w["rel_std"] > 2 * w["median_rel_std"] and w["suggest"]
    # the first suggestion is on the right side (the only unmarked edges that
    # carry the width alone); each later one is the best given those above
    # it, so each lowers the σ those above reach
    first = w["suggest"][0]
    assert first["edge"].startswith("wing/") and first["edge"].endswith("-right"), w["suggest"]
    _assert_each_lowers_the_sigma_above(w["suggest"], w["std"])
    q, m = next((q, m) for q in w["suggest"] for m in full[q["photo"]] if m["edge"] == q["edge"])
    assert c.post("/api/facade/marks", json={"photo": q["photo"], "segment": m["segment"],
                                             "edge": q["edge"], "snap": False}).status_code == 200
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    now = r.get_json()["parameters"]["wing/width"]["std"]
    assert now < w["std"] and abs(now - q["std_after"]) < abs(w["std"] - q["std_after"])


def _assert_each_lowers_the_sigma_above(suggest, start):
    """A list ranked in turn: each suggestion's σ (with it and those above
    it added; one the solve hides is listed but not assumed marked) is
    below the σ the suggestions above it reach (``start`` at the top)."""
    now = start
    for q in suggest:
        if q["std_after"] is None:          # not yet constrained: no σ
            continue
        assert q["std_after"] < now, suggest
        if not q["hidden_in_solve"]:
            now = q["std_after"]


def _ring_with_a_nearer_view(near="photo_04.png", radius=20.0):
    """The test model's six ring cameras (30 m out) with ``near`` brought
    to ``radius``: one photograph that sees its side of the scene larger
    than the others do."""
    from lumigraph.capture.scenes.facade_edges import ring_cameras

    cams = ring_cameras(6, target=[1.5, 0, 4], radius=30, height=4, focal_px=700)
    cams[near] = ring_cameras(6, target=[1.5, 0, 4], radius=radius, height=4, focal_px=700)[near]
    return cams


def _nearer_view_scene():
    """The test scene with photo_04 nearer (:func:`_ring_with_a_nearer_view`), its
    edges projected with ±0.5 px of deterministic noise, and the tower's right-side
    edges: ``(model, cams, K, sizes, seen, right)``."""
    from lumigraph.capture.scenes.facade_edges import project_edges
    from lumigraph.stereo.debevec1996.model import BlockModel
    from lumigraph.stereo.debevec1996.solve import FIXTURE

    m = BlockModel.from_dict(FIXTURE)
    cams = _ring_with_a_nearer_view()
    K = {p: c["K"] for p, c in cams.items()}
    sizes = {p: c["image_size"] for p, c in cams.items()}
    seen = project_edges(m, cams)
    for i, e in enumerate(e for v in seen.values() for e in v):     # ±0.5 px, deterministic
        e["segment"] = (np.asarray(e["segment"]) + 0.5 * np.cos(np.arange(4) + i)).tolist()
    right = ("tower/front-right", "tower/back-right", "tower/top-right", "tower/bottom-right")
    return m, cams, K, sizes, seen, right


def test_the_weak_list_moves_to_another_photograph_once_one_holds_the_parameter():
    """The test model's tower with its right side marked in one photograph
    only: its width is weak. photo_04 is brought nearer (20 m, the others
    30 m) and sees that side, so each of its two right verticals, alone,
    would hold the width best: ranked one mark at a time (the old list)
    the top two are both in photo_04. But a width read in one photograph
    rests on that photograph's pose (its distance sets the scale), which
    the two verticals share: given the first, the second adds less than
    the same edge seen from another viewpoint with its own pose. The list,
    each suggestion the best given those above it, starts with the same
    edge and puts the second in another photograph; and the solver agrees
    (first-order σ of full solves with the pair added): the list's top two
    hold the width better than the two best alone."""
    from lumigraph.capture.scenes.facade_edges import project_edges
    from lumigraph.stereo.debevec1996.automark import std_with_mark
    from lumigraph.stereo.debevec1996.edges import EdgeMarks, Mark
    from lumigraph.stereo.debevec1996.solve import solve_facade
    from lumigraph.view.marking import weak_spots

    m, cams, K, sizes, seen, right = _nearer_view_scene()
    kept, once = {}, None
    for p, v in seen.items():
        mine = [e for e in v if e["edge"] in right]
        if once is None and mine:
            once = (p, mine[0]["edge"])
        kept[p] = [e for e in v if e["edge"] not in right or (p, e["edge"]) == once]

    def solve(extra=()):
        marks = {p: list(v) for p, v in kept.items()}
        for p, edge in extra:
            marks[p].append(next(e for e in seen[p] if e["edge"] == edge))
        return solve_facade(m, EdgeMarks.from_dict({"photographs": marks}, model=m,
                                                   photographs=list(cams)), K, noise_px=0.5)

    sol = solve()
    marked = {(p, e["edge"]) for p, v in kept.items() for e in v}
    weak = {w["parameter"]: w for w in weak_spots(sol, marked, sizes)}
    assert "tower/width" in weak, list(weak)
    new = [(q["photo"], q["edge"]) for q in weak["tower/width"]["suggest"][:2]]
    # the old list: the same candidates, each ranked by the σ it gives alone
    cands = []
    for p, (R, t) in sol.poses.items():
        cam = {p: {"K": sol.K[p], "R": R, "t": t, "image_size": sizes[p]}}
        cands += [Mark(p, e["edge"], np.asarray(e["segment"], float))
                  for e in project_edges(sol.model, cam, occlusion=False)[p]
                  if (p, e["edge"]) not in marked]
    alone = std_with_mark(sol, cands, "tower/width")
    old = [(cands[i].photo, cands[i].edge) for i in np.argsort(alone)[:2]]
    assert old[0][0] == old[1][0] == "photo_04.png", old
    assert new[0] == old[0] and new[1][0] != "photo_04.png", new
    assert all(e in {x["edge"] for x in seen[p]} for p, e in old + new)   # all four in view
    assert solve(new).std["tower/width"] < solve(old).std["tower/width"]


def test_a_refusal_list_moves_to_another_photograph_once_one_constrains_the_unknown():
    """The same scene (photo_04 nearer, seeing the tower's right side) with
    no right-side edge of the tower marked: its width is refused. The best
    edge alone is a right vertical in photo_04, and so is the next best
    alone (the old list's top two, one photograph: the list asked without
    that first edge). Ranked given the first marked, the second suggestion
    is in another photograph (a second vertical in photo_04 shares the
    pose the first rests on), and the solver agrees: with the list's top
    two marked the width's σ is lower than with the two best alone."""
    from lumigraph.stereo.debevec1996.edges import EdgeMarks
    from lumigraph.stereo.debevec1996.solve import Unconstrained, solve_facade
    from lumigraph.view.marking import unconstrained_spots

    m, cams, K, sizes, seen, right = _nearer_view_scene()
    kept = {p: [e for e in v if e["edge"] not in right] for p, v in seen.items()}
    marks = EdgeMarks.from_dict({"photographs": kept}, model=m, photographs=list(cams))
    with pytest.raises(Unconstrained) as refused:
        solve_facade(m, marks, K, noise_px=0.5)
    assert "tower/width" in refused.value.unknowns

    def listed(marked, n):
        return unconstrained_spots(m, marks, K, sizes, ["tower/width"], noise_px=0.5,
                                   marked=marked, suggestions=n)[0]["suggest"]

    marked = {(p, e["edge"]) for p, v in kept.items() for e in v}
    new = listed(marked, 2)
    first = (new[0]["photo"], new[0]["edge"])
    second_alone = listed(marked | {first}, 1)[0]                 # the old list's second
    old = [first, (second_alone["photo"], second_alone["edge"])]
    new = [first, (new[1]["photo"], new[1]["edge"])]
    assert first[0] == old[1][0] == "photo_04.png" and first[1] in right, old
    assert new[1][0] != "photo_04.png" and new[1][1] in right, new

    def width_std(pair):
        more = {p: list(v) for p, v in kept.items()}
        for p, edge in pair:
            more[p].append(next(e for e in seen[p] if e["edge"] == edge))
        return solve_facade(m, EdgeMarks.from_dict({"photographs": more}, model=m,
                                                   photographs=list(cams)), K,
                            noise_px=0.5).std["tower/width"]

    assert width_std(new) < width_std(old)


def test_the_edges_a_refusal_suggests_constrain_what_it_refused():
    """The test model with every visible edge marked but the tower's top:
    the tower's height is free (its vertical edges slide along their own
    lines), the solve refuses naming it, and unconstrained_spots suggests
    first an edge that carries the height (the tower's top), not a vertical
    (the longest edges of the named block). The first suggestion the
    solved model shows, marked (±0.5 px, deterministic), makes the solve
    succeed with the height within 4σ of the truth."""
    from lumigraph.capture.scenes.facade_edges import project_edges, ring_cameras
    from lumigraph.stereo.debevec1996.edges import EdgeMarks
    from lumigraph.stereo.debevec1996.model import BlockModel
    from lumigraph.stereo.debevec1996.solve import FIXTURE, Unconstrained, solve_facade
    from lumigraph.view.marking import unconstrained_spots

    m = BlockModel.from_dict(FIXTURE)
    cams = ring_cameras(6, target=[1.5, 0, 4], radius=30, height=4, focal_px=700)
    seen = project_edges(m, cams)
    for i, e in enumerate(e for v in seen.values() for e in v):
        e["segment"] = (np.asarray(e["segment"]) + 0.5 * np.cos(np.arange(4) + i)).tolist()
    kept = {p: [e for e in v if not e["edge"].startswith("tower/top")] for p, v in seen.items()}
    K = {p: c["K"] for p, c in cams.items()}
    marks = EdgeMarks.from_dict({"photographs": kept}, model=m, photographs=list(cams))
    with pytest.raises(Unconstrained) as refused:
        solve_facade(m, marks, K, noise_px=0.5)
    assert refused.value.unknowns == ("tower/height",)
    spots = unconstrained_spots(m, marks, K, {p: c["image_size"] for p, c in cams.items()},
                                refused.value.unknowns, noise_px=0.5)
    assert [u["parameter"] for u in spots] == ["tower/height"]
    sug = spots[0]["suggest"]
    assert sug and all(q["constrains"] and q["std_after"] > 0 for q in sug)
    # the first is the best edge alone: the tower's top (its verticals do not
    # carry the height); each later one is the best with those above it
    # marked, so the σ the list reaches falls down it
    assert sug[0]["edge"].startswith("tower/top"), sug
    _assert_each_lowers_the_sigma_above(sug, np.inf)
    q = next(q for q in sug if not q["hidden_in_solve"])
    add = next(e for e in seen[q["photo"]] if e["edge"] == q["edge"])
    kept[q["photo"]].append(add)
    sol = solve_facade(m, EdgeMarks.from_dict({"photographs": kept}, model=m,
                                              photographs=list(cams)), K, noise_px=0.5)
    true = m.named_values()["tower/height"]
    assert abs(sol.params["tower/height"] - true) <= 4 * sol.std["tower/height"]


def test_a_refused_solve_answers_the_edges_that_would_constrain_each_unknown(scene, tmp_path):
    """The scene's own marks without the tower's top and the spire: the
    tower's and the spire's heights are free. Solve answers 422 with its
    one-line error and, per unknown it names, the unmarked edges that would
    constrain it (``unconstrained``); the session's state keeps the
    refusal. Marking, per unknown, the first suggestion the photograph
    shows (the scene's own mark of it) makes the next Solve succeed, and
    the refusal is cleared."""
    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    body = json.loads((work / "edges.json").read_text())
    full = {p: list(v) for p, v in body["photographs"].items()}
    for p, ms in body["photographs"].items():
        body["photographs"][p] = [m for m in ms if not m["edge"].startswith(("tower/top", "spire/"))]
    (work / "edges.json").write_text(json.dumps(body))
    c, s = _client(work, work / "edges.json")
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 422
    got = r.get_json()
    assert "\n" not in got["error"] and "do not constrain" in got["error"]
    named = got["error"].split("constrain ")[1].split(":")[0].split(", ")
    assert {"tower/height", "spire/height"} <= set(named)
    assert [u["parameter"] for u in got["unconstrained"]] == named
    for u in got["unconstrained"]:
        assert u["suggest"], u
        for q in u["suggest"]:
            assert set(q) == {"photo", "edge", "constrains", "std_after", "hidden_in_solve", "seam"}
            assert (q["std_after"] is None) != q["constrains"]
        # the list down to the first mark that constrains it lies on the
        # blocks that carry the heights; below it, any edge that lowers σ
        upto = next(i for i, q in enumerate(u["suggest"]) if q["constrains"])
        assert all(q["edge"].split("/")[0] in ("tower", "spire")
                   for q in u["suggest"][:upto + 1]), u["suggest"]
    assert c.get("/api/facade/state").get_json()["refusal"] == {
        "error": got["error"], "unconstrained": got["unconstrained"]}
    for u in got["unconstrained"]:
        have = {(m["photo"], m["edge"]) for m in s.marks.values()}
        q, m = next((q, m) for q in u["suggest"] for m in full[q["photo"]]
                    if m["edge"] == q["edge"])
        if (q["photo"], q["edge"]) not in have:
            assert c.post("/api/facade/marks", json={"photo": q["photo"], "segment": m["segment"],
                                                     "edge": q["edge"], "snap": False}).status_code == 200
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 200, r.get_json()
    assert c.get("/api/facade/state").get_json()["refusal"] is None


def test_the_solve_lists_the_hand_marks_to_check(scene, tmp_path):
    """After a Solve, ``check`` lists the hand-drawn marks that lie farthest
    from where the *other* marks put their edges, in σ (their deleted
    residuals, ``marking.marks_to_check``), highest first, from
    ``CHECK_MIN_SCORE`` up. The scene's own marks (σ = 0.5 px) with one hand
    mark on the house's bottom-front edge moved 2.5 px (5σ) off its line:
    that photograph's pose absorbs most of the move, so the mark's own
    residual is not among the largest (a residual ranking lists the other
    marks it pulled off, not it); by the deleted residual it is listed,
    beside the tower's bottom-front mark on the same image line that it
    contradicts (of two marks that disagree, the others decide which is
    off only as far as they hold that photograph's pose). An accepted
    proposal moved as far is not listed (it was accepted because it lay on
    its edge)."""
    from lumigraph.view.marking import CHECK_MARKS, CHECK_MIN_SCORE, marks_to_check

    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    c, s = _client(work, work / "edges.json")

    def shifted(m, px):
        a, b = np.asarray(m["segment"][:2]), np.asarray(m["segment"][2:])
        d = (b - a) / np.hypot(*(b - a))
        return (np.r_[a, b] + px * np.r_[-d[1], d[0], -d[1], d[0]]).tolist()

    front = [k for k in s.marks if s.marks[k]["edge"] == "house/bottom-front"]
    front.sort(key=lambda k: -np.hypot(s.marks[k]["segment"][2] - s.marks[k]["segment"][0],
                                       s.marks[k]["segment"][3] - s.marks[k]["segment"][1]))
    hand, prop = front[0], front[1]
    c.post(f"/api/facade/marks/{hand}", json={"segment": shifted(s.marks[hand], 5 * EDGE_NOISE_PX)})
    c.post(f"/api/facade/marks/{prop}", json={"segment": shifted(s.marks[prop], 5 * EDGE_NOISE_PX)})
    s.marks[prop]["proposed"] = True
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 200, r.get_json()
    sol = r.get_json()
    check = sol["check"]
    assert 1 <= len(check) <= CHECK_MARKS
    assert hand in [q["id"] for q in check], check
    # ranked by their residuals, the hand marks listed would not include it
    by_residual = marks_to_check(s.marks, {int(k): v for k, v in sol["residual_by_id"].items()})
    assert hand not in [q["id"] for q in by_residual], by_residual
    assert prop not in [q["id"] for q in check]
    assert [q["score"] for q in check] == sorted((q["score"] for q in check), reverse=True)
    for q in check:
        assert CHECK_MIN_SCORE <= q["score"] < float("inf")
        assert q["rms_px"] == sol["residual_by_id"][str(q["id"])]
        assert (q["photo"], q["edge"]) == (s.marks[q["id"]]["photo"], s.marks[q["id"]]["edge"])


def test_a_photograph_left_without_a_rotation_start_starts_from_the_last_solve(scene, tmp_path):
    """Eq. 5.4 starts a photograph's rotation from two edges along each of
    two of the model's axes. A photograph left with vertical edges only (a
    re-snap deletes the solver's outliers, or the user deletes marks) cannot
    start it: in a fresh session the Solve refuses and names it; after a
    Solve, the next one starts it from its pose in that solve, says so in
    its warnings, and fits every mark as before (within 3σ of its edge)."""
    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    c, s = _client(work, work / "edges.json")
    vertical = ("front-left", "front-right", "back-left", "back-right")
    photo = "photo_00.png"
    assert c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX}).status_code == 200
    for k in [k for k, m in s.marks.items()
              if m["photo"] == photo and not m["edge"].endswith(vertical)]:
        assert c.delete(f"/api/facade/marks/{k}").status_code == 200
    assert sum(m["photo"] == photo for m in s.marks.values()) >= 3   # the photograph stays in the solve
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 200, r.get_json()
    sol = r.get_json()
    assert any(photo in w and "last solve" in w for w in sol["warnings"]), sol["warnings"]
    assert max(sol["residual_by_id"].values()) <= 3 * EDGE_NOISE_PX

    fresh, _ = _client(work, work / "edges.json")              # the same marks, no solve before
    r = fresh.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 422 and photo in r.get_json()["error"], r.get_json()
    assert "rotation" in r.get_json()["error"]


def test_solve_answers_parameters_projections_and_residuals(scene, tmp_path):
    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    c, s = _client(work, work / "edges.json")   # the scene's own marks, σ = 0.5 px
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 200, r.get_json()
    sol = r.get_json()
    assert set(sol["residual_by_id"]) == {str(k) for k in s.marks}
    # each mark's RMS distance comes from endpoint noise of σ = 0.5 px: within 3σ
    assert max(sol["residual_by_id"].values()) <= 3 * EDGE_NOISE_PX
    assert set(sol["projected"]) == set(s.photos)
    gt = json.loads((work / "gt.json").read_text())["parameters"]
    for name, v in sol["parameters"].items():
        assert abs(v["value"] - gt[name]) <= 4 * v["std"] + 1e-9, name
    assert c.get("/api/facade/state").get_json()["solution"]["rms_px"] == sol["rms_px"]


@pytest.mark.parametrize("method,url,payload,status,fragment", [
    ("post", "/api/facade/marks", {"photo": "photo_00.png", "segment": [1, 2, 3]}, 400,
     "segment: expected a segment [x0, y0, x1, y1]"),
    ("post", "/api/facade/marks", {"photo": "nope.png", "segment": [1, 2, 30, 2]}, 400,
     "photo: unknown photograph 'nope.png'"),
    ("post", "/api/facade/marks", {"photo": 0, "segment": [1, 2, 900, 2]}, 400,
     "lies outside photograph"),
    ("post", "/api/facade/marks", {"photo": 0, "segment": [1, 2, 30, 2], "edge": "house/top"}, 400,
     "edge: unknown model edge 'house/top'"),
    ("post", "/api/facade/marks/999", {"edge": "house/top-front"}, 400, "id: no mark with id"),
    ("post", "/api/facade/solve", {}, 422, "no marks tied to model edges yet"),
    ("post", "/api/facade/propose", {}, 422, "mark a few edges first"),
    ("post", "/api/facade/proposals/7/accept", None, 400, "no proposal with id"),
    ("get", "/api/facade/photo/17", None, 400, "unknown photograph"),
    ("get", "/api/facade/nothing", None, 404, "no such route"),
])
def test_bad_requests_are_one_line_4xx_and_the_server_keeps_serving(scene, tmp_path, method, url,
                                                                      payload, status, fragment):
    folder, _ = scene
    c, _ = _client(folder, tmp_path / "e.json")
    r = getattr(c, method)(url, json=payload) if payload is not None else getattr(c, method)(url)
    assert r.status_code == status, r.get_json()
    err = r.get_json()["error"]
    assert fragment in err and "\n" not in err, err
    assert c.get("/api/facade/state").status_code == 200
    assert not (tmp_path / "e.json").exists() or _valid(tmp_path / "e.json", folder)


def test_a_request_body_that_is_not_json_is_a_400(scene, tmp_path):
    folder, _ = scene
    c, _ = _client(folder, tmp_path / "e.json")
    r = c.post("/api/facade/marks", data="x0=1", content_type="text/plain")
    assert r.status_code == 400 and "expected a JSON object" in r.get_json()["error"]


def test_an_unreadable_artifact_is_its_one_line_error_and_the_server_keeps_serving(scene, tmp_path):
    from lumigraph.view.app import create_app

    bad = tmp_path / "broken.exr"
    bad.write_bytes(b"not an exr at all")
    folder, _ = scene
    app = create_app(artifacts=[bad], facade=_session(folder, tmp_path / "e.json"))
    c = app.test_client()
    err = c.get("/api/look/0").get_json()["error"]
    assert err.startswith(f"{bad}: ") and "\n" not in err
    assert c.get("/api/facade/state").status_code == 200
    assert c.get("/").status_code == 200


_SAVER = r"""
import sys, numpy as np
from lumigraph.view.marking import FacadeSession
s = FacadeSession.open(sys.argv[1], edges=sys.argv[2])
edge = s.model.edge_names
print("ready", flush=True)
k = 0
while True:                      # edits as fast as the disk takes them
    m = s.add("photo_00.png", [10.0 + k % 7, 20.0, 200.0, 30.0 + k % 5], snap=False)
    s.assign(m["id"], edge[k % len(edge)])
    if k % 3 == 2:
        s.delete(m["id"])
    k += 1
"""


def test_a_kill_mid_save_leaves_the_old_or_the_new_file(scene, tmp_path):
    folder, _ = scene
    edges = tmp_path / "edges.json"
    rng = np.random.default_rng(0)
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    for _ in range(3):
        p = subprocess.Popen([sys.executable, "-c", _SAVER, str(folder), str(edges)],
                             stdout=subprocess.PIPE, text=True, env=env)
        assert p.stdout.readline().strip() == "ready"
        time.sleep(float(rng.uniform(0.2, 0.6)))
        p.send_signal(signal.SIGKILL)
        p.wait()
        marks, _ = _valid(edges, folder)   # complete and valid: the old or the new state
        assert all(m.photo == "photo_00.png" for m in marks.marks)
    # and the next session opens it, clearing what the killed ones left half-written
    _session(folder, edges)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["edges.json", "edges.json.meta.json"]


def test_a_writer_failing_mid_file_leaves_the_old_file(scene, tmp_path, monkeypatch):
    from lumigraph.capture import artifact

    folder, _ = scene
    edges = tmp_path / "edges.json"
    c, s = _client(folder, edges)
    assert c.post("/api/facade/marks", json={"photo": 0, "segment": [10, 20, 200, 30],
                                             "edge": "house/top-front", "snap": False}).status_code == 200
    before = edges.read_bytes()

    def half(path, text):  # the disk fills after half the file
        Path(path).write_text(text[: len(text) // 2])
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(artifact, "dumps_json", lambda obj: json.dumps(obj))
    monkeypatch.setattr(Path, "write_text", half)
    r = c.post("/api/facade/marks", json={"photo": 1, "segment": [10, 20, 200, 30],
                                          "edge": "house/top-front", "snap": False})
    monkeypatch.undo()
    assert r.status_code == 500
    assert edges.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".edges")] == []


@pytest.mark.slow
def test_marking_from_scratch_with_propose_meets_the_facade_bound(scene, tmp_path):
    """Issue 18's done-when, as a new user would go: four edges per
    photograph dragged by hand (σ = 0.5 px) and snapped, Propose, each
    proposal accepted when it lies on its edge (the user's eye; here the
    scene's true edge line, 1.5 px: three times the marks' noise), the
    blocks the solver names as unconstrained marked by hand, Solve; the
    edges the solve's weak list suggests marked by hand where the
    photograph shows them, Solve; then twice: Re-snap to the model, Propose
    again, accept, Solve again, the weak list's edges again; the hand marks
    the Solve lists to check redrawn with snapping off, Solve.

    Seed 2 is a scene the snapping gates and the flow were set on (tuned):
    this checks the flow end to end against issue 17's bound. On never-run
    seeds 281-320 (four independent draws each) the same flow is within
    1.2x of the fully marked solve's expected error in 156 of 160 runs,
    median 0.61x, worst 1.44x (docs/decisions/view-marking.md, fifteenth
    pass; tests/view/eval_from_scratch.py)."""
    from lumigraph.stereo.debevec1996.edges import load_edges
    from lumigraph.stereo.debevec1996.solve import solve_facade

    folder, _ = scene
    truth = truth_lines(folder)
    full = json.loads((folder / "edges.json").read_text())["photographs"]
    c, s = _client(folder, tmp_path / "edges.json")
    rng = np.random.default_rng(7)

    def review():
        """Propose, then accept what lies on its edge (within 3 sigma of the
        marks' noise) and reject the rest, as a user looking at the photo."""
        r = c.post("/api/facade/propose")
        assert r.status_code == 200, r.get_json()
        for q in r.get_json()["proposals"]:
            line = truth[q["photo"]][q["edge"]]
            verdict = "accept" if distance(q["segment"], line) <= 3 * EDGE_NOISE_PX else "reject"
            assert c.post(f"/api/facade/proposals/{q['id']}/{verdict}").status_code == 200

    def drag(photo, mark):
        # the user traces the edge where it is (the scene's mark put back on its
        # true line, as the reference's noise draws are) with the drag's noise
        seg = onto_line(mark["segment"], truth[photo][mark["edge"]]) + rng.normal(0, EDGE_NOISE_PX, 4)
        r = c.post("/api/facade/marks", json={"photo": photo, "segment": seg.tolist()})
        assert r.status_code == 200, r.get_json()
        r = c.post(f"/api/facade/marks/{r.get_json()['id']}", json={"edge": mark["edge"]})
        assert r.status_code == 200

    for p in s.photos:
        for m in four_hand_marks(s.model, full[p]):
            drag(p, m)
    review()
    for attempt in range(4):     # three rounds of hand marks, each solved
        r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
        if r.status_code == 200 or attempt == 3:
            break
        err = r.get_json()["error"]
        assert r.status_code == 422 and "do not constrain" in err, err
        # the user marks (up to four) edges the refusal lists as constraining what it refused
        have = {(m["photo"], m["edge"]) for m in s.marks.values()}
        for p, m in refusal_marks(r.get_json()["unconstrained"], full, have):
            drag(p, m)
    assert r.status_code == 200, r.get_json()

    def heed_weak(r):
        """The page's weak list: mark (by hand) up to four of each weak
        parameter's suggested edges that the photograph shows (an edge of
        the scene's marks), then Solve again."""
        added = 0
        for w in r.get_json()["weak"]:
            n = 0
            for q in w["suggest"]:
                have = {(m["photo"], m["edge"]) for m in s.marks.values()}
                m = next((m for m in full[q["photo"]] if m["edge"] == q["edge"]), None)
                if m is not None and (q["photo"], q["edge"]) not in have and n < 4:
                    drag(q["photo"], m)
                    n += 1
            added += n
        if not added:
            return r
        r2 = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
        assert r2.status_code == 200, r2.get_json()
        return r2

    r = heed_weak(r)
    for _ in range(2):
        # the user's next round: Re-snap to the solved model, Propose again
        # (from every mark so far), accept what lies on its edge, Solve again
        assert c.post("/api/facade/resnap").status_code == 200
        review()
        r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
        assert r.status_code == 200, r.get_json()
        r = heed_weak(r)
    # the hand marks the Solve lists to check: each redrawn, carefully and
    # snapping off, where the photograph shows its edge; Solve
    byedge = {p: {m["edge"]: m for m in full[p]} for p in s.photos}
    for q in r.get_json()["check"]:
        seg = onto_line(byedge[q["photo"]][q["edge"]]["segment"], truth[q["photo"]][q["edge"]]) \
            + rng.normal(0, EDGE_NOISE_PX, 4)
        assert c.post(f"/api/facade/marks/{q['id']}", json={"segment": seg.tolist()}).status_code == 200
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 200, r.get_json()
    sol = r.get_json()
    gt = json.loads((folder / "gt.json").read_text())["parameters"]
    free = list(s.model.parameter_names)
    scratch = np.sqrt(np.mean([((sol["parameters"][n]["value"] - gt[n]) / gt[n]) ** 2 for n in free]))
    marks = load_edges(folder / "edges.json", model=s.model, photographs=s.photos)
    ref = solve_facade(s.model, marks, {p: s.camera.K for p in s.photos}, noise_px=EDGE_NOISE_PX)
    fully = np.sqrt(np.mean([((ref.params[n] - gt[n]) / gt[n]) ** 2 for n in free]))
    print(f"from scratch: RMS relative parameter error {scratch:.5f}, fully marked {fully:.5f}, "
          f"ratio {scratch / fully:.2f} (bound 1.2)")
    assert scratch <= 1.2 * fully
    saved, _ = _valid(tmp_path / "edges.json", folder)
    assert len(saved.marks) == len(s.marks) and any(m.proposed for m in saved.marks)


def test_a_segment_refines_onto_the_step_not_onto_a_texture_line():
    """``refine_on_edge`` (proposals, and snapping when asked): a face edge
    is a step (one side brighter), a brick course a thin line (the same
    level either side). A segment between a step and a stronger thin line
    lands on the step; a thin line alone is refused (no step to land on).
    Noise-free image: the step's position is known to the ¼ px grid the
    profiles are sampled on."""
    from lumigraph.view.marking import refine_on_edge

    g = np.full((60, 80), 60.0)
    g[:, 40:] = 140.0                       # a step between x = 39 and 40: the edge at 39.5
    g[:, 37] = 0.0                          # a dark line 2.5 px away, of stronger contrast
    got = refine_on_edge(g, np.array([38.0, 5.0, 38.5, 55.0]))
    assert got is not None
    assert abs(got[0] - 39.5) <= 0.25 and abs(got[2] - 39.5) <= 0.25, got
    line = np.full((60, 80), 100.0)
    line[:, 37] = 0.0
    assert refine_on_edge(line, np.array([37.0, 5.0, 37.0, 55.0])) is None


def test_a_segment_refines_onto_the_line_most_of_it_shows(monkeypatch):
    """``STEP_CONSENSUS`` (an option, off by default): ``refine_on_edge``
    fits the steps most of its profiles agree on. A wall's edge at x = 39.5
    along 40 of 60 rows, and relief the model lacks (a pilaster's foot) 3 px
    in front along rows 10-29: the line lands on the wall's edge at both
    ends, where a least-squares line through every profile's step (the
    default) comes out tilted, more than a drag's 0.5 px off at one end. Three parallel steps along a third of
    the segment each: no line holds half the profiles, refused.
    Noise-free image: the step's position is known to the ¼ px grid the
    profiles are sampled on."""
    import lumigraph.view.marking as marking

    g = np.full((60, 80), 60.0)
    g[:, 40:] = 140.0                       # the wall's edge between x = 39 and 40
    g[10:30, 40:43] = 60.0                  # the relief: its step 3 px further, x = 42.5
    seg = np.array([40.0, 2.0, 40.0, 58.0])
    monkeypatch.setattr(marking, "STEP_CONSENSUS", True)
    got = marking.refine_on_edge(g, seg)
    assert got is not None
    assert abs(got[0] - 39.5) <= 0.25 and abs(got[2] - 39.5) <= 0.25, got
    monkeypatch.setattr(marking, "STEP_CONSENSUS", False)
    old = marking.refine_on_edge(g, seg)
    assert old is None or max(abs(old[0] - 39.5), abs(old[2] - 39.5)) > 0.5, old
    monkeypatch.setattr(marking, "STEP_CONSENSUS", True)
    thirds = np.full((60, 80), 60.0)
    thirds[:, 40:] = 140.0                  # rows 0-19: the step at 39.5
    thirds[20:40, 40:43] = 60.0             # rows 20-39: at 42.5
    thirds[40:, 37:40] = 140.0              # rows 40-59: at 36.5
    assert marking.refine_on_edge(thirds, seg) is None


def test_snapping_over_the_drag_refuses_a_line_the_image_shows_on_a_fifth_of_it(monkeypatch):
    """``SNAP_OVER_DRAG`` (an option, off by default): the detected line is
    refined over the stretch dragged, not over the detection, so a detection
    covering the top fifth of a long edge (the part against the sky) is not
    carried out over the rest; there the drag is kept as drawn. Where the
    step runs the whole drag, the snap lands on it. Noise-free image: the
    step's position is known to the ½ px grid the profiles are sampled on."""
    import lumigraph.view.marking as marking

    monkeypatch.setattr(marking, "SNAP_OVER_DRAG", True)
    g = np.full((150, 80), 60.0)
    g[:28, 40:] = 200.0                     # a step at x = 39.5 in the top 28 rows only
    det = np.array([[39.55, 2.0, 39.65, 24.0]])  # the detector's short, tilted piece of it
    drag = np.array([39.0, 2.0, 39.0, 140.0])
    assert marking.snap_segment(drag, det, grey=g) is None
    g[:, 40:] = 200.0                       # the step all along
    got = marking.snap_segment(drag, det, grey=g)
    assert got is not None and abs(got[0] - 39.5) <= 0.5 and abs(got[2] - 39.5) <= 0.5, got


def test_edge_band_from_the_covariance_matches_the_solved_edges_error(scene, tmp_path):
    """``edge_offset_std``: the solve's covariance carried to each reprojected
    edge (at a mark's ends). On the scene's own marks (σ = 0.5 px) the solved
    edges' true errors, divided by it, have an RMS within issue 17's bound
    for a reported σ (0.67x to 1.5x)."""
    from lumigraph.stereo.debevec1996.automark import edge_offset_std
    from lumigraph.stereo.debevec1996.solve import project_model_edges

    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    s = _session(work, work / "edges.json")
    s.solve(noise_px=EDGE_NOISE_PX)
    sol, truth = s._sol, truth_lines(work)
    marks = s.edge_marks().marks
    sd = edge_offset_std(sol, marks)
    z = []
    for m, (s0, s1) in zip(marks, sd, strict=True):
        a, b = project_model_edges(sol.model, sol.K[m.photo], *sol.poses[m.photo])[m.edge]
        ta, tb = (np.asarray(v) for v in truth[m.photo][m.edge])
        d = (tb - ta) / np.hypot(*(tb - ta))
        n = np.array([-d[1], d[0]])
        for end, sk in ((m.segment[:2], s0), (m.segment[2:], s1)):
            # the solved line's offset from the true one, across it, at the mark's end
            foot = a + ((end - a) @ (b - a)) / ((b - a) @ (b - a)) * (b - a)
            z.append(((foot - ta) @ n) / sk)
    ratio = float(np.sqrt(np.mean(np.square(z))))
    assert 0.67 <= ratio <= 1.5, ratio


def _refusing(monkeypatch, photo, *, unless_started=True):
    """The page's solver made to end on a pose of ``photo`` that cannot see
    its marks (fault injection: ``CannotSeeMarks``, the refusal of the marking
    eval's fresh seeds 261 and 274), unless ``unless_started`` and the call
    starts ``photo`` from a given rotation. Returns the list of the calls'
    ``rough_rotations``."""
    import lumigraph.stereo.debevec1996.solve as S

    real, calls = S.solve_facade, []

    def fake(model, marks, K, **kw):
        calls.append(kw.get("rough_rotations"))
        started = photo in (kw.get("rough_rotations") or {})
        if any(m.photo == photo for m in marks.marks) and not (unless_started and started):
            raise S.CannotSeeMarks("edges.json", {photo: ("house/top-front", "injected")})
        return real(model, marks, K, **kw)

    monkeypatch.setattr(S, "solve_facade", fake)
    return calls


def test_a_pose_that_cannot_see_its_marks_starts_again_from_the_last_solve(scene, tmp_path,
                                                                          monkeypatch):
    """A Solve whose solver ends on a wrong pose of one photograph (one that
    cannot see its marks, or that its marks do not fix there) solves again
    with that photograph started from its pose in the last Solve, and says
    so; every mark then fits within 3σ of its edge."""
    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    c, s = _client(work, work / "edges.json")
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 200
    photo = "photo_02.png"
    R_last = s._sol.poses[photo][0]
    calls = _refusing(monkeypatch, photo)
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 200, r.get_json()
    sol = r.get_json()
    assert calls[0] is None and np.array_equal(calls[-1][photo], R_last)
    assert any(photo in w and "last solve" in w for w in sol["warnings"]), sol["warnings"]
    assert photo not in sol["dropped"]
    assert max(sol["residual_by_id"].values()) <= 3 * EDGE_NOISE_PX


def test_a_photograph_whose_marks_fit_a_wrong_pose_from_every_start_is_left_out(scene, tmp_path,
                                                                                 monkeypatch):
    """When no start the page has gives a pose of the photograph that sees
    its marks (none after the last Solve's, or no Solve yet), the Solve
    answers the model from the other photographs, the photograph among the
    dropped and a warning naming it: a model and the reason, not a refusal
    that leaves the user nothing; its next Solve starts it from its last
    known pose again."""
    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    c, s = _client(work, work / "edges.json")
    photo = "photo_02.png"
    calls = _refusing(monkeypatch, photo, unless_started=False)
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})   # no Solve before
    assert r.status_code == 200, r.get_json()
    sol = r.get_json()
    assert photo in sol["dropped"] and photo not in sol["projected"]
    assert any(photo in w and "left out" in w for w in sol["warnings"]), sol["warnings"]
    assert len(calls) == 2
    monkeypatch.undo()
    calls = _refusing(monkeypatch, "photo_04.png", unless_started=False)
    r = c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX})
    assert r.status_code == 200
    assert "photo_04.png" in r.get_json()["dropped"] and photo not in r.get_json()["dropped"]
    # photo_04's last known pose was tried before it was left out
    assert any(q and "photo_04.png" in q for q in calls)


def test_a_resnap_never_turns_a_mark_further_than_a_drag_is_off_its_edge(scene, tmp_path,
                                                                         monkeypatch):
    """Re-snap moves a mark onto the step the image shows in its band, but
    a wide band (a pose the solve barely holds) can take the steps of two
    lines at the mark's two ends. The step refinement made to return the
    mark turned about its middle (fault injection): turned 10° the mark is
    flagged and stays; turned 2° (within ``SNAP_ANGLE_DEG``) it moves."""
    import lumigraph.view.marking as marking

    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    c, s = _client(work, work / "edges.json")
    assert c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX}).status_code == 200
    k = max(s.marks, key=lambda j: np.hypot(s.marks[j]["segment"][2] - s.marks[j]["segment"][0],
                                            s.marks[j]["segment"][3] - s.marks[j]["segment"][1]))
    before = list(s.marks[k]["segment"])

    def turned(deg):
        def refine(grey, seg, **kw):
            seg = np.asarray(seg, float)
            m, h = (seg[:2] + seg[2:]) / 2, (seg[2:] - seg[:2]) / 2
            if not np.allclose(m, (np.asarray(before[:2]) + before[2:]) / 2, atol=3.0):
                return seg          # every other mark: where it lies
            a = np.radians(deg)
            h = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) @ h
            return np.r_[m - h, m + h]
        return refine

    monkeypatch.setattr(marking, "refine_on_edge", turned(10.0))
    got = c.post("/api/facade/resnap", json={"every": True}).get_json()
    assert k in got["flagged"] and k not in got["moved"]
    assert s.marks[k]["segment"] == before
    monkeypatch.setattr(marking, "refine_on_edge", turned(2.0))
    got = c.post("/api/facade/resnap", json={"every": True}).get_json()
    assert k in got["moved"] and s.marks[k]["segment"] != before


def test_resnap_moves_an_off_mark_onto_its_step_within_the_band(scene, tmp_path):
    """Re-snap after a Solve (``every``: each mark, not only those the solve
    cannot explain): a mark moved 2 px off its edge (four times the marks'
    noise; not the robust loss's outlier: the pose absorbs part of it) goes
    back onto the image step within the reprojected edge's band, to within
    half a pixel of the true line (the photographs are rendered one sample
    per pixel); a mark is only ever moved onto a step, and the file stays
    valid."""
    folder, _ = scene
    work = tmp_path / "scene"
    shutil.copytree(folder, work)
    c, s = _client(work, work / "edges.json")
    assert c.post("/api/facade/resnap").status_code == 422      # no solve yet
    truth = truth_lines(work)
    # the longest mark of photo_00 shifted 2 px across its true line
    k, m = max(((k, m) for k, m in s.marks.items() if m["photo"] == "photo_00.png"),
               key=lambda km: np.hypot(km[1]["segment"][2] - km[1]["segment"][0],
                                       km[1]["segment"][3] - km[1]["segment"][1]))
    a, b = (np.asarray(v) for v in truth["photo_00.png"][m["edge"]])
    d = (b - a) / np.hypot(*(b - a))
    seg = np.asarray(m["segment"]) + 2.0 * np.tile([-d[1], d[0]], 2)
    assert c.post(f"/api/facade/marks/{k}", json={"segment": seg.tolist()}).status_code == 200
    before = {j: list(v["segment"]) for j, v in s.marks.items()}
    assert c.post("/api/facade/solve", json={"noise_px": EDGE_NOISE_PX}).status_code == 200
    r = c.post("/api/facade/resnap", json={"every": True})
    assert r.status_code == 200, r.get_json()
    got = r.get_json()
    assert k in got["moved"], got
    assert distance(s.marks[k]["segment"], truth["photo_00.png"][m["edge"]]) <= 0.5
    untouched = [j for j in before if j not in got["moved"] and j not in got["deleted"]]
    assert all(s.marks[j]["segment"] == before[j] for j in untouched)
    assert c.post("/api/facade/resnap", json={"every": 1}).status_code == 400
    saved, _ = _valid(work / "edges.json", work)
    assert len(saved.marks) == len(s.marks)
