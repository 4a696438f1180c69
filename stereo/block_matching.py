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

import math
import os
from dataclasses import dataclass, field

import numpy as np

AUTO_WINDOWS = (5, 9, 15)
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
        if np.any(d[np.isfinite(d)] < 0):
            raise ValueError("disparity: values must be >= 0 (x_right = x_left - d)")
        for name in ("cost", "window"):
            if np.asarray(getattr(self, name)).shape != d.shape:
                raise ValueError(f"{name}: expected shape {d.shape}, got {np.shape(getattr(self, name))}")

    @property
    def valid_fraction(self) -> float:
        return float(np.isfinite(self.disparity).mean())

    def save(self, path, *, meta: dict) -> None:
        """Write the disparity as PFM (NaN stored as inf) with its sidecar."""
        from capture.artifact import write_artifact
        from capture.io import write_pfm

        write_artifact(path, lambda tmp: write_pfm(tmp, self.disparity), meta=meta)


# ------------------------------------------------------------------- helpers
def to_gray(image: np.ndarray) -> np.ndarray:
    """Luma ``(H, W)`` float32 in the image's own code units (Rec. 601 weights)."""
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] in (3, 4):
        a = a[..., :3].astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)
    elif a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    elif a.ndim != 2:
        raise ValueError(f"image: expected (H, W) or (H, W, 1|3|4), got shape {a.shape}")
    return np.ascontiguousarray(a, dtype=np.float32)


