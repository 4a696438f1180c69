"""Sand & Teller 2004, "Video Matching" (ACM TOG 23(3), doi:10.1145/1015706.1015765),
as reference §5.1.4 (Figs. 5.6, 5.7) describes it.

Correspondence between two takes of a similar scene that differ in lighting,
in added or removed objects and by a small camera shift. The paper's
*primary* image is our ``reference`` (the field is given on its pixels), its
*secondary* our ``moving``:

1. **Pixel matching** against the 3x3 maximum and minimum images of the
   secondary image (Fig. 5.7): the cost of offset (u, v) at a pixel is
   ``sum_R sum_channels max(0, I - Imax(x+u, y+v), Imin(x+u, y+v) - I)``
   (the unnumbered equation of §5.1.4), zero wherever the primary value lies
   within the secondary's local range, so half-pixel misalignment and
   sampling costs nothing. We match locally contrast-normalised images
   ``(I - G*I) / sqrt(G*(I - G*I)^2 + eps^2)`` so that lighting changes
   (gain, offset, smooth shading) cancel; the reference leaves this
   preprocessing to "other techniques from computer vision".
2. **Matching probability** per pixel from the best cost and how distinct it
   is among the candidates; pixels that match nothing get ~0.
3. **Feature-rich regions only**: offsets are recorded where the primary has
   two-dimensional texture (the structure tensor's smaller eigenvalue well
   above that of the image noise) — corners and edges, not flat areas.
4. **Motion consistency**: a locally weighted linear regression of the
   offsets, weighted by probability x a Gaussian of distance, gives a smooth
   field (a local affine fit per pixel, so no global projective model and no
   distortion correction are assumed).
5. **Iterate**: the probabilities are recomputed around the smoothed field
   (matches far from it are down-weighted) and the regression redone, until
   the field stops changing. Coarse-to-fine over a pyramid for reach.

Two additions (``init="pyramid"``, the default; ``init="none"`` is the
plain method above): the field starts from a brightness-invariant pyramid
flow (:func:`invariant_pyramid_flow`) instead of zero, which reaches an
independently moving object that has too few feature points to pull the
coarse regression its way; and after the iterations every pixel keeps the
regressed field or the start, whichever has the lower matching cost, so the
regression kernel no longer blends the two sides of a motion boundary.

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
# contrast (the images are normalised), summed over channels; a mean excess of
# 0.1 contrast units over the secondary's 3x3 range is a doubtful match.
MATCH_SCALE = 0.1
SUPPORT_HALF = 2.0
SELECT_REGION = 9


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    v, w = values.ravel(), weights.ravel()
    order = np.argsort(v)
    cw = np.cumsum(w[order])
    return float(v[order][np.searchsorted(cw, 0.5 * cw[-1])])


def _as_float(image: np.ndarray) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3:
        raise ValueError(f"image: expected (H, W) or (H, W, C), got {a.shape}")
    out = a[..., :3].astype(np.float32)
    if a.dtype.kind in "ui":
        out /= float(np.iinfo(a.dtype).max)
    return np.ascontiguousarray(out)


INITS = ("pyramid", "none")


def invariant_pyramid_flow(reference: np.ndarray, moving: np.ndarray, *,
                           levels: int | str = "auto", max_motion_px: float | None = None):
    """A brightness-invariant start for the matching: coarse-to-fine pyramid
    flow (:func:`stereo.pyramid_flow.pyramid_flow`, with its colour-guided
    weighted median, radius 10) on the locally contrast-normalised gray
    images, so gain, offset and smooth shading do not break brightness
    constancy. Normalised values (contrast units, mostly within +-4) are
    mapped to [0, 1] as ``0.5 + n / 8``.

    Returns
    -------
    FlowResult
        Of :func:`stereo.pyramid_flow.pyramid_flow` (``levels`` and the
        level choice as there).
    """
    from lumigraph.stereo.pyramid_flow import pyramid_flow

    n = [np.clip(0.5 + normalise_contrast(luma_normalised(x)[..., None])[..., 0] / 8, 0, 1)
         .astype(np.float32) for x in (reference, moving)]
    return pyramid_flow(n[0], n[1], levels=levels, max_motion_px=max_motion_px, median_radius=10,
                        consistency=False)


def normalise_contrast(image: np.ndarray, *, sigma: float = 3.0, eps: float = 0.01) -> np.ndarray:
    """Local contrast normalisation per channel: removes gain, offset and
    smooth shading (any change slower than ``sigma`` pixels).

    Examples
    --------
    >>> x = np.random.default_rng(1).random((20, 20, 1)).astype(np.float32)
    >>> bool(np.allclose(normalise_contrast(x), normalise_contrast(3 * x + 0.2), atol=0.05))
    True
    """
    import cv2

    img = np.asarray(image, np.float32)
    hp = img - cv2.GaussianBlur(img, (0, 0), sigma).reshape(img.shape)
    var = cv2.GaussianBlur(hp * hp, (0, 0), sigma).reshape(img.shape)
    return (hp / np.sqrt(var + eps * eps)).astype(np.float32)


def _minmax(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 3x3 maximum and minimum images (Fig. 5.7)."""
    import cv2

    k = np.ones((3, 3), np.uint8)
    mx = cv2.dilate(img, k, borderType=cv2.BORDER_REPLICATE).reshape(img.shape)
    mn = cv2.erode(img, k, borderType=cv2.BORDER_REPLICATE).reshape(img.shape)
    return mx, mn


