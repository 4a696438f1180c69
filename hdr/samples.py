"""Choosing the pixels a response fit uses, and checking a bracket's inputs.

Response methods need a few hundred pixels whose codes trace the curve over
the whole code range. :func:`sample_pixels` picks them on principle, not at
random: pixels in smooth regions (small local gradient, so a sub-pixel
misregistration or blur does not mix radiances), spread evenly over radiance
(stratified by the sum of codes across the bracket, which rises with
radiance whatever the response is) and over the image, and seen unclipped in
at least two exposures.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> e = np.exp(rng.uniform(-4, 1, (20, 30, 1)))
>>> stack = np.stack([np.clip(e * t * 255, 0, 255).astype(np.uint8) for t in (0.2, 1.0)])
>>> idx = sample_pixels(stack, n=50, bit_depth=8, rng=rng)
>>> idx.shape, bool(np.unique(idx).size == idx.size)
((50,), True)
"""

from __future__ import annotations

import math

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.capture.exposure import check_exposure_times


def check_stack(images: np.ndarray, exposure_times_s, *, bit_depth: int | None,
                where: str = "images", distinct_times: bool = True) -> tuple[np.ndarray, np.ndarray, int]:
    """Validate a bracket: ``(P, H, W, C)`` integer codes and ``P`` times.

    Returns the stack (as given, with a channel axis), the times as float64
    and the bit depth (inferred from the dtype when ``None``). The times are
    checked by :func:`capture.exposure.check_exposure_times`: a bracket needs
    every time distinct; a video of alternating exposures repeats them
    (``distinct_times=False``).

    Raises
    ------
    TypeError
        Non-integer codes.
    InputError
        Wrong shape, codes beyond the bit depth; times (naming
        ``exposure_times_s``) not one per image, not positive, or duplicated.
    """
    z = np.asarray(images)
    if z.ndim == 3:
        z = z[..., None]
    if z.ndim != 4:
        raise InputError(where, f"expected a stack (P, H, W, C), got shape {z.shape}")
    if z.dtype.kind not in "ui":
        raise TypeError(f"images: expected integer code values, got {z.dtype}")
    bd = int(bit_depth) if bit_depth is not None else 8 * z.dtype.itemsize
    if not 1 <= bd <= 16:
        raise InputError(where, f"bit depth must be 1..16, got {bd}")
    if z.size and int(z.max()) >= 2 ** bd:
        raise InputError(where, f"codes up to {int(z.max())} exceed bit depth {bd}")
    t = check_exposure_times(exposure_times_s, z.shape[0], distinct=distinct_times)
    return z, t, bd


MIN_SAMPLES = 2  # pixels a response fit samples at least


def check_samples(samples: int) -> int:
    """The number of pixels a response fit samples (its ``samples``
    argument): at least :data:`MIN_SAMPLES`.

    Raises
    ------
    InputError
        Naming ``samples``.

    Examples
    --------
    >>> check_samples(600)
    600
    >>> try:
    ...     check_samples(1)
    ... except InputError as e:
    ...     print(e)
    samples: expected at least 2 pixels, got 1
    """
    if samples < MIN_SAMPLES:
        raise InputError("samples", f"expected at least {MIN_SAMPLES} pixels, got {samples}")
    return samples


def hat_weight(z: np.ndarray, bit_depth: int) -> np.ndarray:
    """Debevec–Malik's triangle weight ω(z) (reference ch. 6, after eq. 6.5),
    normalised to peak 1, zero at codes 0 and ``z_max``.

    Examples
    --------
    >>> hat_weight(np.array([0, 64, 127, 128, 255]), 8).round(3).tolist()
    [0.0, 0.504, 1.0, 1.0, 0.0]
    """
    zmax = 2 ** bit_depth - 1
    z = np.asarray(z, dtype=np.float64)
    half = zmax / 2.0
    return np.clip(np.minimum(z, zmax - z) / np.floor(half), 0.0, 1.0)


