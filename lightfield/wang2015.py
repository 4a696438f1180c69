"""Occlusion-aware light-field depth: a filtered cost volume over all views
with half-aperture occlusion handling (after Wang, Efros & Ramamoorthi 2015),
then an edge-aware weighted median.

Method (``wang2015`` in :data:`lightfield.methods.DEPTH_METHODS`):

1. **Cost volume.** For each candidate disparity ``d`` (px per view step,
   the HCI convention of :mod:`lightfield.field`: view ``(u, v)`` sees a
   point of disparity ``d`` at ``x - d (v - vc), y - d (u - uc)``) every view
   is resampled onto the centre view's grid (bilinear, ``cv2.warpAffine``)
   and compared with the reference (the centre view; for an even grid axis
   the mean of the central views at that ``d``): the per-view cost
   ``c_k(x, d)`` is the truncated absolute colour difference plus the
   truncated difference of the horizontal and vertical gradients (the data
   term of cost-volume filtering, Hosni et al. 2013, eq. 4), on
   gamma-encoded values so dark texture counts. Quantised input (8-bit
   codes, :func:`quantisation_step`): differences within half a code (the
   gradient term: a quarter) count as none, else the unshifted views, whose
   smooth texture keeps one code in every view, match exactly and pull the
   estimate towards disparity 0.
2. **Occlusion.** Wang et al. 2015 (§4, "occlusion-aware depth
   estimation") observe that at an occlusion edge the views on one side of
   the edge (a half of the aperture, split by the edge's orientation) still
   see the occluded point, so photo-consistency holds on that half only.
   Without estimating edge orientation per pixel we take, at every pixel
   and candidate, the least mean cost over eight half-apertures split at
   0, 45, 90 and 135 degrees (each half keeps the views on its dividing
   line), ``C(x, d) = min_h mean_{k in h} c_k(x, d)`` -- the data term of
   their eq. 6 with the occluder-free half chosen by its cost.
3. **Aggregation.** Each slice ``C(., d)`` is smoothed by a guided filter
   (He et al. 2013) with the centre view as guide: cost-volume filtering
   (Hosni et al. 2013, eq. 2), which averages the cost within regions of
   like colour; radius 1 (3 x 3): larger windows fatten silhouettes, and
   the weighted median (6.) does the wider aggregation.
4. **Coarse to fine.** Steps 1-3 run over every ``stride``-th candidate;
   ``argmin_d`` and a parabola through the least cost and its neighbours
   give a coarse estimate; then every pixel is sampled again one fine
   candidate step either side of it (``cv2.remap`` with per-pixel shifts,
   steps 1-3 again; one more sample so the least of them is in the middle)
   and a parabola through the three fine costs gives the disparity.
   ``N / stride + 4`` passes over the views instead of ``N``.
5. **Confidence.** ``1 - C_min / C_mean`` over the coarse candidates (0: a
   flat cost curve, nothing decided; near 1: one sharp minimum), in [0, 1].
6. **Refinement.** A weighted median (Zhang et al. 2014,
   ``cv2.ximgproc.weightedMedianFilter``) guided by the centre view over the
   confident pixels fills the unsure ones from like-coloured neighbours
   without crossing colour edges (:func:`refill`); where a window holds too
   few confident pixels the estimate is kept. Where a window holds no depth
   edge, the least-squares plane through its confident pixels replaces the
   median (:func:`plane_fit`): a median assumes piecewise-constant depth and
   is biased on slanted surfaces (a floor), a plane fit is not.
7. **Foreground fattening.** Next to a nearer surface a textureless
   background has two photo-consistent explanations: its own disparity
   (on the unoccluded half-aperture, step 2) and the foreground's (at the
   foreground's disparity every view samples the same side of the
   occluding edge, so all views see the flat background and agree). The
   cost cannot choose; aggregation then leaks the foreground's disparity
   outwards (the "foreground fattening" of local stereo, Scharstein &
   Szeliski 2002 §5; Hosni et al. 2013 fix it with a left-right check).
   A light field has no second reference view, so :func:`unfatten` asks
   the data directly: a pixel within ``HALO_RADIUS`` of a farther one
   (by more than ``HALO_JUMP``) whose colour is closer to the farther
   side's mean colour than to the nearer side's, and whose cost at the
   farther disparity is no higher than at its own, takes the farther
   disparity (the visibility order: fattening only ever runs from near to
   far). The cost is the unfiltered one of step 2 (the guided filter
   fattens by its radius itself); three rounds, since a flipped pixel can
   expose the next; ``2 x HALO_PASSES`` more passes over the views.
7b. **Specks** (:func:`despeckle`): a pixel farther than ``HALO_JUMP``
   from the median of its ``SPECKLE`` x ``SPECKLE`` window takes the
   median (flat cost curves on dark, weakly textured, quantised surfaces
   leave isolated gross errors; step 7 passes a far speck on).
8. **Mixed edge pixels** (:func:`soften`, ``soft_edges=True``): a pixel on
   a depth edge takes a disparity between the two sides' by its colour's
   position between their mean colours (the least-squares answer for a
   blended pixel); this lowers the squared error but puts "flying pixels"
   between surfaces (``soft_edges=False`` for triangulation).

Memory: the light field, one gamma-encoded 4-channel copy, and the
aggregated coarse cost volume ``(N / stride, H, W)`` float32; per pass the
view costs ``(K, H, W)``.

Examples
--------
>>> import numpy as np
>>> from lumigraph.lightfield.field import LightField
>>> rng = np.random.default_rng(0)
>>> base = rng.random((40, 48, 3)).astype(np.float32)
>>> views = np.stack([np.stack([np.roll(base, (-(u - 1), -(v - 1)), (0, 1)) for v in range(3)])
...                   for u in range(3)])                  # disparity 1 everywhere
>>> est = estimate_disparity(LightField(views), np.linspace(-2, 2, 21))
>>> bool(np.abs(est.disparity[8:-8, 8:-8] - 1.0).max() < 0.05)
True
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.lightfield.field import LightField
from lumigraph.lightfield.refocus import DisparityEstimate, check_disparity_slopes

#: defaults, tuned on rendered light fields (seed 0 of the scenes in
#: docs/decisions/lightfield-depth.md), never on HCI antinous
RADIUS = 1          # guided-filter radius (px); 0: none
EPS = 1e-3          # guided-filter regulariser (guide in [0, 1])
MEDIAN_RADIUS = 7   # weighted-median radius (px)
UNSURE = 0.2        # share of least-confident pixels the weighted median refills
MIN_SUPPORT = 0.2   # share of a weighted-median window that must be confident
TAU_COLOUR = 0.08   # truncation of the colour difference (gamma-encoded, [0, 1])
TAU_GRAD = 0.04     # truncation of the gradient difference
ALPHA_GRAD = 0.5    # weight of the gradient term
STRIDE = 2          # coarse pass over every 2nd candidate, then per-pixel refinement
HALO_RADIUS = 9     # reach (px) of the fattening check (step 7); 0: none
HALO_JUMP = 0.3     # disparity step (px/view) that makes a pixel a fattening suspect
HALO_PASSES = 3     # rounds of the fattening check
HALO_TOL = 0.15     # disparity tolerance (px/view) of the near / far side classes
GRAD_DEADZONE = 0.25  # the same for the gradient term (gx + gy, Sobel units); tuned
SOFT_RADIUS = 4     # window (px) of the side colours for mixed edge pixels (step 8); 0: none
SOFT_SNAP = 0.3     # mixing fractions within this of 0 or 1 snap to the side
SOFT_TOL = 0.3      # disparity tolerance (px/view) of the two sides' colour classes
SOFT_CONTRAST = 0.03  # least colour difference (L2, gamma-encoded) of the two sides
SPECKLE = 5         # window (px) of the isolated-outlier check (step 7b); 0: none
DEADZONE = 0.5      # dead zone of the colour difference, in quantisation steps of the input


def check_views(views, grid) -> np.ndarray:
    """A ``(U, V)`` boolean mask of the views to use (``None``: all), with at
    least one other view in a row or column than the reference; or
    ``InputError`` naming ``views``.

    >>> int(check_views(None, (3, 3)).sum())
    9
    """
    if views is None:
        return np.ones(grid, bool)
    m = np.asarray(views, bool)
    if m.shape != tuple(grid):
        raise InputError("views", f"expected a {grid[0]}x{grid[1]} mask of views, got shape "
                                  f"{m.shape}")
    if m.sum() < 2:
        raise InputError("views", f"at least 2 views are needed for depth, got {int(m.sum())}")
    return m


def _half_apertures(offsets: np.ndarray) -> np.ndarray:
    """(8, K) weights: the mean over each half-aperture split by a line through
    the grid centre at 0, 45, 90, 135 degrees (rows: each half, both sides)."""
    a, b = offsets[:, 0], offsets[:, 1]
    sides = []
    for proj in (b, a, a + b, a - b):
        for sign in (1, -1):
            sides.append(sign * proj >= -1e-9)
    w = np.array(sides, np.float32)
    # a half with no view off its dividing line says nothing (1 x N grids)
    informative = np.array([np.any(np.abs(o) > 1e-9) for o in
                            [np.where(s, proj, 0) for s, proj in
                             zip(sides, [b, b, a, a, a + b, a + b, a - b, a - b], strict=True)]])
    w = w[informative] if informative.any() else np.ones((1, len(a)), np.float32)
    return w / w.sum(1, keepdims=True)


def _gamma(img: np.ndarray) -> np.ndarray:
    return np.sqrt(np.clip(img, 0, None), dtype=np.float32)


def quantisation_step(img: np.ndarray) -> float:
    """The median gap between the distinct values of ``img`` where they are
    few (quantised input: 8-bit codes after decoding), else 0 (float data).

    >>> quantisation_step(np.arange(10000.0).reshape(100, 100) % 7 / 7)
    0.14285714285714285
    >>> quantisation_step(np.random.default_rng(0).random((100, 100)))
    0.0
    """
    vals = np.unique(img)
    if len(vals) < 2 or len(vals) > img.size // 8:
        return 0.0
    return float(np.median(np.diff(vals)))


def _gradients(img: np.ndarray):
    import cv2

    gray = img.mean(-1).astype(np.float32)
    gx = cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=1, borderType=cv2.BORDER_REFLECT101) * 0.5
    gy = cv2.Sobel(gray, cv2.CV_32F, 0, 1, ksize=1, borderType=cv2.BORDER_REFLECT101) * 0.5
    return gx, gy


def _shift(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """Sample ``img`` at ``(x + dx, y + dy)`` (bilinear, mirrored borders)."""
    import cv2

    h, w = img.shape[:2]
    m = np.array([[1, 0, dx], [0, 1, dy]], np.float64)
    return cv2.warpAffine(img, m, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REFLECT101)


def _matcher(lf: LightField, *, views=None, occlusion: bool = True, radius: int = RADIUS,
             eps: float = EPS):
    """``(slice_cost, guide)``: ``slice_cost(d)`` is the filtered occlusion-aware
    cost (H, W) float32 of disparity ``d``, a number or an (H, W) map (steps
    1-3 above; ``slice_cost(d, filtered=False)``: steps 1-2); ``guide`` the
    gamma-encoded reference view (H, W, 3) in [0, 1]."""
    import cv2

    u, v = lf.grid
    mask = check_views(views, lf.grid)
    uc, vc = lf.center
    data = lf.data
    if data.shape[-1] == 1:
        data = np.repeat(data, 3, -1)
    h, w = data.shape[2:4]
    idx = [(i, j) for i in range(u) for j in range(v) if mask[i, j]]
    offsets = np.array([(i - uc, j - vc) for i, j in idx], np.float64)
    # the reference: the view(s) nearest the grid centre
    ref_rows = [int(np.floor(uc)), int(np.ceil(uc))]
    ref_cols = [int(np.floor(vc)), int(np.ceil(vc))]
    ref = sorted({(i, j) for i in ref_rows for j in ref_cols})
    ref_exact = len(ref) == 1
    if any(not mask[i, j] for i, j in ref):
        raise InputError("views", "the central view(s) must be among the views used")
    weights = _half_apertures(offsets) if occlusion else np.full((1, len(idx)), 1 / len(idx),
                                                                  np.float32)
    # each view as one 4-channel image (R, G, B, 0): cv2 warps 4-channel
    # float images on its vector path (2-3x faster than 3 channels), and
    # cvtColor(BGRA2GRAY) sums the first three channels with fixed weights 10x
    # faster than cv2.transform; so each channel is scaled here to turn those
    # weights into the data term's (the truncation with it: min(s|a|, s tau) =
    # s min(|a|, tau) for s > 0). The gradient term is taken on the difference
    # of the warped grey images, d/dx (S - R): a translation commutes with the
    # gradient, so this equals the difference of the gradients (Sobel 1 x 3).
    lum = np.array([0.114, 0.587, 0.299], np.float32)              # BGRA2GRAY weights
    s_col = np.append((1 - ALPHA_GRAD) / 3 / lum, 0).astype(np.float32)
    tau_col = tuple(float(x) for x in TAU_COLOUR * s_col)
    # quantised input (8-bit): on smooth texture many pixels keep the same
    # code in every view, so the unshifted views match exactly while the true
    # shift leaves interpolated quantisation residuals -- a bias towards 0.
    # A dead zone of half a code makes both "no difference"
    q_step = quantisation_step(_gamma(data[ref[0]]))
    dz = DEADZONE * q_step
    dz_col = tuple(float(x) for x in dz * s_col)
    gdz = float(GRAD_DEADZONE * q_step * (1 - ALPHA_GRAD))
    # grey(P) = (1 - ALPHA_GRAD) mean(R, G, B); the gradient term in its units
    g_unit = np.float32(0.5 / (1 - ALPHA_GRAD)) if ALPHA_GRAD < 1 else np.float32(0)
    tau_g = float(TAU_GRAD / 2 * (1 - ALPHA_GRAD) * 2)   # on Sobel (2x the central difference)
    w_g = float(ALPHA_GRAD * g_unit)
    packed = {key: cv2.merge([*cv2.split(_gamma(data[key])), np.zeros((h, w), np.float32)])
              * s_col for key in set(idx) | set(ref)}
    guide = np.mean([_gamma(data[r]) for r in ref], 0).astype(np.float32)
    gf = cv2.ximgproc.createGuidedFilter(guide, radius, eps) if radius > 0 else None
    per_view = np.empty((len(idx), h, w), np.float32)
    gy_, gx_ = np.mgrid[0:h, 0:w].astype(np.float32)
    sobel = {"ddepth": cv2.CV_32F, "ksize": 1, "borderType": cv2.BORDER_REFLECT101}
    zero = np.zeros((h, w), np.float32)

    def slice_cost(d, filtered: bool = True) -> np.ndarray:
        per_pixel = np.ndim(d) == 2
        if per_pixel:
            d = np.asarray(d, np.float32)

        def get(i, j):
            a = packed[(i, j)]
            if i == uc and j == vc:
                return a
            if per_pixel:   # sample at x - d (j - vc), y - d (i - uc), per pixel
                return cv2.remap(a, gx_ - d * np.float32(j - vc), gy_ - d * np.float32(i - uc),
                                 cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT101)
            return _shift(a, -d * (j - vc), -d * (i - uc))

        r_a = get(*ref[0]) if ref_exact else np.mean([get(*r) for r in ref], 0)
        r_grey = cv2.cvtColor(r_a, cv2.COLOR_BGRA2GRAY)
        for k, (i, j) in enumerate(idx):
            s_a = r_a if (i, j) == ref[0] and ref_exact else get(i, j)
            # (a scalar given to cv2.min applies to the first channel only)
            ad = cv2.min(cv2.absdiff(s_a, r_a), tau_col)
            if dz > 0:   # a difference within half a code is no evidence (quantised input)
                ad = cv2.threshold(cv2.subtract(ad, dz_col), 0, 0, cv2.THRESH_TOZERO)[1]
            c = cv2.cvtColor(ad, cv2.COLOR_BGRA2GRAY)
            diff = cv2.subtract(cv2.cvtColor(s_a, cv2.COLOR_BGRA2GRAY), r_grey)
            gx = cv2.min(cv2.absdiff(cv2.Sobel(diff, dx=1, dy=0, **sobel), zero), tau_g)
            gy = cv2.min(cv2.absdiff(cv2.Sobel(diff, dx=0, dy=1, **sobel), zero), tau_g)
            g = cv2.add(gx, gy)
            if gdz > 0:
                g = cv2.threshold(cv2.subtract(g, gdz), 0, 0, cv2.THRESH_TOZERO)[1]
            cv2.scaleAdd(g, w_g, c, dst=per_view[k])
        halves = weights @ per_view.reshape(len(idx), -1)        # (n_halves, H*W)
        c_min = halves.min(0).reshape(h, w)
        return gf.filter(c_min) if gf is not None and filtered else c_min

    return slice_cost, guide


def cost_volume(lf: LightField, slopes, *, views=None, occlusion: bool = True,
                radius: int = RADIUS, eps: float = EPS) -> tuple[np.ndarray, np.ndarray]:
    """The aggregated cost volume and the guide image.

    Returns
    -------
    cost : (N, H, W) float32
        Filtered occlusion-aware cost per candidate (steps 1-3 above).
    guide : (H, W, 3) float32
        Gamma-encoded reference (centre) view in [0, 1].
    """
    slopes = check_disparity_slopes(slopes)
    slice_cost, guide = _matcher(lf, views=views, occlusion=occlusion, radius=radius, eps=eps)
    return np.stack([slice_cost(float(d)) for d in slopes]), guide


def winner(cost: np.ndarray, slopes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Winner-takes-all over a cost volume ``(N, H, W)`` with a parabola through
    the least cost and its neighbours, and the confidence ``1 - min/mean``:
    ``(disparity, confidence)``, each ``(H, W)`` float32.

    >>> c = np.array([3.0, 1.0, 2.0, 4.0], np.float32)[:, None, None]
    >>> d, q = winner(c, np.arange(4.0))
    >>> round(float(d[0, 0]), 3), round(float(q[0, 0]), 3)
    (1.167, 0.6)
    """
    n = len(slopes)
    best = cost.argmin(0)
    k = np.clip(best, 1, n - 2)
    c0 = np.take_along_axis(cost, (k - 1)[None], 0)[0]
    c1 = np.take_along_axis(cost, k[None], 0)[0]
    c2 = np.take_along_axis(cost, (k + 1)[None], 0)[0]
    den = c0 - 2 * c1 + c2
    ok = (den > 1e-12) & (best == k)
    off = np.clip(np.where(ok, 0.5 * (c0 - c2) / np.where(ok, den, 1), 0.0), -0.5, 0.5)
    step = np.diff(slopes)
    disp = slopes[best] + off * np.where(off >= 0, step[np.minimum(best, n - 2)],
                                         step[np.maximum(best - 1, 0)])
    # the floor keeps a flat (textureless, parallax-free) curve at 0, not 0/0
    floor = np.float32(1e-4)
    conf = 1.0 - (cost.min(0) + floor) / (cost.mean(0) + floor)
    return disp.astype(np.float32), np.clip(conf, 0, 1).astype(np.float32)


