"""Coarse-to-fine pyramid optical flow (reference §5.1.3, eq. 5.1, Fig. 5.5).

At every pyramid level, from the top, the moving image is warped onto the
reference by the current flow and the windowed sum of squared differences of
eq. 5.1 is minimised by its Gauss-Newton (Lucas-Kanade) step: with the structure tensor
``J = sum_w [Ix^2, IxIy; IxIy, Iy^2]`` and ``b = sum_w It [Ix, Iy]`` the update
is ``-J^-1 b`` (Lucas & Kanade 1981; Bouguet's pyramidal form). The refined
field is doubled and copied to the next finer level (Fig. 5.5, left).

``method="dense"`` adds a smoothness term, the combined local-global energy
``sum w^T J_rho w + alpha |grad u|^2 + alpha |grad v|^2`` (Bruhn, Weickert,
Schnörr 2005, doi:10.1023/B:VISI.0000045324.43199.43), solved per warp by
Jacobi sweeps: textureless areas get the flow of their surroundings instead of
an unconstrained local solve.

After each warp a 3x3 median removes isolated outliers; with
``median_radius > 0`` each level ends with the colour-guided weighted median
of Sun, Roth & Black 2010 (doi:10.1109/CVPR.2010.5539939), which keeps motion
boundaries where the image has them. ``finest_level`` stops the refinement
above full size for speed.

Both run forward and (with ``consistency=True``) backward; the
forward-backward round trip gives the occlusion mask, and the smallest
eigenvalue of ``J`` against the image's own noise gives the texture
confidence (a textureless window's ``J`` is noise only).

Examples
--------
>>> import cv2
>>> rng = np.random.default_rng(0)
>>> a = cv2.GaussianBlur(rng.random((64, 80)).astype(np.float32), (0, 0), 2)
>>> b = np.roll(a, (1, 3), axis=(0, 1))          # moving = reference shifted by (3, 1)
>>> r = pyramid_flow(a, b, levels="auto")
>>> np.round(np.median(r.flow[8:-8, 8:-8], axis=(0, 1)), 1).tolist(), r.levels
([3.0, 1.0], 3)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.stereo.luma import luma_normalised, noise_sigma_immerkaer
from lumigraph.stereo.pyramid import (
    build_pyramid,
    check_levels,
    choose_levels,
    estimate_max_motion,
    forward_backward,
    upsample_flow,
    warp,
)

METHODS = ("local", "dense")
MAX_MEDIAN_RADIUS = 64  # px; the weighted median costs O(radius²) per pixel
# Range sigma (uint8 guide levels) of the weighted median: neighbours differing
# by more than ~2 sigma in colour get little weight.
WMF_SIGMA = 25.5
# Motion a level's Gauss-Newton steps are trusted to resolve (px): "auto"
# adds levels until the top is left with at most this, which also keeps the
# exhaustive top-level search small (its cost grows with radius^2 x area).
REACH_PX = 1.5


@dataclass(frozen=True)
class FlowResult:
    """A dense forward flow field with its confidence.

    Attributes
    ----------
    flow : ndarray, float32, ``(H, W, 2)``
        Forward flow (dx, dy) in pixels, reference to moving:
        ``reference(x, y) <-> moving(x + dx, y + dy)``.
    confidence : ndarray, float32, ``(H, W)``
        In [0, 1]: texture confidence times forward-backward consistency for
        pyramid flow; the matching probability for video matching.
    occluded : ndarray, bool, ``(H, W)``
        Forward-backward inconsistent (occluded or unreliable); all False when
        the check was not run.
    levels : int
        Pyramid levels used.
    info : dict
        JSON-able diagnostics: the level choice with every candidate's score,
        iterations, timings, quality figures.
    """

    flow: np.ndarray
    confidence: np.ndarray
    occluded: np.ndarray
    levels: int
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        f = np.asarray(self.flow)
        if f.ndim != 3 or f.shape[2] != 2:
            raise ValueError(f"flow: expected (H, W, 2), got {f.shape}")
        if self.confidence.shape != f.shape[:2] or self.occluded.shape != f.shape[:2]:
            raise ValueError(f"confidence/occluded: expected {f.shape[:2]}, got "
                             f"{self.confidence.shape} and {self.occluded.shape}")
        if self.levels < 1:
            raise ValueError(f"levels: expected >= 1, got {self.levels}")

    def save(self, path, *, meta: dict) -> None:
        """Write ``path`` (Middlebury .flo, unknown = NaN) and the confidence
        as ``<path without .flo>.prob.exr`` (one float32 channel ``Y``), each
        with its ``.meta.json`` sidecar; the .flo (what make checks) last."""
        from pathlib import Path

        from lumigraph.capture import io
        from lumigraph.capture.artifact import write_artifact

        path = Path(path)
        prob = prob_path(path)
        write_artifact(prob, lambda p: io.write_exr(p, self.confidence.astype(np.float32)),
                       meta={**meta, "schema": meta.get("schema", "lumigraph.flow") + ".prob"})
        write_artifact(path, lambda p: io.write_flo(p, self.flow), meta=meta)


def prob_path(flo_path):
    """``flow.flo`` -> ``flow.prob.exr``: where the confidence/probability goes."""
    from pathlib import Path

    p = Path(flo_path)
    return p.with_name((p.name[:-4] if p.name.lower().endswith(".flo") else p.name) + ".prob.exr")


def _gradients(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import cv2

    # Central differences (the derivative the bilinear warp is consistent with).
    k = np.array([[-0.5, 0.0, 0.5]], np.float32)
    return (cv2.filter2D(img, -1, k, borderType=cv2.BORDER_REPLICATE),
            cv2.filter2D(img, -1, k.T, borderType=cv2.BORDER_REPLICATE))


def _box(a: np.ndarray, window: int) -> np.ndarray:
    import cv2

    return cv2.boxFilter(a, -1, (window, window), normalize=True, borderType=cv2.BORDER_REFLECT)


def _shifted(a: np.ndarray, dx: int, dy: int) -> np.ndarray:
    """``a`` sampled at ``(x + dx, y + dy)`` with replicated borders (an
    integer shift by slicing: no interpolation, no resampling cost)."""
    h, w = a.shape[:2]
    r = max(abs(dx), abs(dy))
    if r == 0:
        return a
    import cv2

    pad = cv2.copyMakeBorder(a, r, r, r, r, cv2.BORDER_REPLICATE)
    return pad[r + dy:r + dy + h, r + dx:r + dx + w]


def _hypotheses(i0, i1, flow, *, window):
    """Per pixel, keep the best of its own vector and those of the pixels
    ``window // 2 + 1`` away in the four axis directions, by the windowed SSD
    of eq. 5.1 after warping. Coarse levels smear the flow across motion
    boundaries further than a Gauss-Newton step can reach; a neighbour on the
    right side of the boundary carries the right vector (the propagation
    step of PatchMatch and DIS, here exhaustive over four neighbours)."""
    import cv2

    s = window // 2 + 1
    h, w = flow.shape[:2]
    best = flow.copy()
    # Bilinear is enough to rank hypotheses that differ by pixels. cv2's
    # element-wise ops: this runs at every level, including the full-size one.
    cost = _ssd(warp(i1, flow, cubic=False), i0, 5)
    pad = cv2.copyMakeBorder(flow, s, s, s, s, cv2.BORDER_REPLICATE)
    for dx, dy in ((s, 0), (-s, 0), (0, s), (0, -s)):
        cand = pad[s + dy:s + dy + h, s + dx:s + dx + w]
        c = _ssd(warp(i1, cand, cubic=False), i0, 5)
        better = cv2.compare(c, cost, cv2.CMP_LT)
        best = cv2.copyTo(np.ascontiguousarray(cand), better, best)
        cv2.min(cost, c, dst=cost)
    return best


def _ssd(a, b, window):
    """Windowed mean of ``(a - b)^2`` (eq. 5.1), in place on one temporary."""
    import cv2

    d = cv2.subtract(a, b)
    cv2.multiply(d, d, dst=d)
    return cv2.boxFilter(d, -1, (window, window), dst=d, borderType=cv2.BORDER_REFLECT)


def _search_top(i0, i1, *, radius, window):
    """Exhaustive integer search of eq. 5.1 at the top level, where "the
    offset vectors are computed directly" (reference §5.1.3): every offset
    within ``radius`` is tried and each pixel keeps its lowest windowed SSD."""
    import cv2

    h, w = i0.shape
    best = np.zeros((h, w, 2), np.float32)
    cost = np.full((h, w), np.inf, np.float32)
    pad = cv2.copyMakeBorder(i1, radius, radius, radius, radius, cv2.BORDER_REPLICATE)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            moved = pad[radius + dy:radius + dy + h, radius + dx:radius + dx + w]
            # A tiny penalty on the offset's length breaks ties toward no motion in flat areas.
            c = cv2.add(_ssd(moved, i0, window), 1e-7 * (dx * dx + dy * dy))
            better = cv2.compare(c, cost, cv2.CMP_LT)
            best[better.astype(bool)] = (dx, dy)
            cv2.min(cost, c, dst=cost)
    return best


def _median(flow, guide, radius):
    """Outlier removal after a warp (Sun, Roth, Black 2010,
    doi:10.1109/CVPR.2010.5539939): a 3x3 median, or with ``radius > 0`` their
    boundary-aware weighted median, each neighbour weighted by its colour
    similarity to the centre in ``guide`` (uint8), so a window straddling a
    motion boundary takes the median of the centre's own surface. The
    weighted median is cv2.ximgproc's constant-time joint-histogram filter
    (Zhang, Xu, Jia 2014, doi:10.1109/CVPR.2014.362)."""
    import cv2

    flow = np.ascontiguousarray(flow, np.float32)
    if radius <= 0 or guide is None:
        return cv2.medianBlur(flow, 3)
    three = np.dstack([flow, np.zeros(flow.shape[:2], np.float32)])
    # The filter draws from OpenCV's global generator (theRNG): unseeded, the
    # flow would depend on how much of the stream earlier calls in the process
    # used (two runs on the same frames differed). A fixed seed makes it depend
    # on its inputs alone; the caller's OpenCV stream restarts as a side effect.
    cv2.setRNGSeed(0)
    return np.ascontiguousarray(cv2.ximgproc.weightedMedianFilter(
        guide, three, radius, sigma=WMF_SIGMA)[..., :2])


def _refine_level(i0, i1, flow, *, window, iterations, alpha, sweeps, reg, guide=None,
                  median_radius=0):
    """Warped Gauss-Newton steps at one level; returns the refined flow and the
    structure tensor's smallest eigenvalue (for the confidence)."""
    import cv2

    g0x, g0y = _gradients(i0)
    cross = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], np.float32)
    lam_min = None
    for k in range(iterations):
        i1w = warp(i1, flow)
        g1x, g1y = _gradients(i1w)
        # Averaged gradients: the symmetric linearisation converges in fewer
        # steps. cv2 element-wise ops (SIMD, threaded) as everywhere per warp.
        gx = cv2.addWeighted(g0x, 0.5, g1x, 0.5, 0.0)
        gy = cv2.addWeighted(g0y, 0.5, g1y, 0.5, 0.0)
        it = cv2.subtract(i1w, i0)
        jxx, jxy, jyy = (_box(cv2.multiply(p, q), window) for p, q in ((gx, gx), (gx, gy), (gy, gy)))
        bx, by = _box(cv2.multiply(gx, it), window), _box(cv2.multiply(gy, it), window)
        if alpha <= 0:
            a11, a22 = cv2.add(jxx, reg), cv2.add(jyy, reg)
            det = cv2.subtract(cv2.multiply(a11, a22), cv2.multiply(jxy, jxy))
            du = cv2.divide(cv2.subtract(cv2.multiply(jxy, by), cv2.multiply(a22, bx)), det)
            dv = cv2.divide(cv2.subtract(cv2.multiply(jxy, bx), cv2.multiply(a11, by)), det)
        else:
            # Jacobi sweeps for (J + 4 alpha) d = alpha (S(u + d) - 4u) - b, S the 4-neighbour sum.
            al = np.float32(alpha)
            a11, a22 = jxx + (4 * al + np.float32(reg)), jyy + (4 * al + np.float32(reg))
            det = a11 * a22 - jxy * jxy
            u0, v0 = flow[..., 0], flow[..., 1]
            lap_u = cv2.filter2D(u0, -1, cross, borderType=cv2.BORDER_REPLICATE) - 4 * u0
            lap_v = cv2.filter2D(v0, -1, cross, borderType=cv2.BORDER_REPLICATE) - 4 * v0
            cu, cv_ = al * lap_u - bx, al * lap_v - by
            du = np.zeros_like(u0)
            dv = np.zeros_like(v0)
            for _s in range(sweeps):
                ru = cu + al * cv2.filter2D(du, -1, cross, borderType=cv2.BORDER_REPLICATE)
                rv = cv_ + al * cv2.filter2D(dv, -1, cross, borderType=cv2.BORDER_REPLICATE)
                du = (a22 * ru - jxy * rv) / det
                dv = (a11 * rv - jxy * ru) / det
        flow = cv2.add(flow, cv2.merge([du, dv]))
        # The weighted median is costly: once per level, after its last warp.
        flow = _median(flow, guide, median_radius if k == iterations - 1 else 0)
        if k == iterations - 1:
            tr, d2 = jxx + jyy, np.sqrt(np.maximum((jxx - jyy) ** 2 + 4 * jxy * jxy, 0))
            lam_min = 0.5 * (tr - d2)
    return flow, lam_min


