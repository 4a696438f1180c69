"""Coarse-to-fine pyramid optical flow (reference §5.1.3, eq. 5.1, Fig. 5.5).

At every pyramid level, from the top, frame 1 is warped by the current flow
and the windowed sum of squared differences of eq. 5.1 is minimised by its
Gauss-Newton (Lucas-Kanade) step: with the structure tensor
``J = sum_w [Ix^2, IxIy; IxIy, Iy^2]`` and ``b = sum_w It [Ix, Iy]`` the update
is ``-J^-1 b`` (Lucas & Kanade 1981; Bouguet's pyramidal form). The refined
field is doubled and copied to the next finer level (Fig. 5.5, left).

``method="dense"`` adds a smoothness term, the combined local-global energy
``sum w^T J_rho w + alpha |grad u|^2 + alpha |grad v|^2`` (Bruhn, Weickert,
Schnörr 2005, doi:10.1023/B:VISI.0000045324.43199.43), solved per warp by
Jacobi sweeps: textureless areas get the flow of their surroundings instead of
an unconstrained local solve.

Both run forward and (with ``consistency=True``) backward; the
forward-backward round trip gives the occlusion mask, and the smallest
eigenvalue of ``J`` against the image's own noise gives the texture
confidence (a textureless window's ``J`` is noise only).

Examples
--------
>>> import cv2
>>> rng = np.random.default_rng(0)
>>> a = cv2.GaussianBlur(rng.random((64, 80)).astype(np.float32), (0, 0), 2)
>>> b = np.roll(a, (1, 3), axis=(0, 1))          # frame 1 = frame 0 moved by (3, 1)
>>> r = pyramid_flow(a, b, levels="auto")
>>> np.round(np.median(r.flow[8:-8, 8:-8], axis=(0, 1)), 1).tolist(), r.levels
([3.0, 1.0], 2)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from stereo.pyramid import (build_pyramid, choose_levels, estimate_max_motion, forward_backward,
                            noise_sigma, to_gray, upsample_flow, warp)

METHODS = ("local", "dense")


@dataclass(frozen=True)
class FlowResult:
    """A dense forward flow field with its confidence.

    Attributes
    ----------
    flow : ndarray, float32, ``(H, W, 2)``
        Forward flow (dx, dy) in pixels: ``I0(x, y) <-> I1(x + dx, y + dy)``.
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

        from capture import io
        from capture.artifact import write_artifact

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
    # Bilinear is enough to rank hypotheses that differ by pixels.
    cost = _box((warp(i1, flow, cubic=False) - i0) ** 2, 5)
    for dx, dy in ((s, 0), (-s, 0), (0, s), (0, -s)):
        M = np.float32([[1, 0, dx], [0, 1, dy]])
        cand = cv2.warpAffine(flow, M, (w, h), flags=cv2.INTER_NEAREST,
                              borderMode=cv2.BORDER_REPLICATE)
        c = _box((warp(i1, cand, cubic=False) - i0) ** 2, 5)
        better = c < cost
        best[better] = cand[better]
        cost[better] = c[better]
    return best


def _search_top(i0, i1, *, radius, window):
    """Exhaustive integer search of eq. 5.1 at the top level, where "the
    offset vectors are computed directly" (reference §5.1.3): every offset
    within ``radius`` is tried and each pixel keeps its lowest windowed SSD."""
    import cv2

    h, w = i0.shape
    best = np.zeros((h, w, 2), np.float32)
    cost = np.full((h, w), np.inf, np.float32)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            M = np.float32([[1, 0, -dx], [0, 1, -dy]])
            moved = cv2.warpAffine(i1, M, (w, h), flags=cv2.INTER_NEAREST,
                                   borderMode=cv2.BORDER_REPLICATE)
            # A tiny penalty on the offset's length breaks ties toward no motion in flat areas.
            c = _box((moved - i0) ** 2, window) + 1e-7 * (dx * dx + dy * dy)
            better = c < cost
            best[better] = (dx, dy)
            cost = np.where(better, c, cost)
    return best


