"""The committed ``fixtures/``: they regenerate byte for byte, stay small, and
every one is read as files by the command line, with each tolerance derived
from the fixture's own ground truth and noise (see fixtures/README.md).

Inputs are copied to ``tmp_path`` first: a command never runs on the
committed files, so no test can modify them.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import lumigraph
from scipy import ndimage

from lumigraph.capture import io

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "fixtures"
SCRIPT = FIXTURES / "make_fixtures.py"
NAMES = ("bracket-8bit", "bracket-12bit", "stereo-pair", "rig.json", "camera.json", "lightfield",
         "projector", "flow")


def _copy(tmp_path: Path, name: str) -> Path:
    src, dest = FIXTURES / name, tmp_path / name
    if src.is_dir():
        shutil.copytree(src, dest)
    else:
        shutil.copyfile(src, dest)
    return dest


def _ok(r: subprocess.CompletedProcess) -> None:
    assert r.returncode == 0, r.stderr


# ------------------------------------------------------------- the folder
def test_fixtures_regenerate_byte_for_byte():
    r = subprocess.run([sys.executable, str(SCRIPT), "--check"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr


def test_check_names_every_file_that_differs(tmp_path):
    target = tmp_path / "fixtures"
    shutil.copytree(FIXTURES, target, ignore=shutil.ignore_patterns("__pycache__"))
    png = target / "bracket-8bit" / "exposure_00.png"
    data = bytearray(png.read_bytes())
    data[-20] ^= 1
    png.write_bytes(bytes(data))
    (target / "flow" / "gt.flo").unlink()
    (target / "projector" / "extra.png").write_bytes(b"x")
    r = subprocess.run([sys.executable, str(SCRIPT), "--check", "--target", str(target)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 1
    named = [ln.split(":")[0] for ln in r.stderr.splitlines() if ln.startswith("fixtures/")]
    assert named == ["fixtures/bracket-8bit/exposure_00.png", "fixtures/projector/extra.png",
                     "fixtures/flow/gt.flo"], r.stderr


def test_fixtures_are_small_and_carry_no_sidecars():
    total = 0
    for name in NAMES:
        p = FIXTURES / name
        files = [p] if p.is_file() else [q for q in p.rglob("*") if q.is_file()]
        size = sum(q.stat().st_size for q in files)
        assert size < 300_000, (name, size)
        total += size
        assert not [q for q in files if q.name.endswith(".meta.json")], name
    assert total < 1_500_000
    assert {p.name for p in FIXTURES.iterdir()} - {"__pycache__"} == {*NAMES, "README.md",
                                                                      "make_fixtures.py",
                                                                      "make_bad_inputs.py",
                                                                      "facade", "facade-temple"}


# ------------------------------------------------------------ the brackets
@pytest.mark.parametrize("name, bits", [("bracket-8bit", 8), ("bracket-12bit", 12)])
def test_inspect_reads_the_bracket(tmp_path, name, bits):
    folder = _copy(tmp_path, name)
    _ok(lumigraph("inspect", folder, "--out", tmp_path / "summary.json", "-q"))
    s = json.loads((tmp_path / "summary.json").read_text())
    gt = json.loads((folder / "gt.json").read_text())
    assert (s["kind"], s["count"], s["shape"], s["bit_depth"]) == ("stack", 5, [48, 64, 3], bits)
    assert s["exposure_times_s"] == gt["exposure_times_exact_s"]  # float64, exactly


def _response_bound(folder: Path, fit: dict, knots: int) -> float:
    """Worst per-knot noise of the recovered ln response, from the scene's noise.

    One observation at the darkest scored code (5 % of full scale, where
    ``ln_response_rms`` starts) carries shot + read noise ``sqrt(e + r^2) / e``
    in ln X, with ``e = X * full_well`` electrons, plus the code's rounding
    (one code step of the true ln response over sqrt 12). Each knot of the
    curve sees ``samples * exposures * used / knots_scored`` observations
    (``used``: the fraction of observations inside the scored codes). The
    bound gives the fit no credit for smoothing, and takes every knot as dark
    as the darkest: brighter codes are far less noisy.
    """
    gt = json.loads((folder / "gt.json").read_text())
    stack = json.loads((folder / "stack.json").read_text())
    g = np.load(folder / "gt" / "g.npy")
    top = 2 ** stack["bit_depth"] - 1
    lo, hi = math.ceil(0.05 * top), int(0.95 * top)
    e = float(np.exp(g[:, lo]).min()) * gt["full_well_e"]
    shot_read = gt["noise_scale"] * math.sqrt(e + gt["read_noise_e"] ** 2) / e
    rounding = float((g[:, lo + 1] - g[:, lo]).max()) / math.sqrt(12)
    codes = np.stack([io.read_image(folder / n) for n in stack["images"]])
    used = float(((codes >= lo) & (codes <= hi)).mean())
    per_knot = fit["samples"] * len(stack["images"]) * used / (knots * (hi - lo) / top)
    return math.hypot(shot_read, rounding) / math.sqrt(per_knot)


@pytest.mark.parametrize("name", ["bracket-8bit", "bracket-12bit"])
def test_hdr_response_recovers_the_film_curve(tmp_path, name):
    from lumigraph.hdr.bench import ln_response_rms

    folder = _copy(tmp_path, name)
    out = tmp_path / "response.json"
    _ok(lumigraph("hdr", "response", folder, "--out", out, "-q"))
    body = json.loads(out.read_text())
    bits = json.loads((folder / "stack.json").read_text())["bit_depth"]
    err = ln_response_rms(np.array(body["g"]), np.load(folder / "gt" / "g.npy"), bits)
    bound = _response_bound(folder, body["fit"], body["selection"]["knots"])
    # > 0: the bracket is noisy, an exact curve would mean the truth leaked in
    assert 0 < err < bound, (err, bound)


# -------------------------------------------------- the rig and the pair
def _gt_pose(pair: Path):
    gt = json.loads((pair / "gt.json").read_text())
    right = gt["cam_from_world"]["right"]  # left camera = world
    return (np.array(gt["rig"]["left"]["K"]), np.array(gt["rig"]["right"]["K"]),
            np.array(right["R"]), np.array(right["t"]))


def _project(K, P):
    q = P @ K.T
    return q[..., :2] / q[..., 2:]


def test_rig_rectifies_the_pair_and_gives_depth(tmp_path):
    rig, pair = _copy(tmp_path, "rig.json"), _copy(tmp_path, "stereo-pair")
    K_l, K_r, R, t = _gt_pose(pair)
    rect = tmp_path / "rect"
    _ok(lumigraph("calib", "rectify", "--rig", rig, pair / "left.png", pair / "right.png",
                  "--out", rect, "-q"))
    r = json.loads((rect / "rectification.json").read_text())
    R1, R2, P1, P2 = (np.array(r[k]) for k in ("R1", "R2", "P1", "P2"))

    # Exact correspondences of the render (float64 projections, no lens
    # distortion) land on one row after rectification, up to float64 round-off
    # (~1e-13 px here; before rectification rows differ by pixels), with
    # positive disparity x_left - x_right.
    xy = np.load(pair / "gt" / "right_xy.npy")
    ok = np.isfinite(xy).all(axis=2)
    ys, xs = np.nonzero(ok)
    left = np.column_stack([xs, ys, np.ones(len(xs))])
    right = np.column_stack([xy[ok], np.ones(len(xs))])
    a = _project(P1[:, :3] @ R1 @ np.linalg.inv(K_l), left)
    b = _project(P2[:, :3] @ R2 @ np.linalg.inv(K_r), right)
    assert np.abs(left[:, 1] - right[:, 1]).max() > 1.0  # the fixture is not rectified
    assert np.abs(a[:, 1] - b[:, 1]).max() < 1e-6
    assert (a[:, 0] - b[:, 0]).min() > 0

    # A constant disparity d through `stereo depth` with the same rig: every
    # point lies on the ray of its rectified left pixel and on the ray of the
    # rectified right pixel d to the left, checked with the TRUE cameras and
    # pose against the source pixels of calib rectify's maps. The maps and the
    # reprojection are float32 (2^-24 relative, ~4e-6 px at 64 px): 1e-4 px.
    w, h = r["image_size"]
    d = 4
    io.write_pfm(tmp_path / "d.pfm", np.full((h, w), float(d), np.float32))
    _ok(lumigraph("stereo", "depth", tmp_path / "d.pfm", "--rig", rig, "--frame", "left",
                  "--out", tmp_path / "p.ply", "-q"))
    pts, _ = io.read_ply(tmp_path / "p.ply")
    P = pts.reshape(h, w, 3)
    maps_l = np.load(rect / "maps_left.npy").astype(np.float64)
    maps_r = np.load(rect / "maps_right.npy").astype(np.float64)
    assert np.abs(_project(K_l, P) - maps_l).max() < 1e-4
    assert np.abs(_project(K_r, P @ R.T + t)[:, d:] - maps_r[:, :-d]).max() < 1e-4


# ---------------------------------------------------------------- camera
def test_camera_undistorts_a_ramp(tmp_path):
    from lumigraph.capture.camera import Camera

    cam_file = _copy(tmp_path, "camera.json")
    cam = Camera.load(cam_file)
    w, h = cam.image_size
    # A 16-bit image whose codes are its own pixel coordinates (1000 + 600 x,
    # 1000 + 600 y): bilinear resampling reproduces a linear function, so each
    # undistorted pixel's codes say which source position it sampled.
    slope = 600
    ys, xs = np.mgrid[0:h, 0:w]
    ramp = np.stack([1000 + slope * xs, 1000 + slope * ys, np.full_like(xs, 30000)], -1)
    io.write_image(tmp_path / "ramp.png", ramp.astype(np.uint16))
    out = tmp_path / "undistorted"
    _ok(lumigraph("calib", "undistort", "--camera", cam_file, tmp_path / "ramp.png", "--out", out,
                  "-q"))
    got = (io.read_image(out / "ramp.png")[..., :2].astype(np.float64) - 1000) / slope
    new = Camera.load(out / "camera.json")
    assert np.all(new.dist == 0)
    # Where each output pixel must sample: its ray through the undistorted
    # camera, projected by the fixture camera (with its distortion).
    pix = np.column_stack([xs.ravel(), ys.ravel(), np.ones(xs.size)])
    want = cam.project(pix @ np.linalg.inv(new.K).T).reshape(h, w, 2)
    inside = ((want[..., 0] >= 0) & (want[..., 0] <= w - 1) & (want[..., 1] >= 0)
              & (want[..., 1] <= h - 1))
    assert inside.mean() > 0.9
    # OpenCV's bilinear remap may quantise the position to 1/32 px (<= 1/64 px
    # per axis); the 16-bit output rounds to half a code (0.5 / slope px).
    bound = 1 / 64 + 0.5 / slope + 1e-4
    assert np.abs(got - want)[inside].max() < bound
    # the lens moves pixels by more than a pixel: ignoring it would fail
    assert np.hypot(*(want - np.stack([xs, ys], -1)).transpose(2, 0, 1))[inside].max() > 1.0


# ------------------------------------------------------------ light field
def test_lightfield_refocus_matches_the_synthetic_aperture(tmp_path):
    lf = _copy(tmp_path, "lightfield")
    gt = json.loads((lf / "gt.json").read_text())
    (slope,) = gt["focus_slopes"]
    out = tmp_path / "focus.exr"
    _ok(lumigraph("lightfield", "refocus", lf, "--slope", str(slope), "--out", out, "-q"))
    img = io.read_exr(out)
    truth = np.load(lf / "gt" / "synthetic_aperture.npy")[0]
    # Slope 1 px per view step on a 3x3 grid: every view shifts by whole pixels,
    # where interpolation is exact; the views were stored as 16-bit codes, so
    # each is within half a code of the exact render, and so is their mean
    # (+ float32 summation). The border (|slope| x one view step) sees past
    # the frame in some views and is left out.
    u, v = gt["grid"]
    m = math.ceil(abs(slope) * max(u - 1, v - 1) / 2)
    bound = 0.5 / gt["code_scale"] + 1e-6
    assert img.shape == truth.shape
    assert np.abs(img - truth)[m:-m, m:-m].max() < bound


# -------------------------------------------------------------- projector
def test_separate_projector_conserves_light_and_finds_the_global_part(tmp_path):
    folder = _copy(tmp_path, "projector")
    out = tmp_path / "sep"
    _ok(lumigraph("separate", folder, "--method", "checker", "--out", out, "-q"))
    direct, global_ = (io.read_exr(out / f"{n}.exr") for n in ("direct", "global"))
    trusted = io.read_image(out / "mask.png") == 0
    full, true_global = (np.load(folder / "gt" / f"{n}.npy") for n in ("full", "global"))
    code = 1 / (2 ** json.loads((folder / "stack.json").read_text())["bit_depth"] - 1)
    assert trusted.mean() > 0.9
    # Each checker and its complement add up to the all-white projector (light
    # transport is linear and the captures share their renders), so direct +
    # global = full, up to the two captures' rounding (half a code each).
    assert np.abs(direct + global_ - full)[trusted].max() <= code + 1e-6
    # Nonetheless split: "no global light at all" would be off by exactly the
    # true global light at every pixel; the separation must do better.
    err = np.abs(global_ - true_global)[trusted].mean()
    assert 0 < err < true_global[trusted].mean()


# ------------------------------------------------------------------- flow
WINDOW = 9  # `lumigraph flow` default matching window


def test_flow_pair_is_sub_pixel_against_its_ground_truth(tmp_path):
    folder = _copy(tmp_path, "flow")
    out = tmp_path / "flow.flo"
    _ok(lumigraph("flow", folder / "frame00.png", folder / "frame01.png", "--out", out, "-q"))
    est, truth = io.read_flo(out), io.read_flo(folder / "gt.flo")
    assert est.shape == truth.shape and np.isfinite(truth).all()
    # Well-posed pixels, from the ground truth: the matching window sees one
    # surface (occluded and mixed pixels, dilated by the window's radius, are
    # out) and lies inside both frames (a border of max |flow| + radius).
    r = WINDOW // 2
    gtm = {n: np.load(folder / "gt" / f"{n}.npy") for n in ("occluded", "boundary")}
    ok = ~ndimage.binary_dilation(gtm["occluded"] | gtm["boundary"],
                                  np.ones((WINDOW, WINDOW), bool))
    b = math.ceil(float(np.abs(truth).max())) + r
    ok[:b], ok[-b:], ok[:, :b], ok[:, -b:] = False, False, False, False
    assert ok.sum() > 1000
    epe = np.hypot(*(est - truth).transpose(2, 0, 1))[ok]
    # Sub-pixel: more accurate than the true flow itself rounded to whole
    # pixels (what an exact integer matcher would give; ~0.3 px here). Above
    # zero: the frames carry 1 code of noise and 8-bit rounding.
    whole_pixel = np.hypot(*(np.round(truth) - truth).transpose(2, 0, 1))[ok]
    assert 0 < epe.mean() < whole_pixel.mean(), (epe.mean(), whole_pixel.mean())