def _one_way(g0, g1, *, levels, window, iterations, alpha, sweeps, radius, finest_iterations,
             finest_level=0, guide=None, median_radius=0):
    p0, p1 = build_pyramid(g0, levels), build_pyramid(g1, levels)
    guides = _guide_pyramid(guide, levels) if median_radius > 0 else [None] * levels
    flow = _search_top(p0[-1], p1[-1], radius=radius, window=min(window, 5))
    lam = None
    # Tikhonov term on the local solve: keeps a flat window's step small
    # instead of dividing noise by noise; far below any textured J.
    reg = 1e-5
    for lvl in range(levels - 1, min(finest_level, levels - 1) - 1, -1):
        if lvl < levels - 1:
            flow = upsample_flow(flow, p0[lvl].shape)
            flow = _hypotheses(p0[lvl], p1[lvl], flow, window=window)
        n_it = finest_iterations if lvl == finest_level else iterations
        flow, lam = _refine_level(p0[lvl], p1[lvl], flow, window=window, iterations=n_it,
                                  alpha=alpha, sweeps=sweeps, reg=reg, guide=guides[lvl],
                                  median_radius=max(1, round(median_radius / 2 ** lvl))
                                  if median_radius > 0 else 0)
    if flow.shape[:2] != g0.shape:
        # Stopped early (DIS's "finest scale"): bilinear upsampling to full
        # size; the texture confidence then comes from the reference's own
        # structure tensor at full size (gradients not averaged: noise
        # enters J twice as strongly, hence the factor 2 for lam_noise).
        flow = upsample_flow(flow, g0.shape)
        gx, gy = _gradients(g0)
        jxx, jxy, jyy = (_box(p * q, window) for p, q in ((gx, gx), (gx, gy), (gy, gy)))
        lam = 0.5 * (jxx + jyy - np.sqrt(np.maximum((jxx - jyy) ** 2 + 4 * jxy * jxy, 0))) / 2
    return flow.astype(np.float32), lam


