"""The torch path of flow warping: :func:`lumigraph.stereo.pyramid.warp` and
:func:`lumigraph.stereo.pyramid.forward_backward` on torch's CPU device or CUDA.

A backward warp samples the moving image at ``x + flow(x)`` (reference
§5.1.3; the bicubic kernel is Keys' with a = −0.75, R. Keys, "Cubic
convolution interpolation for digital image processing", IEEE TASSP 29(6),
1981, doi:10.1109/TASSP.1981.1163711, as OpenCV's ``INTER_CUBIC``). The map
``flow + grid`` is one float32 addition, as the numpy path's ``cv2.add``; the
resampling is :func:`lumigraph.capture.remap_torch.remap_tensor`, which
follows ``cv2.remap``'s pixel centres, replicate border and NaN rule. The
forward-backward test (Sundaram, Brox, Keutzer 2010,
doi:10.1007/978-3-642-15549-9_32) is the numpy path's arithmetic on tensors.

The iterative flow estimators themselves (``pyramid_flow``, ``sand2004``,
``kroeger2016``) stay on the CPU: they interleave warps with small
per-level solves, and a device round trip per warp costs more than it saves.

Examples
--------
>>> import numpy as np
>>> img = np.arange(20, dtype=np.float32).reshape(4, 5)
>>> flow = np.zeros((4, 5, 2), np.float32); flow[..., 0] = 1.0   # moving = reference shifted left
>>> warp(img, flow, cubic=False, device="torch-cpu")[0].tolist()
[1.0, 2.0, 3.0, 4.0, 4.0]
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.device import resolve_device, to_numpy, to_torch, torch_modules


def _grid(h, w, device):
    torch, _ = torch_modules()
    y = torch.arange(h, dtype=torch.float32, device=device)[:, None].expand(h, w)
    x = torch.arange(w, dtype=torch.float32, device=device)[None, :].expand(h, w)
    return x, y


def warp_tensor(image, flow, *, border: str = "replicate", cubic: bool = True):
    """Warp a ``(C, H, W)`` float32 tensor by an ``(H, W, 2)`` flow tensor
    (same device): ``image`` sampled at ``x + flow(x)``; NaN outside for
    ``border="constant"``."""
    from lumigraph.capture.remap_torch import remap_tensor

    h, w = flow.shape[:2]
    gx, gy = _grid(h, w, flow.device)
    # the numpy path passes borderValue=NaN, which OpenCV reads as the Scalar
    # (NaN, 0, 0, 0): NaN in the first channel only, 0 in the others
    value = [float("nan")] + [0.0] * (image.shape[0] - 1)
    return remap_tensor(image, flow[..., 0] + gx, flow[..., 1] + gy,
                        interpolation="cubic" if cubic else "linear", border=border,
                        border_value=value)


def warp(image: np.ndarray, flow: np.ndarray, *, border: str = "replicate", cubic: bool = True,
         device="torch-cpu") -> np.ndarray:
    """:func:`lumigraph.stereo.pyramid.warp` through torch on ``device``:
    ``(H, W)`` or ``(H, W, C)`` float32 (a single channel comes back
    ``(H, W)``, as from ``cv2.remap``). With ``border="constant"`` the first
    channel reads NaN outside and the others 0, as the numpy path's
    ``cv2.remap(..., borderValue=NaN)`` does. Bicubic with the constant
    border is not OpenCV's rule (OpenCV 5 marks more pixels NaN there than
    the taps reach); no caller uses that pair."""
    torch, _ = torch_modules()
    dev = resolve_device(device)
    if border not in ("replicate", "constant"):
        raise KeyError(border)
    a = np.asarray(image, np.float32)
    planes = a[None] if a.ndim == 2 else np.moveaxis(a, -1, 0)
    out = to_numpy(warp_tensor(to_torch(planes, dev), to_torch(np.asarray(flow, np.float32), dev),
                               border=border, cubic=cubic))
    return out[0] if out.shape[0] == 1 else np.moveaxis(out, 0, -1)


def forward_backward(forward: np.ndarray, backward: np.ndarray, *, device="torch-cpu"):
    """:func:`lumigraph.stereo.pyramid.forward_backward` through torch on
    ``device``: ``(inconsistent, round_trip_px)`` as numpy arrays."""
    torch, _ = torch_modules()
    dev = resolve_device(device)
    f = to_torch(np.asarray(forward, np.float32), dev)
    b = to_torch(np.moveaxis(np.asarray(backward, np.float32), -1, 0), dev)
    h, w = f.shape[:2]
    bw = warp_tensor(b, f, border="constant", cubic=False).permute(1, 2, 0)
    X, Y = _grid(h, w, f.device)
    tx, ty = X + f[..., 0], Y + f[..., 1]
    outside = (tx < -0.5) | (tx > w - 0.5) | (ty < -0.5) | (ty > h - 0.5)
    s = f + bw
    err2 = s[..., 0] ** 2 + s[..., 1] ** 2
    bound = 0.01 * ((f ** 2).sum(-1) + (bw ** 2).sum(-1)) + 0.5
    bad = outside | ~torch.isfinite(err2) | (err2 > bound)
    rt = torch.sqrt(torch.where(torch.isfinite(err2), err2, torch.full_like(err2, float("inf"))))
    return to_numpy(bad), to_numpy(rt)