def noise_sigma(gray: np.ndarray) -> float:
    """Robust estimate of the sensor noise σ (code values) of one image.

    The 3×3 mask ``[[1,-2,1],[-2,4,-2],[1,-2,1]]`` cancels smooth image content
    and passes white noise with gain 6 (Immerkær 1996). Its mean absolute
    response is taken over 8×8 blocks and the 10th percentile of the blocks
    kept: the smoothest parts of a scene show the noise alone, where a global
    average would count texture and edges as noise.

    Examples
    --------
    >>> g = np.full((64, 64), 100.0) + np.random.default_rng(1).normal(0, 2, (64, 64))
    >>> round(noise_sigma(g.astype(np.float32)), 1)
    2.0
    """
    import cv2

    k = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    r = np.abs(cv2.filter2D(gray, cv2.CV_32F, k)[1:-1, 1:-1])
    h, w = (r.shape[0] // 8) * 8, (r.shape[1] // 8) * 8
    if h == 0 or w == 0:
        return float(np.sqrt(np.pi / 2) * r.mean() / 6.0)
    blocks = r[:h, :w].reshape(h // 8, 8, w // 8, 8).mean(axis=(1, 3))
    # blocks near black or white are clipped (less noise than the sensor's):
    # leave them out
    level = gray[1:h + 1, 1:w + 1].reshape(h // 8, 8, w // 8, 8).mean(axis=(1, 3))
    lo, hi = float(gray.min()), float(gray.max())
    ok = (level > lo + 0.04 * (hi - lo)) & (level < hi - 0.04 * (hi - lo))
    if ok.sum() >= 10:
        blocks = blocks[ok]
    # mean |N(0, s)| = s·sqrt(2/π); the 10th percentile of 8×8 block means of
    # pure noise sits at 0.785 of their mean (measured; the mask's responses
    # are correlated), hence 1/0.785
    return float(np.sqrt(np.pi / 2) * np.percentile(blocks, 10) / 6.0 / 0.785)


def _band(left, right, y0, y1, *, max_disp, windows, thresholds, uniqueness, lr_tolerance,
          subpixel, distinct, noise_var):
    """Match rows ``y0:y1``; ``left``/``right`` carry a margin of rows so box
    filters see real neighbours. Returns per-pixel arrays for the band."""
    import cv2

    margin = max(windows) // 2
    a0, a1 = max(0, y0 - margin), min(left.shape[0], y1 + margin)
    L = left[a0:a1]
    h, w = L.shape
    D = max_disp + 1
    nb = max(1, math.ceil(math.log2(D)))
    low = np.int32((1 << nb) - 1)
    # Right image padded on the left by replicating its first column, so that
    # the shifted view for disparity d is a plain slice (cost for x < d is
    # invalidated below: those pixels have no partner inside the right image).
    Rp = cv2.copyMakeBorder(right[a0:a1], 0, 0, D - 1, 0, cv2.BORDER_REPLICATE)

    # texture: window variance of the left image, per candidate window
    var = []
    for win in windows:
        m = cv2.boxFilter(L, -1, (win, win), borderType=cv2.BORDER_REFLECT)
        m2 = cv2.sqrBoxFilter(L, cv2.CV_32F, (win, win), borderType=cv2.BORDER_REFLECT)
        var.append(m2 - m * m)
    textured = [v >= t for v, t in zip(var, thresholds, strict=True)]
    # smallest textured window per pixel; index len(windows) = none
    pick = np.full((h, w), len(windows), np.uint8)
    for k in range(len(windows) - 1, -1, -1):
        pick[textured[k]] = k
    masks = [(pick == k).astype(np.uint8) for k in range(len(windows))]

    # Cost volume, int32-encoded: the bit pattern of a non-negative float32 is
    # monotone in its value, so (bits & ~low) | d sorts by cost and carries its
    # disparity in the low bits: one integer min gives the argmin (relative
    # cost resolution 2^-(23-nb), far below the noise).
    costs = np.empty((D, h, w), np.float32)
    for d in range(D):
        diff = cv2.subtract(L, Rp[:, D - 1 - d: D - 1 - d + w])
        cv2.sqrBoxFilter(diff, cv2.CV_32F, (windows[-1], windows[-1]), dst=costs[d],
                         borderType=cv2.BORDER_REFLECT)
        for k in range(len(windows) - 1):
            ck = cv2.sqrBoxFilter(diff, cv2.CV_32F, (windows[k], windows[k]),
                                  borderType=cv2.BORDER_REFLECT)
            cv2.copyTo(ck, masks[k], costs[d])
    # Extra INT_MAX columns let the right view's sheared volume (x_r + d) be a
    # strided view of the same memory.
    full = np.empty((D, h, w + D), np.int32)
    full[:, :, w:] = _INT_MAX
    vol = full[:, :, :w]
    np.bitwise_and(costs.view(np.int32), ~low, out=vol)
    # code[d, x] = d where the right image has a partner pixel (x >= d), else
    # all ones (OR gives INT_MAX: never chosen)
    dd = np.arange(D)[:, None]
    code = np.where(np.arange(w)[None, :] >= dd, dd, _INT_MAX).astype(np.int32)[:, None, :]
    np.bitwise_or(vol, code, out=vol)
    del costs
    best = vol.min(axis=0)
    dbest = (best & low).astype(np.int64)
    valid = best != _INT_MAX
    bestc = (best & ~low).view(np.float32)

    # sub-pixel: parabola through d-1, d, d+1
    dm = np.clip(dbest - 1, 0, D - 1)[None]
    dp = np.clip(dbest + 1, 0, D - 1)[None]
    cm = (np.take_along_axis(vol, dm, 0)[0] & ~low).view(np.float32)
    cp = (np.take_along_axis(vol, dp, 0)[0] & ~low).view(np.float32)
    inner = (dbest > 0) & (dbest < D - 1) & (np.take_along_axis(vol, dm, 0)[0] != _INT_MAX)
    disp = dbest.astype(np.float32)
    if subpixel:
        with np.errstate(divide="ignore", invalid="ignore"):
            curv = cm - 2 * bestc + cp
            delta = np.where(inner & (curv > 0), 0.5 * (cm - cp) / curv, 0.0)
        disp = disp + np.clip(delta, -0.5, 0.5).astype(np.float32)

    # left-right: best disparity of each right pixel from the sheared volume
    if lr_tolerance >= 0:
        from numpy.lib.stride_tricks import as_strided

        volR = as_strided(full, shape=(D, h, w), strides=(full.strides[0] + full.strides[2],
                                                          full.strides[1], full.strides[2]),
                          writeable=False)
        dR = (volR.min(axis=0) & low).astype(np.int64)
        xr = np.clip(np.arange(w)[None, :] - dbest, 0, w - 1)
        back = np.take_along_axis(dR, xr, 1)
        consistent = np.abs(back - dbest) <= lr_tolerance
    else:
        consistent = np.ones((h, w), bool)

    # uniqueness: best outside d-1..d+1 (after the left-right check: this
    # overwrites the volume)
    if uniqueness > 0 or distinct > 0:
        for off in (-1, 0, 1):
            idx = np.clip(dbest + off, 0, D - 1)[None]
            np.put_along_axis(vol, idx, _INT_MAX, 0)
        second = vol.min(axis=0)
        secondc = (second & ~low).view(np.float32)
        # ratio test, plus an absolute margin: on a flat (textureless) window
        # every disparity costs 2σ² ± σ²·sqrt(8/n) (noise only), so a winner
        # by less than `distinct` such deviations is chance, not a match
        nwin = np.asarray(windows, np.float32)[np.minimum(pick, len(windows) - 1)] ** 2
        margin = distinct * noise_var * np.sqrt(8.0 / nwin)
        # windows holding little more than noise (variance < 2σ²) must win by
        # three times the margin: chance minima are what they mostly offer
        vpick = var[0].copy()
        for k in range(1, len(windows)):
            np.copyto(vpick, var[k], where=pick == k)
        margin = np.where(vpick < 2 * noise_var, 3 * margin, margin)
        unique = (second == _INT_MAX) | ((secondc > bestc * (1 + uniqueness))
                                         & (secondc - bestc > margin))
    else:
        unique = np.ones((h, w), bool)

    has_texture = pick < len(windows)
    keep = valid & has_texture & unique & consistent
    disp = np.where(keep, disp, np.nan).astype(np.float32)
    win_arr = np.where(has_texture, np.asarray(windows, np.uint8)[np.minimum(pick, len(windows) - 1)], 0)
    s = slice(y0 - a0, y0 - a0 + (y1 - y0))
    counts = {"no_texture": int((valid & ~has_texture)[s].sum()),
              "not_unique": int((valid & has_texture & ~unique)[s].sum()),
              "left_right": int((valid & has_texture & unique & ~consistent)[s].sum())}
    picks = np.bincount(pick[s].ravel(), minlength=len(windows) + 1)
    return disp[s], np.where(valid, bestc, np.nan)[s], win_arr[s].astype(np.uint8), counts, picks


def match(left: np.ndarray, right: np.ndarray, *, max_disp: int, window: int | str = "auto",
          texture_snr: float = 0.5, uniqueness: float = 0.02, lr_tolerance: int = 2,
          distinct: float = 0.2, subpixel: bool = True,
          threads: int | None = None) -> DisparityMap:
    """Dense disparity of a rectified pair by SSD block matching (eq. 5.1).

    Parameters
    ----------
    left, right : ndarray, (H, W) or (H, W, 3)
        Rectified images (any numeric dtype, same shape); left is the reference.
        Colour is reduced to luma.
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
    subpixel : bool
        Parabola refinement of the integer minimum.
    threads : int, optional
        Row bands matched in parallel (OpenCV and numpy release the GIL);
        default: the number of CPUs, at most 4.

    Returns
    -------
    DisparityMap

    Raises
    ------
    ValueError
        Shapes differ, images too small, bad window or ``max_disp``.
    """
    import cv2

    L, R = to_gray(left), to_gray(right)
    if L.shape != R.shape:
        raise ValueError(f"right: expected the left image's shape {L.shape}, got {R.shape}")
    h, w = L.shape
    if not isinstance(max_disp, int | np.integer) or not 1 <= max_disp < w:
        raise ValueError(f"max_disp: expected an integer in [1, {w - 1}] (image width {w}), got {max_disp!r}")
    max_disp = int(max_disp)
    if window == "auto":
        windows, choose = AUTO_WINDOWS, True
    elif isinstance(window, int | np.integer) and window % 2 == 1 and 3 <= window <= 63:
        windows, choose = (int(window),), False
    else:
        raise ValueError(f"window: expected 'auto' or an odd integer in [3, 63], got {window!r}")
    if min(h, w) < max(windows):
        raise ValueError(f"left: image {w}x{h} is smaller than the window {max(windows)}")
    if texture_snr < 0 or uniqueness < 0:
        raise ValueError("texture_snr, uniqueness: expected values >= 0")
    sigma = noise_sigma(L)
    # texture threshold: window variance >= (snr·σ)², σ floored at half a code
    # value (quantisation alone gives σ ≈ 0.29). The noise estimate reads high
    # on finely textured images, so the default snr is modest; flat areas
    # that pass on noise alone are caught by the uniqueness and left-right
    # tests (their cost curve is flat and random).
    thr = (texture_snr * max(sigma, 0.5)) ** 2
    thresholds = tuple(thr for _ in windows)
    n_threads = threads or min(4, os.cpu_count() or 1)
    n_bands = max(1, min(n_threads, h // 32))
    edges = np.linspace(0, h, n_bands + 1).astype(int)
    kw = dict(max_disp=max_disp, windows=windows, thresholds=thresholds, distinct=distinct,
              noise_var=max(sigma, 0.5) ** 2,
              uniqueness=uniqueness, lr_tolerance=lr_tolerance, subpixel=subpixel)
    old = cv2.getNumThreads()
    try:
        if n_bands == 1:
            parts = [_band(L, R, 0, h, **kw)]
        else:
            from concurrent.futures import ThreadPoolExecutor

            cv2.setNumThreads(1)  # our bands are the parallelism
            with ThreadPoolExecutor(n_bands) as ex:
                parts = list(ex.map(lambda i: _band(L, R, edges[i], edges[i + 1], **kw),
                                    range(n_bands)))
    finally:
        cv2.setNumThreads(old)
    disp = np.concatenate([p[0] for p in parts])
    cost = np.concatenate([p[1] for p in parts])
    win = np.concatenate([p[2] for p in parts])
    counts = {k: sum(p[3][k] for p in parts) for k in parts[0][3]}
    picks = sum(p[4] for p in parts)
    n = h * w
    info = {"method": "ssd-block-matching", "max_disp": max_disp, "window": window,
            "texture_snr": texture_snr, "uniqueness": uniqueness, "distinct": distinct, "lr_tolerance": lr_tolerance,
            "subpixel": subpixel, "noise_sigma_estimate": sigma, "texture_threshold_var": thr,
            "rejected_fraction": {k: v / n for k, v in counts.items()},
            "valid_fraction": float(np.isfinite(disp).mean())}
    if choose:
        info["auto"] = {"candidates": list(windows),
                        "share_of_pixels": {str(k): float(picks[i] / n) for i, k in enumerate(windows)},
                        "no_window_textured": float(picks[-1] / n),
                        "rule": "smallest window whose intensity std >= texture_snr * noise sigma"}
    return DisparityMap(disp, cost, win, info)
