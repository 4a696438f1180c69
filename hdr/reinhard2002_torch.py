"""Reinhard et al. (2002) tone reproduction, global and local, on a torch device.

E. Reinhard, M. Stark, P. Shirley and J. Ferwerda, "Photographic Tone
Reproduction for Digital Images", SIGGRAPH 2002, doi:10.1145/566570.566575:
the operators of :mod:`hdr.reinhard2002` (eqs. 1-4 global, 5-9 local) with the
same arithmetic in float32 on the device; the log-average (eq. 1) is summed
in float64 as the numpy local operator does.

**The blurs.** The local operator's centre-surround uses scipy's
``gaussian_filter`` in the numpy code: a kernel of radius ``int(4 σ + 0.5)``
and half-sample symmetric borders (scipy's ``reflect``: ``d c b a | a b c d``).
``kornia.filters.gaussian_blur2d`` differs in both (its ``reflect`` border is
torch's, which does not repeat the edge sample, and its kernel size is the
caller's), which moves the result near borders by more than rounding. So the
blur is separable ``conv2d`` with scipy's kernel on an input padded by an
index gather that reproduces scipy's border, y pass then x pass, as scipy
applies them.

**Where the results differ.** Eq. 9 picks, per pixel, the first scale whose
normalised centre-surround difference reaches ε: a pixel whose difference is
within rounding of ε may pick the next scale on one device and not the other
(a legitimate, rare difference, not a rounding one). Elsewhere the local
operator agrees with the numpy one within float32 rounding
(``tests/device/test_hdr_torch.py`` derives the bound and leaves those pixels
out).

torch is imported inside the functions (the ``gpu`` extra).

Examples
--------
>>> import numpy as np
>>> from lumigraph.hdr.reinhard2002 import tonemap
>>> hdr = np.exp(np.random.default_rng(0).normal(0, 2, (16, 16, 3))).astype(np.float32)
>>> a = tonemap_torch(hdr, method="reinhard", device="torch-cpu")
>>> int(np.abs(a.astype(int) - tonemap(hdr, method="reinhard")).max()) <= 1   # codes
True
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.device import resolve_device, to_numpy, to_torch
from lumigraph.hdr.reinhard2002 import LUMA


def gaussian_kernel(sigma: float) -> np.ndarray:
    """scipy.ndimage's Gaussian weights (truncate 4: radius ``int(4 σ + 0.5)``), float64."""
    radius = int(4.0 * sigma + 0.5)
    x = np.arange(-radius, radius + 1)
    w = np.exp(-0.5 / sigma ** 2 * x ** 2)
    return w / w.sum()


def _reflect_index(n: int, r: int) -> np.ndarray:
    """Indices of ``[-r, n + r)`` under scipy's ``reflect`` (period ``2 n`` mirror)."""
    p = np.arange(-r, n + r) % (2 * n)
    return np.where(p < n, p, 2 * n - 1 - p)


def gaussian_blur(img, sigma: float):
    """``scipy.ndimage.gaussian_filter(img, sigma, mode="reflect")`` of a 2-D
    float32 tensor, on its device (module docstring: why not kornia's)."""
    import torch
    import torch.nn.functional as F

    w = gaussian_kernel(sigma)
    r = (len(w) - 1) // 2
    h, wd = img.shape
    k = torch.from_numpy(w.astype(np.float32)).to(img.device)
    iy = torch.from_numpy(_reflect_index(h, r)).to(img.device)
    ix = torch.from_numpy(_reflect_index(wd, r)).to(img.device)
    y = F.conv2d(img.index_select(0, iy)[None, None], k.view(1, 1, -1, 1))
    return F.conv2d(y.index_select(3, ix), k.view(1, 1, 1, -1))[0, 0]


def log_average(lum, delta: float = 1e-6) -> float:
    """Eq. 1: ``exp(mean(log(δ + L_w)))``, logs in float32, summed in float64."""
    import torch

    return float(torch.exp(torch.log(lum + np.float32(delta)).to(torch.float64).mean()))