def _refine(c0, c1, c2, centre, h):
    """Sub-sample disparity from the costs at ``centre - h, centre, centre + h``
    (per pixel): the vertex of the parabola through them, within one step of
    ``centre`` (beyond it the three samples say nothing).

    >>> float(_refine(np.float32(2), np.float32(1), np.float32(2), 0.5, 0.1))
    0.5
    """
    den = c0 - 2 * c1 + c2
    ok = den > 1e-12
    off = np.clip(np.where(ok, 0.5 * (c0 - c2) / np.where(ok, den, 1), 0.0), -1.0, 1.0)
    # where the curve is not convex the least of the three samples is kept
    off = np.where(ok, off, np.where(c0 < np.minimum(c1, c2), -1.0,
                                     np.where(c2 < np.minimum(c0, c1), 1.0, 0.0)))
    return (centre + off * h).astype(np.float32)


def refill(disp: np.ndarray, conf: np.ndarray, guide: np.ndarray, *,
           radius: int = MEDIAN_RADIUS, plane_jump: float = HALO_JUMP) -> np.ndarray:
    """Step 6: the weighted median (Zhang et al. 2014,
    ``cv2.ximgproc.weightedMedianFilter``, radius ``radius`` px) of the
    disparity over its confident pixels (all but the ``UNSURE`` share of
    least confidence), weighted by colour likeness in ``guide`` (H, W, 3) in
    [0, 1]; where less than ``MIN_SUPPORT`` of a window is confident the
    estimate is kept (with none, the filter returns its least bin, not a
    median). Where a window holds no depth edge (no 3 x 3 span of the
    3 x 3-median-filtered disparity above ``plane_jump``; 0: never) the
    least-squares plane through its confident pixels (:func:`plane_fit`)
    replaces the median: a median is biased on a slanted surface, a plane
    is not. Returns (H, W) float32.

    >>> d = np.full((100, 100), 2.0, np.float32); d[0, 0] = -3.0; d[40:60, 40:60] = 1.0
    >>> q = np.ones_like(d); q[30:70, 30:70] = 0          # an unsure block, 16 %
    >>> guide = np.random.default_rng(0).random((100, 100, 3), np.float32)
    >>> out = refill(d, q, guide, radius=5)
    >>> float(out[50, 50]), float(out[10, 50])          # (without the rule: -3.0, 2.0)
    (1.0, 2.0)
    """
    import cv2

    joint = np.clip(guide * 255 + 0.5, 0, 255).astype(np.uint8)
    keep = (conf >= np.quantile(conf, UNSURE)).astype(np.uint8)
    cv2.setRNGSeed(0)
    med = cv2.ximgproc.weightedMedianFilter(
        joint, np.ascontiguousarray(disp, np.float32), radius, sigma=25.5,
        weightType=cv2.ximgproc.WMF_EXP, mask=keep)
    side = 2 * radius + 1
    support = cv2.boxFilter(keep, cv2.CV_32F, (side, side), borderType=cv2.BORDER_REFLECT101)
    out = np.where(support >= MIN_SUPPORT, med, disp)
    if plane_jump > 0:
        # a median is the right estimate of a piecewise-constant signal, not of
        # a slanted one: on a slope its colour weights pick a value from
        # another row at random (a floor 0.055 px/view per row lost 11 % of
        # its pixels to BadPix(0.07) in the rendered tuning scenes). Where the
        # window holds no depth edge (no 3 x 3 span above plane_jump, isolated
        # outliers taken out by a 3 x 3 median first) the surface is smooth,
        # and the least-squares plane through its confident pixels is
        # unbiased on any slant
        k3 = np.ones((3, 3), np.uint8)
        clean = cv2.medianBlur(np.ascontiguousarray(disp, np.float32), 3)
        span = cv2.dilate(clean, k3) - cv2.erode(clean, k3)
        smooth = (cv2.dilate(span, np.ones((side, side), np.uint8)) <= plane_jump) & (
            support >= MIN_SUPPORT)
        if smooth.any():
            # the outliers the 3 x 3 median took out stay out of the fit too
            inlier = keep * (np.abs(disp - clean) <= plane_jump)
            fit = plane_fit(disp, inlier, radius=radius)
            out = np.where(smooth & np.isfinite(fit), fit, out)
    return out.astype(np.float32)


