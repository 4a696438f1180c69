"""Rectifying a posed (jittered) camera array onto the ideal regular array."""

import json

import cv2
import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph
from scipy.ndimage import map_coordinates

from lumigraph.capture.render import render
from lumigraph.lightfield.field import LightField
from lumigraph.lightfield.refocus import shift_and_add

M = 6   # border excluded: rotation by <= 0.5 deg moves pixels <= ~1.5 px, plus the kernels


@pytest.fixture(scope="module")
def jittered():
    return render("lightfield-array", size=(64, 48), grid="3x3", thin_lens=False,
                  jitter_deg=0.5, focus=(0.35,))


def _rms(a, b):
    return float(np.sqrt(np.mean((a[:, :, M:-M, M:-M] - b[:, :, M:-M, M:-M]) ** 2)))


def _half_pixel_round_trip(gt):
    """Interpolation-only error: the capture's cubic B-spline and the import's
    Lanczos-4 resampling composed at the worst fractional phase (0.5 px on
    both axes); a rotation warp's phases all lie in [0, 0.5], so its round
    trip cannot be worse than this (up to the kernels' sub-pixel variation)."""
    h, w = gt.shape[2:4]
    gx, gy = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    out = np.empty_like(gt)
    for i in range(gt.shape[0]):
        for j in range(gt.shape[1]):
            fw = np.stack([map_coordinates(gt[i, j, ..., c].astype(float), [gy + 0.5, gx + 0.5],
                                           order=3, mode="mirror") for c in range(3)], -1)
            out[i, j] = cv2.remap(fw.astype(np.float32), (gx - 0.5).astype(np.float32),
                                  (gy - 0.5).astype(np.float32), cv2.INTER_LANCZOS4,
                                  borderMode=cv2.BORDER_REFLECT101)
    return _rms(out, gt)


def test_import_with_poses_reproduces_the_ideal_array(jittered, tmp_path):
    folder = tmp_path / "scene"
    jittered.save(folder)
    r = lumigraph("lightfield", "import", folder, "--out", tmp_path / "lf")
    assert r.returncode == 0, r.stderr
    lf = LightField.load(tmp_path / "lf")
    gt = jittered.gt_arrays["views"]
    raw = np.stack([im.astype(np.float32) / 65535 for im in jittered.images]).reshape(gt.shape)
    bound = _half_pixel_round_trip(gt)
    err = _rms(lf.data, gt)
    # 16-bit quantisation (1/65535/sqrt(12) ~ 4e-6) is negligible against the bound.
    assert 0 < err <= bound, (err, bound)
    assert err < 0.6 * _rms(raw, gt)          # the un-rectified views are far off
    meta = json.loads((tmp_path / "lf" / "lightfield.json.meta.json").read_text())
    # The mean optical axis tilts by < 0.5 deg from the grid normal, which
    # shortens the in-plane spacing by at most 1 - cos(0.5 deg) = 3.8e-5.
    assert meta["quality"]["fitted_spacing"] == pytest.approx(1.0, abs=3.8e-5)
    assert lf.focal_px == pytest.approx(64.0)
    # Refocusing the rectified array against the exact synthetic aperture:
    # bounded by the same interpolation error (averaging views cannot add).
    sa = jittered.gt_arrays["synthetic_aperture"][0]
    ref = shift_and_add(lf, 0.35)
    e_ref = float(np.sqrt(np.mean((ref[M:-M, M:-M] - sa[M:-M, M:-M]) ** 2)))
    assert 0 < e_ref <= bound


def test_off_grid_camera_is_refused(jittered, tmp_path):
    cams = json.loads(json.dumps(jittered.stack["lightfield"]["cameras"]))
    R = np.array(cams[4]["cam_from_world"]["R"])
    centre = -R.T @ np.array(cams[4]["cam_from_world"]["t"])
    centre[0] += 0.3                                # 0.3 grid steps off its node
    cams[4]["cam_from_world"]["t"] = (-R @ centre).tolist()
    rig = tmp_path / "rig.json"
    rig.write_text(json.dumps({"cameras": cams}))
    folder = tmp_path / "scene"
    jittered.save(folder)
    files = sorted(folder.glob("view-*.png"))
    r = lumigraph("lightfield", "import", *files, "--grid", "3x3", "--linear", "--rig", rig,
                  "--out", tmp_path / "lf")
    assert_clean_error(r, "view-01-01.png", "grid steps")
    assert not (tmp_path / "lf").exists()
    r = lumigraph("lightfield", "import", *files, "--grid", "3x3", "--linear", "--rig",
                  tmp_path / "missing.json", "--out", tmp_path / "lf")
    assert_clean_error(r, "missing.json")
    rig.write_text(json.dumps({"cameras": cams[:4]}))
    r = lumigraph("lightfield", "import", *files, "--grid", "3x3", "--linear", "--rig", rig,
                  "--out", tmp_path / "lf")
    assert_clean_error(r, "rig.json", "4 cameras")
    assert not (tmp_path / "lf").exists()
    # the library names its argument (poses); the command line reports the flag that set it
    one_place = [dict(c, cam_from_world=cams[4]["cam_from_world"]) for c in cams]
    rig.write_text(json.dumps({"cameras": one_place}))
    r = lumigraph("lightfield", "import", *files, "--grid", "3x3", "--linear", "--rig", rig,
                  "--out", tmp_path / "lf")
    assert_clean_error(r, "error: --rig: ", "do not spread along the grid's columns")
    assert not (tmp_path / "lf").exists()


def test_plane_depth_is_checked_by_the_library(jittered, tmp_path):
    from lumigraph.capture.errors import InputError
    from lumigraph.lightfield.rectify import rectify_views

    with pytest.raises(InputError, match="^plane_depth: expected > 0, got -1"):
        rectify_views([], [], [], grid=(1, 2), plane_depth=-1.0)
    folder = tmp_path / "scene"
    jittered.save(folder)
    r = lumigraph("lightfield", "import", folder, "--plane-depth", "-1", "--out", tmp_path / "lf")
    assert_clean_error(r, "error: --plane-depth: expected a number > 0 or inf, got '-1'")
    assert not (tmp_path / "lf").exists()
