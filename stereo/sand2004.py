"""Sand & Teller 2004, "Video Matching" (ACM TOG 23(3), doi:10.1145/1015706.1015765),
as reference §5.1.4 (Figs. 5.6, 5.7) describes it.

Correspondence between two takes of a similar scene that differ in lighting,
in added or removed objects and by a small camera shift. The paper's
*primary* image is our ``reference`` (the field is given on its pixels), its
*secondary* our ``moving``.

**The default search** (``search="dis"``, issue 15): the lighting is removed
by the local contrast normalisation of step 1 below, so a fast dense matcher
is fair on the normalised frames: dense inverse search
(:mod:`stereo.kroeger2016`) finds the matches, each gets the paper's matching
probability (step 3: the min/max cost of step 2 and texture), matches below
:data:`FILL_KNEE` give way, in proportion, to the probability-weighted fill
of the confident ones spread edge-aware over the reference's colour regions
(a fast global smoother; it plays the part of step 4's weighted regression,
which blends across region edges), and a few variational steps on the
normalised frames give the sub-pixel part. The output probability is the
one described after the list. On the lighting-change family it is 1.5-3x more accurate than
the pyramid search below at about three quarters of its time.

**The pyramid search** (``search="pyramid"``, the paper's own): coarse to
fine over a 2x2-average pyramid, at each level:

1. **Lighting removed by construction.** Both grey levels are locally
   contrast-normalised, ``n = (I - G*I) / sqrt(G*(I - G*I)^2 + eps^2)``
   (:func:`normalise_contrast`, ``G`` a Gaussian of ``CONTRAST_SIGMA`` px): a
   local gain and offset cancel exactly, a gamma or a smooth shading to first
   order over ``G``'s width. The reference leaves this preprocessing to
   "other techniques from computer vision".
2. **Pixel matching** against the maximum and minimum images of the
   secondary (Fig. 5.7; the paper's 3x3 range, or by default the range
   within half a pixel, :func:`_minmax`): the cost of offset (u, v) at a
   pixel is
   ``mean_R max(0, n0 - nmax(x+u, y+v), nmin(x+u, y+v) - n0)`` (the
   unnumbered equation of §5.1.4, mean instead of sum over the region R),
   zero wherever the primary value lies within the secondary's local range,
   so half-pixel misalignment and resampling cost nothing. Candidates are
   the integer offsets within ``radius`` of the current field (wider below
   full size and at the top level); the secondary's range images are warped
   once and the candidates are whole-pixel slices of them.
3. **Matching probability** per pixel: ``exp(-cost / MATCH_SCALE)`` times
   how distinct the best cost is among the candidates, times how textured
   the primary is there (the structure tensor's smaller eigenvalue against
   what image noise gives): flat areas and pixels that match nothing (an
   added or removed object) carry ~0.
4. **Motion consistency**: a locally weighted linear regression
   (:func:`weighted_regression`) of the matched offsets, each weighted by its
   probability times a Gaussian of distance, gives a smooth field (a local
   affine fit per pixel: no global projective model, no distortion
   correction assumed). Where the kernel holds little evidence a kernel
   ``WIDE_FACTOR`` times wider speaks, and where even that holds little, the
   coarser level's field.
5. **Per-pixel choice** by the same cost: the regressed field, the field
   before this round and (below full size) the matches' own 5x5 median.
   The regression treats an independently moving object as an outlier to
   its surroundings' motion; the choice keeps it.
6. **Sub-pixel**: one probability-weighted Lucas-Kanade step on the
   normalised images (:func:`lk_refine`); the min/max cost is flat within
   the secondary's range and locates a match only to about a pixel.
7. **Iterate** matching and regression around the new field (the
   probabilities are recomputed from it), ``max_iterations`` rounds per
   level below full size, one at full size.

At full size, each pixel also keeps the field found ``BOUNDARY_STEP`` px
left, right, up or down if that matches clearly better: the regression
kernel blends the two sides of a motion boundary, the neighbour's field does
not. The output probability is the matching probability of the final field
at every pixel (texture included), so flat regions and changed objects say
they are unreliable.

Design notes, figures and what was tried: ``docs/decisions/video-matching.md``.

Examples
--------
>>> import cv2
>>> rng = np.random.default_rng(0)
>>> a = cv2.GaussianBlur(rng.random((72, 96, 3)).astype(np.float32), (0, 0), 1.5)
>>> b = 0.6 * np.roll(a, (2, -3), axis=(0, 1)) + 0.1       # a darker take, shifted
>>> r = video_matching(a, b)
>>> np.round(np.median(r.flow[10:-10, 10:-10], axis=(0, 1))).tolist()
[-3.0, 2.0]
"""

from __future__ import annotations