def plane_fit(disp: np.ndarray, weight: np.ndarray, *, radius: int) -> np.ndarray:
    """The weighted least-squares plane ``a + b (x' - x) + c (y' - y)``
    through ``disp`` (H, W) over each pixel's ``(2 radius + 1)^2`` window,
    evaluated at the pixel (its ``a``), with weights ``weight`` (H, W) >= 0;
    NaN where the window's weighted points do not fix a plane. Moments by box
    filters in float64 (the normal equations' sums reach 1e9 on a 512 px
    image). Returns (H, W) float64.

    >>> y, x = np.mgrid[0:20, 0:30]
    >>> d = (0.5 + 0.05 * y - 0.02 * x).astype(np.float32)
    >>> w = np.ones(d.shape); w[5, 5] = 0
    >>> bool(np.abs(plane_fit(d, w, radius=3) - d).max() < 1e-6)
    True
    """
    import cv2

    h, w = disp.shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    m = np.asarray(weight, np.float64)
    d = np.asarray(disp, np.float64)
    side = (2 * radius + 1, 2 * radius + 1)

    def box(a):
        return cv2.boxFilter(a, cv2.CV_64F, side, normalize=False,
                             borderType=cv2.BORDER_REFLECT101)

    s0, sx, sy, sd = box(m), box(m * x), box(m * y), box(m * d)
    sxx, sxy, syy = box(m * x * x), box(m * x * y), box(m * y * y)
    sxd, syd = box(m * x * d), box(m * y * d)
    # the moments about the pixel itself, so that the fit's value there is a
    mx, my = sx - x * s0, sy - y * s0
    mxx = sxx - 2 * x * sx + x * x * s0
    mxy = sxy - x * sy - y * sx + x * y * s0
    myy = syy - 2 * y * sy + y * y * s0
    mxd, myd = sxd - x * sd, syd - y * sd
    a = np.stack([np.stack([s0, mx, my], -1), np.stack([mx, mxx, mxy], -1),
                  np.stack([my, mxy, myy], -1)], -2)
    b = np.stack([sd, mxd, myd], -1)
    # a plane needs points off one line: the determinant against its scale
    good = np.linalg.det(a) > 1e-6 * np.maximum(s0, 1) ** 3
    a[~good] = np.eye(3)
    return np.where(good, np.linalg.solve(a, b[..., None])[..., 0, 0], np.nan)


