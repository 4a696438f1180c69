"""Façade photogrammetric modelling (stereo/debevec1996/): the block model,
the marks, the solver and the command line, on exact synthetic marks
(capture/scenes/facade_edges.py). Tolerances: noise-free marks give the true
parameters to round-off (1e-8 relative, a million times the double epsilon
times the problem's conditioning); noisy marks are judged in units of the
standard deviation the solver reports (which the bench checks against 50
noise draws)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_catalog import run_cli
from facade_checks import assert_jacobian_matches_differences, fixture_cameras, fixture_model

from lumigraph.capture.errors import InputError
from lumigraph.capture.scenes.facade_edges import project_edges, ring_cameras, write_facade_folder
from lumigraph.stereo.debevec1996.edges import EdgeMarks
from lumigraph.stereo.debevec1996.model import BlockModel
from lumigraph.stereo.debevec1996.solve import _Problem, solve_facade

ROOT = Path(__file__).resolve().parents[2]
BLOCKS = ROOT / "fixtures" / "facade" / "blocks.json"


@pytest.fixture(scope="module")
def model():
    return fixture_model()


@pytest.fixture(scope="module")
def cams():
    return fixture_cameras()


def marks_of(model, cams, **kw):
    return EdgeMarks.from_dict({"photographs": project_edges(model, cams, **kw)}, model=model,
                               photographs=list(cams))


def K(cams):
    return {p: c["K"] for p, c in cams.items()}


# ------------------------------------------------------------------ the model
def test_model_geometry(model):
    assert model.parameter_names == ("house/depth", "house/height", "roof/height", "tower/width",
                                     "tower/height", "tower/offset_x", "spire/height")
    e = model.edges()
    np.testing.assert_allclose(e["roof/ridge"][0], [-5, 0, 8.5])
    np.testing.assert_allclose(e["tower/top-front"][1], [8, -3, 9])      # flush with the front
    np.testing.assert_allclose(e["spire/hip-front-left"][1], [6.5, -1.5, 11])
    mesh = model.mesh()
    V = mesh.vertices
    for b in set(mesh.face_block):
        F = mesh.faces[mesh.face_block == b]
        # outward counter-clockwise faces: the signed volume of each closed block is positive
        vol = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6
        assert vol > 0, b
    C0, C1 = model.edge_matrices(["tower/top-front"])
    np.testing.assert_allclose(C1[0] @ model.values, e["tower/top-front"][1])
    again = BlockModel.from_dict(model.to_dict(), where="x")
    assert again.named_values() == model.named_values()
    bigger = model.with_values({"tower/width": 4.0})
    assert bigger.named_values()["spire/depth"] == 4.0                 # shared through same_as


@pytest.mark.parametrize("change, fragment", [
    (lambda d: d["blocks"][0].update(parent="spire"), "cycle in the hierarchy"),
    (lambda d: d["blocks"][1].update(kind="dome"), "unknown kind 'dome'"),
    (lambda d: d["blocks"][2].update(parent="garage"), "unknown parent 'garage'"),
    (lambda d: d["blocks"][1]["params"].update(height={"same_as": "chimney/height"}),
     "unknown shared reference 'chimney/height'"),
    (lambda d: d["blocks"][1]["params"].pop("height"), "missing parameter 'height'"),
])
def test_bad_models_are_refused_naming_the_entry(change, fragment):
    d = json.loads(BLOCKS.read_text())
    change(d)
    with pytest.raises(InputError) as e:
        BlockModel.from_dict(d, where="blocks.json")
    assert e.value.where == "blocks.json" and fragment in e.value.problem
    assert "blocks[" in e.value.problem and "\n" not in str(e.value)


# ------------------------------------------------------------------ the solver
def test_analytic_jacobian_matches_finite_differences(model, cams):
    marks = marks_of(model, cams)
    R0 = np.array([c["R"] for c in cams.values()])
    prob = _Problem(model, list(marks.marks), list(cams), K(cams), R0, free_focal=True)
    rng = np.random.default_rng(0)
    x = prob.pack(model.values * 1.1, rng.normal(0, 0.1, (len(cams), 3)),
                  np.array([c["t"] for c in cams.values()]), 1.05)
    A = prob.weights(True)
    assert_jacobian_matches_differences(prob, x, A)


def test_noise_free_marks_give_the_truth(model, cams):
    start = model.with_values(model.values[~model.fixed] * 1.2)      # 20 % off, no rough poses
    sol = solve_facade(start, marks_of(model, cams), K(cams))
    for n, v in model.named_values().items():
        assert abs(sol.params[n] - v) <= 1e-8 * abs(v), n
    for p, c in cams.items():
        R, t = sol.poses[p]
        assert np.abs(R - c["R"]).max() < 1e-8
        np.testing.assert_allclose(sol.centres[p], -c["R"].T @ c["t"], atol=1e-8 * 30)
    assert sol.outliers == [] and sol.dropped == []


def test_sparse_path_gives_the_truth(model, cams, monkeypatch):
    import lumigraph.stereo.debevec1996.solve as solve

    monkeypatch.setattr(solve, "DENSE_MAX_COLUMNS", 0)   # what a large problem takes
    start = model.with_values(model.values[~model.fixed] * 1.2)
    sol = solve_facade(start, marks_of(model, cams), K(cams))
    # LSMR steps stop at their own tolerance: 1e-6 relative, the bench's target
    for n, v in model.named_values().items():
        assert abs(sol.params[n] - v) <= 1e-6 * abs(v), n


def test_free_focal_is_recovered(model, cams):
    wrong = {p: k @ np.diag([1.1, 1.1, 1.0]) for p, k in K(cams).items()}   # 10 % long focal
    wrong = {p: np.array([[k[0, 0], 0, c["K"][0, 2]], [0, k[1, 1], c["K"][1, 2]], [0, 0, 1]])
             for (p, k), c in zip(wrong.items(), cams.values(), strict=True)}
    sol = solve_facade(model, marks_of(model, cams), wrong, free_focal=True)
    assert abs(sol.focal_scale - 1 / 1.1) < 1e-8
    assert abs(sol.params["tower/height"] - 9.0) < 1e-7


def test_noisy_marks_within_the_reported_deviation(model, cams):
    rng = np.random.default_rng(5)
    sol = solve_facade(model, marks_of(model, cams, noise_px=0.5, rng=rng), K(cams), noise_px=0.5)
    assert 0.5 / 1.5 < sol.sigma_px < 0.5 * 1.5       # the endpoint noise, estimated
    for n, v in model.named_values().items():
        if sol.std[n] > 0:
            assert abs(sol.params[n] - v) < 5 * sol.std[n], n


def test_a_robust_pass_that_runs_off_is_not_the_final_start(model, cams, monkeypatch):
    """A robust (soft-loss) pass that drives a size non-positive (it drifts
    along a direction the marks barely hold: seed 19 of the view eval took
    wing/width to -8e7, and the solve answered it with σ 0) tests no mark
    and does not start the final solve: the answer is the plain solve's,
    from the linear initialisation, with no mark left out."""
    import lumigraph.stereo.debevec1996.solve as solve

    rng = np.random.default_rng(5)
    marks = marks_of(model, cams, noise_px=0.5, rng=rng)
    plain = solve_facade(model, marks, K(cams), noise_px=0.5, robust=False)
    real = solve.least_squares

    def runs_off(fun, x0, **kw):
        r = real(fun, x0, **kw)
        if kw.get("loss") == "soft_l1":
            r.x = r.x.copy()
            r.x[model.parameter_names.index("tower/width")] = -8e7   # the first free size
        return r

    monkeypatch.setattr(solve, "least_squares", runs_off)
    sol = solve_facade(model, marks, K(cams), noise_px=0.5)
    assert sol.outliers == []
    for n, v in plain.params.items():
        assert abs(sol.params[n] - v) <= 1e-8 * max(abs(v), 1.0), n


def test_a_linear_start_that_projects_an_edge_to_a_point_starts_from_the_starting_values(
        model, cams, monkeypatch):
    """When the linear initialisation (eq. 5.5) gives parameters at which a
    marked edge projects to a point (few marks, a weak direction: the
    marking eval's seed 44 put an edge through a camera's centre), the
    solve starts from the model's starting values instead of refusing with
    "check the starting values in blocks.json", which are fine: noise-free
    marks then give the truth, as from the linear start."""
    import lumigraph.stereo.debevec1996.solve as solve

    real = solve._linear_translations

    def degenerate(prob, R, th_start, cams_only=None):
        th, t = real(prob, R, th_start, cams_only)
        return np.full_like(th, np.nan), t       # no edge can be projected there

    monkeypatch.setattr(solve, "_linear_translations", degenerate)
    start = model.with_values(model.values[~model.fixed] * 1.1)
    sol = solve_facade(start, marks_of(model, cams), K(cams))
    for n, v in model.named_values().items():
        assert abs(sol.params[n] - v) <= 1e-8 * abs(v), n
    assert any("linear initialisation" in w for w in sol.warnings), sol.warnings


def test_a_linear_start_with_an_edge_next_to_a_camera_centre_starts_from_the_starting_values(
        model, cams, monkeypatch):
    """A seventh camera stands at (20, 0, 6) on the tower's right, where the
    line of ``tower/back-right`` (x = offset + 1.5, y = 0, vertical) passes
    when ``tower/offset_x`` is 18.5. A linear start 10⁻¹¹ m from that puts
    the edge next to the camera's centre: finite, but one Jacobian column
    so large that the rank test's floor (10⁻⁹ of the largest) took every
    other unknown for zero and the solve refused them all (the marking
    eval's seed 152). The solve starts from the starting values instead,
    says so, and noise-free marks give the truth."""
    import lumigraph.stereo.debevec1996.solve as solve
    from lumigraph.capture.scenes.facade_edges import look_at

    cams = dict(cams)
    R, t = look_at([20.0, 0.0, 6.0], [1.5, 0, 4])
    cams["side.png"] = {"K": cams["photo_00.png"]["K"], "R": R, "t": t, "image_size": [640, 480]}
    marks = marks_of(model, cams)
    assert any(m.photo == "side.png" and m.edge == "tower/back-right" for m in marks.marks)
    real, k = solve._linear_translations, model.slot_of("tower/offset_x")

    def near(prob, R, th_start, cams_only=None):
        th, t = real(prob, R, th_start, cams_only)
        th = th.copy()
        th[k] = 20.0 - 1.5 + 1e-11
        return th, t

    monkeypatch.setattr(solve, "_linear_translations", near)
    start = model.with_values(model.values[~model.fixed] * 1.1)
    sol = solve_facade(start, marks, K(cams))
    for n, v in model.named_values().items():
        assert abs(sol.params[n] - v) <= 1e-8 * abs(v), n
    assert any("next to" in w for w in sol.warnings), sol.warnings


# ------------------------------------------------------------------ the command line
def _folder(tmp_path, model, n=4, **kw):
    cams = ring_cameras(n, target=[1.5, 0, 4], radius=30, height=4, focal_px=120,
                        image_size=(128, 96), arc_deg=(-130.0, -50.0))
    start = model.with_values(model.values[~model.fixed] * 1.1)
    return write_facade_folder(tmp_path / "f", model, cams, start=start, **kw), cams


def test_cli_solve_writes_the_model_and_cameras(tmp_path, model):
    folder, cams = _folder(tmp_path, model)
    rc, _, err = run_cli(["stereo", "facade", "solve", str(folder), "--out", str(tmp_path / "o"),
                          "-q"])
    assert rc == 0, err
    body = json.loads((tmp_path / "o" / "model.json").read_text())
    gt = json.loads((folder / "gt.json").read_text())
    assert set(body["parameters"]) == set(gt["parameters"])
    for n, v in gt["parameters"].items():
        assert abs(body["parameters"][n]["value"] - v) <= 1e-8 * v, n
    for p, c in gt["cameras"].items():
        np.testing.assert_allclose(body["cameras"][p]["R"], c["R"], atol=1e-8)
        cam = json.loads((tmp_path / "o" / "cameras" / f"{Path(p).stem}.json").read_text())
        np.testing.assert_allclose(cam["cam_from_world"]["t"], c["t"], atol=1e-6)
    assert (tmp_path / "o" / "model.ply").read_bytes().startswith(b"ply\n")
    assert "PINHOLE" in (tmp_path / "o" / "cameras.txt").read_text()


@pytest.mark.parametrize("edit, fragment", [
    (lambda d: d["blocks"][3].update(parent="spire"), "cycle in the hierarchy"),
    (lambda d: d["blocks"][3].update(kind="dome"), "unknown kind 'dome'"),
])
def test_cli_bad_model_is_exit_2_naming_file_and_entry(tmp_path, model, edit, fragment):
    folder, _ = _folder(tmp_path, model, n=3)
    d = json.loads((folder / "blocks.json").read_text())
    edit(d)
    (folder / "blocks.json").write_text(json.dumps(d))
    rc, _, err = run_cli(["stereo", "facade", "solve", str(folder), "--out", str(tmp_path / "o")])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1, err
    assert "blocks.json" in lines[0] and "blocks[3]" in lines[0] and fragment in lines[0]
    assert not (tmp_path / "o").exists()


def test_cli_unknown_edge_name_is_exit_2_naming_file_and_entry(tmp_path, model):
    folder, _ = _folder(tmp_path, model, n=3)
    d = json.loads((folder / "edges.json").read_text())
    d["photographs"]["photo_01.png"][2]["edge"] = "tower/top-middle"
    (folder / "edges.json").write_text(json.dumps(d))
    rc, _, err = run_cli(["stereo", "facade", "solve", str(folder), "--out", str(tmp_path / "o")])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1, err
    assert "edges.json" in lines[0] and "photo_01.png[2]" in lines[0]
    assert "'tower/top-middle'" in lines[0]


def test_cli_refusal_lists_the_edges_that_would_constrain_each_unknown(tmp_path, model):
    """Marks without the tower's top and the spire leave both heights free
    (the tower's verticals slide along their own lines): exit 2, the one
    error line naming them, then (as the marking page does) per unknown,
    in the error's order, the unmarked edges that would constrain it as
    ``photo edge``. Down to the first that constrains the unknown they lie
    on the tower or the spire, the only blocks whose edges carry the
    heights; none is already marked. Nothing is written."""
    folder, _ = _folder(tmp_path, model)
    d = json.loads((folder / "edges.json").read_text())
    d["photographs"] = {p: [m for m in ms if not m["edge"].startswith(("tower/top", "spire/"))]
                        for p, ms in d["photographs"].items()}
    (folder / "edges.json").write_text(json.dumps(d))
    marked = {(p, m["edge"]) for p, ms in d["photographs"].items() for m in ms}
    rc, _, err = run_cli(["stereo", "facade", "solve", str(folder), "--out", str(tmp_path / "o")])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, err
    assert lines[0].startswith("error: ") and "edges.json" in lines[0], err
    named = lines[0].split("do not constrain ")[1].split(":")[0].split(", ")
    assert {"tower/height", "spire/height"} <= set(named), err
    assert lines[1].startswith("  mark where the photograph shows them"), err
    assert [ln.split(": ")[0].strip() for ln in lines[2:]] == named, err
    for ln in lines[2:]:
        if not ln.strip().startswith(("tower/height", "spire/height")):
            continue
        items = [it.split(" (")[0].split(" ") for it in ln.split(": ", 1)[1].split(", ")]
        assert items and all(len(it) == 2 and (it[0], it[1]) not in marked for it in items), ln
        upto = next(i for i, it in enumerate(ln.split(": ", 1)[1].split(", "))
                    if "(one of several it needs)" not in it)
        assert all(e.split("/")[0] in ("tower", "spire") for _, e in items[:upto + 1]), ln
    assert not (tmp_path / "o").exists()


def test_poorly_determined_rotations_and_parameters_are_said():
    """A solve whose first-order σ says a camera's rotation is unknown to more
    than 1° (or a size to more than a third of itself) warns, naming them;
    exact marks give no such warning."""
    from lumigraph.stereo.debevec1996.solve import FIXTURE, WEAK_ROTATION_RAD, solve_facade

    m = BlockModel.from_dict(FIXTURE)
    cams = ring_cameras(6, target=[1.5, 0, 4], radius=30, height=4, focal_px=700)
    marks = EdgeMarks.from_dict({"photographs": project_edges(m, cams)}, model=m,
                                photographs=list(cams))
    K = {p: c["K"] for p, c in cams.items()}
    exact = solve_facade(m, marks, K, robust=False)
    assert not [w for w in exact.warnings if "poorly determined" in w]
    rng = np.random.default_rng(1)
    noisy = type(marks)(tuple(type(k)(k.photo, k.edge, k.segment + rng.normal(0, 20.0, 4))
                              for k in marks.marks), marks.photographs)
    sol = solve_facade(m, noisy, K, noise_px=20.0, robust=False)
    weak = [p for p, d in sol.pose_std.items() if np.max(d["rotation_rad"]) > WEAK_ROTATION_RAD]
    assert weak
    said = [w for w in sol.warnings if w.startswith("poorly determined camera rotations")]
    assert len(said) == 1 and all(p in said[0] for p in weak)


def test_the_covariance_stays_positive_semi_definite_on_a_nearly_free_direction():
    """``sandwich_covariance`` on a Jacobian whose column-scaled condition
    is 1e9 (the rank test's limit; the marking eval's seed 81 reached such a
    solve): no negative variance, and the variance of the weak direction is
    the exact one, σ²/s_min², to 1e-6 relative. Inverting JᵀJ (the old
    way) squares the condition to 1e18, beyond double precision, and loses
    both. On a well-conditioned Jacobian the two agree to 1e-10."""
    from lumigraph.stereo.debevec1996.solve import sandwich_covariance

    rng = np.random.default_rng(5)
    m, p = 60, 8
    U, _ = np.linalg.qr(rng.normal(size=(m, p)))
    V, _ = np.linalg.qr(rng.normal(size=(p, p)))
    s = np.logspace(0, -9, p)
    J = (U * s) @ V.T
    cov = sandwich_covariance(J, J, 0.5)
    assert np.linalg.eigvalsh(cov).min() >= -1e-12 * np.abs(cov).max()
    weak = V[:, -1]
    exact = 0.25 / s[-1] ** 2
    assert abs(weak @ cov @ weak - exact) < 1e-6 * exact
    old = 0.25 * np.linalg.inv(J.T @ J)
    assert abs(weak @ old @ weak - exact) > 1e-3 * exact or np.linalg.eigvalsh(old).min() < 0
    J2 = (U * np.logspace(0, -2, p)) @ V.T
    assert np.allclose(sandwich_covariance(J2, J2, 0.5), 0.25 * np.linalg.inv(J2.T @ J2),
                       rtol=1e-10, atol=0)
