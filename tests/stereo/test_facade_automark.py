"""Automatic edge marking (stereo/debevec1996/automark.py) on the cases that
broke it: a block flush with its neighbour (its edges on the neighbour's
image lines), a block the model hides, a rough solve whose weak parameter
wanders. Marks carry σ = 0.5 px endpoint noise and the photographs 1 code
of image noise; a recovered parameter is judged in units of the σ the
solver reports for it (the bench checks that σ against the RMS error over
50 noise draws)."""

from __future__ import annotations

import numpy as np
import pytest

from lumigraph.capture.scenes.facade_edges import paint_facade, project_edges, ring_cameras
from lumigraph.stereo.debevec1996.automark import _associate, _resect, automark
from lumigraph.stereo.debevec1996.edges import EdgeMarks
from lumigraph.stereo.debevec1996.model import BlockModel
from lumigraph.stereo.debevec1996.solve import _known_axis, solve_facade


def _hand(model, marks):
    """Four hand marks per photograph: the two longest vertical and the two
    longest horizontal edges along one axis (as the bench marks them)."""
    ax = _known_axis(model, [m["edge"] for m in marks])
    order = np.argsort([-np.hypot(m["segment"][2] - m["segment"][0],
                                  m["segment"][3] - m["segment"][1]) for m in marks])
    pick = [i for i in order if ax[i] == 2][:2]
    for a in (0, 1):
        h = [i for i in order if ax[i] == a][:2]
        if len(h) == 2:
            return [marks[i] for i in pick + h]
    raise AssertionError("no two horizontal edges")


def _run(spec, *, seed, start_factor=1.08, photos=6, arc=(-160.0, -20.0)):
    model = BlockModel.from_dict(spec, where="test")
    V = model.vertices()
    centre = (V.min(0) + V.max(0)) / 2
    size = float(np.linalg.norm(np.ptp(V, axis=0)))
    cams = ring_cameras(photos, target=centre, radius=2.2 * size, height=0.3 * size,
                        focal_px=700, arc_deg=arc, rng=np.random.default_rng(seed),
                        jitter=0.05)
    rng = np.random.default_rng(100 + seed)
    raw = project_edges(model, cams, noise_px=0.5, rng=rng)
    hand = EdgeMarks.from_dict({"photographs": {p: _hand(model, v) for p, v in raw.items()}},
                               model=model, photographs=list(cams))
    images = {p: paint_facade(model, c, rng=rng) for p, c in cams.items()}
    start = model.with_values(model.values[~model.fixed] * start_factor)
    K = {p: c["K"] for p, c in cams.items()}
    res = automark(start, hand, images, K, noise_px=0.5)
    return model, cams, raw, start, K, res


FLUSH = {"blocks": [
    {"name": "tower", "kind": "box",
     "params": {"width": {"value": 4.0, "fixed": True}, "depth": 4.0, "height": 12.0}},
    # the annex's left face is the tower's right face and their fronts are
    # flush: annex/front-left lies on tower/front-right's image line
    {"name": "annex", "kind": "box", "parent": "tower", "on": "base", "x": "offset", "y": "front",
     "params": {"width": 5.0, "depth": 3.0, "height": 4.0, "offset_x": 4.5}}]}


def test_flush_blocks_parameters_recovered():
    model, cams, raw, start, K, res = _run(FLUSH, seed=3)
    sol = solve_facade(start, res.marks, K, noise_px=0.5)      # refuses if one is unconstrained
    # the flush edge was proposed somewhere: it is what fixes width against offset
    assert any(m.proposed and m.edge == "annex/front-left" for m in res.marks.marks)
    for n, v in model.named_values().items():
        if sol.std[n] > 0:
            assert abs(sol.params[n] - v) <= 5 * sol.std[n], (n, sol.params[n], v, sol.std[n])


@pytest.mark.parametrize("seed", [4, 5])
def test_flush_edge_buried_by_a_small_start_is_still_proposed(seed):
    # a start 5 % small puts the annex's left end 0.1 m inside the tower:
    # the plain occlusion test hides the flush edge from every photograph
    # (the premise), so no round could propose it and the annex's width and
    # offset stayed at the start (the bench's village s13, seed 503: 3.2x
    # the fully marked solve's error). Within the association's gate of the
    # rough model it is a candidate
    from lumigraph.capture.scenes.facade_edges import project_edges

    # the annex set back: its front-left corner is the concave one against
    # the tower's right wall, which it alone marks (the village's annex)
    spec = {"blocks": [FLUSH["blocks"][0], {**FLUSH["blocks"][1], "y": "back"}]}
    model, cams, raw, start, K, res = _run(spec, seed=seed, start_factor=0.95)
    plain = project_edges(start, cams, min_length_px=15.0, samples=41)
    assert not any(m["edge"] == "annex/front-left" for v in plain.values() for m in v)
    assert any(m.proposed and m.edge == "annex/front-left" for m in res.marks.marks)
    sol = solve_facade(start, res.marks, K, noise_px=0.5)      # refuses if one is unconstrained
    for n, v in model.named_values().items():
        if sol.std[n] > 0:
            assert abs(sol.params[n] - v) <= 5 * sol.std[n], (n, sol.params[n], v, sol.std[n])