def _refine_level(i0, i1, flow, *, window, iterations, alpha, sweeps, reg):
    """Warped Gauss-Newton steps at one level; returns the refined flow and the
    structure tensor's smallest eigenvalue (for the confidence)."""
    import cv2

    g0x, g0y = _gradients(i0)
    cross = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], np.float32)
    lam_min = None
    for _ in range(iterations):
        i1w = warp(i1, flow)
        g1x, g1y = _gradients(i1w)
        # Averaged gradients: the symmetric linearisation converges in fewer steps.
        gx, gy = 0.5 * (g0x + g1x), 0.5 * (g0y + g1y)
        it = i1w - i0
        jxx, jxy, jyy = _box(gx * gx, window), _box(gx * gy, window), _box(gy * gy, window)
        bx, by = _box(gx * it, window), _box(gy * it, window)
        if alpha <= 0:
            a11, a22 = jxx + reg, jyy + reg
            det = a11 * a22 - jxy * jxy
            du = (-a22 * bx + jxy * by) / det
            dv = (jxy * bx - a11 * by) / det
        else:
            # Jacobi sweeps for (J + 4 alpha) d = alpha (S(u + d) - 4u) - b, S the 4-neighbour sum.
            a11, a22 = jxx + 4 * alpha + reg, jyy + 4 * alpha + reg
            det = a11 * a22 - jxy * jxy
            u0, v0 = flow[..., 0], flow[..., 1]
            lap_u = cv2.filter2D(u0, -1, cross, borderType=cv2.BORDER_REPLICATE) - 4 * u0
            lap_v = cv2.filter2D(v0, -1, cross, borderType=cv2.BORDER_REPLICATE) - 4 * v0
            du = np.zeros_like(u0)
            dv = np.zeros_like(v0)
            for _s in range(sweeps):
                ru = alpha * (lap_u + cv2.filter2D(du, -1, cross, borderType=cv2.BORDER_REPLICATE)) - bx
                rv = alpha * (lap_v + cv2.filter2D(dv, -1, cross, borderType=cv2.BORDER_REPLICATE)) - by
                du = (a22 * ru - jxy * rv) / det
                dv = (a11 * rv - jxy * ru) / det
        flow = flow + np.stack([du, dv], axis=-1)
        # A 3x3 median after each warp removes isolated outliers (Sun, Roth, Black 2010).
        flow = cv2.medianBlur(np.ascontiguousarray(flow, np.float32), 3)
        tr, d2 = jxx + jyy, np.sqrt(np.maximum((jxx - jyy) ** 2 + 4 * jxy * jxy, 0))
        lam_min = 0.5 * (tr - d2)
    return flow, lam_min


def _one_way(g0, g1, *, levels, window, iterations, alpha, sweeps, radius):
    p0, p1 = build_pyramid(g0, levels), build_pyramid(g1, levels)
    flow = _search_top(p0[-1], p1[-1], radius=radius, window=min(window, 5))
    lam = None
    # Tikhonov term on the local solve: keeps a flat window's step small
    # instead of dividing noise by noise; far below any textured J.
    reg = 1e-5
    for lvl in range(levels - 1, -1, -1):
        if lvl < levels - 1:
            flow = upsample_flow(flow, p0[lvl].shape)
            flow = _hypotheses(p0[lvl], p1[lvl], flow, window=window)
        flow, lam = _refine_level(p0[lvl], p1[lvl], flow, window=window, iterations=iterations,
                                  alpha=alpha, sweeps=sweeps, reg=reg)
    return flow.astype(np.float32), lam


