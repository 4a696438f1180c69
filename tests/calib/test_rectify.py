"""Rectification obeys the disparity convention (DESIGN §3) on an asymmetric rig:
equal rows, ``x_right = x_left - d`` with ``d = f B / Z > 0``."""

import numpy as np
import pytest

from lumigraph.calib.rectify import Rectification, rectify
from lumigraph.capture.camera import Camera
from lumigraph.capture.rig import Rig


def _rig(T=(-0.12, 0.004, 0.002)):
    import cv2

    # fx != fy, cx, cy off centre, different cameras, a rotation off every axis:
    # a swapped argument or transposed matrix breaks the row equality below
    Kl = np.array([[310.0, 0, 84], [0, 305, 57], [0, 0, 1]])
    Kr = np.array([[300.0, 0, 78], [0, 298, 62], [0, 0, 1]])
    left = Camera(Kl, [-0.2, 0.05, 1e-3, -5e-4, 0], (160, 120))
    right = Camera(Kr, [-0.1, 0.02, 0, 0, 0], (160, 120))
    R = cv2.Rodrigues(np.array([0.01, -0.03, 0.02]))[0]
    return Rig.from_pose(left, right, R, np.array(T))


def _points(n=200):
    return np.random.default_rng(1).uniform([-0.5, -0.4, 1.5], [0.5, 0.4, 3.0], (n, 3))


def test_rows_equal_and_disparity_is_fB_over_Z():
    rig = _rig()
    r = rectify(rig)
    X = _points()
    xl, xr = r.project_left(X), r.project_right(X)
    Z = (X @ r.R1.T)[:, 2]
    assert np.abs(xl[:, 1] - xr[:, 1]).max() < 1e-9
    d = xl[:, 0] - xr[:, 0]
    assert np.all(d > 0)
    np.testing.assert_allclose(d, r.focal_px * r.baseline / Z, rtol=1e-10)
    assert r.baseline == pytest.approx(rig.baseline, rel=1e-12)


def test_maps_sample_the_original_distorted_pixels():
    import cv2

    rig = _rig()
    r = rectify(rig)
    X = _points()
    xl, xr = r.project_left(X), r.project_right(X)
    pl = rig.left.project(X)
    pr = rig.right.project(X @ rig.R.T + rig.T)
    lx, ly, rx, ry = r.maps()
    assert lx.dtype == np.float32 and lx.shape == (120, 160)
    w, h = r.image_size
    for rect, orig, mx, my in ((xl, pl, lx, ly), (xr, pr, rx, ry)):
        ok = (rect[:, 0] > 1) & (rect[:, 0] < w - 2) & (rect[:, 1] > 1) & (rect[:, 1] < h - 2)
        assert ok.sum() > 20
        q = rect[ok].astype(np.float32)[:, None, :]
        sx = cv2.remap(mx, q[..., 0], q[..., 1], cv2.INTER_LINEAR).ravel()
        sy = cv2.remap(my, q[..., 0], q[..., 1], cv2.INTER_LINEAR).ravel()
        # the maps are smooth: bilinear interpolation of them errs by far less than 0.01 px
        assert np.abs(sx - orig[ok, 0]).max() < 0.01 and np.abs(sy - orig[ok, 1]).max() < 0.01


def test_apply_moves_a_dot_to_the_same_row_with_the_right_disparity():
    rig = _rig()
    r = rectify(rig)
    X = np.array([[0.03, -0.02, 2.0]])
    yy, xx = np.mgrid[0:120, 0:160]

    def dot(p):
        return (255 * np.exp(-((xx - p[0]) ** 2 + (yy - p[1]) ** 2) / (2 * 2.0**2))).astype(np.uint8)

    L = dot(rig.left.project(X)[0])
    R = dot(rig.right.project(X @ rig.R.T + rig.T)[0])
    Lr, Rr = r.apply(L, R)
    assert Lr.dtype == np.uint8 and Lr.shape == (120, 160)

    def centroid(img):
        w = img.astype(float)
        return np.array([(w * xx).sum(), (w * yy).sum()]) / w.sum()

    cl, cr = centroid(Lr), centroid(Rr)
    # 8-bit rounding and bilinear resampling of a 2 px Gaussian shift a centroid by < 0.05 px
    assert abs(cl[1] - cr[1]) < 0.05
    Z = (X @ r.R1.T)[0, 2]
    assert abs((cl[0] - cr[0]) - r.focal_px * r.baseline / Z) < 0.05


def test_depth_and_reproject_agree_and_nan_where_unknown():
    r = rectify(_rig())
    disp = np.full((120, 160), 12.5)
    disp[0, 0] = np.nan
    disp[0, 1] = 0.0
    disp[0, 2] = -3.0
    z = r.disparity_to_depth(disp)
    pts = r.reproject(disp)
    assert z.dtype == np.float32 and pts.shape == (120, 160, 3)
    assert np.isnan(z[0, :3]).all() and np.isnan(pts[0, :3]).all()
    assert z[5, 5] == pytest.approx(r.focal_px * r.baseline / 12.5, rel=1e-6)
    np.testing.assert_allclose(pts[..., 2][1:], z[1:], rtol=1e-6)
    # a reprojected point projects back to its pixel in the left and, shifted by d, the right image
    X = pts[40, 100].astype(np.float64)[None]
    hl = X @ r.P1[:, :3].T + r.P1[:, 3]
    hr = X @ r.P2[:, :3].T + r.P2[:, 3]
    np.testing.assert_allclose(hl[0, :2] / hl[0, 2], [100, 40], atol=1e-3)
    np.testing.assert_allclose(hr[0, :2] / hr[0, 2], [100 - 12.5, 40], atol=1e-3)


def test_save_load_round_trip(tmp_path):
    r = rectify(_rig(), alpha=0.5)
    p = r.save(tmp_path / "rectification.json")
    q = Rectification.load(p)
    for name in ("R1", "R2", "P1", "P2", "Q"):
        np.testing.assert_array_equal(getattr(q, name), getattr(r, name))
    assert q.image_size == r.image_size and q.extra["alpha"] == 0.5
    np.testing.assert_array_equal(q.rig.T, r.rig.T)


def test_refuses_rigs_that_would_break_the_disparity_convention():
    with pytest.raises(ValueError, match="right camera to the right"):
        rectify(_rig(T=(0.12, 0.0, 0.0)))
    with pytest.raises(ValueError, match="horizontal"):
        rectify(_rig(T=(-0.01, 0.12, 0.0)))
    with pytest.raises(ValueError, match="alpha"):
        rectify(_rig(), alpha=2.0)