def test_collinear_edges_share_a_detection_by_extent():
    # edge 0 from y = 0 to 100, edge 1 on the same line from y = 60 to 100, a
    # third parallel line 30 px off: a detection along x = 10 from y = 10 to
    # 95 gives edge 0 all of it and edge 1 its stretch from y = 60
    E = np.array([[10, 0, 10, 100], [10, 60, 10, 100], [40, 0, 40, 100]], float)
    det = np.array([[10.2, 10, 10.2, 95]])
    got = {j: s for _, j, s in _associate(det, E, max_angle_deg=3, max_distance_px=6)}
    assert set(got) == {0, 1}
    np.testing.assert_allclose(got[0], det[0])
    np.testing.assert_allclose(got[1], [10.2, 60, 10.2, 95])
    # a distinct line 1.2 px from edge 0 (coincident means within 1 px), the
    # detection between them: ambiguous, given to neither
    E[1] = [11.2, 0, 11.2, 100]
    det[0, [0, 2]] = 10.5
    assert _associate(det, E, max_angle_deg=3, max_distance_px=6) == []


def test_edges_on_one_image_line_but_not_in_3d_stay_ambiguous():
    """A corner seen just beside a nearer block's silhouette in the rough
    model (reported seed 41 at stop 50: the house's back corner, hidden
    behind the tower in truth, projected onto the tower's silhouette and
    took its detection): the two project within 1 px over the same stretch
    but are different 3-D lines, so the detection is neither's. Where they
    are one 3-D line (a flush neighbour) they share it, as before; where
    they lie side by side on the image line (their extents apart), each
    takes its own part."""
    E = np.array([[10, 0, 10, 100], [10.4, 20, 10.4, 90], [40, 0, 40, 100]], float)
    det = np.array([[10.2, 10, 10.2, 95]])
    kw = dict(max_angle_deg=3, max_distance_px=6)
    assert {j for _, j, _ in _associate(det, E, **kw)} == {0, 1}          # image lines only
    apart = np.eye(3, dtype=bool)
    assert _associate(det, E, same_line=apart, **kw) == []
    one = apart.copy()
    one[0, 1] = one[1, 0] = True
    assert {j for _, j, _ in _associate(det, E, same_line=one, **kw)} == {0, 1}
    E[1] = [10.4, 100, 10.4, 160]                  # side by side: edge 1 beyond edge 0's end
    det = np.array([[10.2, 10, 10.2, 150]])
    got = {j: s for _, j, s in _associate(det, E, same_line=apart, **kw)}
    assert set(got) == {0, 1}
    np.testing.assert_allclose(got[0], [10.2, 10, 10.2, 100])
    np.testing.assert_allclose(got[1], [10.2, 100, 10.2, 150])


def test_same_lines_are_one_line_in_3d():
    from lumigraph.stereo.debevec1996.automark import _same_lines
    from lumigraph.stereo.debevec1996.model import BlockModel
    from lumigraph.stereo.debevec1996.solve import FIXTURE

    m = BlockModel.from_dict(FIXTURE)
    names = ["house/bottom-front", "tower/bottom-front", "tower/bottom-back", "house/front-right",
             "tower/front-right"]
    got = _same_lines(m, names)
    assert np.array_equal(got, got.T) and got.diagonal().all()
    # the tower stands flush with the house's front: its front bottom edge is
    # on the house's; its back one and the two vertical corners are not
    assert got[0, 1] and not got[0, 2] and not got[3, 4]
    assert got.sum() == len(names) + 2
    # a rough model need not keep a flush pair flush: the tower's left corner
    # 5 cm off the house's right one is one line within 2 px at 30 m (700 px
    # focal: 5 cm is 1.2 px there), not within 0.5 px
    rough = m.with_values({"tower/offset_x": 6.55})
    pair = ["house/front-right", "tower/front-left"]
    assert _same_lines(m, pair)[0, 1] and not _same_lines(rough, pair)[0, 1]
    cam = {"K": np.diag([700.0, 700.0, 1.0]), "R": np.eye(3), "t": np.array([-5.0, -3.0, 30.0])}
    assert _same_lines(rough, pair, cam, 2.0)[0, 1]
    assert not _same_lines(rough, pair, cam, 0.5)[0, 1]
    assert _same_lines(m, []).shape == (0, 0)          # a photograph that shows no edge


def test_of_two_lines_given_to_one_edge_the_nearest_is_proposed():
    """A face seen nearly edge-on: its near and far sides project a pixel or
    two apart, and the rough pose can turn it away and hide the far side.
    Both lines are detected, and both given to the near side."""
    from lumigraph.stereo.debevec1996.automark import _one_line

    # the far side hidden (x = 8.3) and the near side (x = 10.3) given a short
    # detection of itself and a long one of the far side: the old rule took
    # the longest. Now the nearest line to the rough edge, its longest piece
    true, far = np.array([10.3, 40, 10.3, 80]), np.array([8.3, 5, 8.3, 95])
    piece = np.array([10.3, 82, 10.3, 98])
    assert np.array_equal(_one_line([far, piece, true], np.array([10.0, 0, 10.0, 100])), true)
    # the rough edge between the two lines: either may be it, neither is proposed
    assert _one_line([far, true], np.array([9.3, 0, 9.3, 100])) is None