import time

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.stereo.luma import luma_normalised, noise_sigma_immerkaer
from lumigraph.stereo.pyramid import (
    build_pyramid,
    check_levels,
    choose_levels,
    estimate_max_motion,
    upsample_flow,
)
from lumigraph.stereo.pyramid_flow import FlowResult

# Cost scale of the matching probability: the cost is in units of local
# contrast (the images are normalised to unit local RMS); a mean excess of
# 0.1 over the secondary's 3x3 range is a doubtful match.
MATCH_SCALE = 0.1
# Kernel-weighted probability mass (about two confident matches) at which the
# regressed field and the coarser level's field weigh equally.
SUPPORT_HALF = 2.0
# The fallback regression kernel where the regular one holds little evidence.
WIDE_FACTOR = 4.0
# Width of the contrast normalisation's Gaussian, px of each level.
CONTRAST_SIGMA = 3.0
# Its floor (units of the [0, 1] image; about one 8-bit code, the noise of a
# good camera): local contrast well above it is normalised exactly, flat
# areas are not blown up beyond the noise.
CONTRAST_EPS = 0.004
# Texture term of the probability: the structure tensor's smaller eigenvalue
# against TEXTURE_NOISE x what image noise alone gives (sigma^2 / 2 for
# central differences); 0.5 at that ratio.
TEXTURE_NOISE = 25.0
# The output probability's texture term: 0.5 where the smaller eigenvalue
# is 2x what noise alone gives (pure noise: ~0.1-0.2; real texture: ~1).
OUTPUT_TEXTURE_NOISE = 2.0
# Final boundary step: candidate fields taken this far either side, px, and
# compared over this region (side, px).
BOUNDARY_STEP = 6
SELECT_REGION = 7
SELECT_MARGIN = 0.8
SELECT_ABS = 0.01
SELECT_TEXTURE = 0.15
LOCAL_N = 3
# Ridge of the Lucas-Kanade refinement, in squared contrast units per pixel
# of window weight: gradients below ~0.1 contrast units/px do not move the field.
LK_RIDGE = 0.01
LK_SIGMA = 4.0  # px of full size
LK_MIN_SIGMA = 1.5
LK_ITERATIONS = 1
# Reach of the secondary's local range, px: 1 the paper's 3x3, 0.5 half a pixel.
MINMAX_REACH = 0.5
LOCAL_CANDIDATE = True
FULL_SIZE_ITERATIONS = 1
# First-round search radius at the levels below the top but above full size.
COARSE_RADIUS = 3
# The top level searches this far (px of that level) at most.
TOP_RADIUS_MAX = 4

# The default search (issue 15; docs/decisions/video-matching.md), chosen on
# seed 0 of the kinds layers/natural/noise/cartoon of the lighting family:
SEARCHES = ("dis", "pyramid")
# 8-bit codes per unit of normalised contrast when DIS matches the normalised
# frames: +-3.2 local RMS (beyond it: clipped) over the 8-bit range.
DIS_CODES = 40.0
# Matching probability at and above which a DIS match stands as it is; below
# it the probability-weighted fill takes over in proportion.
FILL_KNEE = 0.1
# The fill's fast global smoother (Min et al. 2014): smoothness weight and the
# colour difference (8-bit codes) at which the guide cuts it.
FILL_LAMBDA = 1000.0
FILL_SIGMA_COLOR = 5.0
# Variational steps on the normalised frames after the fill (sub-pixel).
DIS_REFINE_ITERATIONS = 6


def _as_gray(image: np.ndarray, where: str) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim not in (2, 3) or a.size == 0:
        raise InputError(where, f"expected an (H, W) or (H, W, C) image, got shape {a.shape}")
    if min(a.shape[:2]) < 8:
        raise InputError(where, f"image is too small ({a.shape}); need at least 8x8 pixels")
    if a.ndim == 3 and a.shape[2] not in (1, 3, 4):
        raise InputError(where, f"expected 1, 3 or 4 channels, got {a.shape[2]}")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    return luma_normalised(a[..., :3] if a.ndim == 3 else a)


def normalise_contrast(image: np.ndarray, *, sigma: float = CONTRAST_SIGMA,
                       eps: float | None = None) -> np.ndarray:
    """Local contrast normalisation: ``(I - G*I) / sqrt(G*(I - G*I)^2 + eps^2)``,
    per channel, ``G`` a Gaussian of ``sigma`` px. Removes a local gain and
    offset exactly, a gamma or smooth shading to first order over ``sigma``.
    ``eps`` (units of ``I``) keeps flat areas at ~0 instead of amplified
    noise.

    Examples
    --------
    >>> x = np.random.default_rng(1).random((20, 20, 1)).astype(np.float32)
    >>> bool(np.allclose(normalise_contrast(x), normalise_contrast(3 * x + 0.2), atol=0.05))
    True
    """
    import cv2

    eps = CONTRAST_EPS if eps is None else eps
    img = np.asarray(image, np.float32)
    hp = img - cv2.GaussianBlur(img, (0, 0), sigma).reshape(img.shape)
    var = cv2.GaussianBlur(hp * hp, (0, 0), sigma).reshape(img.shape)
    return (hp / np.sqrt(var + eps * eps)).astype(np.float32)


