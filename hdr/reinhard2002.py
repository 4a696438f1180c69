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
    """Eq. 5-9: dodging and burning with a centre-surround scale selection."""
    import scipy.ndimage as ndi

    lw_bar = float(np.exp(np.mean(np.log(delta + lum))))
    l = key * lum / lw_bar
    s = 1.0
    v1_prev = ndi.gaussian_filter(l, 1.0 / (2 * np.sqrt(2)) * s)
    chosen = v1_prev.copy()
    done = np.zeros(l.shape, bool)
    for _ in range(scales):
        s_next = s * 1.6
        v1 = v1_prev
        v2 = ndi.gaussian_filter(l, 1.0 / (2 * np.sqrt(2)) * s_next)
        v = (v1 - v2) / (2.0 ** phi * key / s ** 2 + v1)
        stop = (np.abs(v) >= eps) & ~done
        chosen[stop] = v1[stop]
        done |= stop
        chosen[~done] = v2[~done]
        v1_prev, s = v2, s_next
    return l / (1.0 + chosen)


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """Linear [0, 1] -> sRGB-encoded [0, 1] (IEC 61966-2-1)."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def tonemap(radiance: np.ndarray, *, method: str = "reinhard", key: float = 0.18,
            white: float | None = None, bit_depth: int = 8) -> np.ndarray:
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
    rgb = np.asarray(radiance, dtype=np.float64)
    if rgb.ndim == 2:
        rgb = np.repeat(rgb[..., None], 3, axis=2)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InputError("radiance", f"expected (H, W, 3), got {np.shape(radiance)}")
    if not np.isfinite(rgb).all():
        raise InputError("radiance", "contains NaN/inf; tone mapping needs finite radiance")
    rgb = np.maximum(rgb, 0.0)
    lum = _luminance(rgb)
    ld = global_operator(lum, key=key, white=white) if method == "reinhard" else \
        local_operator(lum, key=key)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(lum > 0, ld / lum, 0.0)
    out = srgb_encode(rgb * ratio[..., None])
    top = 2 ** bit_depth - 1
    return np.round(out * top).astype(np.uint8 if bit_depth == 8 else np.uint16)