HIDDEN = {"blocks": [
    {"name": "house", "kind": "box",
     "params": {"width": {"value": 10.0, "fixed": True}, "depth": 6.0, "height": 6.0}},
    # a low shed behind the house: no camera of the front arc sees it
    {"name": "shed", "kind": "box", "parent": "house", "on": "base", "x": "centre", "y": "offset",
     "params": {"width": 4.0, "depth": 2.0, "height": 2.0, "offset_y": 4.0}}]}


def test_hidden_block_gets_no_proposal_and_is_named():
    model, cams, raw, start, K, res = _run(HIDDEN, seed=2, photos=5, arc=(-120.0, -60.0))
    seen = {(p, m["edge"]) for p, v in raw.items() for m in v}
    assert not any(e.startswith("shed/") for _, e in seen)      # the premise: all hidden
    proposed = {(m.photo, m.edge) for m in res.marks.marks if m.proposed}
    assert proposed and proposed <= seen
    # never silently wrong: the shed's parameters are named, not quietly kept
    named = " ".join(res.warnings)
    for n in ("shed/width", "shed/depth", "shed/height", "shed/offset_y"):
        assert n in named, named
    with pytest.raises(Exception, match="shed/"):
        solve_facade(start, res.marks, K, noise_px=0.5)



def test_rough_solve_retests_what_a_re_solve_lets_wander():
    # the bench's tower, camera seed 8, noise draw 1: holding the parameters
    # that fail the trust test and re-solving let annex/width go to 0, and
    # untested it took the annex onto the wrong lines (ratio 18.8). The
    # parameters must come out within 5 of the σ the solver reports
    from lumigraph.stereo import bench_facade as B

    model, cams = B.scene("tower", 8)
    rng = np.random.default_rng(500 + 10 * 8 + 1)
    raw, _ = B._marks(model, cams, noise=0.5, rng=rng)
    hand = EdgeMarks.from_dict({"photographs": {p: _hand(model, v) for p, v in raw.items()}},
                               model=model, photographs=list(cams))
    images = {p: paint_facade(model, c, rng=rng) for p, c in cams.items()}
    start = model.with_values(model.values[~model.fixed] * rng.uniform(0.9, 1.1))
    K = B._K(cams)
    res = automark(start, hand, images, K, noise_px=0.5)
    sol = solve_facade(start, res.marks, K, noise_px=0.5)
    for n, v in model.named_values().items():
        if sol.std[n] > 0:
            assert abs(sol.params[n] - v) <= 5 * sol.std[n], (n, sol.params[n], v, sol.std[n])


def test_cli_refuses_to_overwrite_the_input_edges_naming_the_path(tmp_path):
    # the refusal names the file (the library's convention), not the flag;
    # --force passes the generic guard against replacing a file it did not
    # write, which refuses first otherwise
    from cli_catalog import _facade_folder, run_cli

    _facade_folder(tmp_path)
    edges = tmp_path / "facade" / "edges.json"
    before = edges.read_bytes()
    rc, _, err = run_cli(["stereo", "facade", "automark", tmp_path / "facade", "--out", edges,
                          "--force", "-q"])
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and lines[0].startswith(f"error: {edges}:"), err
    assert "--out" not in lines[0] and edges.read_bytes() == before


def _in_turn_directly(E, Jc, c, scale, *, var, count, markable):
    """The refusal list's greedy rule computed the plain way: per step and
    per candidate, the null space and the pseudo-inverse of the whole
    stacked matrix from its own SVD (what the rank-two updates replace)."""
    from lumigraph.stereo.debevec1996.solve import NULL_WEIGHT, RANK_RCOND

    def null_and_std(Q):
        _, s, Vt = np.linalg.svd(Q, full_matrices=True)
        keep = s > RANK_RCOND * s[0]
        r = int(keep.sum())
        std = np.sqrt(var * ((Vt[:r] / s[:r, None]) ** 2).sum(0))[c] / scale
        return Vt[r:], s, float(std.max())

    Q, left, out = E, list(range(len(Jc))), []
    while left and len(out) < count:
        N, s, std_now = null_and_std(Q)
        w_now = float(np.linalg.norm(N[:, c], axis=0).max()) if len(N) else 0.0
        got = []
        for j in left:
            Nj = null_and_std(np.vstack([Q, Jc[j]]))[0]
            w = float(np.linalg.norm(Nj[:, c], axis=0).max()) if len(Nj) else 0.0
            got.append((j, w, null_and_std(np.vstack([Q, Jc[j]]))[2] if w <= NULL_WEIGHT else None))
        con = [g for g in got if g[2] is not None]
        if con:
            j, _, sd = min(con, key=lambda g: g[2])
            if w_now <= NULL_WEIGHT and not sd < std_now:
                break
        else:
            j, w, sd = min(got, key=lambda g: g[1])
            if not w < w_now - 1e-6:
                break
        out.append((j, sd))
        Q = np.vstack([Q, Jc[j]]) if markable[j] else Q
        left.remove(j)
    return out