def pyramid_flow(image0: np.ndarray, image1: np.ndarray, *, levels: int | str = "auto",
                 max_motion_px: float | None = None, method: str = "local", window: int = 9,
                 iterations: int = 3, alpha: float = 2e-3, sweeps: int = 20,
                 consistency: bool = True) -> FlowResult:
    """Forward optical flow from ``image0`` to ``image1`` by coarse-to-fine warping.

    Parameters
    ----------
    image0, image1 : ndarray, ``(H, W)`` or ``(H, W, 3)``
        uint8/uint16 codes or float in [0, 1]; same shape. Converted to gray.
    levels : int or "auto"
        Pyramid levels. ``"auto"``: the fewest levels whose top level leaves at
        most ``window // 2`` px of motion, from ``max_motion_px`` when given,
        else estimated by tiled phase correlation; every candidate's score is
        in ``info["level_choice"]``.
    max_motion_px : float, optional
        Expected largest motion (pixels) for ``levels="auto"``.
    method : {"local", "dense"}
        Local Lucas-Kanade solve, or the regularised (combined local-global)
        solve that fills textureless areas from their surroundings.
    window : int
        Odd side of the square window of eq. 5.1 (pixels, at every level).
    iterations : int
        Warps per level.
    alpha : float
        Smoothness weight of ``"dense"`` (intensities in [0, 1]).
    sweeps : int
        Jacobi sweeps per warp for ``"dense"``.
    consistency : bool
        Also compute the backward flow and mark forward-backward inconsistent
        pixels as occluded (doubles the cost).

    Returns
    -------
    FlowResult

    Raises
    ------
    ValueError
        Different shapes, empty images, or bad options (named, with the value).
    """
    t0 = time.perf_counter()
    a, b = np.asarray(image0), np.asarray(image1)
    if a.shape != b.shape:
        raise ValueError(f"image1: expected the shape of image0 {a.shape}, got {b.shape}")
    if a.size == 0 or min(a.shape[:2]) < 4:
        raise ValueError(f"image0: expected at least 4x4 pixels, got {a.shape}")
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    if window < 3 or window % 2 == 0:
        raise ValueError(f"window: expected an odd size >= 3, got {window}")
    if iterations < 1:
        raise ValueError(f"iterations: expected >= 1, got {iterations}")
    g0, g1 = to_gray(a), to_gray(b)
    if a.dtype.kind == "f":  # float input is taken as already in [0, 1]
        g0, g1 = g0.astype(np.float32), g1.astype(np.float32)
    reach = max(1.0, window / 4)
    if levels == "auto":
        if max_motion_px is None:
            est, tiles = estimate_max_motion(g0, g1)
            choice = choose_levels(g0.shape, max_motion_px=est, reach_px=reach, source="estimated")
            choice_d = {**choice.to_dict(), "tiles": tiles}
        else:
            choice = choose_levels(g0.shape, max_motion_px=float(max_motion_px), reach_px=reach)
            choice_d = choice.to_dict()
        n_levels = choice.levels
    elif isinstance(levels, int | np.integer) and not isinstance(levels, bool) and levels >= 1:
        n_levels = int(levels)
        choice_d = {"levels": n_levels, "source": "given"}
    else:
        raise ValueError(f"levels: expected 'auto' or an integer >= 1, got {levels!r}")
    # Search radius at the top level: the motion left there, plus a margin.
    top_motion = choice_d.get("max_motion_px", 2.0 * 2 ** (n_levels - 1)) / 2 ** (n_levels - 1)
    radius = int(min(6, max(1, np.ceil(top_motion) + 1)))
    choice_d["top_search_radius_px"] = radius
    opts = dict(levels=n_levels, window=window, iterations=iterations,
                alpha=alpha if method == "dense" else 0.0, sweeps=sweeps, radius=radius)
    fwd, lam = _one_way(g0, g1, **opts)
    t_fwd = time.perf_counter() - t0
    # Texture confidence: lambda_min of J against that of pure noise. With
    # central differences a noise of sigma gives E[Ix^2] = sigma^2 / 2 per
    # image, and the averaged gradient halves that again: sigma^2 / 4.
    sigma = max(noise_sigma(g0), 1.0 / 1024)
    lam_noise = sigma ** 2 / 4
    tex = (lam / (lam + 25 * lam_noise)).astype(np.float32)
    occluded = np.zeros(g0.shape, bool)
    info = {"method": method, "level_choice": choice_d, "window": window,
            "iterations": iterations, "noise_sigma": sigma}
    if method == "dense":
        info.update(alpha=alpha, sweeps=sweeps)
    if consistency:
        bwd, _ = _one_way(g1, g0, **opts)
        occluded, rt = forward_backward(fwd, bwd)
        info["occluded_fraction"] = float(occluded.mean())
        info["median_round_trip_px"] = float(np.median(rt[np.isfinite(rt)])) if np.isfinite(rt).any() else None
    conf = np.where(occluded, 0.0, tex).astype(np.float32)
    resid = np.abs(warp(g1, fwd) - g0)
    info["quality"] = {"mean_abs_residual": float(resid[~occluded].mean()) if (~occluded).any()
                       else None, "mean_confidence": float(conf.mean())}
    info["timings_s"] = {"forward": t_fwd, "total": time.perf_counter() - t0}
    return FlowResult(fwd, conf, occluded, n_levels, info)