def candidate_grid(h: int, w: int, n: int) -> int:
    """Stride of the pixel grid :func:`sample_pixels` draws from: every pixel
    while the image has at most ``16 n`` of them, else every ``s``-th row and
    column so that about ``16 n`` remain.

    Why: the fit uses ``n`` pixels; ranking every pixel of a 12 MP bracket to
    pick 600 costs time and memory in proportion to all pixels of all frames
    (the iPhone set needed 2.4 GB). A regular grid 16× denser than the pick
    still offers each of the 64 radiance strata ~16 candidates per pick.

    Examples
    --------
    >>> candidate_grid(120, 160, 600), candidate_grid(768, 512, 600), candidate_grid(4032, 3024, 600)
    (1, 6, 35)
    """
    return max(1, int(math.sqrt(h * w / (16.0 * max(n, 1)))))


COARSE_ZMAX = 255  # the pick reads codes at 8-bit resolution (one step = z_max / 255)


def _coarse(codes: np.ndarray, zmax: int) -> np.ndarray:
    """Codes rounded to steps of ``zmax / 255`` (:data:`COARSE_ZMAX`), i.e.
    read as 8-bit codes ``round(z · 255 / z_max)``; codes of 8 bits or fewer
    are returned as they are.

    Examples
    --------
    >>> _coarse(np.array([0, 128, 129, 4095], np.uint16), 4095).tolist()
    [0, 8, 8, 255]
    >>> _coarse(np.array([7, 200], np.uint8), 255).tolist()
    [7, 200]
    """
    if zmax <= COARSE_ZMAX:
        return codes
    # floor(z·255/z_max + 1/2) in integers (exact; int64 holds 65535·510)
    return (codes.astype(np.int64) * (2 * COARSE_ZMAX) + zmax) // (2 * zmax)