def test_a_refusal_list_in_turn_matches_the_pseudo_inverse_of_the_whole_stack():
    """The refusal list's cheap step (the candidate's two rows turned to
    pin null directions or measure the range, against the marks' SVD)
    gives the same list and σ as the
    SVD of the whole stack per candidate, on a stack built to be hard:
    five null directions (what the refusal names; one candidate's two
    rows cannot pin them all, so lists start with marks that do not
    constrain alone), one direction held 10⁻⁶ as strongly as the rest
    (above the rank test's 10⁻⁹: an update through the inverse of the
    information loses its digits there, as a first form of this step did
    on a rendered scene, answering σ = 0), candidates that see none of the
    null space, and some not markable."""
    from lumigraph.stereo.debevec1996.automark import _constraining_in_turn

    rng = np.random.default_rng(3)
    n = 14
    basis = np.linalg.qr(rng.normal(size=(n, n)))[0]
    sv = np.r_[np.linspace(3.0, 1.0, n - 6), 1e-6, np.zeros(5)]
    E = rng.normal(size=(40, n)) @ np.diag(np.r_[np.ones(n - 6), np.zeros(6)])
    E = np.linalg.qr(E)[0][:, :n] @ np.diag(sv) @ basis.T          # singular values sv
    Jc = rng.normal(size=(30, 2, n))
    for j in range(0, 30, 3):                      # some see none of the null space
        Jc[j] = Jc[j] @ (basis[:, :n - 5] @ basis[:, :n - 5].T)
    markable = rng.random(30) > 0.2
    for col in range(n):
        c, scale = np.array([col]), np.array([1.0])
        if np.linalg.norm(basis[col, n - 5:]) < 0.2:               # not an unknown of the null space
            continue
        fast = _constraining_in_turn(E, Jc, c, scale, var=0.25, count=6, markable=markable)
        slow = _in_turn_directly(E, Jc, c, scale, var=0.25, count=6, markable=markable)
        assert [j for j, _ in fast] == [j for j, _ in slow], (col, fast, slow)
        for (_, a), (_, b) in zip(fast, slow, strict=True):
            assert (a is None) == (b is None) and (a is None or abs(a - b) <= 1e-6 * b), (col, a, b)


def test_a_linear_start_with_an_edge_next_to_a_camera_centre_is_degenerate():
    """A Jacobian column 10¹⁰ times the others' (a marked edge projected next to
    a camera's centre at the linear start) is a degenerate start, as a
    non-finite one is; a spread of 10³ between parameters' columns (a
    parameter that barely moves its edges) is not. Beside such a column the
    rank test's floor (10⁻⁹ of the largest) would call every other
    parameter unconstrained."""
    from lumigraph.stereo.debevec1996.solve import _degenerate_start, _rank_deficient

    rng = np.random.default_rng(0)
    names = ["a/width", "a/height", "b/width", "p.png:rotation", "p.png:position"]
    J = rng.normal(size=(20, 5)) * [100, 0.1, 50, 1e4, 10]
    assert not _degenerate_start(J, names)
    assert _rank_deficient(J, names) == []
    J[:3, 1] = 1e12
    assert _degenerate_start(J, names)
    assert _rank_deficient(J, names) == ["a/width", "b/width"]   # the false refusal it prevents
    J[0, 0] = np.nan
    assert _degenerate_start(J, names)


def _noisy_solve(seed, *, off=None):
    """The solver's fixture building seen by six ring cameras, every visible
    edge marked with σ = 0.5 px endpoint noise; ``off``: (mark index, px)
    moved across its line."""
    from lumigraph.stereo.debevec1996.solve import FIXTURE

    m = BlockModel.from_dict(FIXTURE)
    cams = ring_cameras(6, target=[1.5, 0, 4], radius=30, height=4, focal_px=700)
    marks = EdgeMarks.from_dict({"photographs": project_edges(m, cams)}, model=m,
                                photographs=list(cams))
    rng = np.random.default_rng(seed)
    noisy = [type(k)(k.photo, k.edge, k.segment + rng.normal(0, 0.5, 4)) for k in marks.marks]
    if off is not None:
        i, px = off
        a, b = noisy[i].segment[:2], noisy[i].segment[2:]
        d = (b - a) / np.hypot(*(b - a))
        noisy[i] = type(noisy[i])(noisy[i].photo, noisy[i].edge,
                                  noisy[i].segment + px * np.r_[-d[1], d[0], -d[1], d[0]])
    sol = solve_facade(m, type(marks)(tuple(noisy), marks.photographs),
                       {p: c["K"] for p, c in cams.items()}, robust=False)
    return sol, noisy


def test_deleted_residuals_are_unit_scaled_on_noise_alone():
    """On marks with only their σ = 0.5 px noise, each mark's distance from
    where the others put its edge, in its own σ, squared, is χ²₂/2: mean 1,
    variance 1. Over the 410 marks of 5 draws the mean of the squares has a
    standard error of about 1/√410 ≈ 0.05 if they were independent; the
    tolerance (0.25, five of those) allows for the marks' correlation and
    the linearisation, and still fails a score off by a factor of 1.15 in σ."""
    from lumigraph.stereo.debevec1996.automark import deleted_residuals

    sq = []
    for seed in range(5):
        sol, noisy = _noisy_solve(seed)
        t = deleted_residuals(sol, noisy)
        assert np.all(np.isfinite(t)), "every edge of this building is seen in several photographs"
        sq.append(t**2)
    sq = np.concatenate(sq)
    assert abs(sq.mean() - 1.0) < 0.25, sq.mean()


