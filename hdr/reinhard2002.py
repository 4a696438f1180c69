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

from dataclasses import dataclass

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
    # written out per channel, not ``rgb @ LUMA``: a BLAS kernel may sum the three
    # products in another order at a block's edge, and a band of rows must give
    # the bits the whole image gives
    return np.maximum(rgb[..., 0] * LUMA[0] + rgb[..., 1] * LUMA[1] + rgb[..., 2] * LUMA[2], 0.0)


# The log-average's sum is kept in fixed point, 2^-32 per unit of ln L: integer
# sums do not depend on their order, so bands of rows add up to the whole image's
# bits. (|ln(δ + L)| <= 89 for float32 L, so 2^24 terms fit an int64; the
# rounding, <= 2^-33 per term, moves L̄_w by < 1e-9 relative.)
_LOG_SCALE = 2.0 ** 32
_LOG_CHUNK = 1 << 24


def _log_sum(logs: np.ndarray) -> int:
    """The fixed-point sum of ``logs`` (any float array), exact and order-free."""
    q = logs.ravel()
    total = 0
    for i in range(0, q.size, _LOG_CHUNK):
        total += int(np.rint(q[i:i + _LOG_CHUNK] * _LOG_SCALE).astype(np.int64).sum())
    return total


@dataclass(frozen=True)
class ToneStatistics:
    """The whole image's statistics the operators need: the fixed-point sum of
    ``ln(δ + L_w)`` over ``count`` pixels and the largest luminance."""

    log_sum: int
    count: int
    max_luminance: float

    @property
    def log_average(self) -> float:
        """``L̄_w = exp(mean ln(δ + L_w))`` (eq. 1)."""
        return float(np.exp(self.log_sum / (self.count * _LOG_SCALE)))

    def __add__(self, other: ToneStatistics) -> ToneStatistics:
        return ToneStatistics(self.log_sum + other.log_sum, self.count + other.count,
                              max(self.max_luminance, other.max_luminance))


def _lum_statistics(lum: np.ndarray, *, local: bool, delta: float = 1e-6) -> ToneStatistics:
    """:class:`ToneStatistics` of a luminance map as each operator computes its
    logs (the local one in float32, the global one in float64)."""
    if local:
        logs = np.log(np.float32(delta) + lum.astype(np.float32, copy=False))
    else:
        logs = np.log(delta + lum)
    return ToneStatistics(_log_sum(logs), int(lum.size), float(lum.max()) if lum.size else 0.0)


def global_operator(lum: np.ndarray, *, key: float = 0.18, white: float | None = None,
                    delta: float = 1e-6, statistics: ToneStatistics | None = None) -> np.ndarray:
    """Eq. 1-4 on a luminance map: display luminance in [0, 1].

    ``statistics`` (of the whole image, when ``lum`` is a band of it) gives
    ``L̄_w`` and the largest luminance; by default they are ``lum``'s own.
    """
    st = statistics if statistics is not None else _lum_statistics(lum, local=False, delta=delta)
    lw_bar = st.log_average
    scaled = key * lum / lw_bar
    # max(key·L/L̄) is key·max(L)/L̄ to the bit: each step is a monotone rounding
    lwhite = float(key * np.float64(st.max_luminance) / lw_bar) if white is None else float(white)
    return scaled * (1.0 + scaled / max(lwhite, 1e-12) ** 2) / (1.0 + scaled)


LOCAL_SCALES = 8
_TRUNCATE = 4.0  # scipy.ndimage.gaussian_filter's default support, in sigmas


def _sigma(s: float) -> float:
    return 1.0 / (2 * np.sqrt(2)) * s


def local_halo(scales: int = LOCAL_SCALES) -> int:
    """Rows the local operator reads beyond a pixel: the support of its widest
    blur (scale ``1.6^scales``, truncated at 4 sigma as scipy's filter is).

    Examples
    --------
    >>> local_halo()
    61
    """
    return int(_TRUNCATE * _sigma(1.6 ** scales) + 0.5)