def local_operator_torch(lum, *, key: float = 0.18, phi: float = 8.0, eps: float = 0.05,
                         scales: int = 8, delta: float = 1e-6, return_scale: bool = False):
    """:func:`hdr.reinhard2002.local_operator` on a float32 ``(H, W)`` tensor;
    with ``return_scale`` also the index of the scale each pixel used
    (``scales`` where none stopped)."""
    import torch

    lw_bar = log_average(lum, delta)
    l = lum * np.float32(key / lw_bar)
    s = 1.0
    v1 = gaussian_blur(l, 1.0 / (2 * np.sqrt(2)) * s)
    chosen = v1.clone()
    done = torch.zeros(l.shape, dtype=torch.bool, device=l.device)
    picked = torch.full(l.shape, scales, dtype=torch.int16, device=l.device)
    for k in range(scales):
        s_next = s * 1.6
        v2 = gaussian_blur(l, 1.0 / (2 * np.sqrt(2)) * s_next)
        v = (v1 - v2) / (v1 + np.float32(2.0 ** phi * key / s ** 2))
        stop = (v.abs() >= eps) & ~done
        chosen = torch.where(stop, v1, chosen)
        picked = torch.where(stop, k, picked)
        done |= stop
        chosen = torch.where(done, chosen, v2)
        v1, s = v2, s_next
    out = l / (chosen + np.float32(1.0))
    return (out, picked) if return_scale else out


def global_operator_torch(lum, *, key: float = 0.18, white: float | None = None,
                          delta: float = 1e-6):
    """:func:`hdr.reinhard2002.global_operator` on a float32 tensor (eqs. 1-4)."""
    lw_bar = log_average(lum, delta)
    scaled = lum * np.float32(key / lw_bar)
    lwhite = float(scaled.max()) if white is None else float(white)
    return scaled * (1.0 + scaled / np.float32(max(lwhite, 1e-12) ** 2)) / (1.0 + scaled)


def luminance_torch(rgb):
    """``max(rgb @ LUMA, 0)`` of a non-negative float32 ``(H, W, 3|1)`` tensor."""
    if rgb.shape[2] == 1:
        return rgb[..., 0]
    return (rgb[..., 0] * np.float32(LUMA[0]) + rgb[..., 1] * np.float32(LUMA[1])
            + rgb[..., 2] * np.float32(LUMA[2])).clamp_min(0.0)


def display_torch(rgb, *, method: str = "reinhard", key: float = 0.18,
                  white: float | None = None):
    """The sRGB-encoded display values in [0, 1] (before quantisation), a
    float32 ``(H, W, 3)`` tensor, from non-negative float32 radiance ``(H, W, 3|1)``."""
    import torch

    lum = luminance_torch(rgb)
    ld = global_operator_torch(lum, key=key, white=white) if method == "reinhard" else \
        local_operator_torch(lum, key=key)
    ratio = torch.where(lum > 0, ld / torch.where(lum > 0, lum, 1.0), 0.0)
    x = (rgb * ratio[..., None]).clamp(0.0, 1.0)
    if x.shape[2] == 1:
        x = x.expand(-1, -1, 3)
    return torch.where(x <= 0.0031308, 12.92 * x, 1.055 * torch.pow(x, 1 / 2.4) - 0.055)


def tonemap_torch(radiance: np.ndarray, *, method: str = "reinhard", key: float = 0.18,
                  white: float | None = None, bit_depth: int = 8, device="cuda") -> np.ndarray:
    """:func:`hdr.reinhard2002.tonemap` on a torch device; the radiance must be
    checked already (the numpy ``tonemap(..., device=...)`` does it and calls
    this). ``(H, W, 3)`` uint8/uint16 on the host."""
    import torch

    dev = resolve_device(device)
    rgb = np.asarray(radiance)
    if rgb.ndim == 2:
        rgb = rgb[..., None]
    x = to_torch(rgb.astype(np.float32, copy=False), dev).clamp_min(0.0)
    top = 2 ** bit_depth - 1
    disp = display_torch(x, method=method, key=key, white=white)
    codes = torch.round(disp * np.float32(top))
    out = to_numpy(codes.to(torch.int32))
    return out.astype(np.uint8 if bit_depth == 8 else np.uint16)