def test_a_mark_off_its_edge_scores_highest_though_its_residual_does_not():
    """A mark moved 2.5 px (5σ) across its line: the solve pulls towards it,
    so its own residual need not be the largest, but its distance from
    where the other marks put its edge is (the deleted residual), and
    beyond what noise alone gives."""
    from lumigraph.stereo.debevec1996.automark import deleted_residuals

    for i in (3, 17, 40):
        sol, noisy = _noisy_solve(11, off=(i, 2.5))
        t = deleted_residuals(sol, noisy)
        assert int(np.argmax(t)) == i, (i, np.argsort(-t)[:3], t[i])
        # significant: P(√(χ²₂/2) > 2.5) = e^-6.25 ≈ 0.002 per mark on noise alone
        assert t[i] > 2.5


def test_a_mark_that_alone_holds_a_parameter_cannot_be_checked():
    """The only mark of the building's one edge that fixes a parameter: the
    others leave that parameter free, so nothing can check the mark (inf),
    and the other marks still score finitely."""
    from lumigraph.stereo.debevec1996.automark import deleted_residuals

    sol, noisy = _noisy_solve(3)
    model = sol.model
    # keep one mark of each edge that moves with tower/height; drop the rest of them
    names = [m.edge for m in noisy]
    height_edges = [e for e in dict.fromkeys(names) if e.startswith("tower/top")]
    keep = [m for m in noisy if m.edge not in height_edges]
    first = next(m for m in noisy if m.edge == height_edges[0])
    marks = keep + [first]
    K = {p: sol.K[p] for p in sol.poses}
    sol2 = solve_facade(model, EdgeMarks(tuple(marks), tuple(sol.poses)), K, robust=False)
    t = deleted_residuals(sol2, marks)
    assert np.isinf(t[-1])
    assert np.all(np.isfinite(t[:-1]))


@pytest.mark.parametrize("side", ["left", "right", "top", "bottom"])
def test_painted_edge_sits_where_it_projects(side):
    # the photographs automatic marking is tested on must not move an edge:
    # a half-plane painted through paint_facade's triangle fill, box-filtered
    # to pixels, puts its edge (coverage summed across it) on the true line.
    # Per fine row the span's end is quantised to 1/ss px (uniform error,
    # sd (1/ss)/sqrt(12)); over 16 pixel rows x ss fine rows of a generic
    # slope the mean's sd is 0.0032 px at ss = 8: 0.02 px is six of them.
    # OpenCV's fill, used before, grew the painted side by 0.06-0.12 px.
    from lumigraph.capture.scenes.facade_edges import _paint_triangle

    ss, n, slope, x0 = 8, 40, 0.37, 20.3
    mirror, transpose = side in ("right", "bottom"), side in ("top", "bottom")
    ys = np.arange(12, 28)
    # the painted side: x < x0 + slope (y - 20) ("left"), as two triangles;
    # mirrored in x (the painted side to the right), transposed (an edge
    # across the columns), or both
    quad = np.array([[-5, -5], [x0 - 25 * slope, -5], [x0 + 25 * slope, 45], [-5, 45]], float)
    if mirror:
        quad[:, 0] = n - 1 - quad[:, 0]
    if transpose:
        quad = quad[:, ::-1]
    fine = np.zeros((n * ss, n * ss))
    for tri in (quad[[0, 1, 2]], quad[[0, 2, 3]]):
        _paint_triangle(fine, tri, ss, 1.0)
    cov = fine.reshape(n, ss, n, ss).mean(axis=(1, 3))
    if transpose:
        cov = cov.T
    if mirror:
        cov = cov[:, ::-1]
    # the coverage of row y sums to edge + 0.5: pixel k spans [k - 0.5, k + 0.5]
    edge = cov[ys].sum(1) - 0.5
    truth = x0 + slope * (ys - 20)
    assert abs(np.mean(edge - truth)) < 0.02


