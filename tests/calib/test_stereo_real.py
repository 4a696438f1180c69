"""Stereo rigs: synthetic (exact R, T) and OpenCV's real photos (RMS against
OpenCV's own pipeline, rectified rows)."""

import numpy as np
import pytest
from conftest import need_shared

from lumigraph.calib.calibrate import calibrate, calibrate_stereo
from lumigraph.calib.detect import BoardSpec, detect
from lumigraph.calib.rectify import rectify
from lumigraph.capture.render import render


def _rect_y_rms(rig, ld, rd):
    import cv2

    r = rectify(rig)
    ys = []
    for a, b in zip(ld, rd, strict=True):
        common, ia, ib = np.intersect1d(a.ids, b.ids, return_indices=True)
        if len(common) == 0:
            continue
        yl = cv2.undistortPoints(a.image_points[ia].reshape(-1, 1, 2), rig.left.K, rig.left.dist, R=r.R1, P=r.P1)
        yr = cv2.undistortPoints(b.image_points[ib].reshape(-1, 1, 2), rig.right.K, rig.right.dist, R=r.R2, P=r.P2)
        ys.append(yl.reshape(-1, 2)[:, 1] - yr.reshape(-1, 2)[:, 1])
    return float(np.sqrt(np.mean(np.concatenate(ys) ** 2)))


def test_synthetic_rig_recovers_R_T():
    import cv2

    s = render("boards-stereo", size=(320, 240), seed=6, views=10)
    board = BoardSpec.parse(s.stack["board"])
    n = len(s.images) // 2
    ld = [detect(im, board) for im in s.images[:n]]
    rd = [detect(im, board) for im in s.images[n:]]
    rig = calibrate_stereo(ld, rd, model="k1k2p1p2k3")
    Rt, Tt = np.array(s.gt["rig"]["R"]), np.array(s.gt["rig"]["T"])
    angle = np.degrees(np.linalg.norm(cv2.Rodrigues(rig.R @ Rt.T)[0]))
    # with the intrinsics fixed, the relative rotation inherits the principal-point
    # errors of both cameras (a shift of c by dc tilts a ray by dc/f): bound it by
    # 4 sigma of their combined principal-point uncertainty
    sl, sr = rig.left.extra["std"], rig.right.extra["std"]
    sigma = np.hypot(np.hypot(sl["cx"], sl["cy"]), np.hypot(sr["cx"], sr["cy"])) / rig.left.K[0, 0]
    assert 0 < angle < np.degrees(4 * sigma), (angle, np.degrees(sigma))
    assert 0 < abs(rig.baseline / np.linalg.norm(Tt) - 1) < 0.01
    assert _rect_y_rms(rig, ld, rd) < 0.2


@pytest.fixture(scope="module")
def real():
    from lumigraph.capture.io import read_image

    folder = need_shared("data", "calib-real")
    left = [read_image(p) for p in sorted(folder.glob("left*.jpg"))]
    right = [read_image(p) for p in sorted(folder.glob("right*.jpg"))]
    return left, right


def test_real_rms_no_worse_than_opencv_same_model(real):
    import cv2

    left, _ = real
    board = BoardSpec.parse("checker:10x7:1")
    cam = calibrate([detect(im, board) for im in left], model="k1k2p1p2k3")
    obj, img = [], []
    for im in left:  # OpenCV's own pipeline (its calibration tutorial's calls)
        ok, c = cv2.findChessboardCorners(im, (9, 6))
        assert ok
        img.append(cv2.cornerSubPix(im, c, (11, 11), (-1, -1), (3, 30, 1e-3)))
        obj.append(board.object_points.astype(np.float32))
    rms_cv = cv2.calibrateCamera(obj, img, (640, 480), None, None)[0]
    assert cam.extra["rms_px"] <= rms_cv


def test_real_rig_rectifies_rows_within_half_a_pixel(real):
    left, right = real
    board = BoardSpec.parse("checker:10x7:1")
    ld = [detect(im, board) for im in left]
    rd = [detect(im, board) for im in right]
    rig = calibrate_stereo(ld, rd, model="k1k2p1p2k3")
    assert rig.T[0] < 0
    assert _rect_y_rms(rig, ld, rd) < 0.5
