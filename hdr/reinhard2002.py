"""Reinhard et al. (2002): photographic tone reproduction, global and local.

E. Reinhard, M. Stark, P. Shirley and J. Ferwerda, "Photographic Tone
Reproduction for Digital Images", SIGGRAPH 2002, doi:10.1145/566570.566575.

Luminance is scaled to the key ``a`` by the log-average ``L̄_w``
(eq. 1-2: ``L = a L_w / L̄_w``); the global operator compresses with
``L_d = L (1 + L/L_white²) / (1 + L)`` (eq. 4); the local one divides by the
largest-scale centre-surround average ``V1(x, s_m)`` whose normalised
difference stays below ε (eq. 5-9, "dodging and burning"), using Gaussian
blurs at scales growing by 1.6. Colour is carried by scaling RGB by
``L_d / L``; the result is sRGB-encoded 8- or 16-bit.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> hdr = np.exp(rng.normal(0, 2, (16, 16, 3))).astype(np.float32)
>>> out = tonemap(hdr, method="reinhard")
>>> out.dtype.name, bool(out.min() >= 0 and out.max() <= 255)
('uint8', True)
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.errors import InputError

LUMA = np.array([0.2126, 0.7152, 0.0722])


def check_key(key: float) -> float:
    """The key ``a`` of :func:`tonemap` (and :func:`hdr.kang2003.tonemap_video`):
    a finite number > 0 (0 maps every pixel to black, NaN too).

    Raises
    ------
    InputError
        Naming ``key``.

    Examples
    --------
    >>> check_key(0.18)
    0.18
    >>> try:
    ...     check_key(0)
    ... except InputError as e:
    ...     print(e)
    key: expected a finite number > 0, got 0
    """
    try:
        ok = np.isfinite(key) and key > 0
    except TypeError:
        ok = False
    if not ok or isinstance(key, bool):
        raise InputError("key", f"expected a finite number > 0, got {key!r}")
    return float(key)


def _luminance(rgb):
    return np.maximum(rgb @ LUMA, 0.0)


def global_operator(lum: np.ndarray, *, key: float = 0.18, white: float | None = None,
                    delta: float = 1e-6) -> np.ndarray:
    """Eq. 1-4 on a luminance map: display luminance in [0, 1]."""
    lw_bar = float(np.exp(np.mean(np.log(delta + lum))))
    scaled = key * lum / lw_bar
    lwhite = float(scaled.max()) if white is None else float(white)
    return scaled * (1.0 + scaled / max(lwhite, 1e-12) ** 2) / (1.0 + scaled)


def local_operator(lum: np.ndarray, *, key: float = 0.18, phi: float = 8.0, eps: float = 0.05,
                   scales: int = 8, delta: float = 1e-6) -> np.ndarray:
    """Eq. 5-9: dodging and burning with a centre-surround scale selection.

    Works in float32 with the scale pyramid updated in place: one blur per scale
    and a handful of image-sized float32 arrays, whatever the input's dtype (a
    12 MP frame: ~0.3 GB, where float64 copies of every scale took ~1.9 GB in
    all). The log-average is accumulated in float64.
    """
    import scipy.ndimage as ndi

    lum = np.asarray(lum)
    lw_bar = float(np.exp(np.mean(np.log(np.float32(delta) + lum.astype(np.float32, copy=False)),
                                  dtype=np.float64)))
    l = (lum * np.float32(key / lw_bar)).astype(np.float32, copy=False)
    s = 1.0
    v1 = ndi.gaussian_filter(l, 1.0 / (2 * np.sqrt(2)) * s, output=np.float32)
    chosen = v1.copy()
    done = np.zeros(l.shape, bool)
    v2 = np.empty_like(l)
    v = np.empty_like(l)
    for _ in range(scales):
        s_next = s * 1.6
        ndi.gaussian_filter(l, 1.0 / (2 * np.sqrt(2)) * s_next, output=v2)
        # v = (v1 - v2) / (2^phi a / s^2 + v1), in place
        np.add(v1, np.float32(2.0 ** phi * key / s ** 2), out=v)
        np.divide(np.subtract(v1, v2, out=chosen, where=~done), v, out=v, where=~done)
        stop = np.abs(v) >= eps
        stop &= ~done
        chosen[stop] = v1[stop]
        done |= stop
        np.copyto(chosen, v2, where=~done)
        v1, v2, s = v2, v1, s_next
    np.add(chosen, np.float32(1.0), out=chosen)
    return np.divide(l, chosen, out=l)


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """Linear [0, 1] -> sRGB-encoded [0, 1] (IEC 61966-2-1)."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def tonemap(radiance: np.ndarray, *, method: str = "reinhard", key: float = 0.18,
            white: float | None = None, bit_depth: int = 8, device="cpu") -> np.ndarray:
    """Tone-map linear radiance to a displayable sRGB image.

    Parameters
    ----------
    radiance : ndarray, ``(H, W, 3)`` or ``(H, W)`` float, linear, finite, ≥ 0
    method : {"reinhard", "reinhard-local"}
    key : float
        The scene key ``a`` (0.18 = middle grey), > 0 (:func:`check_key`).
    white : float, optional
        ``L_white`` of the global operator (default: the largest scaled luminance).
    bit_depth : {8, 16}
    device : {"cpu", "cuda", "torch-cpu", "auto"}
        Where it runs (:mod:`lumigraph.capture.device`): ``"cpu"`` is this
        numpy code; a torch device runs :func:`hdr.reinhard2002_torch.tonemap_torch`
        (float32; codes agree within one, :mod:`hdr.reinhard2002_torch`).

    Returns
    -------
    ndarray, ``(H, W, 3)`` uint8 or uint16, sRGB-encoded.

    Raises
    ------
    InputError
        Naming ``radiance`` when it is not ``(H, W[, 3])`` or holds NaN/inf.
    """
    if method not in ("reinhard", "reinhard-local"):
        raise ValueError(f"method: expected 'reinhard' or 'reinhard-local', got {method!r}")
    if bit_depth not in (8, 16):
        raise ValueError(f"bit_depth: expected 8 or 16, got {bit_depth}")
    key = check_key(key)
    rgb = np.asarray(radiance)
    if rgb.dtype.kind not in "fiu":
        raise InputError("radiance", f"expected numbers, got {rgb.dtype}")
    if rgb.ndim == 2:
        rgb = rgb[..., None]
    if rgb.ndim != 3 or rgb.shape[2] not in (1, 3):
        raise InputError("radiance", f"expected (H, W, 3), got {np.shape(radiance)}")
    if not np.isfinite(rgb).all():
        raise InputError("radiance", "contains NaN/inf; tone mapping needs finite radiance")
    if device != "cpu":
        from lumigraph.capture.device import resolve_device

        dev = resolve_device(device)
        if dev.uses_torch:
            from lumigraph.hdr.reinhard2002_torch import tonemap_torch

            return tonemap_torch(rgb, method=method, key=key, white=white, bit_depth=bit_depth,
                                 device=dev)
    # Row bands: the float64 work of the luminance and the encoding never holds more than
    # a band (a 12 MP radiance map would need 5 full-size float64 copies otherwise).
    h = rgb.shape[0]
    band = max(1, (1 << 18) // max(rgb.shape[1], 1))
    dt = np.float64 if method == "reinhard" else np.float32
    lum = np.empty(rgb.shape[:2], dt)
    for r in range(0, h, band):
        x = np.maximum(rgb[r:r + band].astype(np.float64), 0.0)
        lum[r:r + band] = _luminance(x) if x.shape[2] == 3 else x[..., 0]
    ld = global_operator(lum, key=key, white=white) if method == "reinhard" else \
        local_operator(lum, key=key)
    top = 2 ** bit_depth - 1
    out = np.empty(rgb.shape[:2] + (3,), np.uint8 if bit_depth == 8 else np.uint16)
    for r in range(0, h, band):
        lb = lum[r:r + band].astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(lb > 0, ld[r:r + band] / lb, 0.0)
        x = np.maximum(rgb[r:r + band].astype(np.float64), 0.0) * ratio[..., None]
        out[r:r + band] = np.round(srgb_encode(x) * top)
    return out