def _minmax(img: np.ndarray) -> np.ndarray:
    """The secondary's local maximum and minimum images (Fig. 5.7), stacked
    ``(H, W, 2)``. With
    ``MINMAX_REACH`` 1 the paper's 3x3 neighbourhood; with 0.5 the range of
    the linearly interpolated image within half a pixel (the pixel and the
    midpoints to its four neighbours, Birchfield & Tomasi's sampling-
    insensitive range): still zero cost for any sub-pixel misalignment of
    a sampled edge, but a fine texture no longer fits inside every range."""
    import cv2

    if MINMAX_REACH >= 1:
        k = np.ones((3, 3), np.uint8)
        return np.dstack([cv2.dilate(img, k, borderType=cv2.BORDER_REPLICATE),
                          cv2.erode(img, k, borderType=cv2.BORDER_REPLICATE)])
    p = cv2.copyMakeBorder(img, 1, 1, 1, 1, cv2.BORDER_REPLICATE)
    h, w = img.shape
    mids = [0.5 * (img + p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w])
            for dx, dy in ((-1, 0), (1, 0), (0, -1), (0, 1))]
    hi, lo = img.copy(), img.copy()
    for m in mids:
        np.maximum(hi, m, out=hi)
        np.minimum(lo, m, out=lo)
    return np.dstack([hi, lo])