@pytest.mark.parametrize("name, seed, draw, switch", [
    # a draw of the bench's tower (a tuning scene) whose proposals include
    # three with one end 2-2.5 px off their true edges (the detector's
    # segment ran on past a corner): each pulls its solved edge towards
    # itself, so the residual check passes them; measured against where the
    # other marks put their edges they are 3 sigma off or more, and go.
    # (One such proposal on the install of 2026-12-05: OpenCV 5.1.0.95,
    # NumPy 2.4.6, SciPy 1.17.1)
    ("tower", 3, 531, "_CHECK_CONTRADICTED"),
    # the house's left wall seen nearly edge-on from photo_03 (a reported
    # scene, a fresh draw): the rough pose turns it away, its far side (2.5
    # px from the near one) is hidden, and of two detections given to the
    # near side the longer, the far side's, went to it, 2.2 px off, with the
    # roof's rake above it; the two agree, so neither is contradicted
    ("house", 2, 11023, "_ONE_LINE_EACH"),
])
def test_proposals_off_their_edge_are_not_kept(name, seed, draw, switch):
    """No proposal ends more than 1.5 px (3 sigma of a hand mark) from its
    true edge; with the step that keeps them out switched off, some do."""
    import lumigraph.stereo.debevec1996.automark as am
    from lumigraph.stereo import bench_facade as BF
    from lumigraph.stereo.debevec1996.solve import project_model_edges

    model, cams = BF.scene(name, seed)
    rng = np.random.default_rng(draw)
    raw, _ = BF._marks(model, cams, noise=0.5, rng=rng)
    hand = EdgeMarks.from_dict({"photographs": {p: BF.four_hand_marks(model, v)
                                                for p, v in raw.items()}},
                               model=model, photographs=list(cams))
    images = {p: paint_facade(model, c, rng=rng) for p, c in cams.items()}
    start = model.with_values(model.values[~model.fixed] * rng.uniform(0.9, 1.1))

    def far_ends(marks):
        out = set()
        for m in marks.marks:
            c = cams[m.photo]
            a, b = project_model_edges(model, np.array(c["K"]), np.array(c["R"]),
                                       np.array(c["t"]))[m.edge]
            d = b - a
            n = np.array([-d[1], d[0]]) / np.hypot(*d)
            if m.proposed and max(abs((m.segment[:2] - a) @ n), abs((m.segment[2:] - a) @ n)) > 1.5:
                out.add((m.photo, m.edge))
        return out

    setattr(am, switch, False)
    try:
        before = am.automark(start, hand, images, BF._K(cams), noise_px=0.5)
    finally:
        setattr(am, switch, True)
    after = am.automark(start, hand, images, BF._K(cams), noise_px=0.5)
    assert far_ends(before.marks)                  # the premise
    assert not far_ends(after.marks)
    # nothing else is lost: the solve holds no parameter it did not
    assert set(after.solution.held) <= set(before.solution.held)


def _resect_case(seed=3):
    model = BlockModel.from_dict(FLUSH, where="test")
    V = model.vertices()
    centre = (V.min(0) + V.max(0)) / 2
    size = float(np.linalg.norm(np.ptp(V, axis=0)))
    cams = ring_cameras(3, target=centre, radius=2.2 * size, height=0.3 * size, focal_px=700,
                        arc_deg=(-160.0, -20.0), rng=np.random.default_rng(seed), jitter=0.05)
    raw = project_edges(model, cams)
    marks = EdgeMarks.from_dict({"photographs": {p: _hand(model, v) for p, v in raw.items()}},
                                model=model, photographs=list(cams))
    return model, cams, marks


def test_a_photograph_left_out_is_resected_from_its_rough_rotation():
    # the translation from exact marks and the true rotation is exact: eq. 5.5
    # with the model known is linear in t, and 4 lines give 8 rows for 3 unknowns
    model, cams, marks = _resect_case()
    K = {p: c["K"] for p, c in cams.items()}
    got = _resect(model, marks, K, list(cams),
                  rough_rotations={p: c["R"] for p, c in cams.items()})
    assert set(got) == set(cams)
    for p, (R, t) in got.items():
        np.testing.assert_array_equal(R, cams[p]["R"])
        scale = np.linalg.norm(np.ravel(cams[p]["t"]))
        np.testing.assert_allclose(t, np.ravel(cams[p]["t"]), rtol=0, atol=1e-9 * scale)


def test_resection_needs_a_rough_rotation_and_marks_that_fix_t():
    model, cams, marks = _resect_case()
    K = {p: c["K"] for p, c in cams.items()}
    p = list(cams)[0]
    assert _resect(model, marks, K, [p], rough_rotations=None) == {}
    # only the two vertical marks: parallel lines leave t free along them
    from dataclasses import replace
    vert = [m for m in marks.of(p) if _known_axis(model, [m.edge])[0] == 2]
    assert len(vert) == 2
    only = replace(marks, marks=tuple(vert))
    assert _resect(model, only, K, [p], rough_rotations={p: cams[p]["R"]}) == {}


def test_cli_records_each_start_tried_in_the_meta(tmp_path):
    # the brief's rule for automatic choices: every candidate's score is on
    # record, and exactly one is marked kept
    import json

    from cli_catalog import _facade_folder, run_cli

    _facade_folder(tmp_path)
    out = tmp_path / "proposed.json"
    rc, _, err = run_cli(["stereo", "facade", "automark", tmp_path / "facade", "--out", out, "-q"])
    assert rc == 0, err
    from lumigraph.capture.artifact import meta_path

    starts = json.loads(meta_path(out).read_text())["quality"]["starts"]
    assert 1 <= len(starts) <= 3 and sum(s["chosen"] for s in starts) == 1, starts
    assert all({"start", "hand_marks_rejected", "held", "proposed", "sigma_px", "fits_noise",
                "hand_marks_fit_noise"} <= set(s) for s in starts), starts


