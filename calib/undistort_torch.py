"""The torch path of undistortion and rectification: OpenCV's
``initUndistortRectifyMap`` built on the device, then resampled there.

For every output pixel ``(u, v)`` of the new camera ``P`` (3×3 part) and the
rectifying rotation ``R``, the ray ``(x, y, w) = (P R)⁻¹ (u, v, 1)`` is taken
to the normalised plane, distorted by the source camera's Brown–Conrady /
rational model (Zhang 2000, doi:10.1109/34.888718; reference ch. 5, §5.1.1;
the formula in :mod:`lumigraph.capture.camera`) and mapped to pixels with the
source ``fx, fy, cx, cy`` — the skew of the source matrix is ignored, as
OpenCV's ``initUndistortRectifyMap`` ignores it. The distortion step is
kornia's ``distort_points``, whose model and coefficient order are OpenCV's;
its convention is that ``new_K`` normalises the *input* pixels and ``K``
re-projects the result, so it is called with ``new_K = I`` on points that are
already normalised. The maps are computed in float64 and rounded to float32,
as OpenCV does, and resampled with :func:`lumigraph.capture.remap_torch.remap_tensor`
(OpenCV's pixel-centre and border rules).

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.camera import Camera
>>> cam = Camera(np.array([[90., 0, 41], [0, 88, 29], [0, 0, 1]]), [-0.2, 0.03, 0, 0, 0], (80, 60))
>>> mx, my = undistort_rectify_maps(cam, np.eye(3), cam.K, (80, 60), device="torch-cpu")
>>> import cv2
>>> cx, cy = cv2.initUndistortRectifyMap(cam.K, cam.dist, np.eye(3), cam.K, (80, 60), cv2.CV_32FC1)
>>> float(np.abs(mx - cx).max()) <= float(np.spacing(np.float32(np.abs(cx).max())))
True
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.device import resolve_device, to_numpy, to_torch, torch_modules


def maps_tensor(camera, R, P, image_size, device):
    """``(map_x, map_y)`` float32 tensors ``(H, W)`` on ``device`` (a resolved
    :class:`~lumigraph.capture.device.Device`): the source pixel of ``camera``
    for each pixel of the new camera ``P`` rotated by ``R``."""
    torch, kornia = torch_modules()
    w, h = (int(v) for v in image_size)
    P3 = np.asarray(P, np.float64)[:, :3]
    iR = np.linalg.inv(P3 @ np.asarray(R, np.float64))
    it = torch.as_tensor(iR, dtype=torch.float64, device=device.torch)
    v = torch.arange(h, dtype=torch.float64, device=device.torch)[:, None]
    u = torch.arange(w, dtype=torch.float64, device=device.torch)[None, :]
    X = it[0, 0] * u + it[0, 1] * v + it[0, 2]
    Y = it[1, 0] * u + it[1, 1] * v + it[1, 2]
    W = it[2, 0] * u + it[2, 1] * v + it[2, 2]
    pts = torch.stack([X / W, Y / W], -1).reshape(-1, 2)
    dist = np.zeros(max(5, camera.dist.size))
    dist[:camera.dist.size] = camera.dist
    K = torch.as_tensor(camera.K, dtype=torch.float64, device=device.torch)
    eye = torch.eye(3, dtype=torch.float64, device=device.torch)
    d = torch.as_tensor(dist, dtype=torch.float64, device=device.torch)
    src = kornia.geometry.calibration.distort_points(pts, K, d, eye).reshape(h, w, 2)
    return src[..., 0].to(torch.float32), src[..., 1].to(torch.float32)


def undistort_rectify_maps(camera, R, P, image_size, *, device="torch-cpu"):
    """``initUndistortRectifyMap(camera.K, camera.dist, R, P, image_size,
    CV_32FC1)`` computed through torch/kornia; numpy ``(H, W)`` float32 maps.

    Parameters
    ----------
    camera : Camera
        The source (distorted) camera.
    R : array (3, 3)
        Rectifying rotation (identity for undistortion).
    P : array (3, 3) or (3, 4)
        New camera matrix (its left 3×3 is used).
    image_size : (int, int)
        ``(w, h)`` of the output.
    device : str
        ``"torch-cpu"`` or ``"cuda"``.
    """
    dev = resolve_device(device)
    mx, my = maps_tensor(camera, R, P, image_size, dev)
    return to_numpy(mx), to_numpy(my)


def resample(image: np.ndarray, maps, device) -> np.ndarray:
    """``cv2.remap(image, mx, my, INTER_LINEAR, BORDER_CONSTANT, 0)`` with the
    device's map tensors ``maps``; same dtype and channels as ``image``."""
    torch, _ = torch_modules()
    from lumigraph.capture.remap_torch import remap_tensor

    a = np.asarray(image)
    if a.dtype not in (np.uint8, np.uint16, np.float32, np.float64):
        raise ValueError(f"image: expected uint8, uint16, float32 or float64, got {a.dtype}")
    dt = torch.float64 if a.dtype == np.float64 else torch.float32
    planes = a[None] if a.ndim == 2 else np.moveaxis(a, -1, 0)
    out = remap_tensor(to_torch(planes, device, dtype=dt), *maps)
    if a.dtype.kind == "u":
        from lumigraph.capture.remap_torch import round_like_cv2

        out = round_like_cv2(out, a.dtype, channels=planes.shape[0])
    res = to_numpy(out).astype(a.dtype, copy=False)
    return res[0] if a.ndim == 2 else np.moveaxis(res, 0, -1)
