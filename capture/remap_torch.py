"""``cv2.remap`` on torch: the resampling the torch paths of undistortion,
rectification and flow warping share.

``remap(image, map_x, map_y)`` samples ``image`` at ``(map_x, map_y)`` per
output pixel, in OpenCV's conventions, so that the torch path gives the
numpy/OpenCV path's result within float32 rounding:

- pixel centres at integer coordinates: ``map_x = x`` is the identity
  (``grid_sample``/kornia need ``align_corners=True`` and a normalisation
  to reach the same; see below);
- bilinear, or Keys bicubic with ``A = −0.75`` (OpenCV's ``interpolateCubic``);
  the taps of ``floor(x) + {0, 1}`` (``{−1 .. 2}`` for cubic) with weights
  from the fractional part;
- ``border="constant"``: every tap outside the image reads ``border_value``
  (NaN propagates: ``0 · NaN`` is NaN, so with a NaN border a point on the
  last column, whose right tap is outside with weight 0, is NaN, exactly as
  ``cv2.remap`` gives); ``"replicate"``: taps are clamped to the edge;
- 8- and 16-bit images are interpolated in float32 and rounded to nearest,
  saturated to the type's range.

OpenCV 5's ``remap`` interpolates at the float coordinates for images of
1, 3 and 4 channels, but still snaps them to the nearest 1/32 px (its older
table path) for 2 channels (flow fields) and for more than 4; there, 8-bit
results are rounded half up from exact fixed-point weights. Which channel
counts snap is asked of the installed OpenCV once (:func:`snaps_to_32nds`),
and the torch path snaps the same ones, so it reproduces OpenCV's arithmetic
in its own order of operations, hence "within float32 rounding".

Why not ``torch.nn.functional.grid_sample`` or ``kornia.geometry.remap``:
they take normalised coordinates, ``x_n = 2x/(W − 1) − 1``, and undo the
normalisation inside; the round trip moves a sample by up to about
``W · 2⁻²⁴`` px (0.0002 px at 4000 px), and their zero padding is not
OpenCV's NaN rule. Both are checked against ``cv2.remap`` in
``tests/device/test_remap_torch.py`` (identity and known shifts agree with
``align_corners=True`` and not with ``False``).

Examples
--------
>>> import numpy as np
>>> img = np.arange(12, dtype=np.float32).reshape(3, 4)
>>> mx = np.array([[0.5, 3.0]], np.float32); my = np.array([[0.0, 1.5]], np.float32)
>>> remap(img, mx, my, device="torch-cpu").tolist()
[[0.5, 9.0]]
"""

from __future__ import annotations

import functools

import numpy as np

from lumigraph.capture.device import resolve_device, to_numpy, to_torch, torch_modules

INTERPOLATIONS = ("linear", "cubic")
BORDERS = ("constant", "replicate")
CUBIC_A = -0.75  # OpenCV's INTER_CUBIC (Keys' kernel with a = -0.75)
# Coordinates are clamped to this before the integer part is taken, so a huge
# or infinite map entry is simply far outside (as cv2 saturates them).
_FAR = float(1 << 22)


TAB = 32  # OpenCV's INTER_TAB_SIZE: sub-pixel steps of the table path


@functools.cache
def snaps_to_32nds(channels: int, interpolation: str = "linear") -> bool:
    """True when the installed ``cv2.remap`` snaps sample positions to 1/32 px
    for float images of ``channels`` channels with this interpolation (its
    table path). Found once by remapping a small random image at positions
    between the 1/32 steps, both ways on torch's CPU device: the nearer is
    OpenCV's (the two differ by a hundred times the float32 rounding)."""
    import cv2

    torch, _ = torch_modules()
    img = np.random.default_rng(0).random((6, 7, channels)).astype(np.float32)
    mx = np.array([[1.3, 2.71, 3.05, 4.49]], np.float32)
    my = np.array([[1.17, 2.9, 3.33, 2.02]], np.float32)
    flag = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC}[interpolation]
    ref = np.asarray(cv2.remap(img, mx, my, flag), np.float64).reshape(1, 4, channels)
    t = torch.from_numpy(np.moveaxis(img, -1, 0).copy())
    err = []
    for snap in (False, True):
        out = remap_tensor(t, torch.from_numpy(mx), torch.from_numpy(my),
                           interpolation=interpolation, snap=snap)
        err.append(float(np.abs(np.moveaxis(out.numpy(), 0, -1) - ref).max()))
    return err[1] < err[0]


def _cubic_weights(f):
    """OpenCV's ``interpolateCubic`` coefficients for taps −1, 0, 1, 2 at
    fractional offset ``f`` (a tensor); the last is 1 minus the others."""
    a = CUBIC_A
    g = f + 1
    w0 = ((a * g - 5 * a) * g + 8 * a) * g - 4 * a
    w1 = ((a + 2) * f - (a + 3)) * f * f + 1
    h = 1 - f
    w2 = ((a + 2) * h - (a + 3)) * h * h + 1
    return [w0, w1, w2, 1 - w0 - w1 - w2]