def _around(model, photos: int, *, arc):
    """``photos`` cameras on an arc around the model, 700 px focal length."""
    V = model.vertices()
    centre = (V.min(0) + V.max(0)) / 2
    size = float(np.linalg.norm(np.ptp(V, axis=0)))
    return ring_cameras(photos, target=centre, radius=2.2 * size, height=0.3 * size,
                        focal_px=700, arc_deg=arc, rng=np.random.default_rng(0), jitter=0.05)


def test_proposals_on_edges_the_solved_model_hides_are_named():
    # a proposal the solve fits but whose edge the solved model hides (or
    # shows elsewhere on its line) is the mark of a block moved onto other
    # image lines (session 36: the wing's corner on a window frame)
    from lumigraph.stereo.debevec1996.automark import _unseen_proposals
    from lumigraph.stereo.debevec1996.edges import Mark
    from lumigraph.stereo.debevec1996.solve import project_model_edges

    model = BlockModel.from_dict(FLUSH, where="test")
    cams = _around(model, 5, arc=(-160.0, -20.0))
    raw = project_edges(model, cams)
    marks = EdgeMarks.from_dict({"photographs": raw}, model=model, photographs=list(cams))
    K = {p: c["K"] for p, c in cams.items()}
    sol = solve_facade(model, marks, K, noise_px=0.5)
    images = {p: np.zeros((c["image_size"][1], c["image_size"][0]), np.uint8)
              for p, c in cams.items()}
    photo = next(iter(cams))
    seen = {m["edge"]: np.asarray(m["segment"], float) for m in raw[photo]}
    shown = next(e for e, s in seen.items() if np.hypot(*(s[2:] - s[:2])) > 60)
    hidden = next(e for e in model.edge_names if e not in seen)
    full = project_model_edges(model, K[photo], *sol.poses[photo])
    s = seen[shown]
    d = s[2:] - s[:2]
    beyond = np.r_[s[2:] + 0.1 * d, s[2:] + 0.9 * d]        # on its line, past its end
    props = [Mark(photo, shown, s, proposed=True),
             Mark(photo, hidden, np.r_[full[hidden][0], full[hidden][1]], proposed=True),
             Mark(photo, shown + "", beyond, proposed=True)]
    got = _unseen_proposals(sol, props[:2], images, min_length_px=15.0)
    assert got == [(photo, hidden)]
    assert _unseen_proposals(sol, props[2:], images, min_length_px=15.0) == [(photo, shown)]


WING = {"blocks": [
    {"name": "house", "kind": "box",
     "params": {"width": {"value": 10.0, "fixed": True}, "depth": 6.0, "height": 6.0}},
    # the wing's right face is the house's left wall: its right end is a
    # concave crease against the house (the rendered building's wing)
    {"name": "wing", "kind": "box", "parent": "house", "on": "base", "x": "offset", "y": "back",
     "params": {"width": 4.0, "depth": 4.0, "height": 4.0, "offset_x": -7.0}}]}


@pytest.mark.parametrize("crease", [True, False])
def test_a_lone_proposal_on_an_edge_the_model_hides_is_replaced_by_the_crease(crease):
    # session 36's s21 d3: the one proposal for the wing's front-right corner
    # lay on a window frame, fixed the wing's right end alone (no residual
    # can test it) and put that end behind the house, which then hides the
    # edge it was made for. Left out, the end is free again; where the
    # photographs show the crease along it (painted walls facing two ways:
    # two grey levels), the crease replaces it; where they show nothing
    # (a flat grey picture), nothing changes
    from dataclasses import replace

    from lumigraph.stereo.debevec1996 import automark as am
    from lumigraph.stereo.debevec1996.edges import Mark
    from lumigraph.stereo.debevec1996.solve import project_model_edges

    model = BlockModel.from_dict(WING, where="test")
    cams = _around(model, 5, arc=(-170.0, -100.0))
    rng = np.random.default_rng(1)
    raw = project_edges(model, cams, noise_px=0.5, rng=rng)
    # every edge marked but those whose 3-D line slides with the wing's right end
    right = {"wing/front-right", "wing/back-right", "wing/top-right", "wing/bottom-right"}
    hand = EdgeMarks.from_dict({"photographs": {p: [m for m in v if m["edge"] not in right]
                                                for p, v in raw.items()}},
                               model=model, photographs=list(cams))
    if crease:
        images = {p: paint_facade(model, c, rng=rng) for p, c in cams.items()}
    else:
        images = {p: np.clip(120 + rng.normal(0, 1, (c["image_size"][1], c["image_size"][0])),
                             0, 255).astype(np.uint8) for p, c in cams.items()}
    K = {p: c["K"] for p, c in cams.items()}
    rough = model.with_values(model.values[~model.fixed] * 1.1)
    assert set(solve_facade(rough, hand, K, noise_px=0.5, hold_unconstrained=True).held) == {
        "wing/width", "wing/offset_x"}                          # the premise: the end is free
    # the lone wrong proposal: the corner 0.6 m inside the house, in one photograph
    photo = next(iter(cams))
    wrong = model.with_values({"wing/width": 4.6, "wing/offset_x": -6.7})
    a, b = project_model_edges(wrong, np.asarray(K[photo], float),
                               np.asarray(cams[photo]["R"], float),
                               np.asarray(cams[photo]["t"], float).ravel())["wing/front-right"]
    prop = Mark(photo, "wing/front-right", np.r_[a, b], proposed=True)
    sol = solve_facade(rough, replace(hand, marks=tuple(hand.marks) + (prop,)), K, noise_px=0.5,
                       hold_unconstrained=True)
    assert not sol.held
    unseen = am._unseen_proposals(sol, [prop], images, min_length_px=15.0)
    assert unseen == [(photo, "wing/front-right")]
    kept = {(photo, prop.edge): prop}
    got, now, said = am._replace_unseen(
        sol, kept, unseen, current=rough, marks=hand, K=K, images=images,
        greys={p: am._grey(i) for p, i in images.items()}, rough=rough, trust=0.3,
        rough_rotations=None, noise_px=0.5, where="test")
    if not crease:
        assert got is sol and now is kept and said == []
        return
    assert said and "crease found along the direction they fixed replaces them" in said[-1]
    assert not got.held
    assert all(m is not prop for m in now.values())
    assert len({m.photo for m in now.values()}) >= 2
    # each crease proposal on its true edge within 1.5 px (3 σ of a mark)
    for m in now.values():
        cam = cams[m.photo]
        e0, e1 = project_model_edges(model, np.asarray(cam["K"], float), np.asarray(cam["R"], float),
                                     np.asarray(cam["t"], float).ravel())[m.edge]
        n = np.array([-(e1 - e0)[1], (e1 - e0)[0]]) / np.hypot(*(e1 - e0))
        assert max(abs((m.segment[:2] - e0) @ n), abs((m.segment[2:] - e0) @ n)) <= 1.5
    # the right end (offset + width / 2) where it is, within 3 σ of the solve's own
    i, j = got.unknowns.index("wing/offset_x"), got.unknowns.index("wing/width")
    c = np.zeros(len(got.unknowns))
    c[i], c[j] = 1.0, 0.5
    end = got.params["wing/offset_x"] + got.params["wing/width"] / 2
    assert abs(end + 5.0) <= 3.0 * np.sqrt(c @ got.covariance @ c), end