def unfatten(disp: np.ndarray, guide: np.ndarray, cost, *, trusted: np.ndarray | None = None,
             radius: int = HALO_RADIUS, jump: float = HALO_JUMP,
             tol: float = HALO_TOL) -> np.ndarray:
    """Step 7: undo foreground fattening. ``disp`` (H, W) float32, ``guide``
    (H, W, 3) the reference view in [0, 1], ``cost(d)`` the cost (H, W) of a
    per-pixel disparity map ``d``; ``trusted`` (H, W) bool, the pixels whose
    estimate may be passed on (default all). A pixel takes ``far``, the
    least trusted disparity within ``radius`` px (the farthest surface
    nearby), where

    - ``disp - far > jump`` (a depth edge within reach),
    - its colour is nearer (L1 in ``guide``) to the mean colour of the
      window's far-side pixels (pixels with a depth edge in their own
      window, within ``tol`` of its least disparity) than to that of the
      near-side pixels (within ``tol`` of its greatest): the pixel looks like
      the background,
    - and ``cost(far) <= cost(disp)``: the data accept the far disparity.

    Returns (H, W) float32.

    >>> d = np.full((20, 40), 0.2, np.float32); d[:, :24] = 1.5    # 4 px fattened
    >>> g = np.full((20, 40, 3), 0.1, np.float32); g[:, :20] = 0.8  # the true edge: x = 20
    >>> flat = lambda m: np.zeros(m.shape, np.float32)   # a textureless scene: all ties
    >>> out = unfatten(d, g, flat, radius=6)
    >>> [round(float(out[10, x]), 2) for x in (19, 21, 23)]
    [1.5, 0.2, 0.2]
    """
    import cv2

    side = 2 * radius + 1
    kernel = np.ones((side, side), np.uint8)
    if trusted is None:
        trusted = np.ones(disp.shape, bool)
    # the farthest and nearest *trusted* disparities nearby: an unsure pixel
    # (a textureless patch, estimated anywhere) must not pull others with it
    big = np.float32(np.abs(disp).max() + 1)
    far = cv2.erode(np.where(trusted, disp, big).astype(np.float32), kernel)
    near = cv2.dilate(np.where(trusted, disp, -big).astype(np.float32), kernel)
    suspect = ((disp - far) > jump) & (far < big)
    if not suspect.any():
        return disp

    def mean_colour(member):
        m = member.astype(np.float32)
        total = cv2.boxFilter(guide * m[..., None], -1, (side, side), normalize=False)
        count = cv2.boxFilter(m, -1, (side, side), normalize=False)
        return total / np.maximum(count, 1e-6)[..., None]

    # the sides: pixels next to a depth edge of their own, on its far / near side
    edge = trusted & ((near - far) > jump) & (far < big) & (near > -big)
    to_far = np.abs(guide - mean_colour(edge & (disp <= far + tol))).sum(-1)
    to_near = np.abs(guide - mean_colour(edge & (disp >= near - tol))).sum(-1)
    suspect &= to_far < to_near
    if not suspect.any():
        return disp
    far = np.where(suspect, far, disp).astype(np.float32)   # no far shifts where unused
    flip = suspect & (cost(far) <= cost(disp))
    return np.where(flip, far, disp).astype(np.float32)


