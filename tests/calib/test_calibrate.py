"""Calibration accuracy against exact ground truth, model selection, exports."""

import numpy as np
import pytest

from lumigraph.calib.calibrate import calibrate
from lumigraph.calib.detect import BoardSpec, Detection, detect
from lumigraph.capture.render import render


def _dets(s, noise_rms=0.0, seed=0):
    board = BoardSpec.parse(s.stack["board"])
    rng = np.random.default_rng(seed)
    out = []
    for im in s.images:
        d = detect(im, board)
        if noise_rms and len(d):
            d = Detection(d.ids, d.image_points + rng.normal(0, noise_rms / np.sqrt(2), d.image_points.shape),
                          d.object_points, d.image_size)
        out.append(d)
    return out


@pytest.fixture(scope="module")
def clean():
    return render("boards", size=(320, 240), seed=4, views=12)


def test_auto_recovers_K_within_its_own_uncertainty(clean):
    cam = calibrate(_dets(clean))
    Kt = np.array(clean.gt["camera"]["K"])
    std = cam.extra["std"]
    # the covariance from the Jacobian describes the spread of the estimate; a
    # correct fit lies within 4 sigma (plus 0.02 px for the renderer's own
    # detection bias). Bounded below too: an exact answer would mean leaked GT.
    for name, (i, j) in {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}.items():
        err = abs(cam.K[i, j] - Kt[i, j])
        assert 0 < err < 4 * std[name] + 0.02 * (1 + Kt[i, j] / 300), (name, err, std[name])
    assert cam.model != "none"
    assert 0 < cam.extra["rms_px"] < 0.15


def test_injected_noise_gives_the_expected_rms(clean):
    # iid noise of 0.2 px RMS (2-D): RSS = sigma^2 (2N - p) -> RMS = 0.2 sqrt(1 - p/2N),
    # plus the detection error (~0.04 px) in quadrature
    cam = calibrate(_dets(clean, noise_rms=0.2, seed=1), model="k1k2p1p2k3")
    p, n = cam.extra["n_params"], cam.extra["n_points"]
    expected = np.hypot(0.2, 0.045) * np.sqrt(1 - p / (2 * n))
    assert abs(cam.extra["rms_px"] / expected - 1) < 0.1


def test_camera_json_fields_and_candidates(clean):
    cam = calibrate(_dets(clean))
    d = cam.to_dict()
    for key in ("image_size", "K", "dist", "model", "rms_px", "std", "views", "candidates", "warnings"):
        assert key in d
    assert [c["model"] for c in d["candidates"]] == ["none", "k1", "k1k2", "k1k2p1p2", "k1k2p1p2k3",
                                                     "rational"]
    assert sum(c["chosen"] for c in d["candidates"]) == 1
    none = d["candidates"][0]
    assert none["significantly_worse"]  # the lens has k1 = -0.12: no distortion must lose
    assert all("cam_from_world" in v for v in d["views"] if v["used"])


def test_outlier_view_is_rejected(clean):
    dets = _dets(clean)
    bad = dets[3]
    rng = np.random.default_rng(9)
    dets[3] = Detection(bad.ids, bad.image_points + rng.normal(0, 3.0, bad.image_points.shape),
                        bad.object_points, bad.image_size)
    cam = calibrate(dets, model="k1k2p1p2k3", names=[f"v{k}" for k in range(len(dets))])
    rejected = [v["name"] for v in cam.extra["views"] if not v["used"]]
    assert rejected == ["v3"]


def test_exports_are_readable(clean, tmp_path):
    import cv2

    from lumigraph.calib.export import colmap_cameras, opencv_yaml

    cam = calibrate(_dets(clean), model="k1k2p1p2k3")
    (tmp_path / "c.yml").write_text(opencv_yaml(cam))
    fs = cv2.FileStorage(str(tmp_path / "c.yml"), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("camera_matrix").mat(), cam.K)
    np.testing.assert_allclose(fs.getNode("distortion_coefficients").mat().ravel(), cam.dist)
    assert int(fs.getNode("image_width").real()) == 320
    line = colmap_cameras([cam]).splitlines()[-1].split()
    assert line[1] == "FULL_OPENCV" and [int(line[2]), int(line[3])] == [320, 240]
    np.testing.assert_allclose([float(v) for v in line[4:8]], [cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]])


def test_too_few_views_and_no_board_refused():
    from lumigraph.capture.errors import InputError

    s = render("boards", size=(320, 240), seed=4, views=12)
    dets = _dets(s)
    with pytest.raises(InputError, match="at least 3"):
        calibrate(dets[:2])
    empty = Detection(np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 3)), (320, 240))
    with pytest.raises(InputError, match="no calibration board"):
        calibrate([empty, empty])


def test_undistort_straightens_the_board(clean):
    import cv2

    from lumigraph.calib.undistort import undistorter
    from lumigraph.capture.camera import Camera

    cam = Camera.from_dict(clean.gt["camera"])
    u = undistorter(cam)
    board = BoardSpec.parse(clean.stack["board"])

    def off_plane(points, obj):
        # a plane's undistorted image obeys one homography; lens distortion bends it
        H, _ = cv2.findHomography(obj[:, :2], points)
        proj = cv2.perspectiveTransform(obj[None, :, :2], H)[0]
        return float(np.sqrt(np.mean(np.sum((proj - points) ** 2, axis=1))))

    raw, und = [], []
    for img in clean.images[:8]:
        d0, d1 = detect(img, board), detect(u.apply(img), board)
        if len(d0) == 0:  # a steeply tilted view the detector misses
            continue
        assert len(d1) == 54
        raw.append(off_plane(d0.image_points, d0.object_points))
        und.append(off_plane(d1.image_points, d1.object_points))
    # detection noise (~0.05 px) bounds the straightened residual; k1 = -0.12 bends
    # the raw boards by several tenths of a pixel
    assert max(und) < 0.15
    assert np.mean(raw) > 2 * np.mean(und)