def _guide_pyramid(image, levels):
    """uint8 guide images (colour where given) for the weighted median."""
    a = np.asarray(image)
    f = a.astype(np.float32) / (float(np.iinfo(a.dtype).max) if a.dtype.kind in "ui" else 1.0)
    if f.ndim == 3:
        f = np.ascontiguousarray(f[..., :3])
    return [np.clip(np.rint(p * 255), 0, 255).astype(np.uint8) for p in build_pyramid(f, levels)]


def check_options(*, levels: int | str = "auto", window: int = 9, iterations: int = 3,
                  finest_iterations: int | None = None, finest_level: int = 0,
                  median_radius: int = 0) -> int | str:
    """Check :func:`pyramid_flow`'s options (their ranges are documented
    there) before any image is read; returns ``levels`` as ``"auto"`` or an
    ``int`` (:func:`stereo.pyramid.check_levels`).

    Raises
    ------
    InputError
        Naming the first option out of its range.

    Examples
    --------
    >>> check_options(levels=3, finest_level=1)
    3
    >>> check_options(levels=2, finest_level=2)
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: finest_level: must be below levels (2), got 2
    """
    levels = check_levels(levels)
    if window < 3 or window % 2 == 0:
        raise InputError("window", f"expected an odd size >= 3, got {window}")
    if iterations < 1:
        raise InputError("iterations", f"expected >= 1, got {iterations}")
    if finest_iterations is not None and finest_iterations < 1:
        raise InputError("finest_iterations", f"expected >= 1, got {finest_iterations}")
    if not 0 <= median_radius <= MAX_MEDIAN_RADIUS:
        raise InputError("median_radius", f"expected 0..{MAX_MEDIAN_RADIUS} pixels, got {median_radius}")
    if finest_level < 0:
        raise InputError("finest_level", f"expected a level >= 0, got {finest_level}")
    if levels != "auto" and finest_level >= levels:
        raise InputError("finest_level", f"must be below levels ({levels}), got {finest_level}")
    return levels