def local_operator(lum: np.ndarray, *, key: float = 0.18, phi: float = 8.0, eps: float = 0.05,
                   scales: int = LOCAL_SCALES, delta: float = 1e-6,
                   statistics: ToneStatistics | None = None) -> np.ndarray:
    """Eq. 5-9: dodging and burning with a centre-surround scale selection.

    Works in float32 with the scale pyramid updated in place: one blur per scale
    and a handful of image-sized float32 arrays, whatever the input's dtype (a
    12 MP frame: ~0.3 GB, where float64 copies of every scale took ~1.9 GB in
    all). The log-average is accumulated in fixed point (``statistics``: the
    whole image's, when ``lum`` is a band of it with :func:`local_halo` rows
    around; the blurs reflect at the band's edges, so only rows that far from
    an edge that is not the image's are exact).
    """
    import scipy.ndimage as ndi

    lum = np.asarray(lum)
    st = statistics if statistics is not None else _lum_statistics(lum, local=True, delta=delta)
    lw_bar = st.log_average
    l = (lum * np.float32(key / lw_bar)).astype(np.float32, copy=False)
    s = 1.0
    v1 = ndi.gaussian_filter(l, _sigma(s), output=np.float32, truncate=_TRUNCATE)
    chosen = v1.copy()
    done = np.zeros(l.shape, bool)
    v2 = np.empty_like(l)
    v = np.empty_like(l)
    for _ in range(scales):
        s_next = s * 1.6
        ndi.gaussian_filter(l, _sigma(s_next), output=v2, truncate=_TRUNCATE)
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


def _check_radiance(radiance) -> np.ndarray:
    rgb = np.asarray(radiance)
    if rgb.dtype.kind not in "fiu":
        raise InputError("radiance", f"expected numbers, got {rgb.dtype}")
    if rgb.ndim == 2:
        rgb = rgb[..., None]
    if rgb.ndim != 3 or rgb.shape[2] not in (1, 3):
        raise InputError("radiance", f"expected (H, W, 3), got {np.shape(radiance)}")
    if not np.isfinite(rgb).all():
        raise InputError("radiance", "contains NaN/inf; tone mapping needs finite radiance")
    return rgb


def _band(rgb: np.ndarray) -> int:
    return max(1, (1 << 18) // max(rgb.shape[1], 1))


def _lum(rgb: np.ndarray, method: str) -> np.ndarray:
    """The luminance each operator works on (float64 global, float32 local),
    computed in row bands (float64 work never holds more than a band)."""
    h = rgb.shape[0]
    band = _band(rgb)
    lum = np.empty(rgb.shape[:2], np.float64 if method == "reinhard" else np.float32)
    for r in range(0, h, band):
        x = np.maximum(rgb[r:r + band].astype(np.float64), 0.0)
        lum[r:r + band] = _luminance(x) if x.shape[2] == 3 else x[..., 0]
    return lum


def tonemap_statistics(radiance_bands, *, method: str = "reinhard") -> ToneStatistics:
    """The whole image's :class:`ToneStatistics` from its bands of rows
    (an iterable of ``(n, W, 3)`` radiance), for :func:`tonemap`'s
    ``statistics``: the first pass of a tone mapping by bands."""
    total = None
    for rgb in radiance_bands:
        st = _lum_statistics(_lum(_check_radiance(rgb), method), local=method != "reinhard")
        total = st if total is None else total + st
    if total is None:
        raise InputError("radiance", "no rows")
    return total


def tonemap(radiance: np.ndarray, *, method: str = "reinhard", key: float = 0.18,
            white: float | None = None, bit_depth: int = 8, device="cpu",
            statistics: ToneStatistics | None = None) -> np.ndarray:
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
    statistics : ToneStatistics, optional
        The whole image's (:func:`tonemap_statistics`) when ``radiance`` is a
        band of its rows (with :func:`local_halo` rows around it for the
        local operator); default: ``radiance``'s own.

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
    rgb = _check_radiance(radiance)
    if device != "cpu":
        from lumigraph.capture.device import resolve_device

        dev = resolve_device(device)
        if dev.uses_torch:
            if statistics is not None:
                raise InputError("device", "tone mapping by bands (statistics=) runs on the "
                                           "cpu device")
            from lumigraph.hdr.reinhard2002_torch import tonemap_torch

            return tonemap_torch(rgb, method=method, key=key, white=white, bit_depth=bit_depth,
                                 device=dev)
    # Row bands: the float64 work of the luminance and the encoding never holds more than
    # a band (a 12 MP radiance map would need 5 full-size float64 copies otherwise).
    h = rgb.shape[0]
    band = _band(rgb)
    lum = _lum(rgb, method)
    ld = global_operator(lum, key=key, white=white, statistics=statistics) \
        if method == "reinhard" else local_operator(lum, key=key, statistics=statistics)
    top = 2 ** bit_depth - 1
    out = np.empty(rgb.shape[:2] + (3,), np.uint8 if bit_depth == 8 else np.uint16)
    for r in range(0, h, band):
        lb = lum[r:r + band].astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(lb > 0, ld[r:r + band] / lb, 0.0)
        x = np.maximum(rgb[r:r + band].astype(np.float64), 0.0) * ratio[..., None]
        out[r:r + band] = np.round(srgb_encode(x) * top)
    return out