def despeckle(disp: np.ndarray, *, size: int = SPECKLE, jump: float = HALO_JUMP) -> np.ndarray:
    """Step 7b: a pixel farther than ``jump`` (px/view, the depth-edge step
    of steps 6b-8) from the median of its ``size`` x ``size`` window (3 or 5)
    takes that median. Such a pixel is a speck: a surface holds no
    structure smaller than half the window, and a median is unbiased on a
    plane (any slant) and keeps a straight or convex depth edge. The specks
    come from flat cost curves (dark, weakly textured, quantised surfaces)
    that steps 6-7 leave alone or make (step 7 passes a far speck on to its
    neighbours). ``disp`` (H, W); returns (H, W) float32.

    >>> d = np.add.outer(0.05 * np.arange(12), np.zeros(12)).astype(np.float32)
    >>> d[6, 6] = -1.0; d[:, 9:] = 2.5                  # a speck; a depth edge
    >>> out = despeckle(d)
    >>> round(float(out[6, 6]), 2), float(out[6, 9]), bool((out[:, :6] == d[:, :6]).all())
    (0.3, 2.5, True)
    """
    import cv2

    disp = np.ascontiguousarray(disp, np.float32)
    med = cv2.medianBlur(disp, size)       # float input: 3 or 5 only
    return np.where(np.abs(disp - med) > jump, med, disp).astype(np.float32)