def remap_tensor(image, map_x, map_y, *, interpolation: str = "linear",
                 border: str = "constant", border_value: float = 0.0, snap: bool | None = None):
    """Resample a ``(C, H, W)`` floating tensor at ``(map_x, map_y)``, each
    ``(Ho, Wo)`` on the same device; returns ``(C, Ho, Wo)`` in the image's
    dtype. ``border_value``: one float for every channel, or one per channel.
    ``snap``: positions to the nearest 1/32 px first (default: as the
    installed OpenCV does for this many channels, :func:`snaps_to_32nds`).
    Conventions in the module docstring."""
    torch, _ = torch_modules()
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation: expected one of {INTERPOLATIONS}, got {interpolation!r}")
    if border not in BORDERS:
        raise ValueError(f"border: expected one of {BORDERS}, got {border!r}")
    C, H, W = image.shape
    dt = image.dtype
    mx = torch.nan_to_num(map_x.to(dt), nan=-_FAR, posinf=_FAR, neginf=-_FAR).clamp(-_FAR, _FAR)
    my = torch.nan_to_num(map_y.to(dt), nan=-_FAR, posinf=_FAR, neginf=-_FAR).clamp(-_FAR, _FAR)
    if snap is None:
        snap = snaps_to_32nds(C, interpolation)
    if snap:  # rint(x·32)/32: the multiply and divide by 2^5 are exact
        mx, my = torch.round(mx * TAB) / TAB, torch.round(my * TAB) / TAB
    x0f, y0f = torch.floor(mx), torch.floor(my)
    fx, fy = mx - x0f, my - y0f  # exact: x and floor(x) share their leading bits
    x0, y0 = x0f.to(torch.int64), y0f.to(torch.int64)
    if interpolation == "linear":
        offsets, wx, wy = (0, 1), [1 - fx, fx], [1 - fy, fy]
    else:
        offsets, wx, wy = (-1, 0, 1, 2), _cubic_weights(fx), _cubic_weights(fy)
    bv = torch.as_tensor(border_value, dtype=dt, device=image.device)
    if bv.ndim:  # one value per channel
        bv = bv.reshape(C, 1, 1)
    flat = image.reshape(C, H * W)
    cols = []
    for i in offsets:
        xi = x0 + i
        cols.append((xi.clamp(0, W - 1), (xi >= 0) & (xi < W)))
    out = None
    for wj, j in zip(wy, offsets, strict=True):
        yj = y0 + j
        yc, yin = yj.clamp(0, H - 1), (yj >= 0) & (yj < H)
        row = None
        for wi, (xc, xin) in zip(wx, cols, strict=True):
            v = flat[:, (yc * W + xc).reshape(-1)].reshape(C, *mx.shape)
            if border == "constant":
                v = torch.where(yin & xin, v, bv)
            row = wi * v if row is None else row + wi * v
        out = wj * row if out is None else out + wj * row
    return out


def round_like_cv2(values, dtype, *, channels: int):
    """Float32 remap results to ``dtype`` (uint8/uint16) as ``cv2.remap``
    rounds them: to nearest, ties to even (``saturate_cast``), except 8-bit
    images on the table path (:func:`snaps_to_32nds`), whose fixed-point sum
    rounds ties up; on that path the bilinear float32 value is exact (weights
    are multiples of 1/1024), so ``floor(v + 0.5)`` is OpenCV's result."""
    torch, _ = torch_modules()
    hi = float(np.iinfo(dtype).max)
    if dtype == np.uint8 and snaps_to_32nds(channels):
        return torch.floor(values + 0.5).clamp(0.0, hi)
    return torch.round(values).clamp(0.0, hi)


def remap(image: np.ndarray, map_x: np.ndarray, map_y: np.ndarray, *,
          interpolation: str = "linear", border: str = "constant", border_value: float = 0.0,
          device="torch-cpu") -> np.ndarray:
    """``cv2.remap`` through torch on ``device`` ("torch-cpu" or "cuda").

    Parameters
    ----------
    image : ndarray, ``(H, W)`` or ``(H, W, C)``, uint8, uint16, float32 or float64
    map_x, map_y : ndarray, ``(Ho, Wo)`` float32
        Source pixel per output pixel (pixel centres at integers).
    interpolation : {"linear", "cubic"}
    border : {"constant", "replicate"}
    border_value : float or sequence of float
        Value of every tap outside the image for ``"constant"`` (NaN allowed
        for float images), or one per channel. Note that ``cv2.remap`` takes
        a plain number as the Scalar ``(v, 0, 0, 0)``: only the first channel
        gets ``v``; pass ``(v, 0, …)`` here to reproduce that.

    Returns
    -------
    ndarray, ``(Ho, Wo)`` or ``(Ho, Wo, C)``, the image's dtype
        Integer types rounded to nearest and saturated, as ``cv2.remap``.
    """
    torch, _ = torch_modules()
    dev = resolve_device(device)
    a = np.asarray(image)
    if a.ndim not in (2, 3):
        raise ValueError(f"image: expected (H, W) or (H, W, C), got shape {a.shape}")
    if a.dtype not in (np.uint8, np.uint16, np.float32, np.float64):
        raise ValueError(f"image: expected uint8, uint16, float32 or float64, got {a.dtype}")
    mx, my = np.asarray(map_x), np.asarray(map_y)
    if mx.shape != my.shape or mx.ndim != 2:
        raise ValueError(f"map_x, map_y: expected two (Ho, Wo) arrays, got {mx.shape}, {my.shape}")
    dt = torch.float64 if a.dtype == np.float64 else torch.float32
    planes = a[None] if a.ndim == 2 else np.moveaxis(a, -1, 0)
    t = to_torch(planes, dev, dtype=dt)
    out = remap_tensor(t, to_torch(mx, dev, dtype=torch.float32), to_torch(my, dev, dtype=torch.float32),
                       interpolation=interpolation, border=border, border_value=border_value)
    if a.dtype.kind == "u":
        out = round_like_cv2(out, a.dtype, channels=planes.shape[0])
    res = to_numpy(out).astype(a.dtype, copy=False)
    return res[0] if a.ndim == 2 else np.moveaxis(res, 0, -1)
