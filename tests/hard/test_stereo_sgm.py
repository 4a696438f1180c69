"""Hard cases for semi-global matching: an exposure change between the views,
a textureless card, a disparity range too small for the scene, KITTI's wide
range and sky, and images of different sizes (exit 2). The peer, OpenCV
StereoSGBM (its best of MODE_SGBM and MODE_HH at OpenCV's recommended P1/P2),
runs on the same inputs in the same test."""

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph
from scipy import ndimage

from lumigraph.capture import io
from lumigraph.capture.bench import shared_data
from lumigraph.capture.render import render
from lumigraph.stereo import hirschmuller2008 as sgm
from lumigraph.stereo.bench_stereo import exposure_changed, visible


def _sgbm_best(left, right, max_disp, gt, mask):
    import cv2

    c = 1 if left.ndim == 2 else 3
    best = 1.0
    for mode in (cv2.STEREO_SGBM_MODE_SGBM, cv2.STEREO_SGBM_MODE_HH):
        for w in (3, 5):
            sg = cv2.StereoSGBM_create(0, int(16 * np.ceil((max_disp + 1) / 16)), w, P1=8 * c * w * w,
                                       P2=32 * c * w * w, disp12MaxDiff=1, uniquenessRatio=10, mode=mode)
            d = sg.compute(left, right).astype(np.float32) / 16
            d[d < 0] = np.nan
            best = min(best, _bad2(d, gt, mask))
    return best


def _bad2(d, gt, mask):
    return float(np.mean(~(np.abs(d[mask] - gt[mask]) <= 2.0)))  # missing counts as bad


@pytest.fixture(scope="module")
def pair():
    s = render("stereo-pair", size=(240, 180))
    gt = s.gt_arrays["disparity"].astype(np.float64)
    return s.images[0], s.images[1], gt, visible(gt), int(s.gt["suggested_max_disp"]) - 1


def test_census_codes_survive_a_monotonic_exposure_change(pair):
    # census compares each neighbour with the centre: a monotonic tone change
    # keeps every comparison except where it merges two grey levels into one
    # (quantisation ties), which can only clear a bit, never set one
    g = sgm._guide(pair[1], pair[1])[0]  # an 8-bit grey image
    a, b = sgm.census(g), sgm.census(exposure_changed(g))
    assert np.all((a | b) == a)  # b's bits are a subset of a's
    assert np.mean(a == b) > 0.5


def test_exposure_change_between_the_views(pair):
    left, right, gt, nonocc, max_disp = pair
    right_dark = exposure_changed(right)  # brightness x0.6 and gamma 1/1.25
    ours = sgm.match(left, right_dark, max_disp=max_disp).disparity
    peer = _sgbm_best(left, right_dark, max_disp, gt, nonocc)
    assert _bad2(ours, gt, nonocc) <= peer


def test_textureless_card_is_not_garbage(pair):
    s = render("stereo-pair", size=(240, 180), textureless=True)
    card = ndimage.binary_erosion(np.abs(s.gt_arrays["depth"] - 2.6) < 1e-9, iterations=8)
    assert card.sum() > 500
    gt = s.gt_arrays["disparity"]
    d = sgm.match(s.images[0], s.images[1], max_disp=47).disparity
    # SGM may carry the card's edges across it (the paths); what it gives
    # there must then be right: a flat card holds no evidence for any other
    # value, so at most 10 % of it may carry a chance value (the bound of
    # block matching's textureless test)
    wrong = np.isfinite(d[card]) & (np.abs(d[card] - gt[card]) > 2)
    assert wrong.mean() < 0.1


def test_range_too_small_is_said(pair, tmp_path):
    left, right, gt, _, max_disp = pair
    small = int(np.nanmax(gt)) // 2
    res = sgm.match(left, right, max_disp=small)
    assert any("max_disp" in w for w in res.info["warnings"])
    # the pixels beyond the range are unknown, not pinned at the range's end
    beyond = np.isfinite(gt) & (gt > small + 2)
    assert np.mean(np.isfinite(res.disparity[beyond]) & (res.disparity[beyond] >= small - 0.5)) < 0.05
    # the command line says so on stderr and in the sidecar, and still writes the map
    L, R = tmp_path / "L.png", tmp_path / "R.png"
    io.write_image(L, left)
    io.write_image(R, right)
    out = tmp_path / "d.pfm"
    r = lumigraph("stereo", "match", L, R, "--max-disp", str(small), "--out", out)
    assert r.returncode == 0, r.stderr
    assert "max_disp" in r.stderr and "range" in r.stderr
    import json

    meta = json.loads((tmp_path / "d.pfm.meta.json").read_text())
    assert any("max_disp" in w for w in meta["warnings"])


def test_images_of_different_sizes_exit_2(pair, tmp_path):
    left, right = pair[0], pair[1]
    L, R = tmp_path / "L.png", tmp_path / "R.png"
    io.write_image(L, left)
    io.write_image(R, right[:, :-3])
    out = tmp_path / "d.pfm"
    r = lumigraph("stereo", "match", L, R, "--max-disp", "16", "--out", out)
    assert_clean_error(r, str(R), "differs from the left image")
    assert not out.exists()


@pytest.fixture(scope="module")
def kitti():
    base = shared_data("data", "stereo-kitti2015")
    if not base.exists():
        pytest.skip("../shared/data/stereo-kitti2015 not present")
    left = io.read_image(base / "image_2" / "000046_10.png")
    right = io.read_image(base / "image_3" / "000046_10.png")
    v = io.read_image(base / "disp_occ_0" / "000046_10.png").astype(np.float64)
    gt = np.where(v > 0, v / 256.0, np.nan)
    max_disp = int(16 * np.ceil((np.nanmax(gt) + 2) / 16)) - 1
    return left, right, gt, max_disp, sgm.match(left, right, max_disp=max_disp).disparity


def test_kitti_wide_range(kitti):
    left, right, gt, max_disp, disparity = kitti
    known = np.isfinite(gt)
    assert _bad2(disparity, gt, known) <= _sgbm_best(left, right, max_disp, gt, known)


@pytest.mark.xfail(strict=True, reason="known limitation (docs/decisions/stereo-sgm.md): the "
                   "paths carry the trees' and poles' disparities into KITTI's smooth sky more "
                   "often than StereoSGBM does")
def test_kitti_sky(kitti):
    left, right, _, max_disp, disparity = kitti
    # the sky (bright blue in the upper third, no LiDAR) is at infinity: its
    # smooth gradient matches every disparity alike, and what the paths carry
    # into it from trees and poles is wrong. No worse than the peer there.
    import cv2

    r, b = left[..., 0].astype(int), left[..., 2].astype(int)
    sky = (b > r + 25) & (b > 150)
    sky[left.shape[0] // 3:] = False
    assert sky.mean() > 0.1

    def far_off(d):
        return np.mean(np.isfinite(d[sky]) & (d[sky] > 3))

    peer = []
    for mode in (cv2.STEREO_SGBM_MODE_SGBM, cv2.STEREO_SGBM_MODE_HH):
        sg = cv2.StereoSGBM_create(0, max_disp + 1, 3, P1=72, P2=288, disp12MaxDiff=1,
                                   uniquenessRatio=10, mode=mode)
        d = sg.compute(left, right).astype(np.float32) / 16
        d[d < 0] = np.nan
        peer.append(far_off(d))
    assert far_off(disparity) <= min(peer)
