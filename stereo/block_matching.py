"""Block-matching stereo on a rectified pair: SSD window matching along rows.

For each left pixel ``(x, y)`` and each disparity ``d`` in ``[0, max_disp]``
the cost is the mean over a ``(2w+1) × (2w+1)`` window of the squared
difference between the left image and the right image shifted by ``d``
(reference ch. 5, eq. 5.1, with ``(dx, dy) = (−d, 0)``: after rectification
the epipolar line of a left pixel is its own row, so the search is 1-D). The
best integer disparity is refined to sub-pixel precision by fitting a parabola
through the costs at ``d − 1, d, d + 1``. A match is kept only when

- the window holds enough texture: its intensity variance exceeds
  ``texture_snr² · σ²`` (``σ`` the sensor noise, estimated from the image), so
  flat regions come out unknown (NaN) rather than as guesses;
- it is unique: no disparity outside ``d ± 1`` costs less than
  ``(1 + uniqueness)`` times the best;
- left and right agree: matching the right image against the left gives back
  the same disparity within ``lr_tolerance`` pixels (occluded pixels fail).

With ``window="auto"`` each pixel uses the smallest candidate window whose
texture passes the test (small windows keep depth edges sharp, large ones
carry weakly textured areas); the share of pixels per window is recorded.

Speed: 8-bit pairs are scanned by a small C kernel (``stereo/_ssd.c``, built
at install time, loaded with ctypes): column and window sums updated
incrementally (O(1) per pixel and disparity), the bests tracked in the same
pass, and the decision fused per row. Its integer SSD and float32 decision
reproduce the numpy/OpenCV path bit for bit; that path runs, with one
warning, when the kernel was not built, and for float inputs.

Convention (DESIGN §3): left is the reference, ``x_right = x_left − d``,
``d > 0``, NaN for unknown.

Reference: D. Scharstein and R. Szeliski, "A taxonomy and evaluation of dense
two-frame stereo correspondence algorithms", IJCV 47, 2002,
doi:10.1023/A:1014573219977 (SSD aggregation, WTA, sub-pixel fit, left–right
check); noise estimate after J. Immerkær, "Fast noise variance estimation",
CVIU 64(2), 1996, doi:10.1006/cviu.1996.0060.

Examples
--------
>>> from scipy.ndimage import gaussian_filter
>>> rng = np.random.default_rng(0)
>>> right = gaussian_filter(rng.uniform(0, 255, (40, 80)), 1.5).astype(np.float32)
>>> left = np.roll(right, 6, axis=1)          # every pixel has disparity 6
>>> result = match(left, right, max_disp=12, window=5)
>>> d = result.disparity[:, 20:]
>>> round(float(np.nanmedian(d)), 2), bool(np.mean(np.isfinite(d)) > 0.9)
(6.0, True)
"""

from __future__ import annotations

import functools
import math
import queue
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from lumigraph.capture.batch import default_threads
from lumigraph.capture.errors import InputError
from lumigraph.stereo.luma import luma_codes, noise_sigma_smooth_blocks

AUTO_WINDOWS = (5, 9, 15)
WINDOW_RANGE = (3, 63)  # odd window sides match accepts
BAND_ROWS = 64
# How the defaults of match() were chosen: docs/decisions/stereo-block-matching-defaults.md
_INT_MAX = np.iinfo(np.int32).max


@dataclass(frozen=True)
class DisparityMap:
    """A left-reference disparity map and what it is based on.

    Attributes
    ----------
    disparity : ndarray, (H, W) float32
        Pixels; ``x_right = x_left − d``; NaN where unknown (no texture, not
        unique, left–right disagreement, outside the search range).
    cost : ndarray, (H, W) float32
        The best mean squared difference per pixel (code values²); NaN where
        never computed.
    window : ndarray, (H, W) uint8
        Side of the window used at each pixel (0 where the texture test
        failed for every candidate).
    info : dict
        Parameters, the noise estimate, the ``auto`` choice (candidates and
        their share of pixels) and how many pixels each test rejected.
    """

    disparity: np.ndarray
    cost: np.ndarray
    window: np.ndarray
    info: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        d = np.asarray(self.disparity)
        if d.ndim != 2 or d.dtype != np.float32:
            raise ValueError(f"disparity: expected (H, W) float32, got {d.shape} {d.dtype}")
        if (d < 0).any():  # NaN compares False
            raise ValueError("disparity: values must be >= 0 (x_right = x_left - d)")
        for name in ("cost", "window"):
            if np.asarray(getattr(self, name)).shape != d.shape:
                raise ValueError(f"{name}: expected shape {d.shape}, got {np.shape(getattr(self, name))}")

    @property
    def valid_fraction(self) -> float:
        return float(np.isfinite(self.disparity).mean())

    def save(self, path, *, meta: dict) -> None:
        """Write the disparity as PFM (NaN stored as inf) with its sidecar."""
        from lumigraph.capture.artifact import write_artifact
        from lumigraph.capture.io import write_pfm

        write_artifact(path, lambda tmp: write_pfm(tmp, self.disparity), meta=meta)


# ------------------------------------------------------------------- helpers
_SCRATCH: queue.SimpleQueue = queue.SimpleQueue()


@contextmanager
def _scratch():
    """Scratch buffers for one band's cost volume, returned to a module-wide
    pool afterwards. Kept between calls because fresh memory costs a page
    fault per 4 KiB on first write, which for a volume of tens of MB takes
    longer than filling it; the pool holds at most one buffer per thread that
    ever matched at the same time."""
    try:
        buffers = _SCRATCH.get_nowait()
    except queue.Empty:
        buffers = {}
    try:
        yield buffers
    finally:
        _SCRATCH.put(buffers)


CHANNELS = ("color", "luma")
PREFILTERS = ("none", "local-mean")
PREFILTER_SIZE = 9