def pyramid_flow(reference: np.ndarray, moving: np.ndarray, *, levels: int | str = "auto",
                 max_motion_px: float | None = None, method: str = "local", window: int = 9,
                 iterations: int = 3, finest_iterations: int | None = None,
                 finest_level: int = 0, alpha: float = 2e-3, sweeps: int = 20,
                 median_radius: int = 0,
                 consistency: bool = True) -> FlowResult:
    """Forward optical flow from ``reference`` to ``moving`` by coarse-to-fine warping.

    Parameters
    ----------
    reference, moving : ndarray, ``(H, W)`` or ``(H, W, 3)``
        The image the flow is given on, and the image it points into
        (``reference(x) <-> moving(x + flow(x))``). uint8/uint16 codes or
        float in [0, 1]; same shape. Converted to luma
        (:func:`lumigraph.stereo.luma.luma_normalised`).
    levels : int or "auto"
        Pyramid levels, 1..12 (:data:`stereo.pyramid.MAX_LEVELS`). ``"auto"``:
        the fewest levels whose top level leaves at most ``window // 2`` px of
        motion, from ``max_motion_px`` when given, else estimated by tiled
        phase correlation; every candidate's score is in
        ``info["level_choice"]``.
    max_motion_px : float, optional
        Expected largest motion (pixels) for ``levels="auto"``.
    method : {"local", "dense"}
        Local Lucas-Kanade solve, or the regularised (combined local-global)
        solve that fills textureless areas from their surroundings.
    window : int
        Odd side of the square window of eq. 5.1 (pixels, at every level),
        at least 3.
    iterations : int
        Warps per level, at least 1.
    finest_iterations : int, optional
        Warps at the finest (full-size) level, where each costs 4x the level
        above; default ``iterations``. One is usually enough there, the
        coarser levels having done the large steps.
    finest_level : int
        Pyramid level at which refinement stops (0: full size), ``>= 0`` and,
        when ``levels`` is given as a number, below it. At 1 the flow is
        solved at half size and upsampled, for about a quarter of the cost
        (the "finest scale" of DIS, Kroeger et al. 2016).
    alpha : float
        Smoothness weight of ``"dense"`` (intensities in [0, 1]).
    sweeps : int
        Jacobi sweeps per warp for ``"dense"``.
    median_radius : int
        0..64 (:data:`MAX_MEDIAN_RADIUS`). 0: a 3x3 median after each warp.
        > 0: after each level's last warp, the colour-guided weighted median
        of Sun, Roth & Black (radius in full-size pixels, halved per level),
        which pulls vectors smeared across a motion boundary back to their
        own surface; slower.
    consistency : bool
        Also compute the backward flow and mark forward-backward inconsistent
        pixels as occluded (doubles the cost).

    Returns
    -------
    FlowResult

    Raises
    ------
    ValueError
        Different shapes or empty images (named, with the value).
    InputError
        An option out of its range (:func:`check_options`, naming it).
    """
    t0 = time.perf_counter()
    a, b = np.asarray(reference), np.asarray(moving)
    if a.shape != b.shape:
        raise ValueError(f"moving: expected the shape of reference {a.shape}, got {b.shape}")
    if a.size == 0 or min(a.shape[:2]) < 4:
        raise ValueError(f"reference: expected at least 4x4 pixels, got {a.shape}")
    if method not in METHODS:
        raise InputError("method", f"expected one of {METHODS}, got {method!r}")
    if finest_iterations is None:
        finest_iterations = iterations
    levels = check_options(levels=levels, window=window, iterations=iterations,
                           finest_iterations=finest_iterations, finest_level=finest_level,
                           median_radius=median_radius)
    g0, g1 = luma_normalised(a), luma_normalised(b)
    if a.dtype.kind == "f":  # float input is taken as already in [0, 1]
        g0, g1 = g0.astype(np.float32), g1.astype(np.float32)
    reach = REACH_PX
    if levels == "auto":
        if max_motion_px is None:
            est, tiles = estimate_max_motion(g0, g1)
            choice = choose_levels(g0.shape, max_motion_px=est, reach_px=reach, source="estimated")
            choice_d = {**choice.to_dict(), "tiles": tiles}
        else:
            choice = choose_levels(g0.shape, max_motion_px=float(max_motion_px), reach_px=reach)
            choice_d = choice.to_dict()
        n_levels = choice.levels
    else:
        n_levels = levels
        choice_d = {"levels": n_levels, "source": "given"}
    # Search radius at the top level: the motion left there, plus a margin.
    top_motion = choice_d.get("max_motion_px", 2.0 * 2 ** (n_levels - 1)) / 2 ** (n_levels - 1)
    radius = int(min(6, max(1, np.ceil(top_motion) + 1)))
    choice_d["top_search_radius_px"] = radius
    opts = dict(levels=n_levels, window=window, iterations=iterations,
                alpha=alpha if method == "dense" else 0.0, sweeps=sweeps, radius=radius,
                finest_iterations=finest_iterations, finest_level=finest_level,
                median_radius=median_radius)
    fwd, lam = _one_way(g0, g1, guide=a, **opts)
    t_fwd = time.perf_counter() - t0
    # Texture confidence: lambda_min of J against that of pure noise. With
    # central differences a noise of sigma gives E[Ix^2] = sigma^2 / 2 per
    # image, and the averaged gradient halves that again: sigma^2 / 4.
    sigma = max(noise_sigma_immerkaer(g0), 1.0 / 1024)
    lam_noise = sigma ** 2 / 4
    tex = (lam / (lam + 25 * lam_noise)).astype(np.float32)
    occluded = np.zeros(g0.shape, bool)
    info = {"method": method, "level_choice": choice_d, "window": window,
            "iterations": iterations, "finest_iterations": finest_iterations,
            "finest_level": finest_level, "median_radius": median_radius,
            "noise_sigma": sigma}
    if method == "dense":
        info.update(alpha=alpha, sweeps=sweeps)
    if consistency:
        bwd, _ = _one_way(g1, g0, guide=b, **opts)
        occluded, rt = forward_backward(fwd, bwd)
        info["occluded_fraction"] = float(occluded.mean())
        info["median_round_trip_px"] = float(np.median(rt[np.isfinite(rt)])) if np.isfinite(rt).any() else None
    conf = np.where(occluded, 0.0, tex).astype(np.float32)
    resid = np.abs(warp(g1, fwd, cubic=False) - g0)
    info["quality"] = {"mean_abs_residual": float(resid[~occluded].mean()) if (~occluded).any()
                       else None, "mean_confidence": float(conf.mean())}
    info["timings_s"] = {"forward": t_fwd, "total": time.perf_counter() - t0}
    return FlowResult(fwd, conf, occluded, n_levels, info)