@pytest.mark.parametrize("seed", range(3))
def test_the_votes_gate_prefilter_gives_the_moving_edges_what_association_gives_them(seed):
    """``_support`` leaves out the detections within no moving edge's gates
    before ``_associate``: each detection is decided on its own, so the
    moving edges get exactly the segments they get from every detection.
    Detections scattered about edges, a third of them near-copies of an
    edge (within the gates), some two edges nearly on one line."""
    from lumigraph.stereo.debevec1996.automark import _in_gates

    rng = np.random.default_rng(seed)
    E = rng.uniform(0, 300, (30, 4))
    E[1] = E[0] + [0.4, 0.4, 60.0, 60.0 * (E[0, 3] - E[0, 1]) / (E[0, 2] - E[0, 0])]  # near one line
    near = E[rng.integers(0, 30, 80)] + rng.normal(0, 1.5, (80, 4))
    det = np.concatenate([near, rng.uniform(0, 300, (160, 4))])
    moving = rng.random(30) < 0.4
    kw = dict(max_angle_deg=5.0, max_distance_px=4.0)
    full = [(i, j, s) for i, j, s in _associate(det, E, **kw) if moving[j]]
    keep = np.flatnonzero(_in_gates(det, E[moving], **kw))
    some = [(int(keep[i]), j, s) for i, j, s in _associate(det[keep], E, **kw) if moving[j]]
    assert len(full) >= 10                       # the case gives the moving edges something
    assert len(keep) < len(det)                  # and the prefilter leaves some out
    assert [(i, j) for i, j, _ in full] == [(i, j) for i, j, _ in some]
    assert all(np.array_equal(a, b) for (_, _, a), (_, _, b) in zip(full, some, strict=True))


def test_ray_triangles_by_components_is_moller_trumbore():
    """The component form of ``ray_triangles`` against the textbook one
    (``np.cross``) on random rays and triangles: equal to round-off."""
    from lumigraph.capture.scenes.facade_edges import ray_triangles

    rng = np.random.default_rng(0)
    O, d, tris = rng.normal(size=(50, 3)), rng.normal(size=(50, 3)), rng.normal(size=(40, 3, 3))
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    pv = np.cross(d[:, None], e2[None])
    det = np.einsum("ktj,tj->kt", pv, e1)
    s = O[:, None] - v0[None]
    q = np.cross(s, e1[None])
    ok, u, v, tt = ray_triangles(O, d, tris)
    assert np.array_equal(ok, np.abs(det) > 1e-12)
    # where ray and triangle are far from parallel (|det| > 0.1, terms of
    # order 1) both forms are exact to a few units of round-off (1e-16)
    well = np.abs(det) > 0.1
    assert well.mean() > 0.5
    for got, want in ((u, np.einsum("ktj,ktj->kt", s, pv) / det),
                      (v, np.einsum("kj,ktj->kt", d, q) / det),
                      (tt, np.einsum("ktj,tj->kt", q, e2) / det)):
        np.testing.assert_allclose(got[well], want[well], rtol=1e-12, atol=1e-12)