def _local_mean_response(a, *, cap, integer, gain=1.0):
    """``clip(gain · (a − mean₉ₓ₉(a)), −cap, cap) + cap``: each pixel's
    difference from its local mean, so that a gain or offset between the two
    views (exposure, vignetting, a different sensor response) no longer enters
    the SSD, and clipped so that a few strong edges do not dominate a window's
    cost (the normalised-response prefilter of OpenCV's StereoBM). ``gain``
    (see :func:`_response_gain`) scales the response before the clipping.
    Integer inputs stay integers, rounded half up, so every engine sees the
    same values."""
    import cv2

    k = PREFILTER_SIZE
    if integer:
        a32 = a.astype(np.int32)
        s = cv2.boxFilter(a32, -1, (k, k), normalize=False, borderType=cv2.BORDER_REFLECT)
        if gain == 1.0:
            r = np.floor_divide(k * k * a32 - s + (k * k) // 2, k * k)
        else:
            r = np.floor((k * k * a32 - s).astype(np.float32) * np.float32(gain / (k * k))
                         + np.float32(0.5)).astype(np.int32)
        return (np.clip(r, -cap, cap) + cap).astype(np.uint16)
    m = cv2.boxFilter(a, -1, (k, k), borderType=cv2.BORDER_REFLECT)
    return (np.clip(gain * (a - m), -cap, cap) + cap).astype(np.float32)


def _response_gain(left, right):
    """The contrast of ``left`` relative to ``right`` (2-D planes): the ratio
    of the median absolute local-mean responses. A darker exposure or a
    flatter tone curve scales every local difference of one view by about
    the same factor, which the offset removal alone leaves in the SSD (and the
    clipping then cuts the two views at different places); scaling the right
    view's response by this ratio before clipping brings both to one
    contrast. Views of one exposure give a ratio near 1 (the median over the
    whole image barely moves with the occlusions at the borders)."""
    import cv2

    k = PREFILTER_SIZE

    def spread(a):
        # k²·a − window sum: exact in float32 for code values (k²·255 < 2^24),
        # so an offset between grey views leaves the ratio exactly 1; the
        # median over every other row and column (a quarter of the pixels)
        # is as good an estimate of a global spread, at a quarter of the cost
        a = np.asarray(a, np.float32)
        s = cv2.boxFilter(a, -1, (k, k), normalize=False, borderType=cv2.BORDER_REFLECT)
        r = np.abs(a[::2, ::2] * np.float32(k * k) - s[::2, ::2])
        return float(np.median(r))

    sl, sr = spread(left), spread(right)
    return sl / sr if sl > 0 and sr > 0 else 1.0


def _match_images(left, right, *, channels="color", prefilter="none", cap=31.0):
    """The images block matching compares, as ``(C, H, W)`` planes, and the
    float luma for the texture and noise estimates.

    ``channels="color"`` on colour inputs keeps R, G and B (``C = 3``): the SSD
    sums over them, so two surfaces of equal luma but different hue still
    differ. Otherwise luma (``C = 1``). 8-bit inputs stay integers for an
    exact integer SSD: colour as the code values, luma in quarter code values
    as uint16 (whole code values would add the rounding noise of the luma
    weights); other inputs become float32. With ``prefilter="local-mean"``
    every plane is replaced by its local-mean response (``cap`` in 8-bit code
    values, scaled to the input's range for other dtypes), the right view's
    scaled by the contrast ratio of the two lumas (:func:`_response_gain`);
    the texture and noise estimates keep the plain luma."""
    L, R = luma_codes(left), luma_codes(right)
    gray, gray_right = L, R
    a, b = np.asarray(left), np.asarray(right)
    integer = a.dtype == np.uint8 and b.dtype == np.uint8
    colour = channels == "color" and a.ndim == 3 and a.shape[2] in (3, 4) and b.shape == a.shape
    if colour:
        dt = np.uint16 if integer else np.float32
        L = np.ascontiguousarray(np.moveaxis(a[..., :3], -1, 0), dtype=dt)
        R = np.ascontiguousarray(np.moveaxis(b[..., :3], -1, 0), dtype=dt)
        code = 1
    else:
        code = 4 if integer else 1
        if integer:
            L, R = np.rint(L * 4).astype(np.uint16), np.rint(R * 4).astype(np.uint16)
        L, R = L[None], R[None]
    if prefilter == "local-mean":
        if integer:
            c = int(round(code * cap))
        else:
            full = (np.iinfo(a.dtype).max if np.issubdtype(a.dtype, np.integer)
                    else max(float(max(L.max(), R.max())) - float(min(L.min(), R.min())), 1e-12))
            c = cap * full / 255.0
        g = _response_gain(gray, gray_right)
        L = np.stack([_local_mean_response(x, cap=c, integer=integer) for x in L])
        R = np.stack([_local_mean_response(x, cap=c, integer=integer, gain=g) for x in R])
    return L, R, gray, code


def _noise_var(image, luma_sigma, nch):
    """Noise of what is matched, in code values²: ``(scale, variance)``.

    ``variance`` is the noise variance of a pixel summed over the ``nch``
    planes (σ² of the luma; Σ σ_c² over R, G, B), against which the texture
    test weighs a window's variance. ``scale`` is the spread of a pixel's
    squared difference summed over the planes: σ² for one plane,
    ``sqrt(Σ σ_c⁴)`` for three independent ones, so that a flat window's cost
    spreads by ``scale · sqrt(8/n)`` either way. Each σ is floored at half a
    code value (quantisation alone gives σ ≈ 0.29)."""
    if nch == 1:
        v = max(luma_sigma, 0.5) ** 2
        return v, v
    a = np.asarray(image)
    s2 = [max(noise_sigma_smooth_blocks(np.ascontiguousarray(a[..., c], dtype=np.float32)), 0.5) ** 2 for c in range(3)]
    return float(np.sqrt(sum(v * v for v in s2))), float(sum(s2))


def _texture(planes, windows, thresholds):
    """Window variance of the left image (summed over its float ``planes``:
    the luma, or R, G, B) per candidate window, and per pixel the index of
    the smallest window whose variance passes its threshold
    (``len(windows)`` = none)."""
    import cv2

    var = []
    for win in windows:
        v = 0
        for g in planes:
            m = cv2.boxFilter(g, -1, (win, win), borderType=cv2.BORDER_REFLECT)
            m2 = cv2.sqrBoxFilter(g, cv2.CV_32F, (win, win), borderType=cv2.BORDER_REFLECT)
            v = v + (m2 - m * m)
        var.append(v)
    gray = planes[0]
    pick = np.full(gray.shape, len(windows), np.uint8)
    for k in range(len(windows) - 1, -1, -1):
        np.copyto(pick, k, where=var[k] >= thresholds[k], casting="unsafe")
    return var, pick


@dataclass(frozen=True)
class _Costs:
    """How window SSDs become comparable int32 costs for one image.

    ``wins`` are the windows whose costs are computed (the used candidates),
    ``cwin`` (H, W) uint8 the index into ``wins`` per pixel (None for one).
    A cost is stored as
    ``(c << nb) | d`` so one integer min carries its disparity, with ``c`` in
    integer units, ``unit`` per code value² of mean squared difference (summed
    over the planes): for 8-bit inputs (a pixel's squared difference, summed
    over planes, is at most ``sqmax``: 1020² for quarter-code luma, 3·255² for
    colour) the window sum shifted right by ``rshift`` (one window: sums used
    as they come unless too wide for 30 bits) or, with several windows, the
    sum times ``scale[k]`` = 2^shift / n_k truncated (a mean in fixed point,
    so that pixels with different windows compare in the left–right check);
    for float inputs the largest possible cost, ``nch · span²``, maps to
    2^(30 - nb)."""

    wins: tuple
    cwin: np.ndarray | None
    nb: int
    unit: float
    integer: bool
    rshift: int = 0
    scale: tuple | None = None
    sqmax: int = 0  # integer: the largest per-pixel squared difference (summed over planes)


def _costs(windows, pick, *, D, integer, span, nch=1, code=4):
    if len(windows) == 1:
        used = [0]
    else:
        used = [k for k, c in enumerate(np.bincount(pick.ravel(), minlength=len(windows) + 1)[:-1])
                if c] or [0]
    # untextured pixels are refused later, but their costs still compete for
    # the right image's best (left–right check): they use the largest window
    index = np.full(len(windows) + 1, len(used) - 1, np.uint8)
    index[used] = np.arange(len(used))
    wins = tuple(windows[k] for k in used)
    cwin = index[pick] if len(used) > 1 else None
    nb = max(1, math.ceil(math.log2(D)))
    if not integer:
        return _Costs(wins, cwin, nb, 2.0 ** (30 - nb) / (nch * span ** 2), False)
    sqmax = nch * (255 * code) ** 2
    if len(wins) == 1:
        n = wins[0] ** 2
        shift = min(30 - nb - math.ceil(math.log2(n * sqmax + 1)), 0)
        return _Costs(wins, cwin, nb, code ** 2 * n * 2.0 ** shift, True, rshift=-shift,
                      sqmax=sqmax)
    shift = 30 - nb - math.ceil(math.log2(sqmax + 1))
    return _Costs(wins, cwin, nb, code ** 2 * 2.0 ** shift, True,
                  scale=tuple(2.0 ** shift / win ** 2 for win in wins), sqmax=sqmax)


def _scan_numpy(left, right_padded, y0, y1, *, D, costs, scratch):
    """Rows ``y0:y1`` on numpy/OpenCV, one pass per disparity over a cost volume.

    ``left`` is the whole matching image, ``(C, H, W + D)`` planes with ``D``
    reflected columns on their right, ``right_padded`` the right one with
    ``D - 1`` replicated columns on the left and ``D`` on the right (so every
    disparity's view is a plain slice of width ``W + D``); squared differences
    are summed over the ``C`` planes. Returns the encoded best, the costs at ``d* ∓ 1``, the
    best outside ``d* - 1 .. d* + 1`` and the best of every right pixel, each
    (y1 - y0, W) int32."""
    import cv2

    wins, nb = costs.wins, costs.nb
    margin = max(wins) // 2
    H = left.shape[1]
    a0, a1 = max(0, y0 - margin), min(H, y1 + margin)
    L, Rp = left[:, a0:a1], right_padded[:, a0:a1]
    nch, h, wp = L.shape
    w = wp - D
    reflect = cv2.BORDER_REFLECT
    integer = costs.integer
    if len(wins) > 1:
        cw = costs.cwin[a0:a1]
        masks = [np.pad(cw == k, ((0, 0), (0, D))).astype(np.uint8) for k in range(len(wins))]
        merged = np.empty((h, wp), np.int32 if integer else np.float32)
    sq = np.empty((h, wp), np.int32 if integer else np.float32)

    def squares(diff):
        """Per-pixel squared difference summed over the planes, into ``sq``."""
        if integer:
            np.square(diff[0], out=sq, dtype=np.int32)
            for c in range(1, nch):
                sq[...] += np.square(diff[c], dtype=np.int32)
        else:
            cv2.multiply(diff[0], diff[0], dst=sq)
            for c in range(1, nch):
                cv2.add(sq, cv2.multiply(diff[c], diff[c]), dst=sq)

    # A window sum of squares can pass 2^31 (a 63 px window of colour codes):
    # OpenCV's int32 box filter would wrap, so wide windows sum in float64,
    # exact below 2^53, and are shifted or scaled from there as the C kernel
    # does from its int64 sums.
    wide = integer and max(wins) ** 2 * costs.sqmax >= 2 ** 31

    def cost_into(v, diff):
        if wide:
            squares(diff)
            sq64 = sq.astype(np.float64)
            if len(wins) == 1:
                s64 = cv2.boxFilter(sq64, -1, (wins[0], wins[0]), normalize=False,
                                    borderType=reflect)
                v[...] = np.right_shift(s64.astype(np.int64), costs.rshift)
                return
            for k, win in enumerate(wins):
                mk = cv2.boxFilter(sq64, -1, (win, win), normalize=False, borderType=reflect)
                mk = (mk * costs.scale[k]).astype(np.int32)  # truncation, as the C kernel
                cv2.copyTo(mk, masks[k], merged)
            v[...] = merged
            return
        if integer:
            squares(diff)
            if len(wins) == 1:
                cv2.boxFilter(sq, -1, (wins[0], wins[0]), dst=v, normalize=False, borderType=reflect)
                if costs.rshift:
                    np.right_shift(v, costs.rshift, out=v)
                return
            for k, win in enumerate(wins):
                mk = cv2.boxFilter(sq, -1, (win, win), normalize=False, borderType=reflect)
                mk = (mk * costs.scale[k]).astype(np.int32)  # truncation, as the C kernel
                cv2.copyTo(mk, masks[k], merged)
            v[...] = merged
        elif len(wins) == 1:
            n = wins[0] ** 2
            if nch == 1:
                cv2.sqrBoxFilter(diff[0], cv2.CV_32F, (wins[0], wins[0]), dst=sq, normalize=False,
                                 borderType=reflect)
            else:
                squares(diff)
                cv2.boxFilter(sq, -1, (wins[0], wins[0]), dst=sq, normalize=False, borderType=reflect)
            np.multiply(sq, costs.unit / n, out=v, casting="unsafe")
        else:
            squares(diff)
            for k, win in enumerate(wins):
                mk = cv2.boxFilter(sq, -1, (win, win), borderType=reflect)
                cv2.copyTo(mk, masks[k], merged)
            np.multiply(merged, costs.unit, out=v, casting="unsafe")

    # Columns x < d have no partner in the right image, and D columns of
    # padding on the right let the right view's volume (x_r = x - d) be a
    # flat slice: both hold INT_MAX, never chosen.
    size = D * h * wp
    buf = scratch.get("vol")
    if buf is None or buf.size < size:
        # room for any band of this image, so one allocation serves them all
        buf = scratch["vol"] = np.empty(D * max(h, BAND_ROWS + 2 * margin + 2) * wp, np.int32)
    flat = buf[:size]
    vol = flat.reshape(D, h, wp)  # contiguous: reductions over d run at full speed
    slab = h * wp  # flat distance between disparities
    best = np.full((h, wp), _INT_MAX, np.int32)
    best_r = np.full(h * wp, _INT_MAX, np.int32)
    diff = np.empty((nch, h, wp), L.dtype)
    for d in range(D):
        cur = vol[d]
        for c in range(nch):
            cv2.absdiff(L[c], Rp[c, :, D - 1 - d: D - 1 - d + wp], dst=diff[c])
        cost_into(cur, diff)
        np.left_shift(cur, nb, out=cur)
        np.bitwise_or(cur, d, out=cur)
        cur[:, :d] = _INT_MAX
        cur[:, w:] = _INT_MAX
        np.minimum(best, cur, out=best)
        # the right pixel x - d sees this cost at disparity d
        np.minimum(best_r[:best_r.size - d], cur.reshape(-1)[d:], out=best_r[:best_r.size - d])
    best = best[:, :w]
    dbest = (best & np.int32((1 << nb) - 1)).astype(np.intp)
    pix = np.arange(h)[:, None] * wp + np.arange(w)  # flat index of (y, x)
    em = np.take(flat, pix + np.maximum(dbest - 1, 0) * slab)
    ep = np.take(flat, pix + np.minimum(dbest + 1, D - 1) * slab)
    # runner-up outside d*-1..d*+1 (this overwrites the volume)
    for off in (-1, 0, 1):
        np.put(flat, pix + np.clip(dbest + off, 0, D - 1) * slab, _INT_MAX)
    second = vol.min(axis=0)[:, :w]
    s = slice(y0 - a0, y1 - a0)
    return best[s], em[s], ep[s], second[s], best_r.reshape(h, wp)[s, :w]


def _match_c(kernel, left, right_rev, y0, y1, out, *, D, costs, pick, vpick, windows,
             subpixel, lr_tolerance, uniqueness, distinct, noise_var, tex_var):
    """Rows ``y0:y1`` through the compiled kernel (``stereo/_ssd.c``): the scan
    and the decision of ``_decide``, fused per row, written into the rows of
    ``out`` = (disparity, cost) (H, W) float32; returns the rejection counts.
    ``left`` and ``right_rev`` are ``(C, H, ·)`` planes, the latter the padded
    right image with its columns reversed."""
    nch, H, wp = left.shape
    w = wp - D
    wins = np.asarray(costs.wins, np.int32)
    rshift = np.asarray([costs.rshift] * len(wins), np.int32)
    scale = None if costs.scale is None else np.asarray(costs.scale, np.float64)
    cwin = costs.cwin
    sides = np.asarray(windows, np.int32)
    counts = np.zeros(3, np.int64)

    def ptr(a):
        return None if a is None else int(a.ctypes.data)

    rc = kernel(ptr(left), left.strides[1] // 2, ptr(right_rev), right_rev.strides[1] // 2,
                nch, left.strides[0] // 2, right_rev.strides[0] // 2, H, w, D, int(y0), int(y1), len(wins), ptr(wins), ptr(cwin), ptr(rshift),
                ptr(scale), costs.nb, ptr(pick), len(windows), ptr(sides), ptr(vpick),
                int(subpixel), int(lr_tolerance), int(uniqueness > 0 or distinct > 0),
                1 + uniqueness, distinct * noise_var, 2 * tex_var, costs.unit,
                ptr(out[0]), ptr(out[1]), ptr(counts))
    if rc != 0:
        raise RuntimeError(f"stereo/_ssd.c: match of rows {y0}:{y1} failed (code {rc})")
    return counts


@functools.cache
def _pool():
    """Worker threads for the kernel's row bands, started once (starting
    threads per call costs as much as matching a small pair)."""
    from concurrent.futures import ThreadPoolExecutor

    return ThreadPoolExecutor(default_threads(), thread_name_prefix="stereo-ssd")


@functools.cache
def _kernel():
    """The compiled scan as a ctypes function, or None (with one warning) when
    the extension was not built; the numpy path gives identical results."""
    import ctypes
    import importlib

    try:
        f = ctypes.CDLL(importlib.import_module("lumigraph.stereo._ssd").__file__).lumigraph_ssd_match
    except (ImportError, OSError, AttributeError) as e:
        warnings.warn(f"lumigraph.stereo.block_matching: compiled kernel stereo/_ssd.c unavailable ({e}); "
                      "using the numpy path (same results, 5-10x slower). Reinstall "
                      "(pip install -e .) with a C compiler to build it.", stacklevel=3)
        return None
    P, I, F = ctypes.c_void_p, ctypes.c_int, ctypes.c_double
    L = ctypes.c_int64
    f.argtypes = [P, I, P, I, I, L, L, I, I, I, I, I, I, P, P, P, P, I, P, I, P, P, I, I, I, F, F,
                  F, F, P, P, P]
    f.restype = I
    return f


def _picked_variance(var, pick):
    """The window variance of each pixel's picked window (the smallest when none)."""
    vpick = var[0].copy()
    for k in range(1, len(var)):
        np.copyto(vpick, var[k], where=pick == k)
    return vpick


def _decide(best, em, ep, second, best_r, *, var, pick, windows, costs, D, uniqueness,
            lr_tolerance, subpixel, distinct, noise_var, tex_var):
    """Disparity and cost per pixel from the scan's encoded costs:
    parabola sub-pixel fit, uniqueness, left–right check, texture test."""
    h, w = best.shape
    nb, unit = costs.nb, costs.unit
    low = np.int32((1 << nb) - 1)
    dbest = (best & low).astype(np.intp)
    valid = best != _INT_MAX
    bestc = (best >> nb).astype(np.float32)
    x = np.arange(w)

    # sub-pixel: parabola through d-1, d, d+1
    disp = dbest.astype(np.float32)
    if subpixel:
        inner = valid & (dbest > 0) & (dbest < D - 1) & (em != _INT_MAX) & (ep != _INT_MAX)
        cm = (em >> nb).astype(np.float32)
        cp = (ep >> nb).astype(np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            curv = cm - 2 * bestc + cp
            delta = np.where(inner & (curv > 0), 0.5 * (cm - cp) / curv, 0.0)
        disp += np.clip(delta, -0.5, 0.5).astype(np.float32)

    # left-right: the right pixel x - d must choose d back (within tolerance)
    if lr_tolerance >= 0:
        back = np.take_along_axis(best_r, x - np.minimum(dbest, x), axis=1) & low
        consistent = np.abs(back - dbest) <= lr_tolerance
    else:
        consistent = np.ones((h, w), bool)

    # per-pixel window size (pixels) and its variance, for the noise margin
    nwin = np.asarray(windows, np.float32)[np.minimum(pick, len(windows) - 1)] ** 2
    vpick = _picked_variance(var, pick)
    if uniqueness > 0 or distinct > 0:
        secondc = (second >> nb).astype(np.float32)
        # ratio test, plus an absolute margin: on a flat (textureless) window
        # every disparity costs 2σ² ± σ²·sqrt(8/n) (noise only), so a winner
        # by less than `distinct` such deviations is chance, not a match
        margin = distinct * noise_var * np.sqrt(8.0 / nwin) * unit
        # windows holding little more than noise (variance < 2σ²) must win by
        # three times the margin: chance minima are what they mostly offer
        margin = np.where(vpick < 2 * tex_var, 3 * margin, margin)
        unique = (second == _INT_MAX) | ((secondc > bestc * (1 + uniqueness))
                                         & (secondc - bestc > margin))
    else:
        unique = np.ones((h, w), bool)

    has_texture = pick < len(windows)
    keep = valid & has_texture & unique & consistent
    disp = np.where(keep, disp, np.nan).astype(np.float32)
    counts = {"no_texture": int((valid & ~has_texture).sum()),
              "not_unique": int((valid & has_texture & ~unique).sum()),
              "left_right": int((valid & has_texture & unique & ~consistent).sum())}
    return disp, np.where(valid, bestc / unit, np.nan).astype(np.float32), counts


# ------------------------------------------- the precondition: a rectified pair
RECTIFIED_MIN_MATCHES = 12  # fewer feature matches confirm nothing


def vertical_offsets(left, right, *, max_features: int = 1500) -> dict:
    """Matched-feature offsets of a pair: median |Δy| and median Δx (px).

    ORB features matched with a cross-check and Lowe's ratio; a rectified
    pair has |Δy| ≈ 0 and Δx = d > 0.

    Returns
    -------
    dict
        ``matches`` (how many), and with at least 8 matches
        ``median_abs_dy``, ``p90_abs_dy`` and ``median_dx``.
    """
    import cv2

    def u8(a):
        g = luma_codes(a)
        lo, hi = float(g.min()), float(g.max())
        return np.clip((g - lo) * (255.0 / max(hi - lo, 1e-9)), 0, 255).astype(np.uint8)

    orb = cv2.ORB_create(max_features)
    k1, d1 = orb.detectAndCompute(u8(left), None)
    k2, d2 = orb.detectAndCompute(u8(right), None)
    if d1 is None or d2 is None or len(k1) < 2 or len(k2) < 2:
        return {"matches": 0}
    bf = cv2.BFMatcher(cv2.NORM_HAMMING)
    good = []
    for pair in bf.knnMatch(d1, d2, k=2):
        if len(pair) == 2 and pair[0].distance < 0.75 * pair[1].distance:
            good.append(pair[0])
    if len(good) < 8:
        return {"matches": len(good)}
    p1 = np.array([k1[m.queryIdx].pt for m in good])
    p2 = np.array([k2[m.trainIdx].pt for m in good])
    # keep matches consistent with one fundamental matrix (drops repeats)
    if len(good) >= 12:
        _, inl = cv2.findFundamentalMat(p1, p2, cv2.FM_RANSAC, 1.5, 0.999)
        if inl is not None and inl.sum() >= 8:
            keep = inl.ravel().astype(bool)
            p1, p2 = p1[keep], p2[keep]
    dy = p1[:, 1] - p2[:, 1]
    dx = p1[:, 0] - p2[:, 0]
    return {"matches": len(p1), "median_abs_dy": float(np.median(np.abs(dy))),
            "p90_abs_dy": float(np.percentile(np.abs(dy), 90)), "median_dx": float(np.median(dx))}


def check_rectified(left, right, *, remedy: str = "rectify the pair first") -> dict:
    """Refuse a pair that :func:`match` cannot use: not rectified (matched
    features offset vertically by more than 1 px, median) or swapped (the
    median ``x_left - x_right`` below -0.5 px).

    Parameters
    ----------
    left, right : ndarray, (H, W) or (H, W, C)
        The pair as it would be matched.
    remedy : str
        What to do about an unrectified pair, ending its message (a caller
        that can rectify says how).

    Returns
    -------
    dict
        :func:`vertical_offsets`; with fewer than ``RECTIFIED_MIN_MATCHES``
        matches nothing is confirmed (and nothing refused).

    Raises
    ------
    InputError
        Naming ``right``.
    """
    off = vertical_offsets(left, right)
    if off["matches"] >= RECTIFIED_MIN_MATCHES:
        if off["median_abs_dy"] > 1.0:
            raise InputError("right", "the pair is not rectified: matched features are offset "
                                      f"vertically by {off['median_abs_dy']:.1f} px (median "
                                      f"over {off['matches']}); {remedy}")
        if off["median_dx"] < -0.5:
            raise InputError("right", "matched features lie to the right in the right image "
                                      f"(median x_left - x_right = {off['median_dx']:.1f} px): "
                                      "are left and right swapped?")
    return off


# ------------------------------------------------------- the steps of match
def _check_modes(*, channels, prefilter, prefilter_cap):
    """Refuse an unknown ``channels`` or ``prefilter`` and a cap <= 0."""
    if channels not in CHANNELS:
        raise InputError("channels", f"expected one of {CHANNELS}, got {channels!r}")
    if prefilter not in PREFILTERS:
        raise InputError("prefilter", f"expected one of {PREFILTERS}, got {prefilter!r}")
    if not prefilter_cap > 0:
        raise InputError("prefilter_cap", f"expected a value > 0, got {prefilter_cap!r}")


def _check_lr_tolerance(lr_tolerance):
    if isinstance(lr_tolerance, bool) or not isinstance(lr_tolerance, int | np.integer) \
            or lr_tolerance < -1:
        raise InputError("lr_tolerance", f"expected an integer >= -1 (-1 disables the check), "
                                         f"got {lr_tolerance!r}")


def _check_options(left, right, *, channels, prefilter, prefilter_cap):
    """Refuse an unknown ``channels`` or ``prefilter``, a cap <= 0 and two
    images of different shapes (before any conversion)."""
    _check_modes(channels=channels, prefilter=prefilter, prefilter_cap=prefilter_cap)
    if np.shape(left) != np.shape(right):
        raise InputError("right", f"expected the left image's shape {np.shape(left)}, got {np.shape(right)}")


def _check_search(shape, *, max_disp, window, engine, texture_snr, uniqueness):
    """The search checked against the matched ``(C, H, W)`` planes' size:
    ``(max_disp, windows)``, the candidate window sides (one, or
    ``AUTO_WINDOWS`` for ``"auto"``)."""
    _, h, w = shape
    if not isinstance(max_disp, int | np.integer) or not 1 <= max_disp < w:
        raise InputError("max_disp", f"expected an integer in [1, {w - 1}] (image width {w}), "
                                     f"got {max_disp!r}")
    if window == "auto":
        windows = AUTO_WINDOWS
    elif (isinstance(window, int | np.integer) and window % 2 == 1
          and WINDOW_RANGE[0] <= window <= WINDOW_RANGE[1]):
        windows = (int(window),)
    else:
        raise InputError("window", f"expected 'auto' or an odd integer in [3, 63], got {window!r}")
    if min(h, w) < max(windows):
        raise InputError("left", f"image {w}x{h} is smaller than the window {max(windows)}")
    if engine not in ("auto", "numpy"):
        raise InputError("engine", f"expected 'auto' or 'numpy', got {engine!r}")
    for name, v in (("texture_snr", texture_snr), ("uniqueness", uniqueness)):
        if not v >= 0:  # NaN too
            raise InputError(name, f"expected a value >= 0, got {v!r}")
    return int(max_disp), windows


def check_match_options(image_shape, *, max_disp: int, window: int | str = "auto",
                        texture_snr: float = 1.0, uniqueness: float = 0.02,
                        channels: str = "luma", prefilter: str = "local-mean",
                        prefilter_cap: float = 31.0, engine: str = "auto",
                        lr_tolerance: int = 3) -> None:
    """Check :func:`match`'s options for images of ``image_shape`` before the
    pair is rectified or matched (``match`` checks them again itself).

    Parameters
    ----------
    image_shape : tuple
        ``(H, W)`` or ``(H, W, C)`` of the left image.
    max_disp, window, texture_snr, uniqueness, channels, prefilter, prefilter_cap, engine
        As for :func:`match`.

    Raises
    ------
    InputError
        Naming the argument: ``max_disp`` outside ``[1, W - 1]``, ``window``
        not ``"auto"`` or odd in [3, 63], an image smaller than the window,
        negative ``texture_snr``/``uniqueness``, an unknown mode,
        ``lr_tolerance`` not an integer >= -1.

    Examples
    --------
    >>> check_match_options((48, 64), max_disp=16, window=9)
    >>> check_match_options((48, 64), max_disp=64)
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: max_disp: expected an integer in [1, 63] (image width 64), got 64
    """
    _check_modes(channels=channels, prefilter=prefilter, prefilter_cap=prefilter_cap)
    _check_lr_tolerance(lr_tolerance)
    h, w = tuple(image_shape)[:2]
    _check_search((1, h, w), max_disp=max_disp, window=window, engine=engine,
                  texture_snr=texture_snr, uniqueness=uniqueness)


@dataclass(frozen=True)
class _Noise:
    """The noise the decision weighs against: ``sigma`` of the left luma
    (code values), ``scale`` and ``variance`` of what is matched (see
    :func:`_noise_var`) and the texture test's ``threshold`` (a window
    variance, code values²)."""

    sigma: float
    scale: float
    variance: float
    threshold: float


def _noise(left, gray, nch, *, texture_snr):
    """Estimate the left image's noise and set the texture threshold from it."""
    sigma = noise_sigma_smooth_blocks(gray)
    scale, variance = _noise_var(left, sigma, nch)
    # texture threshold: window variance >= snr² times the noise variance of
    # what is matched (σ² of the luma, or Σσ² of R, G, B); flat areas that pass on
    # noise alone are caught by the uniqueness and left-right tests (their
    # cost curve is flat and random).
    return _Noise(sigma, scale, variance, texture_snr ** 2 * variance)


def _texture_planes(left, gray, nch):
    """The float planes whose window variance the texture test weighs: the
    luma, or R, G and B when colour is matched."""
    if nch == 1:
        return [gray]
    return [np.ascontiguousarray(np.asarray(left)[..., c], dtype=np.float32) for c in range(3)]


def _span(L, R):
    """Range of the matched values over both images (at least 1): the float
    costs' scale."""
    return max(float(max(L.max(), R.max())) - float(min(L.min(), R.min())), 1.0)


def _padded(L, R, D):
    """Both images padded so that every disparity's view is a plain slice of
    width ``W + D``: left with ``D`` reflected columns on its right, right
    with ``D - 1`` replicated columns on its left and ``D`` on its right."""
    import cv2

    Lp = np.stack([cv2.copyMakeBorder(c, 0, 0, 0, D, cv2.BORDER_REFLECT) for c in L])
    Rp = np.stack([cv2.copyMakeBorder(c, 0, 0, D - 1, D, cv2.BORDER_REPLICATE) for c in R])
    return Lp, Rp


def _scan_decide_c(kernel, Lp, Rp, *, D, costs, var, pick, windows, n_threads, decide):
    """Scan and decide every row through the compiled kernel, one band of
    rows per thread: ``(disparity, cost, rejection counts)``."""
    _, h, wp = Lp.shape
    w = wp - D
    # one band per thread: each band start costs a window of rows
    n_bands = max(1, min(n_threads, h // max(costs.wins)))
    edges = np.linspace(0, h, n_bands + 1).astype(int)
    out = (np.empty((h, w), np.float32), np.empty((h, w), np.float32))
    Rr = np.ascontiguousarray(Rp[:, :, ::-1])
    vpick = _picked_variance(var, pick) if decide["distinct"] > 0 else None

    def one(i):
        return _match_c(kernel, Lp, Rr, edges[i], edges[i + 1], out, D=D, costs=costs,
                        pick=pick, vpick=vpick, windows=windows, **decide)

    if n_threads == 1 or n_bands == 1:
        parts = [one(i) for i in range(n_bands)]
    else:  # ctypes releases the GIL
        parts = list(_pool().map(one, range(n_bands)))
    c = sum(parts)
    counts = {"no_texture": int(c[0]), "not_unique": int(c[1]), "left_right": int(c[2])}
    return out[0], out[1], counts


def _scan_numpy_bands(Lp, Rp, *, D, costs, n_threads):
    """Scan every row on numpy/OpenCV in bands of about ``BAND_ROWS`` rows:
    the five encoded ``(H, W)`` int32 arrays :func:`_decide` reads."""
    h = Lp.shape[1]
    # bands of about BAND_ROWS rows keep each disparity's working set in the
    # CPU cache; threads take bands in turn, each with its own scratch volume
    n_bands = max(1, round(h / BAND_ROWS))
    edges = np.linspace(0, h, n_bands + 1).astype(int)

    def one(i):
        with _scratch() as scratch:
            return _scan_numpy(Lp, Rp, edges[i], edges[i + 1], D=D, costs=costs, scratch=scratch)

    if n_threads == 1 or n_bands == 1:
        parts = [one(i) for i in range(n_bands)]
    else:
        from concurrent.futures import ThreadPoolExecutor

        import cv2

        old = cv2.getNumThreads()
        try:
            cv2.setNumThreads(1)  # our bands are the parallelism
            with ThreadPoolExecutor(min(n_threads, n_bands)) as ex:
                parts = list(ex.map(one, range(n_bands)))
        finally:
            cv2.setNumThreads(old)
    return [np.concatenate([p[j] for p in parts]) for j in range(5)]


def _info(disp, pick, counts, windows, *, noise, nch, engine, timings, max_disp, window,
          texture_snr, uniqueness, distinct, lr_tolerance, subpixel, prefilter, prefilter_cap):
    """The result's record: parameters, the noise estimate, the share of
    pixels each test rejected and, for ``window="auto"``, each window's share."""
    h, w = pick.shape
    n = h * w
    info = {"method": "ssd-block-matching", "max_disp": max_disp, "window": window,
            "texture_snr": texture_snr, "uniqueness": uniqueness, "distinct": distinct, "lr_tolerance": lr_tolerance,
            "subpixel": subpixel, "channels": "rgb" if nch == 3 else "luma", "prefilter": prefilter, "prefilter_cap": prefilter_cap,
            "noise_sigma_estimate": noise.sigma, "texture_threshold_var": noise.threshold,
            "rejected_fraction": {k: v / n for k, v in counts.items()},
            "valid_fraction": float(np.isfinite(disp).mean()),
            "engine": engine, "timings_s": timings}
    if window == "auto":
        picks = np.bincount(pick.ravel(), minlength=len(windows) + 1)
        info["auto"] = {"candidates": list(windows),
                        "share_of_pixels": {str(k): float(picks[i] / n) for i, k in enumerate(windows)},
                        "no_window_textured": float(picks[-1] / n),
                        "rule": "smallest window whose intensity std >= texture_snr * noise sigma"
                                + (" (summed over R, G, B)" if nch == 3 else "")}
    return info


# ------------------------------------------------------------------- match


def match(left: np.ndarray, right: np.ndarray, *, max_disp: int, window: int | str = "auto",
          texture_snr: float = 1.0, uniqueness: float = 0.02, lr_tolerance: int = 3,
          distinct: float = 0.0, subpixel: bool = True, channels: str = "luma",
          prefilter: str = "local-mean", prefilter_cap: float = 31.0, threads: int | None = None,
          engine: str = "auto", device="cpu") -> DisparityMap:
    """Dense disparity of a rectified pair by SSD block matching (eq. 5.1).

    Parameters
    ----------
    left, right : ndarray, (H, W) or (H, W, 3)
        Rectified images (any numeric dtype, same shape); left is the reference.
    max_disp : int, keyword-only
        Largest disparity searched (pixels); disparities ``0..max_disp``.
    window : int or "auto"
        Odd window side (3..63), or ``"auto"``: per pixel the smallest of
        ``AUTO_WINDOWS`` = (5, 9, 15) whose texture passes the test.
    texture_snr : float
        A window must have an intensity standard deviation ≥ ``texture_snr ·
        σ``, ``σ`` the noise estimated from the left image (0 disables).
    uniqueness : float
        Keep a match only if every disparity outside ``d ± 1`` costs more than
        ``(1 + uniqueness)`` times the best (0 disables).
    distinct : float
        The runner-up must also cost at least ``distinct · σ² · sqrt(8/n)``
        more than the best (``n`` window pixels): the spread of costs that
        noise alone produces on a flat window (0 disables).
    lr_tolerance : int
        Largest left–right disagreement in pixels (−1 disables the check).
        The defaults of these four were chosen on the rendered ``stereo-pair``
        scenes only (``docs/decisions/stereo-block-matching-defaults.md``);
        the Middlebury pairs of the bench are held out.
    subpixel : bool
        Parabola refinement of the integer minimum.
    channels : {"color", "luma"}
        What the SSD compares on colour inputs: ``"luma"`` (Rec. 601 luma) or
        ``"color"``, the squared differences of R, G and B summed (eq. 5.1
        per channel), which tells apart surfaces of equal luma but different
        hue. Grey inputs are luma either way. Luma is the default: colour
        lowered bad-2.0 on the rendered pairs a little but makes a match up
        to 1.8x slower (``docs/decisions/stereo-block-matching-defaults.md``).
        The texture test always uses luma.
    prefilter : {"none", "local-mean"}
        ``"local-mean"`` matches each image's difference from its 9×9 local
        mean, clipped to ``±prefilter_cap`` (the normalised-response prefilter
        of OpenCV's StereoBM), the right view's response scaled by the ratio
        of the two views' median absolute responses: an offset and a gain
        between the views (exposure, tone curve) cancel, at the price of
        low-frequency signal. The default: it lowered bad-2.0 on the tuned
        real pairs (Middlebury 2001/2003) and beats StereoBM on every pair of
        the bench, while ``"none"`` does better on our rendered pairs, which
        share one exposure (``docs/decisions/stereo-block-matching-defaults.md``).
    prefilter_cap : float
        Clipping of the local-mean response, in 8-bit code values (scaled to
        the input's range for other dtypes).
    threads : int, optional
        Row bands matched in parallel (OpenCV and numpy release the GIL);
        default: the number of CPUs, at most 4.
    engine : {"auto", "numpy"}
        ``"auto"`` scans 8-bit pairs with the compiled kernel
        (``stereo/_ssd.c``) when it was built, else with numpy/OpenCV;
        ``"numpy"`` forces the latter. Both give identical results; float
        inputs always take the numpy path. ``info["engine"]`` says which ran
        and ``info["timings_s"]`` the time per phase (prepare: luma, noise,
        texture; scan; decide: what is left after the scan).
    device : {"cpu", "cuda", "torch-cpu", "auto"}
        Where the scan (cost volume, box aggregation, best and runner-up
        per pixel) runs (:mod:`lumigraph.capture.device`): ``"cpu"`` as
        ``engine`` says; the others :mod:`lumigraph.stereo.block_matching_torch`
        (``info["engine"]`` then names the device). 8-bit pairs give
        identical results; float pairs agree to float32 rounding of the
        window sums (a cost unit, so a near-tie may fall the other way).
        The decision stays on numpy.

    Returns
    -------
    DisparityMap

    Raises
    ------
    InputError
        Naming the argument: shapes differ, images too small, bad window or
        ``max_disp`` (:func:`check_match_options` checks the options alone,
        before the images are at hand).
    """
    t0 = time.perf_counter()
    from lumigraph.capture.device import resolve_device

    dev = resolve_device(device)
    # validate, and the images as compared (planes) and as tested for texture (luma)
    _check_options(left, right, channels=channels, prefilter=prefilter, prefilter_cap=prefilter_cap)
    _check_lr_tolerance(lr_tolerance)
    L, R, gray, code = _match_images(left, right, channels=channels, prefilter=prefilter,
                                     cap=prefilter_cap)
    nch = L.shape[0]
    max_disp, windows = _check_search(L.shape, max_disp=max_disp, window=window, engine=engine,
                                      texture_snr=texture_snr, uniqueness=uniqueness)
    # noise, texture test and window choice per pixel
    noise = _noise(left, gray, nch, texture_snr=texture_snr)
    var, pick = _texture(_texture_planes(left, gray, nch), windows,
                         tuple(noise.threshold for _ in windows))
    # integer cost encoding and padded images for the scan
    D = max_disp + 1
    costs = _costs(windows, pick, D=D, integer=L.dtype == np.uint16, span=_span(L, R), nch=nch,
                   code=code)
    Lp, Rp = _padded(L, R, D)
    n_threads = threads or default_threads()
    kernel = _kernel() if costs.integer and engine != "numpy" and not dev.uses_torch else None
    t1 = time.perf_counter()
    # scan every disparity, then decide: sub-pixel, uniqueness, left-right, texture
    decide = dict(subpixel=subpixel, lr_tolerance=lr_tolerance, uniqueness=uniqueness,
                  distinct=distinct, noise_var=noise.scale, tex_var=noise.variance)
    if kernel is not None:  # the compiled kernel fuses the decision into the scan
        disp, cost, counts = _scan_decide_c(kernel, Lp, Rp, D=D, costs=costs, var=var, pick=pick,
                                            windows=windows, n_threads=n_threads, decide=decide)
        t2 = time.perf_counter()
    else:
        if dev.uses_torch:
            from lumigraph.stereo import block_matching_torch

            scan = block_matching_torch.scan(Lp, Rp, D=D, costs=costs, device=dev)
        else:
            scan = _scan_numpy_bands(Lp, Rp, D=D, costs=costs, n_threads=n_threads)
        t2 = time.perf_counter()
        disp, cost, counts = _decide(*scan, var=var, pick=pick, windows=windows, costs=costs,
                                     D=D, **decide)
    # the result and its record
    win = np.asarray((*windows, 0), np.uint8)[pick]
    timings = {"prepare": t1 - t0, "scan": t2 - t1, "decide": time.perf_counter() - t2}
    info = _info(disp, pick, counts, windows, noise=noise, nch=nch,
                 engine=dev.name if dev.uses_torch else "numpy" if kernel is None else "c",
                 timings=timings, max_disp=max_disp,
                 window=window, texture_snr=texture_snr, uniqueness=uniqueness, distinct=distinct,
                 lr_tolerance=lr_tolerance, subpixel=subpixel, prefilter=prefilter,
                 prefilter_cap=prefilter_cap)
    return DisparityMap(disp, cost, win, info)
