"""The ``device=`` argument of every call ported here: ``"auto"`` without a
GPU is the numpy/OpenCV path itself (identical output), ``"cuda"`` without
one is an InputError naming ``device``, an unknown name likewise."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("kornia")

from lumigraph.capture.errors import InputError  # noqa: E402


def _calls():
    from lumigraph.calib.rectify import rectify
    from lumigraph.calib.undistort import undistorter
    from lumigraph.capture.camera import Camera
    from lumigraph.capture.patterns import checker_set
    from lumigraph.capture.rig import Rig
    from lumigraph.separation.separate import separate
    from lumigraph.stereo.block_matching import match
    from lumigraph.stereo.hirschmuller2008 import match as sgm
    from lumigraph.stereo.pyramid import forward_backward, warp

    rng = np.random.default_rng(0)
    cam = Camera(np.array([[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]]), [-0.1, 0.01, 0, 0, 0],
                 (64, 48))
    img = rng.integers(0, 256, (48, 64)).astype(np.uint8)
    u = undistorter(cam)
    rect = rectify(Rig.from_pose(cam, cam, np.eye(3), [-0.1, 0, 0]))
    ps = checker_set((64, 48), square=4, shifts=2)
    stack = np.stack([0.5 * p + 0.2 for p in ps.images])[..., None].astype(np.float32)
    flow = rng.normal(0, 1, (48, 64, 2)).astype(np.float32)
    gray = rng.random((48, 64)).astype(np.float32)
    return {
        "undistort": lambda dev: u.apply(img, device=dev),
        "rectify": lambda dev: np.stack(rect.apply(img, img, device=dev)),
        "separate": lambda dev: separate(stack, method="checker", device=dev).direct,
        "match": lambda dev: match(img, np.roll(img, -3, 1), max_disp=8, window=5,
                                   device=dev).disparity,
        "sgm": lambda dev: sgm(img, np.roll(img, -3, 1), max_disp=8, device=dev).disparity,
        "warp": lambda dev: warp(gray, flow, device=dev),
        "forward_backward": lambda dev: forward_backward(flow, -flow, device=dev)[1],
    }


CALLS = ("undistort", "rectify", "separate", "match", "sgm", "warp", "forward_backward")


@pytest.mark.parametrize("name", CALLS)
def test_auto_and_cuda_without_a_gpu(name):
    call = _calls()[name]
    if not torch.cuda.is_available():
        np.testing.assert_array_equal(call("auto"), call("cpu"))
        with pytest.raises(InputError, match="^device: .*no CUDA GPU"):
            call("cuda")
    with pytest.raises(InputError, match="^device: unknown device"):
        call("gpu")
