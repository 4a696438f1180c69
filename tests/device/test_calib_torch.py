"""``calib undistort`` / ``calib rectify`` on the torch path against OpenCV.

Maps: OpenCV and the torch path both evaluate the map in float64 and round
once to float32. Their float64 values differ by a few float64 roundings
(~1e-13 px at these sizes), far below a float32 half-ulp, so the float32
maps are equal except where a value sits within that distance of a float32
rounding boundary: then they differ by one float32 ulp of the coordinate.
Bound: ``spacing(float32(max |coordinate|))``.

Images: with maps equal to that bound, the resampled values differ by the
float32 rounding of the bilinear sum (``8·u·max|p|``, derivation in
``test_remap_torch.py``) plus one map ulp times the steepest step between
neighbouring pixels (``ulp · max|p|``). Integer images: at most one code,
and only where the float value lies within that bound of a half.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("kornia")
cv2 = pytest.importorskip("cv2")

from lumigraph.calib.rectify import rectify  # noqa: E402
from lumigraph.calib.undistort import undistorter  # noqa: E402
from lumigraph.calib.undistort_torch import undistort_rectify_maps  # noqa: E402
from lumigraph.capture import io  # noqa: E402
from lumigraph.capture.camera import Camera  # noqa: E402
from lumigraph.capture.rig import Rig  # noqa: E402

U = 2.0 ** -24
SIZE = (97, 61)  # (w, h), asymmetric and odd


def _camera(dist):
    K = np.array([[110.0, 0, 50.3], [0, 104.0, 29.1], [0, 0, 1]])
    return Camera(K, np.asarray(dist, float), SIZE)


CAMS = {
    "k1k2": [-0.22, 0.05, 0, 0, 0],
    "tangential": [-0.18, 0.03, 1.5e-3, -2e-3, 0.01],
    "rational": [-0.2, 0.03, 1e-3, -2e-3, 0.01, 0.02, -0.004, 0.001],
}


def _image(dtype, seed=0, channels=None):
    rng = np.random.default_rng(seed)
    w, h = SIZE
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    base = 2.0 * x + 0.7 * y + 40 * rng.random((h, w))
    if channels:
        base = np.stack([base * (1 + 0.1 * c) for c in range(channels)], -1)
    base = base / base.max()
    if dtype == np.uint8:
        return np.round(base * 255).astype(np.uint8)
    if dtype == np.uint16:
        return np.round(base * 65535).astype(np.uint16)
    return base.astype(np.float32)


def _ulp(maps):
    return float(np.spacing(np.float32(max(np.abs(m).max() for m in maps))))


def _compare(got, ref, img, map_ulp):
    assert got.shape == ref.shape and got.dtype == ref.dtype
    top = float(np.abs(img).max())
    if img.dtype.kind == "u":
        diff = np.abs(got.astype(np.int64) - ref.astype(np.int64))
        assert diff.max() <= 1
        return
    np.testing.assert_allclose(got, ref, rtol=0, atol=8 * U * top + map_ulp * top)


@pytest.mark.parametrize("name", list(CAMS))
def test_maps_match_opencv(name):
    cam = _camera(CAMS[name])
    R = cv2.Rodrigues(np.array([0.02, -0.015, 0.01]))[0]
    P = np.array([[100.0, 0, 47.0, 0], [0, 100.0, 31.0, 0], [0, 0, 1, 0]])
    for RR, PP in ((np.eye(3), cam.K), (R, P)):
        ref = cv2.initUndistortRectifyMap(cam.K, cam.dist, RR, PP[:, :3], SIZE, cv2.CV_32FC1)
        got = undistort_rectify_maps(cam, RR, PP, SIZE, device="torch-cpu")
        tol = _ulp(ref)
        for g, r in zip(got, ref, strict=True):
            assert g.dtype == np.float32 and g.shape == (SIZE[1], SIZE[0])
            np.testing.assert_allclose(g, r, rtol=0, atol=tol)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("keep_all", [False, True])
def test_undistort_apply(dtype, keep_all):
    u = undistorter(_camera(CAMS["tangential"]), keep_all=keep_all)
    for img in (_image(dtype), _image(dtype, seed=1, channels=3)):
        ref = u.apply(img)
        got = u.apply(img, device="torch-cpu")
        _compare(got, ref, img, _ulp(u.maps()))


def test_undistort_keeps_a_single_channel_axis():
    u = undistorter(_camera(CAMS["k1k2"]))
    img = _image(np.uint8)[..., None]
    assert u.apply(img, device="torch-cpu").shape == img.shape == u.apply(img).shape


def _rig():
    left = _camera(CAMS["tangential"])
    right = Camera(np.array([[108.0, 0, 48.2], [0, 103.0, 30.4], [0, 0, 1]]),
                   np.array([-0.15, 0.02, -1e-3, 1e-3, 0.0]), SIZE)
    R = cv2.Rodrigues(np.array([0.01, 0.03, -0.008]))[0]
    return Rig.from_pose(left, right, R, [-0.12, 0.004, 0.002])


@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
@pytest.mark.parametrize("alpha", [0.0, 1.0])
def test_rectify_apply(dtype, alpha):
    rect = rectify(_rig(), alpha=alpha)
    left, right = _image(dtype, seed=2), _image(dtype, seed=3, channels=3)
    ref = rect.apply(left, right)
    got = rect.apply(left, right, device="torch-cpu")
    tol = _ulp(rect.maps())
    _compare(got[0], ref[0], left, tol)
    _compare(got[1], ref[1], right, tol)


def _write_inputs(tmp_path):
    cam = _camera(CAMS["tangential"])
    cam.save(tmp_path / "camera.json")
    _rig().save(tmp_path / "rig.json")
    io.write_image(tmp_path / "a.png", _image(np.uint8, seed=4))
    io.write_image(tmp_path / "b.png", _image(np.uint8, seed=5))


def test_cli_rectify_torch_cpu_matches_the_library_on_cpu(tmp_path):
    """The command in-process (a fresh interpreter costs seconds of torch
    import); the cpu side is the library call the command makes."""
    from lumigraph.calib.cli import main

    _write_inputs(tmp_path)
    rect = tmp_path / "rect"
    assert main(["rectify", "--rig", str(tmp_path / "rig.json"), str(tmp_path / "a.png"),
                 str(tmp_path / "b.png"), "--out", str(rect), "--device", "torch-cpu", "-q"]) == 0
    ref = rectify(Rig.load(tmp_path / "rig.json")).apply(io.read_image(tmp_path / "a.png"),
                                                         io.read_image(tmp_path / "b.png"))
    for name, want in zip(("left.png", "right.png"), ref, strict=True):
        got = io.read_image(rect / name).astype(np.int64)
        assert np.abs(got - want.astype(np.int64)).max() <= 1  # one code at a half


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
def test_cuda_without_gpu_is_exit_2(tmp_path, capsys):
    from lumigraph.calib.cli import main

    _write_inputs(tmp_path)
    out = tmp_path / "out"
    # in-process: a fresh interpreter per command costs seconds of torch import
    assert main(["undistort", "--camera", str(tmp_path / "camera.json"), str(tmp_path / "a.png"),
                 "--out", str(out), "--device", "cuda"]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: --device") and "no CUDA GPU" in lines[0]
    assert not out.exists()
    from lumigraph.capture.errors import InputError

    rect = rectify(_rig())
    with pytest.raises(InputError, match="device"):
        rect.apply(_image(np.uint8), _image(np.uint8), device="cuda")


def test_kornia_distortion_against_our_camera_model():
    """kornia's ``distort_points`` is our (OpenCV's) Brown–Conrady/rational
    model in OpenCV's coefficient order, with two conventions checked here:
    ``new_K`` normalises the *input* pixels (so normalised points go in with
    ``new_K = I``), and the skew of ``K`` is ignored on the way back to pixels
    (as in ``initUndistortRectifyMap``), where ``Camera.project`` applies it.
    Bound: float64 rounding of a few dozen operations on values of ~100 px,
    64·2⁻⁵³·100 px."""
    import kornia

    rng = np.random.default_rng(7)
    xy = rng.uniform(-0.4, 0.4, (50, 2))
    pts = np.concatenate([xy, np.ones((50, 1))], 1)
    eye = torch.eye(3, dtype=torch.float64)
    tol = 64 * 2.0 ** -53 * 200
    for dist in CAMS.values():
        cam = _camera(dist)
        got = kornia.geometry.calibration.distort_points(
            torch.from_numpy(xy), torch.from_numpy(cam.K), torch.tensor(dist, dtype=torch.float64),
            eye).numpy()
        np.testing.assert_allclose(got, cam.project(pts), rtol=0, atol=tol)
    skewed = Camera(np.array([[110.0, 2.5, 50.3], [0, 104.0, 29.1], [0, 0, 1]]),
                    np.asarray(CAMS["k1k2"], float), SIZE)
    got = kornia.geometry.calibration.distort_points(
        torch.from_numpy(xy), torch.from_numpy(skewed.K),
        torch.tensor(CAMS["k1k2"], dtype=torch.float64), eye).numpy()
    ours = skewed.project(pts)
    yd = skewed.distort_normalized(xy)[:, 1]
    np.testing.assert_allclose(got[:, 0] + 2.5 * yd, ours[:, 0], rtol=0, atol=tol)