def soften(disp: np.ndarray, guide: np.ndarray, *, radius: int = SOFT_RADIUS,
           jump: float = HALO_JUMP, tol: float = SOFT_TOL, snap: float = SOFT_SNAP,
           min_contrast: float = SOFT_CONTRAST) -> np.ndarray:
    """Step 8: mixed pixels at depth edges. A pixel on a depth edge (its 3 x 3
    neighbourhood spans more than ``jump``) sees a blend of the near and the
    far surface; the data cannot place the edge within it (every view sees
    the same blend at the near disparity), and a hard choice is off by the
    whole jump. Its colour in ``guide`` (H, W, 3), projected onto the line
    from the far side's mean colour to the near side's (pixels within
    ``radius`` px next to a depth edge, within ``tol`` of the window's least /
    greatest disparity, as in :func:`unfatten`), gives the mixing fraction
    ``a`` in [0, 1] (snapped to 0 or 1 within ``snap``); the disparity
    becomes ``a near3 + (1 - a) far3`` over the 3 x 3 neighbourhood: the
    least-squares estimate for a blended pixel. Skipped where the sides'
    colours differ by less than ``min_contrast``. Returns (H, W) float32.

    >>> d = np.full((9, 12), 0.2, np.float32); d[:, :6] = 1.2          # edge at x = 6
    >>> g = np.full((9, 12, 3), 0.1, np.float32); g[:, :6] = 0.9
    >>> g[:, 5] = 0.5                                                  # a half-mixed pixel
    >>> [round(float(x), 2) for x in soften(d, g, radius=3)[4, 4:8]]
    [1.2, 0.8, 0.2, 0.2]
    """
    import cv2

    k3 = np.ones((3, 3), np.uint8)
    side = (2 * radius + 1, 2 * radius + 1)
    lo3, hi3 = cv2.erode(disp, k3), cv2.dilate(disp, k3)
    far = cv2.erode(disp, np.ones(side, np.uint8))
    near = cv2.dilate(disp, np.ones(side, np.uint8))

    def mean_colour(member):
        m = member.astype(np.float32)
        total = cv2.boxFilter(guide * m[..., None], -1, side, normalize=False)
        count = cv2.boxFilter(m, -1, side, normalize=False)
        return total / np.maximum(count, 1e-6)[..., None], count

    edge = (near - far) > jump
    c_far, n_far = mean_colour(edge & (disp <= far + tol))
    c_near, n_near = mean_colour(edge & (disp >= near - tol))
    axis = c_near - c_far
    norm2 = (axis * axis).sum(-1)
    a = np.clip(((guide - c_far) * axis).sum(-1) / np.maximum(norm2, 1e-12), 0, 1)
    a = np.where(a < snap, 0, np.where(a > 1 - snap, 1, a))
    ok = ((hi3 - lo3) > jump) & (norm2 > min_contrast ** 2) & (n_far > 0) & (n_near > 0)
    return np.where(ok, a * hi3 + (1 - a) * lo3, disp).astype(np.float32)


