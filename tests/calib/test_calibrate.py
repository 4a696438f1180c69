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


def _fold_problem(clean):
    """The fixture's corners with 0.2 px noise, rounded to float32 (the values
    OpenCV's solver sees), and the all-view k1k2p1p2k3 solution."""
    from lumigraph.calib.zhang2000 import calibrate_fixed

    dets = [d for d in _dets(clean, noise_rms=0.2, seed=3) if len(d)]
    obj = [d.object_points.astype(np.float32).astype(np.float64) for d in dets]
    img = [d.image_points.astype(np.float32).astype(np.float64) for d in dets]
    full = calibrate_fixed(obj, img, dets[0].image_size, model="k1k2p1p2k3")
    return obj, img, dets[0].image_size, full


def test_refine_reaches_opencvs_optimum_on_a_subset_of_views(clean):
    # The held-out refits of model choice (calibrate._heldout) are Schur-complement
    # Levenberg-Marquardt from the all-view solution (zhang2000.refine). On the same
    # float32 points, run to convergence, it must land on OpenCV's own optimum for
    # those views: every intrinsic within a thousandth of its standard deviation
    # (a difference no choice of model could notice), the squared error no larger.
    from lumigraph.calib.zhang2000 import calibrate_fixed, refine

    obj, img, size, full = _fold_problem(clean)
    train = [v for v in range(len(obj)) if v % 4 != 1]
    ref = calibrate_fixed([obj[v] for v in train], [img[v] for v in train], size, model="k1k2p1p2k3",
                          K0=full.K, dist0=full.dist, rvecs0=full.rvecs[train],
                          tvecs0=full.tvecs[train], max_iter=200, eps=1e-14)
    K, dist, _, _, sq, steps = refine(obj, img, model="k1k2p1p2k3", K=full.K, dist=full.dist,
                                      rvecs=full.rvecs, tvecs=full.tvecs, views=train, rtol=1e-14)
    assert steps >= 1
    ours = np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist]
    theirs = np.r_[ref.K[0, 0], ref.K[1, 1], ref.K[0, 2], ref.K[1, 2], ref.dist]
    sigma = np.array([ref.std[n] for n in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")])
    assert np.all(np.abs(ours - theirs) <= 1e-3 * sigma), (ours - theirs) / sigma
    n = sum(len(img[v]) for v in train)
    assert sq <= ref.rms_px ** 2 * n * (1 + 1e-9)


def test_refine_frees_only_the_models_terms(clean):
    # started from the richer solution, a simpler model's fixed terms are zero and stay zero
    from lumigraph.calib.zhang2000 import refine

    obj, img, _, full = _fold_problem(clean)
    _, dist, _, _, _, _ = refine(obj, img, model="k1k2", K=full.K, dist=full.dist,
                                 rvecs=full.rvecs, tvecs=full.tvecs)
    assert dist.shape == (5,) and np.all(dist[2:] == 0) and np.all(dist[:2] != 0)