def sample_pixels(images: np.ndarray, *, n: int, bit_depth: int, rng: np.random.Generator,
                  margin: float = 0.02) -> np.ndarray:
    """Flat pixel indices (into ``H·W``) of ``n`` pixels for a response fit.

    Candidates are the pixels of a regular grid (:func:`candidate_grid`;
    every pixel for small images), so time and memory scale with ``n``, not
    with the frames' size: only the grid's codes are copied. Smoothness is
    the range of the channel-mean codes in the 3×3 neighbourhood (full
    resolution) of the frame with the most mid-range codes.

    Codes deeper than 8 bits are read at 8-bit resolution for the choice
    (rounded to steps of ``z_max / 255``): the clipping test, the smoothness
    and the radiance strata. Why: which pixels are picked is a draw, and a
    fit's error over the pick scatters by 5–15 % between draws (walls kind,
    one scene: 15 % between sampling seeds), more than the 1–3 % a finer
    quantisation can buy (``docs/decisions/hdr-debevec-noise.md``). Read at
    one resolution, the same scene gets the same pick whether it was stored
    in 8, 12 or 16 bits, so a deeper file's fit differs from the 8-bit one
    only by what its codes add. Exact ranking at 16 bits was no better a
    pick in expectation (24 scenes per kind, the 16-bit pick ÷ the 8-bit
    pick fitted to the same 8-bit data: 0.97–1.03 ± 0.01–0.02).

    Parameters
    ----------
    images : ndarray, ``(P, H, W, C)`` integer codes
    n : int
        Pixels wanted (fewer are returned only if fewer qualify).
    bit_depth : int
    rng : numpy.random.Generator
        Breaks ties within a radiance stratum (deterministic under a seed);
        one draw per grid pixel, so the draws do not depend on which pixels
        qualify.
    margin : float
        Codes within ``margin·z_max`` of 0 or ``z_max`` count as clipped
        (judged on the 8-bit reading of deeper codes).

    Returns
    -------
    ndarray of int64, ``(m,)``, ``m <= n``, unique, sorted by radiance.

    Raises
    ------
    InputError
        When fewer than 8 pixels are unclipped in two exposures.
    """
    p, h, w, c = images.shape
    zmax = 2 ** bit_depth - 1
    # Deeper codes are chosen from at 8-bit resolution (see the docstring): the
    # same analog bracket then gets the same pick at every depth.
    zq = min(zmax, COARSE_ZMAX)
    st = candidate_grid(h, w, n)
    ys = np.arange(st // 2, h, st)
    xs = np.arange(st // 2, w, st)
    # Rows first (contiguous runs), then columns of the small copy: a strided
    # 4-D copy in one step walks every element slowly.
    rows = np.ascontiguousarray(images[:, st // 2::st])
    sub = np.ascontiguousarray(rows[:, :, st // 2::st])  # (P, h', w', C), small
    del rows
    sub = _coarse(sub, zmax)
    z = sub.reshape(p, -1, c)
    lo, hi = margin * zq, (1 - margin) * zq
    zlo, zhi = z[..., 0], z[..., 0]
    for k in range(1, c):  # channel min and max (a reduction over a short last axis is slow)
        zlo, zhi = np.minimum(zlo, z[..., k]), np.maximum(zhi, z[..., k])
    inr = (zlo > lo) & (zhi < hi)  # (P, M): every channel in range
    ok = inr.sum(axis=0)
    cand = np.flatnonzero(ok >= min(2, p))
    if cand.size < 8:
        raise InputError("images", f"only {cand.size} pixels are unclipped in two exposures; "
                                   "the bracket does not constrain a response (add exposures "
                                   "between the ones given)")
    # Smoothness from the frame with the most mid-range codes, at full resolution:
    # a sub-pixel misregistration or blur mixes radiances only where codes vary.
    ref = int(np.argmax(inr.sum(axis=1)))
    img = images[ref]
    gy, gx = np.divmod(cand, xs.size)
    py, px = ys[gy], xs[gx]
    flat = img.reshape(-1, c)
    vmin = vmax = None
    for dy in (-1, 0, 1):
        row = np.clip(py + dy, 0, h - 1) * w
        for dx in (-1, 0, 1):
            px_ = _coarse(flat[row + np.clip(px + dx, 0, w - 1)], zmax)  # (M, C)
            v = px_[:, 0].astype(np.int32)
            for k in range(1, c):
                v += px_[:, k]
            vmin = v if vmin is None else np.minimum(vmin, v)
            vmax = v if vmax is None else np.maximum(vmax, v)
    g = (vmax - vmin) / (c * zq)
    # Prefer smooth pixels: keep the smoother part of each radiance stratum.
    tot = sub.reshape(p, -1, c).sum(axis=0, dtype=np.int64)[cand]  # (M, C)
    s = tot.sum(axis=1) / c
    nbins = max(8, min(n, 64))
    edges = np.linspace(s.min(), s.max() + 1e-9, nbins + 1)
    b = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, nbins - 1)
    # Rank within a stratum by local range (jittered so ties spread spatially).
    # One draw per grid pixel, not per candidate: a code that crosses the
    # clipping margin then changes only its own pixel's candidacy, not every
    # later candidate's jitter (nor the generator's state after the pick).
    m = ys.size * xs.size
    key = g * (1.0 + 0.25 * rng.random(m)[cand]) + 1e-6 * rng.random(m)[cand]
    order = np.lexsort((key, b))
    bs = b[order]
    start = np.searchsorted(bs, np.arange(nbins))
    rank = np.arange(order.size) - start[bs]
    counts = np.bincount(bs, minlength=nbins)
    # Equal quota per non-empty stratum; spare quota goes to the next ranks.
    quota = int(np.ceil(n / max(np.count_nonzero(counts), 1)))
    for _ in range(4):
        take = order[rank < quota]
        if take.size >= n or quota >= counts.max():
            break
        quota = int(np.ceil(quota * n / max(take.size, 1))) + 1
    sel = rank < quota
    take = order[sel]
    if take.size > n:
        # Trim the roughest picks first (largest rank), keeping every stratum.
        take = take[np.argsort(rank[sel], kind="stable")[:n]]
    take = take[np.argsort(s[take], kind="stable")]  # by radiance
    return (py[take] * w + px[take]).astype(np.int64)