def estimate_disparity(lf: LightField, slopes, *, views=None, occlusion: bool = True,
                       radius: int = RADIUS, eps: float = EPS, stride: int = STRIDE,
                       median_radius: int = MEDIAN_RADIUS,
                       halo_radius: int = HALO_RADIUS,
                       soft_edges: bool = True) -> DisparityEstimate:
    """Disparity of the centre view (px per view step) with confidence.

    Coarse to fine: the cost volume is built over every ``stride``-th
    candidate; each pixel's winner is then refined on the full candidate grid
    (the costs of its two fine neighbours and itself, sampled per pixel with
    ``cv2.remap``, and one more so the parabola is centred on the least) by a
    parabola. This needs ``N / stride + 4`` passes over
    the views instead of ``N``; it assumes the cost curve, sampled every
    ``stride`` candidates, still has its least value next to the true one.

    Parameters
    ----------
    lf : LightField
        Views ``(U, V, H, W, C)``; any grid of at least 2 views.
    slopes : sequence of float
        Candidate disparities, increasing, at least 3
        (:func:`~lumigraph.lightfield.refocus.check_disparity_slopes`); the
        sub-pixel fit resolves well below their spacing.
    views : (U, V) bool, optional
        Views to use (a cross: the central row and column); default all.
    occlusion : bool
        Min over half-apertures (True) or the mean over all views.
    radius, eps : guided-filter radius (px) and regulariser.
    stride : int
        Coarse step, in candidates (1: every candidate, no refinement pass).
    median_radius : int
        Weighted-median radius (px); 0 skips the refinement.
    halo_radius : int
        Reach (px) of the fattening check (step 7, :func:`unfatten`); 0
        skips it.
    soft_edges : bool
        Step 8 (:func:`soften`): mixed pixels at depth edges get a
        disparity between the two sides' by their colour (lower squared
        error; False keeps every pixel on one surface, for triangulation
        without "flying pixels").

    Returns
    -------
    DisparityEstimate
        ``disparity`` and ``confidence`` (H, W) float32, ``slopes``.
    """

    slopes = check_disparity_slopes(slopes)
    if not isinstance(stride, (int, np.integer)) or stride < 1:
        raise InputError("stride", f"must be a whole number >= 1, got {stride!r}")
    n = len(slopes)
    slice_cost, guide = _matcher(lf, views=views, occlusion=occlusion, radius=radius, eps=eps)
    sub = np.arange(0, n, stride)
    if sub[-1] != n - 1:
        sub = np.append(sub, n - 1)
    cost = np.stack([slice_cost(float(slopes[k])) for k in sub])
    if len(sub) >= 3:
        disp, conf = winner(cost, slopes[sub])
    else:
        disp, conf = np.zeros(cost.shape[1:], np.float32), np.zeros(cost.shape[1:], np.float32)
    if len(sub) < n:
        del cost
        # fine samples one fine step either side of the coarse estimate: every
        # pixel of a surface is sampled at nearly its neighbours' disparities,
        # so the guided filter mixes like with like
        steps = np.diff(slopes)
        h = steps[np.clip(np.searchsorted(slopes, disp), 1, n - 1) - 1].astype(np.float32)
        c = np.stack([slice_cost(disp + o * h) for o in (-1, 0, 1)])
        # centre the parabola on the least sample: the fit is biased when the
        # minimum lies off the middle one (the curve is V- not parabola-shaped);
        # the missing fourth sample costs one pass, per pixel
        m = c.argmin(0) - 1
        far = slice_cost(disp + 2 * m * h)
        c = np.concatenate([far[None], c, far[None]])     # offsets -2 .. 2 (the ends: far)
        at = lambda o: np.take_along_axis(c, (m + o + 2)[None], 0)[0]  # noqa: E731
        disp = _refine(at(-1), at(0), at(1), disp + m * h, h)
        disp = np.clip(disp, slopes[0], slopes[-1]).astype(np.float32)
    else:
        del cost
    if median_radius > 0:
        disp = refill(disp, conf, guide, radius=median_radius)
    if halo_radius > 0:
        # on the unfiltered cost (the guided filter is itself a source of
        # fattening); repeated, since a flipped pixel can expose the next
        trusted = conf >= np.quantile(conf, UNSURE)
        raw = lambda d: slice_cost(d, filtered=False)  # noqa: E731
        for _ in range(HALO_PASSES):
            disp = unfatten(disp, guide, raw, trusted=trusted, radius=halo_radius)
    if SPECKLE > 0:
        disp = despeckle(disp, size=SPECKLE)
    if soft_edges and SOFT_RADIUS > 0:
        disp = soften(disp, guide)
    return DisparityEstimate(np.ascontiguousarray(disp, np.float32), conf, slopes)