def _cost(n0, mx1, mn1, field, *, region):
    """Per-pixel matching cost of the offsets ``field`` (mean over ``region``)."""
    import cv2

    h, w = n0.shape[:2]
    X, Y = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    mx_x, my_x = X + field[..., 0], Y + field[..., 1]
    hi = cv2.remap(mx1, mx_x, my_x, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    lo = cv2.remap(mn1, mx_x, my_x, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    hi, lo = hi.reshape(n0.shape), lo.reshape(n0.shape)
    c = np.maximum(0.0, np.maximum(n0 - hi, lo - n0)).sum(axis=2)
    return cv2.boxFilter(c, -1, (region, region), borderType=cv2.BORDER_REFLECT)


def _features(gray: np.ndarray, *, window: int = 5) -> np.ndarray:
    """Feature-rich pixels: the structure tensor's smaller eigenvalue above
    25x what image noise alone gives (sigma^2 / 2 for central differences)."""
    import cv2

    k = np.array([[-0.5, 0.0, 0.5]], np.float32)
    gx = cv2.filter2D(gray, -1, k, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.filter2D(gray, -1, k.T, borderType=cv2.BORDER_REPLICATE)
    box = (window, window)
    jxx, jxy, jyy = (cv2.boxFilter(a, -1, box) for a in (gx * gx, gx * gy, gy * gy))
    lam = 0.5 * (jxx + jyy - np.sqrt((jxx - jyy) ** 2 + 4 * jxy * jxy))
    sigma = max(noise_sigma_immerkaer(gray), 1.0 / 1024)
    return lam > 25 * sigma * sigma / 2


def weighted_regression(offsets: np.ndarray, weights: np.ndarray, *, sigma: float,
                        ridge: float = 1e-4) -> np.ndarray:
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
    import cv2

    h, w = weights.shape
    wgt = np.asarray(weights, np.float64)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)

    def g(a):
        return cv2.GaussianBlur(a, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)

    # Moments about each pixel: sum w (x - x0)^k ... from moments about 0.
    s = g(wgt)
    sx, sy = g(wgt * xx), g(wgt * yy)
    sxx, sxy, syy = g(wgt * xx * xx), g(wgt * xx * yy), g(wgt * yy * yy)
    mx, my = sx - xx * s, sy - yy * s
    mxx = sxx - 2 * xx * sx + xx * xx * s
    myy = syy - 2 * yy * sy + yy * yy * s
    mxy = sxy - xx * sy - yy * sx + xx * yy * s
    lam = ridge * sigma * sigma * s + 1e-12
    A = np.stack([np.stack([s + 1e-12, mx, my], -1),
                  np.stack([mx, mxx + lam, mxy], -1),
                  np.stack([my, mxy, myy + lam], -1)], -2)
    out = np.empty((h, w, 2), np.float32)
    for c in range(2):
        d = np.asarray(offsets[..., c], np.float64)
        su, sux, suy = g(wgt * d), g(wgt * d * xx), g(wgt * d * yy)
        rhs = np.stack([su, sux - xx * su, suy - yy * su], -1)
        out[..., c] = np.linalg.solve(A, rhs[..., None])[..., 0, 0]
    return out


def _match(n0, mx1, mn1, field, *, radius, region, prior_px):
    """Best integer offset around ``field`` per pixel, its cost, a sub-pixel
    parabola refinement, and the mean cost over all candidates."""
    h, w = n0.shape[:2]
    offs = [(dx, dy) for dy in range(-radius, radius + 1) for dx in range(-radius, radius + 1)]
    costs = np.empty((len(offs), h, w), np.float32)
    for i, (dx, dy) in enumerate(offs):
        costs[i] = _cost(n0, mx1, mn1, field + np.float32([dx, dy]), region=region)
    mean = costs.mean(axis=0)
    if prior_px is not None:
        # Motion consistency: candidates far from the smoothed field cost more.
        d2 = np.array([dx * dx + dy * dy for dx, dy in offs], np.float32)[:, None, None]
        costs = costs + mean[None] * (1 - np.exp(-d2 / (2 * prior_px ** 2)))
    k = np.argmin(costs, axis=0)
    best = np.take_along_axis(costs, k[None], 0)[0]
    side = 2 * radius + 1
    bx, by = k % side, k // side
    sub = np.zeros((h, w, 2), np.float32)
    for axis, (b, step) in enumerate(((bx, 1), (by, side))):
        inner = (b > 0) & (b < side - 1)
        kk = np.clip(k, step, len(offs) - 1 - step)
        cm = np.take_along_axis(costs, (kk - step)[None], 0)[0]
        cp = np.take_along_axis(costs, (kk + step)[None], 0)[0]
        den = cm - 2 * best + cp
        ok = inner & (den > 1e-9)
        sub[..., axis] = np.where(ok, np.clip(0.5 * (cm - cp) / np.where(ok, den, 1), -0.5, 0.5), 0)
    off = np.stack([bx - radius, by - radius], -1).astype(np.float32) + sub
    return field + off, best, mean


def video_matching(reference: np.ndarray, moving: np.ndarray, *, levels: int | str = "auto",
                   max_motion_px: float | None = None, region: int = 5,
                   regression_sigma: float = 9.0, max_iterations: int = 6, tol_px: float = 0.02,
                   radius: int = 2, init: str = "pyramid",
                   initial_flow: np.ndarray | None = None) -> FlowResult:
    """Sand-Teller correspondence field from ``reference`` to ``moving``.

    Parameters
    ----------
    reference, moving : ndarray, ``(H, W)`` or ``(H, W, 3)``
        The paper's primary and secondary takes: the field is given on the
        reference's pixels and points into the moving image. uint8/uint16
        codes or float; same shape. Colour channels are matched
        independently and their costs summed.
    levels : int or "auto"
        Pyramid levels, 1..12 (:func:`stereo.pyramid.check_levels`);
        ``"auto"`` from ``max_motion_px`` or a phase-correlation estimate, as
        :func:`stereo.pyramid_flow.pyramid_flow`.
    region : int
        Side of the region R of the matching cost, pixels.
    regression_sigma : float
        Kernel width of the locally weighted regression, pixels of each level.
    max_iterations : int
        Match/regress rounds per level at most; stops earlier when the
        field's mean change is below ``tol_px``.
    radius : int
        Search radius around the current field at each level below the top.
    init : {"pyramid", "none"}
        Start of the field. ``"pyramid"`` (default):
        :func:`invariant_pyramid_flow`, then matching and regression at full
        size only, and finally every pixel keeps whichever of the regressed
        field and the start has the lower matching cost (a per-pixel
        refinement against the cost: the regression kernel blends the two
        sides of a motion boundary). ``"none"``: the paper's coarse-to-fine
        start from zero offsets.
    initial_flow : ndarray, ``(H, W, 2)``, optional
        A start field given by the caller (overrides ``init``).

    Returns
    -------
    FlowResult
        ``flow`` the correspondence field ``(H, W, 2)`` float32 (reference ->
        moving), ``confidence`` the per-pixel matching probability of that
        field in [0, 1], ``occluded`` where it is below 0.5.
    """
    import cv2

    t0 = time.perf_counter()
    a, b = np.asarray(reference), np.asarray(moving)
    if a.shape != b.shape:
        raise ValueError(f"moving: expected the shape of reference {a.shape}, got {b.shape}")
    if a.size == 0 or min(a.shape[:2]) < 8:
        raise ValueError(f"reference: expected at least 8x8 pixels, got {a.shape}")
    if region < 1 or region % 2 == 0:
        raise ValueError(f"region: expected an odd size >= 1, got {region}")
    if regression_sigma <= 0:
        raise ValueError(f"regression_sigma: expected > 0, got {regression_sigma}")
    if init not in INITS:
        raise ValueError(f"init: expected one of {INITS}, got {init!r}")
    levels = check_levels(levels)
    fa, fb = _as_float(a), _as_float(b)
    g0 = luma_normalised(fa)
    start_result = None
    if init == "pyramid" and initial_flow is None:
        start_result = invariant_pyramid_flow(fa, fb, levels=levels, max_motion_px=max_motion_px)
        initial_flow = start_result.flow
    if initial_flow is not None:
        # The start already spans the large motions: match at full size only.
        levels = 1
    if levels == "auto":
        if max_motion_px is None:
            est, _tiles = estimate_max_motion(g0, luma_normalised(fb))
            source = "estimated"
        else:
            est, source = float(max_motion_px), "given"
        choice = choose_levels(g0.shape, max_motion_px=est, reach_px=5.0, source=source)
        n_levels, choice_d = choice.levels, choice.to_dict()
    else:
        n_levels, est = levels, None
        choice_d = {"levels": n_levels, "source": "given"}
    p0, p1 = build_pyramid(fa, n_levels), build_pyramid(fb, n_levels)
    field = np.zeros(p0[-1].shape[:2] + (2,), np.float32)
    start = None
    if initial_flow is not None:
        start = np.asarray(initial_flow, np.float32)
        if start.shape != fa.shape[:2] + (2,):
            raise ValueError(f"initial_flow: expected {fa.shape[:2] + (2,)}, got {start.shape}")
        field = upsample_flow(start, p0[-1].shape[:2])
    history = []
    for lvl in range(n_levels - 1, -1, -1):
        if lvl < n_levels - 1:
            field = upsample_flow(field, p0[lvl].shape[:2])
        n0 = normalise_contrast(p0[lvl].reshape(p0[lvl].shape[:2] + (-1,)))
        n1 = normalise_contrast(p1[lvl].reshape(p1[lvl].shape[:2] + (-1,)))
        mx1, mn1 = _minmax(n1)
        feat = _features(luma_normalised(p0[lvl]))
        top = lvl == n_levels - 1
        r = radius
        if top and est is not None:
            r = int(min(6, max(radius, np.ceil(est / 2 ** (n_levels - 1)) + 1)))
        prior = None
        for it in range(max_iterations):
            matched, best, mean = _match(n0, mx1, mn1, field, radius=r, region=region,
                                         prior_px=prior)
            # Probability: a good absolute match that is also distinct from
            # the other candidates; features only.
            distinct = np.clip(1 - best / np.maximum(mean, 1e-6), 0, 1)
            prob = np.exp(-best / MATCH_SCALE) * distinct * feat
            sig = max(2.0, regression_sigma / 2 ** lvl)
            fit = weighted_regression(matched, prob, sigma=sig)
            if top and it == 0 and initial_flow is None:
                # No coarser level to inherit from: start flat areas at the
                # dominant (probability-weighted median) offset.
                wsum = prob.sum()
                base = (np.float32([_weighted_median(matched[..., c], prob) for c in (0, 1)])
                        if wsum > 0 else np.zeros(2, np.float32))
                field = np.broadcast_to(base, field.shape).astype(np.float32)
            # Where the kernel holds little matching evidence (flat areas),
            # keep the field inherited from the coarser level: support is the
            # kernel-weighted probability mass, SUPPORT_HALF the mass (about
            # two confident matches) at which fit and inherited field weigh equally.
            support = cv2.GaussianBlur(prob.astype(np.float32), (0, 0), sig) * (2 * np.pi * sig * sig)
            wfit = (support / (support + SUPPORT_HALF))[..., None]
            new = (wfit * fit + (1 - wfit) * field).astype(np.float32)
            change = float(np.mean(np.hypot(*(new - field).transpose(2, 0, 1))))
            field = new
            history.append({"level": lvl, "iteration": it, "radius": r,
                            "mean_change_px": change, "features": float(feat.mean()),
                            "mean_probability": float(prob[feat].mean()) if feat.any() else 0.0})
            prior, r = 1.5, radius
            if change < tol_px * 2 ** lvl:
                break
    # Final probability of the field at every pixel (not only features): the
    # cost at the field itself against the typical feature cost.
    n0 = normalise_contrast(fa)
    mx1, mn1 = _minmax(normalise_contrast(fb))
    if start is not None:
        # Final per-pixel refinement against the matching cost: the regression
        # blends the two sides of a motion boundary within its kernel; where
        # the starting field matches better (the Sand-Teller cost over a 9x9
        # region, robust to the lighting change), that pixel keeps it.
        cands = np.stack([field, start])
        costs = np.stack([_cost(n0, mx1, mn1, f, region=SELECT_REGION) for f in cands])
        keep = np.argmin(costs, 0)
        field = np.take_along_axis(cands, keep[None, ..., None], 0)[0]
        info_select = {"start_kept_fraction": float(keep.mean())}
    else:
        info_select = {}
    c = _cost(n0, mx1, mn1, field, region=region)
    tau = max(float(np.median(c)), 1e-3)
    prob = np.exp(-np.log(2) * (c / (2 * tau)) ** 2).astype(np.float32)  # 0.5 at twice typical
    info = {"method": "sand2004", "level_choice": choice_d, "region": region,
            "regression_sigma": regression_sigma, "init": init, "iterations": history,
            **info_select,
            "quality": {"mean_probability": float(prob.mean()),
                        "unmatched_fraction": float((prob < 0.5).mean())},
            "timings_s": {"total": time.perf_counter() - t0}}
    if start_result is not None:
        # The pyramid that reached the large motions is the start's.
        n_levels = start_result.levels
        info["level_choice"] = start_result.info["level_choice"]
    return FlowResult(field.astype(np.float32), prob, prob < 0.5, n_levels, info)