def _warp(img: np.ndarray, field: np.ndarray) -> np.ndarray:
    import cv2

    h, w = img.shape[:2]
    xs = np.arange(w, dtype=np.float32)[None, :] + field[..., 0]
    ys = np.arange(h, dtype=np.float32)[:, None] + field[..., 1]
    return cv2.remap(img, xs, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def _cost_at(n0, hl, region):
    """Region-mean Sand-Teller cost of primary ``n0`` against the aligned
    max/min images ``hl`` (``(H, W, 2)``)."""
    import cv2

    hi, lo = cv2.split(hl)
    c = n0 - hi
    np.maximum(c, lo - n0, out=c)
    np.maximum(c, 0.0, out=c)
    return cv2.boxFilter(c, -1, (region, region), borderType=cv2.BORDER_REFLECT)


def texture_weight(gray: np.ndarray, *, window: int = 5, noise_factor: float = TEXTURE_NOISE,
                   _cached: dict | None = None) -> np.ndarray:
    """How two-dimensionally textured each pixel's neighbourhood is, in [0, 1):
    ``lam / (lam + noise_factor * sigma^2 / 2)`` with ``lam`` the structure
    tensor's smaller eigenvalue over a ``window`` box and ``sigma`` the
    image's noise (Immerkaer): ~0 on flat areas and along straight edges
    (aperture problem), near 1 at corners and on texture."""
    import cv2

    if _cached:
        lam, sigma = _cached["lam"], _cached["sigma"]
        return (lam / (lam + noise_factor * sigma * sigma / 2)).astype(np.float32)
    g = np.asarray(gray, np.float32)
    k = np.array([[-0.5, 0.0, 0.5]], np.float32)
    gx = cv2.filter2D(g, -1, k, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.filter2D(g, -1, k.T, borderType=cv2.BORDER_REPLICATE)
    box = (window, window)
    jxx, jxy, jyy = (cv2.boxFilter(a, -1, box) for a in (gx * gx, gx * gy, gy * gy))
    lam = np.maximum(0.5 * (jxx + jyy - np.sqrt((jxx - jyy) ** 2 + 4 * jxy * jxy)), 0)
    sigma = max(noise_sigma_immerkaer(g), 1.0 / 1024)
    if _cached is not None:
        _cached.update(lam=lam, sigma=sigma)
    return (lam / (lam + noise_factor * sigma * sigma / 2)).astype(np.float32)


def weighted_regression(offsets: np.ndarray, weights: np.ndarray, *, sigma: float,
                        ridge: float = 1e-4, step: int = 1) -> np.ndarray:
    """Locally weighted linear regression of an offset field.

    At every pixel ``x0`` fits ``d(x) = a + B (x - x0)`` to all offsets, each
    weighted by ``weights(x) * exp(-|x - x0|^2 / (2 sigma^2))``, and returns
    ``a``. The weighted sums are Gaussian-filtered moment images, so the cost
    is independent of ``sigma``. Where the weights vanish the fit falls back
    (ridge on ``B``) to the weighted mean.

    Parameters
    ----------
    offsets : ndarray, ``(H, W, 2)``
    weights : ndarray, ``(H, W)``, >= 0
    sigma : float
        Kernel width, pixels.
    step : int
        Solve on a grid ``step`` times coarser (moments box-summed, then
        blurred there) and interpolate the fit: for ``sigma`` of several
        pixels the fit is smooth on that scale, and the cost drops by
        ``step**2``. 1 is exact.

    Returns
    -------
    ndarray, float32, ``(H, W, 2)``

    Examples
    --------
    >>> yy, xx = np.mgrid[0:30, 0:40].astype(np.float32)
    >>> d = np.stack([0.1 * xx + 2, -0.05 * yy], -1)       # an affine field
    >>> w = (np.random.default_rng(0).random((30, 40)) > 0.7).astype(np.float32)
    >>> bool(np.abs(weighted_regression(d, w, sigma=4) - d).max() < 1e-3)
    True
    """
    return _regress(offsets, weights, [(sigma, step)], ridge=ridge)[0]


def _regress(offsets, weights, scales, *, ridge=1e-4):
    """:func:`weighted_regression` at several ``(sigma, step)`` scales, the
    moment planes built once."""

    h, w = weights.shape
    # Coordinates centred on the image keep the moments well conditioned.
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    xx -= w / 2
    yy -= h / 2
    wgt = np.asarray(weights, np.float32)
    d0 = np.asarray(offsets[..., 0], np.float32)
    d1 = np.asarray(offsets[..., 1], np.float32)
    wx, wy = wgt * xx, wgt * yy
    planes = [wgt, wx, wy, wx * xx, wx * yy, wy * yy]
    for d in (d0, d1):
        wd = wgt * d
        planes += [wd, wd * xx, wd * yy]
    full = np.stack(planes, -1)
    return [_solve_moments(full, h, w, sigma, max(1, int(step)), ridge, xx, yy)
            for sigma, step in scales]


def _solve_moments(stack, h, w, sigma, step, ridge, xx, yy):
    import cv2

    hs, ws = -(-h // step), -(-w // step)
    if step > 1:
        if (hs * step, ws * step) != (h, w):
            stack = cv2.copyMakeBorder(stack, 0, hs * step - h, 0, ws * step - w,
                                       cv2.BORDER_CONSTANT, value=0)
        # Block means (INTER_AREA at an integer factor): the moment sums up
        # to a common factor, which the solve does not see.
        stack = cv2.resize(stack, (ws, hs), interpolation=cv2.INTER_AREA)
        # Low-res pixel centres in full-resolution (centred) coordinates.
        gy = (np.arange(hs, dtype=np.float64) * step + (step - 1) / 2 - h / 2)[:, None]
        gx = (np.arange(ws, dtype=np.float64) * step + (step - 1) / 2 - w / 2)[None, :]
        sg = sigma / step
    else:
        gy, gx, sg = yy.astype(np.float64), xx.astype(np.float64), sigma
    m = cv2.GaussianBlur(stack, (0, 0), sg, borderType=cv2.BORDER_CONSTANT).astype(np.float64)
    s, sx, sy, sxx, sxy, syy = (m[..., i] for i in range(6))
    gx, gy = np.broadcast_to(gx, s.shape), np.broadcast_to(gy, s.shape)
    # Moments about each grid point x0 from the moments about the origin.
    mx, my = sx - gx * s, sy - gy * s
    mxx = sxx - 2 * gx * sx + gx * gx * s
    myy = syy - 2 * gy * sy + gy * gy * s
    mxy = sxy - gx * sy - gy * sx + gx * gy * s
    lam = ridge * sigma * sigma * s + 1e-12
    a11, a12, a13 = s + 1e-12, mx, my
    a22, a23, a33 = mxx + lam, mxy, myy + lam
    # Closed-form 3x3 symmetric solve for the constant term (Cramer's rule).
    c11 = a22 * a33 - a23 * a23
    c12 = a13 * a23 - a12 * a33
    c13 = a12 * a23 - a13 * a22
    det = a11 * c11 + a12 * c12 + a13 * c13
    det = np.where(np.abs(det) > 1e-30, det, 1e-30)
    out = np.empty((hs, ws, 2), np.float32) if step > 1 else np.empty((h, w, 2), np.float32)
    for c in range(2):
        su, sux, suy = (m[..., 6 + 3 * c + i] for i in range(3))
        r1, r2, r3 = su, sux - gx * su, suy - gy * su
        out[..., c] = (c11 * r1 + c12 * r2 + c13 * r3) / det
    if step > 1:
        # Low-res centres sit at (step - 1) / 2 + k * step: resize's own rule.
        out = cv2.resize(out, (ws * step, hs * step), interpolation=cv2.INTER_LINEAR)[:h, :w]
    return np.ascontiguousarray(out, np.float32)


def _match(n0, mm1, field, *, radius, region):
    """Best integer offset within ``radius`` around ``field`` per pixel (the
    secondary's max/min images warped once by the field, the candidates then
    whole-pixel shifts of them), its cost and the mean cost over the
    candidates."""
    import cv2

    h, w = n0.shape
    r = radius
    hl = cv2.copyMakeBorder(_warp(mm1, field), r, r, r, r, cv2.BORDER_REPLICATE)
    hi, lo = np.ascontiguousarray(hl[..., 0]), np.ascontiguousarray(hl[..., 1])
    side = 2 * r + 1
    best = mean = idx = better = None
    centre = r * side + r
    # The centre (no change) first: ties (the cost is flat near a match)
    # keep the current field.
    for i in [centre] + [j for j in range(side * side) if j != centre]:
        dy, dx = divmod(i, side)
        c = n0 - hi[dy:dy + h, dx:dx + w]
        np.maximum(c, lo[dy:dy + h, dx:dx + w] - n0, out=c)
        np.maximum(c, 0.0, out=c)
        c = cv2.boxFilter(c, -1, (region, region), borderType=cv2.BORDER_REFLECT)
        if best is None:
            best, mean = c, c.copy()
            idx, better = np.full((h, w), centre, np.int16), np.empty((h, w), bool)
            continue
        mean += c
        np.less(c, best, out=better)
        np.copyto(best, c, where=better)
        np.copyto(idx, i, where=better)
    off = np.stack([idx % side - r, idx // side - r], -1).astype(np.float32)
    # No sub-pixel step here: the cost is flat within the secondary's 3x3
    # range, so the regression and the gradient refinement give the fraction.
    return field + off, best, mean / (2 * r + 1) ** 2


def _gradients(img):
    import cv2

    k = np.array([[-0.5, 0.0, 0.5]], np.float32)
    return (cv2.filter2D(img, -1, k, borderType=cv2.BORDER_REPLICATE),
            cv2.filter2D(img, -1, k.T, borderType=cv2.BORDER_REPLICATE))


def lk_refine(n0, n1, field, weight, *, sigma, iterations, grad0=None):
    """Sub-pixel refinement of ``field`` on the contrast-normalised images:
    Gauss-Newton steps of a probability-weighted Lucas-Kanade fit (each
    pixel's brightness-constancy residual of ``n1`` warped by the field,
    weighted by ``weight`` and a Gaussian window of ``sigma`` px). The
    min/max matching cost is flat within the secondary's 3x3 range, so on
    its own it locates a match to about a pixel; the gradients of the
    normalised images, invariant to the same gain and offset, locate it to
    a fraction. A ridge keeps flat areas (no gradient) where they were."""
    import cv2

    gx0, gy0 = grad0 if grad0 is not None else _gradients(n0)
    wgt = np.asarray(weight, np.float32)
    field = field.copy()

    def g(a):
        return cv2.GaussianBlur(a, (0, 0), sigma)

    for _ in range(iterations):
        n1w = _warp(n1, field)
        gx1, gy1 = _gradients(n1w)
        gx, gy = 0.5 * (gx0 + gx1), 0.5 * (gy0 + gy1)
        it = n1w - n0
        # A robust residual weight: a pixel that differs by more than a
        # contrast unit is an outlier (changed content), not a shift.
        w = wgt / (1 + it * it)
        wx, wy = w * gx, w * gy
        jxx, jxy, jyy = g(wx * gx), g(wx * gy), g(wy * gy)
        bx, by = g(wx * it), g(wy * it)
        ridge = LK_RIDGE * (g(w) + 1e-3)
        jxx += ridge
        jyy += ridge
        det = jxx * jyy - jxy * jxy
        du = -(jyy * bx - jxy * by) / det
        dv = -(jxx * by - jxy * bx) / det
        field[..., 0] += np.clip(du, -1, 1)
        field[..., 1] += np.clip(dv, -1, 1)
    return field


def _support(prob, sigma):
    """Kernel-weighted probability mass within ``sigma`` (number of confident matches)."""
    import cv2

    f = max(1, int(sigma // 2))
    h, w = prob.shape
    if f > 1:
        small = cv2.resize(prob, (-(-w // f), -(-h // f)), interpolation=cv2.INTER_AREA)
        s = cv2.GaussianBlur(small, (0, 0), sigma / f) * (2 * np.pi * (sigma / f) ** 2)
        return cv2.resize(s, (w, h), interpolation=cv2.INTER_LINEAR)
    return cv2.GaussianBlur(prob, (0, 0), sigma) * (2 * np.pi * sigma * sigma)


def _choose(n0, mm1, cands, allowed=None, abs_margin=None):
    """Per pixel, the candidate field that matches best over SELECT_REGION
    (a later candidate must beat the kept one by SELECT_MARGIN and
    ``abs_margin``, default SELECT_ABS: noise in the cost would otherwise swap
    equally good fields at random). Returns the field and the index kept."""
    abs_margin = SELECT_ABS if abs_margin is None else abs_margin
    field = cands[0]
    best = _cost_at(n0, _warp(mm1, field), SELECT_REGION)
    keep = np.zeros(best.shape, np.int8)
    out = field.copy()
    better = np.empty(best.shape, bool)
    for i, f in enumerate(cands[1:], 1):
        c = _cost_at(n0, _warp(mm1, f), SELECT_REGION)
        np.less(c, SELECT_MARGIN * best - abs_margin, out=better)
        if allowed is not None and allowed[i] is not None:
            better &= allowed[i]
        np.copyto(out, f, where=better[..., None])
        np.copyto(keep, i, where=better)
        np.copyto(best, c, where=better)
    return out, keep


def _choose_side(n0, mm1, field):
    """Each pixel keeps the field found BOUNDARY_STEP px away if that matches
    better here (cost over SELECT_REGION): the regression blends the two
    sides of a motion boundary within its kernel, the neighbour's field does
    not. Returns the field and which candidate each pixel kept (0: its own)."""
    import cv2

    h, w = n0.shape
    s = BOUNDARY_STEP
    pad = cv2.copyMakeBorder(field, s, s, s, s, cv2.BORDER_REPLICATE)
    cands = [field] + [pad[s + dy:s + dy + h, s + dx:s + dx + w]
                       for dx, dy in ((-s, 0), (s, 0), (0, -s), (0, s))]
    return _choose(n0, mm1, cands, abs_margin=0.0)


def _probability(best, mean, texture):
    distinct = np.clip(1 - best / np.maximum(mean, 1e-6), 0, 1)
    return (np.exp(-best / MATCH_SCALE) * distinct * texture).astype(np.float32)


def _codes(n: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(128 + DIS_CODES * n), 0, 255).astype(np.uint8)


def _guide8(image: np.ndarray) -> np.ndarray:
    """The reference as 8-bit codes (colour kept) for the edge-aware fill."""
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 3:
        a = a[..., :3]
    if a.dtype != np.uint8:
        scale = 255.0 / np.iinfo(a.dtype).max if a.dtype.kind in "ui" else 255.0
        a = np.clip(np.rint(a * scale), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(a)


def _dis_search(reference, n0, n1, mm1, tex, *, region, max_motion_px=None):
    """The default correspondence search: the lighting is removed by the
    contrast normalisation (``n0``, ``n1``), so a brightness-constancy
    matcher is fair there; dense inverse search (:mod:`stereo.kroeger2016`,
    its default preset) on the normalised frames as 8-bit codes gives the
    matches. Each match's probability is the paper's (min/max cost against
    ``mm1``, times texture ``tex``); below :data:`FILL_KNEE` the field is
    replaced, in proportion, by the probability-weighted fill of the
    confident matches, spread by a fast global smoother guided by the
    reference's colour (Min et al. 2014, doi:10.1109/TIP.2014.2366600): flat
    areas and unmatched objects take the motion of their own region, not of
    whatever the patch search drifted to. A few variational steps on the
    normalised frames (:func:`stereo.kroeger2016.variational_refine`) give
    the sub-pixel part."""
    from lumigraph.stereo.kroeger2016 import (
        dense_inverse_search,
        variational_refine,
        weighted_fill,
    )

    c0, c1 = _codes(n0), _codes(n1)
    f = dense_inverse_search(c0, c1, consistency=False, max_motion_px=max_motion_px).flow
    prob = (tex * np.exp(-_cost_at(n0, _warp(mm1, f), region) / MATCH_SCALE)).astype(np.float32)
    fill = weighted_fill(_guide8(reference), f, prob, lam=FILL_LAMBDA,
                         sigma_colour=FILL_SIGMA_COLOR)
    w = np.minimum(1.0, prob / FILL_KNEE)[..., None]
    f = (w * f + (1 - w) * fill).astype(np.float32)
    return variational_refine(c0, c1, f, DIS_REFINE_ITERATIONS)


def video_matching(reference: np.ndarray, moving: np.ndarray, *, levels: int | str = "auto",
                   max_motion_px: float | None = None, region: int = 5,
                   regression_sigma: float = 9.0, max_iterations: int = 2, tol_px: float = 0.05,
                   radius: int = 1, refine_boundaries: bool = True,
                   initial_flow: np.ndarray | None = None, search: str | None = None) -> FlowResult:
    """Sand-Teller correspondence field from ``reference`` to ``moving``.

    Parameters
    ----------
    reference, moving : ndarray, ``(H, W)`` or ``(H, W, 3)``
        The paper's primary and secondary takes: the field is given on the
        reference's pixels and points into the moving image. uint8/uint16
        codes or float in [0, 1]; same height and width. Matched on luma.
    levels : int or "auto"
        Pyramid levels of the pyramid search, 1..12
        (:func:`stereo.pyramid.check_levels`); ``"auto"`` from
        ``max_motion_px`` or a phase-correlation estimate on the
        contrast-normalised images, so that the top level leaves at most
        ``TOP_RADIUS_MAX - 1`` px of motion. An integer selects the pyramid
        search (``search=None``).
    region : int
        Side of the region R of the matching cost, px (odd).
    regression_sigma : float
        Kernel width of the locally weighted regression at full size, px
        (halved per level, at least 2).
    max_iterations : int
        Match/regress rounds per level below full size at most (one at full
        size); fewer when the field's mean change falls below ``tol_px``
        (px of full size).
    radius : int
        Search radius around the current field below the top level, px.
    refine_boundaries : bool
        The final per-pixel choice among shifted fields (module docstring).
    initial_flow : ndarray, ``(H, W, 2)``, optional
        A start field (then the pyramid search's matching runs at full size
        only).
    search : {None, "dis", "pyramid"}
        How the matches are found (module docstring). ``"dis"``, the
        default: dense inverse search on the contrast-normalised frames,
        the probability-weighted edge-aware fill and a variational step
        (:func:`_dis_search`; ``region`` and ``max_motion_px`` apply).
        ``"pyramid"``: the paper's coarse-to-fine min/max matching and
        regression (every other option applies). None: ``"pyramid"`` when
        ``levels`` is an integer or ``initial_flow`` is given, else ``"dis"``.

    Returns
    -------
    FlowResult
        ``flow`` the correspondence field ``(H, W, 2)`` float32 (reference ->
        moving), ``confidence`` the matching probability of that field in
        [0, 1] (texture included: flat areas and changed objects are low),
        ``occluded`` where it is below 0.5 at a textured pixel (a match that
        failed, not a flat area).

    Raises
    ------
    InputError
        Naming ``reference``/``moving`` (empty, smaller than 8x8, sizes
        differ) or the option out of range.
    """

    import cv2

    t0 = time.perf_counter()
    g0, g1 = _as_gray(reference, "reference"), _as_gray(moving, "moving")
    if g0.shape != g1.shape:
        raise InputError("moving", f"is {g1.shape[1]}x{g1.shape[0]} but reference is "
                                   f"{g0.shape[1]}x{g0.shape[0]}; give two frames of one size")
    if not isinstance(region, int | np.integer) or region < 1 or region % 2 == 0:
        raise InputError("region", f"expected an odd size >= 1, got {region}")
    if not regression_sigma > 0:
        raise InputError("regression_sigma", f"expected > 0 px, got {regression_sigma}")
    if not isinstance(radius, int | np.integer) or not 1 <= radius <= 4:
        raise InputError("radius", f"expected an integer 1..4, got {radius}")
    if not isinstance(max_iterations, int | np.integer) or max_iterations < 1:
        raise InputError("max_iterations", f"expected an integer >= 1, got {max_iterations}")
    levels = check_levels(levels)
    if search is None:
        # A pyramid depth asked for is the pyramid search asked for.
        search = "dis" if levels == "auto" and initial_flow is None else "pyramid"
    if search not in SEARCHES:
        raise InputError("search", f"expected one of {', '.join(SEARCHES)}, got {search!r}")
    if search == "dis" and levels != "auto":
        raise InputError("levels", f"only the pyramid search has levels (got {levels}); "
                                   "leave levels at 'auto' or choose search='pyramid'")
    if initial_flow is None and search == "dis":
        # The default (issue 15): DIS on the contrast-normalised frames,
        # its weak matches filled by the probability-weighted edge-aware
        # fill, then refined (_dis_search).
        n0, n1 = normalise_contrast(g0), normalise_contrast(g1)
        mm1 = _minmax(n1)
        tex_cache: dict = {}
        tex = texture_weight(g0, _cached=tex_cache)
        if np.array_equal(g0, g1):
            field = np.zeros((*g0.shape, 2), np.float32)  # zero is exact: skip the search
        else:
            field = _dis_search(reference, n0, n1, mm1, tex, region=region,
                                max_motion_px=max_motion_px)
        n_levels, choice_d = 1, {"levels": 1, "source": "dis search (levels not used)"}
        history, info_select = [], {}
    else:
        h, w = g0.shape
        est = full = None
        if initial_flow is not None:
            start = np.asarray(initial_flow, np.float32)
            if start.shape != (h, w, 2):
                raise InputError("initial_flow", f"expected shape {(h, w, 2)}, got {start.shape}")
            n_levels, choice_d = 1, {"levels": 1, "source": "initial_flow"}
        elif levels == "auto":
            if max_motion_px is None:
                full = normalise_contrast(g0), normalise_contrast(g1)
                est, _ = estimate_max_motion(*full)
                source = "estimated"
            else:
                est, source = float(max_motion_px), "given"
            choice = choose_levels(g0.shape, max_motion_px=est, reach_px=TOP_RADIUS_MAX - 1.0,
                                   source=source)
            n_levels, choice_d = choice.levels, choice.to_dict()
        else:
            n_levels, choice_d = levels, {"levels": levels, "source": "given"}
        p0, p1 = build_pyramid(g0, n_levels), build_pyramid(g1, n_levels)
        if initial_flow is not None:
            field = start
        else:
            field = np.zeros(p0[-1].shape + (2,), np.float32)
        history = []
        info_select = {}
        for lvl in range(n_levels - 1, -1, -1):
            if field.shape[:2] != p0[lvl].shape:
                field = upsample_flow(field, p0[lvl].shape)
            if lvl == 0 and full is not None:
                n0, n1 = full  # already made for the motion estimate
            else:
                n0, n1 = normalise_contrast(p0[lvl]), normalise_contrast(p1[lvl])
            mm1 = _minmax(n1)
            tex_cache = {}
            tex = texture_weight(p0[lvl], _cached=tex_cache)
            top = lvl == n_levels - 1 and initial_flow is None
            # Below the top, the first round at reduced sizes searches wider: an
            # object whose motion the coarser level's regression blended into
            # its surroundings' is caught here (a level-1 pixel costs a quarter).
            r = max(radius, COARSE_RADIUS) if lvl > 0 else radius
            if top:
                reach = est / 2 ** lvl if est is not None else TOP_RADIUS_MAX
                r = int(min(TOP_RADIUS_MAX, max(radius, np.ceil(reach) + 1)))
            sig = max(2.0, regression_sigma / 2 ** lvl)
            for it in range(max_iterations if lvl > 0 else min(max_iterations, FULL_SIZE_ITERATIONS)):
                matched, best, mean = _match(n0, mm1, field, radius=r, region=region)
                prob = _probability(best, mean, tex)
                # Where the kernel holds little matching evidence (flat areas)
                # a kernel WIDE_FACTOR times wider speaks, and where even that
                # holds little, the field inherited from the coarser level.
                new = field
                scales = [(sig * f, max(1, int(sig * f // 2))) for f in (WIDE_FACTOR, 1)]
                for (sg, _), fit in zip(scales, _regress(matched, prob, scales), strict=True):
                    support = _support(prob, sg)
                    wfit = (support / (support + SUPPORT_HALF))[..., None]
                    new = (wfit * fit + (1 - wfit) * new).astype(np.float32)
                if LOCAL_CANDIDATE:
                    # The regression treats an independently moving object as
                    # outliers to its surroundings' motion; the field before it
                    # and (below full size) the matches' own 5x5 median do not.
                    # Each pixel keeps whichever matches best over SELECT_REGION.
                    cands = [new, field]
                    if lvl > 0:
                        cands.append(np.stack([cv2.medianBlur(np.ascontiguousarray(matched[..., c]), 5)
                                               for c in (0, 1)], -1))
                    new, _ = _choose(n0, mm1, cands[:LOCAL_N], allowed=[None, None, tex > SELECT_TEXTURE])
                change = float(np.mean(np.abs(new - field)))
                field = new
                history.append({"level": lvl, "iteration": it, "radius": r,
                                "mean_change_px": change,
                                "mean_probability": float(prob.mean())})
                r = radius
                if change < tol_px / 2 ** lvl:
                    break
            if refine_boundaries and lvl == 0:
                field, keep = _choose_side(n0, mm1, field)
                info_select = {"neighbour_field_fraction": float((keep > 0).mean())}
            if LK_ITERATIONS:
                w_lk = tex * np.exp(-_cost_at(n0, _warp(mm1, field), region)
                                    / MATCH_SCALE)
                field = lk_refine(n0, n1, field, w_lk, sigma=max(LK_MIN_SIGMA, LK_SIGMA / 2 ** lvl),
                                  iterations=LK_ITERATIONS)
    # n0, mm1 are level 0's now.
    c = _cost_at(n0, _warp(mm1, field), region)
    tex = texture_weight(g0, noise_factor=OUTPUT_TEXTURE_NOISE, _cached=tex_cache)
    prob = (np.exp(-c / MATCH_SCALE) * tex).astype(np.float32)
    failed = (prob < 0.5) & (tex > 0.5)
    info = {"method": "sand2004", "search": "initial_flow" if initial_flow is not None else search,
            "level_choice": choice_d, "region": region,
            "regression_sigma": regression_sigma, "iterations": history, **info_select,
            "quality": {"mean_probability": float(prob.mean()),
                        "textured_fraction": float((tex > 0.5).mean()),
                        "unmatched_fraction": float(failed.mean())},
            "timings_s": {"total": time.perf_counter() - t0}}
    return FlowResult(np.ascontiguousarray(field, np.float32), prob, failed, n_levels, info)
