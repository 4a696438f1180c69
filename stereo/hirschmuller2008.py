"""Semi-global matching (SGM) on a rectified pair.

H. Hirschmüller, "Stereo processing by semiglobal matching and mutual
information", IEEE TPAMI 30(2), 2008, doi:10.1109/TPAMI.2007.1166 (first as
"Accurate and efficient stereo processing by semi-global matching and mutual
information", CVPR 2005). The steps, with the paper's equations:

1. **Matching cost** ``C(p, d)``: by default the Hamming distance between
   9×7 census codes of the left pixel ``p`` and the right pixel ``p − d``
   (census as the cost of SGM: Hirschmüller & Scharstein, "Evaluation of
   stereo matching costs on images with radiometric differences", TPAMI
   31(9), 2009, doi:10.1109/TPAMI.2008.221, where it was the most robust to
   exposure and gain changes), summed over a small ``cost_window``; or our SSD
   window cost (``cost="ssd"``, eq. 5.1 of the reference, truncated).
2. **Aggregation along paths** (eq. 13): for each of 8 directions ``r``,
   ``L_r(p, d) = C(p, d) + min(L_r(p−r, d), L_r(p−r, d±1) + P1,
   min_k L_r(p−r, k) + P2) − min_k L_r(p−r, k)``, with ``P2`` adapted to the
   intensity step along the path (eq. 12's remark: ``P2 = P2' / |I_p − I_{p−r}|``;
   here ``max(P1, P2' · e / (e + |ΔI|))`` with ``e = edge``, which stays finite
   on flat areas), summed into ``S(p, d) = Σ_r L_r(p, d)`` (eq. 14).
3. **Disparity** (section 3.4): winner-take-all over ``S``, sub-pixel by a
   parabola through ``S`` at ``d−1, d, d+1``; the right image's disparity from
   the same ``S`` (``min_d S(x_r + d, d)``), and the left–right check
   (eq. 15). Also a uniqueness test (the runner-up outside ``d ± 1`` must
   cost ``(1 + uniqueness)`` times the best) and speckle filtering (section
   4.3: connected segments of under ``speckle_size`` pixels whose
   disparities differ from their neighbours' are removed).

Unknown (NaN) where any check fails, where the best disparity is the largest
searched (the true one may lie beyond: a share above ``RANGE_WARNING`` of
such pixels adds a warning that the range is too small) and where it is the
largest the left border allows (``d = x``: the match may lie left of the
right image). No value is interpolated into occlusions or the left band.

Speed: the census, costs, aggregation and winner search run in a small C
kernel (``stereo/_sgm.c``, built at install time, loaded with ctypes); the
numpy twin of every step gives the same integers and runs, with one warning,
when the kernel was not built. Time and memory grow as ``H · W · D``.

Convention (DESIGN §3): left is the reference, ``x_right = x_left − d``,
``d > 0``, NaN for unknown.

Examples
--------
>>> from scipy.ndimage import gaussian_filter
>>> rng = np.random.default_rng(0)
>>> right = gaussian_filter(rng.uniform(0, 255, (40, 80)), 1.0).astype(np.uint8)
>>> left = np.roll(right, 6, axis=1)          # every pixel has disparity 6
>>> result = match(left, right, max_disp=12)
>>> d = result.disparity[:, 20:]
>>> round(float(np.nanmedian(d)), 2), bool(np.mean(np.isfinite(d)) > 0.9)
(6.0, True)
"""

from __future__ import annotations

import functools
import time
import warnings

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.stereo.block_matching import DisparityMap

COSTS = ("census", "ssd")
LR_CHECKS = ("winners", "paper")
CENSUS = (9, 7)  # census window (width, height): 62 bits
CENSUS_MAX = CENSUS[0] * CENSUS[1] - 1
SSD_TRUNCATION = 24.0  # code values: SSD costs are capped at this RMS difference
TEXTURE_WINDOW = (21, 21)  # where the texture test looks for evidence
RANGE_WARNING = 0.02  # share of pixels whose best is max_disp above which we warn
# median cost of the winners (share of the largest pixel cost: for census the
# share of differing bits) above which we warn: random codes differ in half
# their bits, the best of a few dozen random candidates in about 0.4; the
# well-matched pairs of the tuning set have medians of 0.13-0.16
COST_WARNING = 0.25
# How the defaults were chosen: docs/decisions/stereo-sgm.md
DEFAULTS = {"cost": "census", "cost_window": 3, "p1": 12, "p2": 200, "edge": 8, "paths": 8,
            "uniqueness": 0.005, "lr_tolerance": 2, "speckle_size": 20, "speckle_range": 2.0,
            "texture_snr": 1.0, "lr_check": "winners"}


# ----------------------------------------------------------------- kernels
@functools.cache
def _kernel():
    """The compiled kernels as ctypes functions (a dict), or None (with one
    warning) when the extension was not built; numpy gives the same results."""
    import ctypes
    import importlib

    try:
        lib = ctypes.CDLL(importlib.import_module("lumigraph.stereo._sgm").__file__)
        fns = {k: getattr(lib, f"lumigraph_sgm_{k}")
               for k in ("census", "cost", "aggregate", "wta", "claims")}
    except (ImportError, OSError, AttributeError) as e:
        warnings.warn(f"lumigraph.stereo.hirschmuller2008: compiled kernel stereo/_sgm.c unavailable "
                      f"({e}); using the numpy path (same results, much slower). Reinstall "
                      "(pip install -e .) with a C compiler to build it.", stacklevel=3)
        return None
    P, I = ctypes.c_void_p, ctypes.c_int
    fns["census"].argtypes = [P, I, I, I, I, P]
    fns["cost"].argtypes = [P, P, I, I, I, I, I, P]
    fns["aggregate"].argtypes = [P, P, I, I, I, I, I, I, I, P]
    fns["wta"].argtypes = [P, I, I, I, P, P, P, P, P, P]
    fns["claims"].argtypes = [P, P, P, I, I, P]
    for f in fns.values():
        f.restype = I
    return fns


def _ptr(a):
    return int(a.ctypes.data)


def _call(fn, *args):
    rc = fn(*args)
    if rc:
        raise RuntimeError(f"stereo/_sgm.c: {fn.__name__} failed (code {rc})")


def census(image: np.ndarray, *, kernel=None) -> np.ndarray:
    """9×7 census transform of an ``(H, W)`` uint8 image: ``(H, W)`` uint64,
    bit ``k`` (raster order over the window, centre skipped) set where the
    neighbour is darker than the centre; outside the image the nearest border
    pixel stands in.

    >>> census(np.array([[0, 9], [9, 9]], np.uint8))[1, 1] > 0
    np.True_
    """
    img = np.ascontiguousarray(image, dtype=np.uint8)
    h, w = img.shape
    wx, wy = CENSUS
    if kernel is not None:
        out = np.empty((h, w), np.uint64)
        _call(kernel["census"], _ptr(img), h, w, wx, wy, _ptr(out))
        return out
    rx, ry = wx // 2, wy // 2
    p = np.pad(img, ((ry, ry), (rx, rx)), mode="edge")
    out = np.zeros((h, w), np.uint64)
    bit = 0
    for dy in range(-ry, ry + 1):
        for dx in range(-rx, rx + 1):
            if dx == 0 and dy == 0:
                continue
            nb = p[ry + dy:ry + dy + h, rx + dx:rx + dx + w]
            out |= (nb < img).astype(np.uint64) << np.uint64(bit)
            bit += 1
    return out


def _window_sum(v, r):
    """Sum of ``v`` (rows × columns) over a (2r+1)² window, the coordinates clamped to the array."""
    if r == 0:
        return v
    p = np.pad(v, r, mode="edge").astype(np.int64)
    c = np.cumsum(np.cumsum(p, 0), 1)
    c = np.pad(c, ((1, 0), (1, 0)))
    n = 2 * r + 1
    return c[n:, n:] - c[:-n, n:] - c[n:, :-n] + c[:-n, :-n]


def _census_cost(cl, cr, D, r, invalid, kernel):
    """``(H, W, D)`` uint16: Hamming distances summed over the (2r+1)² window
    (rows clamped to the image, columns to those whose right pixel exists);
    ``invalid`` where ``x < d``."""
    h, w = cl.shape
    if kernel is not None:
        out = np.empty((h, w, D), np.uint16)
        _call(kernel["cost"], _ptr(cl), _ptr(cr), h, w, D, r, int(invalid), _ptr(out))
        return out
    out = np.full((h, w, D), invalid, np.uint16)
    for d in range(min(D, w)):
        ham = np.bitwise_count(cl[:, d:] ^ cr[:, :w - d]).astype(np.int32)
        out[:, d:, d] = _window_sum(ham, r)
    return out


def _ssd_cost(L, R, D, side, invalid):
    """``(H, W, D)`` uint16: the mean squared difference of the luma over a
    ``side × side`` window (eq. 5.1; window clamped as for census), truncated
    at ``SSD_TRUNCATION²`` and scaled so that the truncation maps to
    ``CENSUS_MAX · side²``: both costs share ``P1``/``P2``."""
    h, w = L.shape
    full = CENSUS_MAX * side * side
    out = np.full((h, w, D), invalid, np.uint16)
    t2 = SSD_TRUNCATION ** 2
    for d in range(min(D, w)):
        diff = L[:, d:] - R[:, :w - d]
        msd = _window_sum(diff * diff, side // 2) / float(side * side)
        out[:, d:, d] = np.rint(np.minimum(msd, t2) * (full / t2)).astype(np.uint16)
    return out


def _step(C, prev, P1, P2):
    """One step of eq. 13 for rows of pixels: ``C``, ``prev`` (N, D) int32, ``P2`` (N,)."""
    m = prev.min(1, keepdims=True)
    v = prev.copy()
    np.minimum(v[:, 1:], prev[:, :-1] + P1, out=v[:, 1:])
    np.minimum(v[:, :-1], prev[:, 1:] + P1, out=v[:, :-1])
    np.minimum(v, m + P2[:, None], out=v)
    return C + v - m


def _penalty2(P1, P2, edge, a, b):
    if edge <= 0:
        return np.full(np.shape(a), P2, np.int32)
    return np.maximum(P1, (P2 * edge) // (edge + np.abs(a - b))).astype(np.int32)


def aggregate(cost: np.ndarray, guide: np.ndarray, *, p1: int, p2: int, edge: int, paths: int = 8,
              kernel=None) -> np.ndarray:
    """``S(p, d) = Σ_r L_r(p, d)`` (eqs. 13–14) over 8 (or 4) paths.

    ``cost`` (H, W, D) uint16, ``guide`` (H, W) uint8 (the intensities that
    adapt ``P2``); ``p1``, ``p2`` in cost units. Returns (H, W, D) uint16.
    Paths start afresh (``L_r = C``) at the image border.

    >>> c = np.zeros((3, 4, 5), np.uint16); c[..., 2] = 0; c[..., [0, 1, 3, 4]] = 9
    >>> int(aggregate(c, np.zeros((3, 4), np.uint8), p1=1, p2=4, edge=0)[1, 1].argmin())
    2
    """
    C = np.ascontiguousarray(cost, dtype=np.uint16)
    g = np.ascontiguousarray(guide, dtype=np.uint8)
    h, w, D = C.shape
    if kernel is not None:
        S = np.empty_like(C)
        _call(kernel["aggregate"], _ptr(C), _ptr(g), h, w, D, int(p1), int(p2), int(edge), int(paths),
              _ptr(S))
        return S
    C32 = C.astype(np.int32)
    gi = g.astype(np.int32)
    S = np.zeros((h, w, D), np.int32)
    xs = np.arange(w)
    for sgn in (1, -1):
        cols = range(w) if sgn > 0 else range(w - 1, -1, -1)
        rows = range(h) if sgn > 0 else range(h - 1, -1, -1)
        # horizontal: from (x - sgn, y), every row at once
        prev = None
        for x in cols:
            if prev is None:
                cur = C32[:, x]
            else:
                cur = _step(C32[:, x], prev, p1, _penalty2(p1, p2, edge, gi[:, x], gi[:, x - sgn]))
            S[:, x] += cur
            prev = cur
        # from the previous row: (x - sgn·dx, y - sgn)
        for dx in ((-1, 0, 1) if paths == 8 else (0,)):
            xp = xs - sgn * dx
            ok = (xp >= 0) & (xp < w)
            prev = None
            for y in rows:
                if prev is None:
                    cur = C32[y].copy()
                else:
                    cur = C32[y].copy()
                    cur[ok] = _step(C32[y][ok], prev[xp[ok]], p1,
                                    _penalty2(p1, p2, edge, gi[y][ok], gi[y - sgn][xp[ok]]))
                S[y] += cur
                prev = cur
    return S.astype(np.uint16)


def winners(S: np.ndarray, *, right: bool = True, kernel=None) -> dict:
    """Winner-take-all over ``d ≤ min(x, D − 1)`` (ties: the smaller ``d``):
    ``best``, the sums ``sb``, ``sm``/``sp`` at ``best ∓ 1`` (−1 outside the
    range), the runner-up ``second`` outside ``best ± 1`` (int32 max when
    none) and ``best_r``, the right image's best ``d`` (``min_d S(x_r + d, d)``;
    only with ``right``, the paper's left–right check).

    >>> S = np.full((1, 3, 2), 9, np.uint16); S[0, 2, 1] = 1
    >>> winners(S)["best"].tolist(), winners(S)["best_r"].tolist()
    ([[0, 0, 1]], [[0, 1, 0]])
    """
    S = np.ascontiguousarray(S, dtype=np.uint16)
    h, w, D = S.shape
    if kernel is not None:
        out = {"best": np.empty((h, w), np.int16), "sb": np.empty((h, w), np.int32),
               "sm": np.empty((h, w), np.int32), "sp": np.empty((h, w), np.int32),
               "second": np.empty((h, w), np.int32)}
        if right:
            out["best_r"] = np.empty((h, w), np.int16)
        _call(kernel["wta"], _ptr(S), h, w, D, *(_ptr(out[k]) for k in
                                                  ("best", "sb", "sm", "sp", "second")),
              _ptr(out["best_r"]) if right else None)
        return out
    big = np.iinfo(np.int32).max
    ds = np.arange(D)
    xs = np.arange(w)
    allowed = ds[None, :] <= xs[:, None]  # (W, D)
    V = np.where(allowed[None], S.astype(np.int64), big)
    best = V.argmin(2)
    sb = np.take_along_axis(V, best[..., None], 2)[..., 0]
    dmax = np.minimum(xs, D - 1)[None, :]
    sm = np.where(best > 0, np.take_along_axis(V, np.maximum(best - 1, 0)[..., None], 2)[..., 0], -1)
    sp = np.where(best < dmax, np.take_along_axis(V, np.minimum(best + 1, D - 1)[..., None], 2)[..., 0],
                  -1)
    far = np.abs(ds[None, None, :] - best[..., None]) > 1
    second = np.where(far, V, big).min(2)
    out = {"best": best.astype(np.int16), "sb": sb.astype(np.int32), "sm": sm.astype(np.int32),
           "sp": sp.astype(np.int32), "second": second.astype(np.int32)}
    if not right:
        return out
    # right image: T[y, xr, d] = S[y, xr + d, d] where xr + d < W
    xi = xs[:, None] + ds[None, :]
    okr = xi < w
    T = np.where(okr[None], S.astype(np.int64)[:, np.minimum(xi, w - 1), ds[None, :]], big)
    out["best_r"] = T.argmin(2).astype(np.int16)
    return out


# ----------------------------------------------------------------- checks
def _check(left, right, *, max_disp, cost, cost_window, p1, p2, edge, paths, uniqueness,
           lr_tolerance, speckle_size, speckle_range, engine):
    a, b = np.asarray(left), np.asarray(right)
    if a.shape[:2] != b.shape[:2]:
        raise InputError("right", f"size {b.shape[1]}x{b.shape[0]} differs from the left image's "
                                  f"{a.shape[1]}x{a.shape[0]}")
    check_sgm_options(a.shape, max_disp=max_disp, cost=cost, cost_window=cost_window, p1=p1, p2=p2,
                      edge=edge, paths=paths, uniqueness=uniqueness, lr_tolerance=lr_tolerance,
                      speckle_size=speckle_size, speckle_range=speckle_range, engine=engine)


def check_sgm_options(image_shape, *, max_disp: int, cost: str = DEFAULTS["cost"],
                      cost_window: int = DEFAULTS["cost_window"], p1: int = DEFAULTS["p1"],
                      p2: int = DEFAULTS["p2"], edge: int = DEFAULTS["edge"],
                      paths: int = DEFAULTS["paths"], uniqueness: float = DEFAULTS["uniqueness"],
                      lr_tolerance: int = DEFAULTS["lr_tolerance"],
                      speckle_size: int = DEFAULTS["speckle_size"],
                      speckle_range: float = DEFAULTS["speckle_range"], engine: str = "auto") -> None:
    """Check :func:`match`'s options for images of ``image_shape`` (``(H, W)``
    or ``(H, W, C)``) before the images are read or rectified.

    Raises
    ------
    InputError
        Naming the argument.

    Examples
    --------
    >>> check_sgm_options((48, 64), max_disp=16)
    >>> check_sgm_options((48, 64), max_disp=16, paths=6)
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: paths: expected 4 or 8, got 6
    """
    h, w = tuple(image_shape)[:2]
    if not isinstance(max_disp, int | np.integer) or not 1 <= max_disp < w:
        raise InputError("max_disp", f"expected an integer in [1, {w - 1}] (image width {w}), "
                                     f"got {max_disp!r}")
    if cost not in COSTS:
        raise InputError("cost", f"expected one of {', '.join(COSTS)}, got {cost!r}")
    if not isinstance(cost_window, int | np.integer) or cost_window not in (1, 3, 5):
        raise InputError("cost_window", f"expected 1, 3 or 5, got {cost_window!r}")
    if cost == "ssd" and cost_window == 1:
        raise InputError("cost_window", "the SSD cost needs a window of 3 or 5 (one pixel is not a window)")
    if min(h, w) < max(CENSUS):
        raise InputError("left", f"image {w}x{h} is smaller than the census window {CENSUS[0]}x{CENSUS[1]}")
    for name, v in (("p1", p1), ("p2", p2), ("edge", edge)):
        if not isinstance(v, int | np.integer) or v < 0:
            raise InputError(name, f"expected an integer >= 0, got {v!r}")
    if p2 < p1:
        raise InputError("p2", f"expected p2 >= p1 ({p1}), got {p2}")
    n = cost_window * cost_window
    # 8 paths of at most (C_max + P2) each must fit the uint16 sum
    if 8 * n * (CENSUS_MAX + p2) > 65535:
        raise InputError("p2", f"too large for cost_window {cost_window}: at most "
                               f"{65535 // (8 * n) - CENSUS_MAX}, got {p2}")
    if paths not in (4, 8):
        raise InputError("paths", f"expected 4 or 8, got {paths!r}")
    if not uniqueness >= 0:
        raise InputError("uniqueness", f"expected a value >= 0, got {uniqueness!r}")
    if not isinstance(lr_tolerance, int | np.integer) or lr_tolerance < -1:
        raise InputError("lr_tolerance", f"expected an integer >= -1 (-1 disables), got {lr_tolerance!r}")
    if not isinstance(speckle_size, int | np.integer) or speckle_size < 0:
        raise InputError("speckle_size", f"expected an integer >= 0 (0 disables), got {speckle_size!r}")
    if not speckle_range > 0:
        raise InputError("speckle_range", f"expected a value > 0, got {speckle_range!r}")
    if engine not in ("auto", "numpy"):
        raise InputError("engine", f"expected 'auto' or 'numpy', got {engine!r}")


def _guide(left, right):
    """8-bit luma of both views for the census and the P2 adaptation: 8-bit
    inputs as they are, others scaled by the joint range of the pair."""
    from lumigraph.stereo.luma import luma_codes

    L, R = luma_codes(left), luma_codes(right)
    if np.asarray(left).dtype == np.uint8 and np.asarray(right).dtype == np.uint8:
        return np.rint(L).astype(np.uint8), np.rint(R).astype(np.uint8), L, R
    lo = min(float(np.nanmin(L)), float(np.nanmin(R)))
    hi = max(float(np.nanmax(L)), float(np.nanmax(R)))
    s = 255.0 / max(hi - lo, 1e-12)
    L, R = (L - lo) * s, (R - lo) * s
    return np.rint(L).astype(np.uint8), np.rint(R).astype(np.uint8), L, R


# ----------------------------------------------------------------- match
def match(left: np.ndarray, right: np.ndarray, *, max_disp: int, cost: str = DEFAULTS["cost"],
          cost_window: int = DEFAULTS["cost_window"], p1: int = DEFAULTS["p1"],
          p2: int = DEFAULTS["p2"], edge: int = DEFAULTS["edge"], paths: int = DEFAULTS["paths"],
          uniqueness: float = DEFAULTS["uniqueness"], lr_tolerance: int = DEFAULTS["lr_tolerance"],
          speckle_size: int = DEFAULTS["speckle_size"],
          speckle_range: float = DEFAULTS["speckle_range"],
          texture_snr: float = DEFAULTS["texture_snr"], lr_check: str = DEFAULTS["lr_check"],
          subpixel: bool = True, engine: str = "auto", device="cpu") -> DisparityMap:
    """Dense disparity of a rectified pair by semi-global matching.

    Parameters
    ----------
    left, right : ndarray, (H, W) or (H, W, 3)
        Rectified images (any numeric dtype, same size); left is the reference.
        Matched on their luma (8-bit; other dtypes scaled by the pair's range).
    max_disp : int, keyword-only
        Largest disparity searched (pixels); disparities ``0..max_disp``.
    cost : {"census", "ssd"}
        9×7 census Hamming distance (robust to exposure and gain changes
        between the views) or the mean squared luma difference (eq. 5.1,
        truncated at ``SSD_TRUNCATION`` code values RMS).
    cost_window : {1, 3, 5}
        Side of the window the pixel costs are summed over (1: none; SSD needs 3 or 5).
    p1, p2 : int
        Penalties of eq. 13 per window pixel (census bits; multiplied by
        ``cost_window²``): ``p1`` for a 1 px disparity change along a path,
        ``p2`` for a larger jump.
    edge : int
        Intensity step (8-bit code values) at which ``P2`` halves:
        ``P2 = max(P1, P2' · edge / (edge + |ΔI|))``; 0 keeps ``P2`` constant.
    paths : {4, 8}
        Aggregation directions.
    uniqueness : float
        The runner-up outside ``d ± 1`` must cost at least ``(1 + uniqueness)``
        times the best (0 disables). With ``subpixel``, ``d ± 2`` on the side
        where the parabola puts the minimum is left out too: the far wall of
        the minimum's own valley, 1.5 px from it at most, is not a second
        match (docs/decisions/stereo-sgm.md).
    lr_tolerance : int
        Largest left–right disagreement in pixels (−1 disables).
    speckle_size, speckle_range : int, float
        Segments (4-connected, neighbours within ``speckle_range`` px) of
        fewer than ``speckle_size`` pixels are set unknown (0 disables).
    texture_snr : float
        A pixel whose luma standard deviation over ``TEXTURE_WINDOW`` (21×21)
        is below ``texture_snr · σ`` (``σ`` the sensor noise estimated from
        the left image) holds no evidence of its own: unknown, rather than the
        value the paths carried in from elsewhere (0 disables).
    subpixel : bool
        Parabola refinement of the integer minimum of ``S``.
    engine : {"auto", "numpy"}
        ``"auto"``: the compiled kernel when it was built; ``"numpy"`` forces
        the numpy twin (identical results).
    device : {"cpu", "cuda", "torch-cpu", "auto"}
        Where the aggregation along the paths (eqs. 13–14) runs
        (:mod:`lumigraph.capture.device`): ``"cpu"`` as ``engine`` says; the
        others :mod:`lumigraph.stereo.hirschmuller2008_torch` (the same
        integers). The census, the costs, the winners and the checks stay on
        the CPU.

    Returns
    -------
    DisparityMap
        ``disparity`` float32 (NaN unknown), ``cost`` the aggregated cost
        ``S`` at the best disparity divided by the number of paths,
        ``window`` the cost window side; ``info`` the parameters, the share
        of pixels each test rejected, timings and ``warnings``.

    Raises
    ------
    InputError
        Naming the argument (:func:`check_sgm_options` checks the options
        alone, before the images are at hand).
    """
    import cv2

    from lumigraph.capture.device import resolve_device

    t0 = time.perf_counter()
    dev = resolve_device(device)
    _check(left, right, max_disp=max_disp, cost=cost, cost_window=cost_window, p1=p1, p2=p2,
           edge=edge, paths=paths, uniqueness=uniqueness, lr_tolerance=lr_tolerance,
           speckle_size=speckle_size, speckle_range=speckle_range, engine=engine)
    if not texture_snr >= 0:
        raise InputError("texture_snr", f"expected a value >= 0, got {texture_snr!r}")
    if lr_check not in LR_CHECKS:
        raise InputError("lr_check", f"expected one of {', '.join(LR_CHECKS)}, got {lr_check!r}")
    kernel = _kernel() if engine == "auto" else None
    gl, gr, Lf, Rf = _guide(left, right)
    h, w = gl.shape
    D = int(max_disp) + 1
    n = cost_window * cost_window
    invalid = CENSUS_MAX * n
    if cost == "census":
        C = _census_cost(census(gl, kernel=kernel), census(gr, kernel=kernel), D, cost_window // 2,
                         invalid, kernel)
    else:
        C = _ssd_cost(Lf.astype(np.float64), Rf.astype(np.float64), D, cost_window, invalid)
    t1 = time.perf_counter()
    if dev.uses_torch:
        from lumigraph.stereo import hirschmuller2008_torch

        S = hirschmuller2008_torch.aggregate(C, gl, p1=p1 * n, p2=p2 * n, edge=edge, paths=paths,
                                             device=dev)
    else:
        S = aggregate(C, gl, p1=p1 * n, p2=p2 * n, edge=edge, paths=paths, kernel=kernel)
    t2 = time.perf_counter()
    win = winners(S, right=lr_check == "paper" and lr_tolerance >= 0, kernel=kernel)
    # how well the winners match on their own (pixels that see the whole range)
    own = np.take_along_axis(C[:, D - 1:], win["best"][:, D - 1:, None].astype(np.intp), 2)
    match_cost = float(np.median(own)) / invalid if own.size else float("nan")
    del C
    t3 = time.perf_counter()
    disp, counts = _decide(win, D=D, uniqueness=uniqueness, lr_tolerance=lr_tolerance,
                           subpixel=subpixel, lr_check=lr_check, kernel=kernel, S=S)
    sigma = None
    if texture_snr > 0:
        from lumigraph.stereo.luma import noise_sigma_smooth_blocks

        sigma = max(noise_sigma_smooth_blocks(Lf.astype(np.float32)), 0.5)  # 8-bit luma codes
        g = Lf.astype(np.float32)
        m = cv2.boxFilter(g, -1, TEXTURE_WINDOW, borderType=cv2.BORDER_REPLICATE)
        m2 = cv2.sqrBoxFilter(g, cv2.CV_32F, TEXTURE_WINDOW, borderType=cv2.BORDER_REPLICATE)
        flat = np.isfinite(disp) & (m2 - m * m < (texture_snr * sigma) ** 2)
        disp[flat] = np.nan
        counts["no_texture"] = int(flat.sum())
    if speckle_size > 0:
        d16 = np.where(np.isfinite(disp), np.rint(disp * 16), -16).astype(np.int16)
        before = d16 >= 0
        cv2.filterSpeckles(d16, -16, int(speckle_size), int(round(speckle_range * 16)))
        speck = before & (d16 < 0)
        disp[speck] = np.nan
        counts["speckle"] = int(speck.sum())
    t4 = time.perf_counter()
    npx = h * w
    info = {"method": "sgm", "max_disp": int(max_disp), "cost": cost, "cost_window": cost_window,
            "census": list(CENSUS) if cost == "census" else None, "p1": p1, "p2": p2, "edge": edge,
            "paths": paths, "uniqueness": uniqueness, "lr_tolerance": lr_tolerance,
            "speckle_size": speckle_size, "speckle_range": speckle_range, "subpixel": subpixel,
            "texture_snr": texture_snr, "noise_sigma_estimate": sigma,
            "rejected_fraction": {k: v / npx for k, v in counts.items()},
            "valid_fraction": float(np.isfinite(disp).mean()),
            "engine": "c" if kernel is not None else "numpy",
            "aggregation_device": dev.name,
            "timings_s": {"cost": t1 - t0, "aggregate": t2 - t1, "winners": t3 - t2,
                          "decide": t4 - t3},
            "warnings": []}
    info["median_match_cost"] = match_cost
    at_limit = counts["at_max_disp"] / npx
    if at_limit > RANGE_WARNING:
        info["warnings"].append(
            f"{100 * at_limit:.1f}% of pixels have their best match at max_disp = {max_disp}: the "
            "scene's disparities likely exceed the searched range (those pixels are unknown); "
            "search a larger max_disp")
    elif match_cost > COST_WARNING:
        info["warnings"].append(
            f"the median best match differs in {100 * match_cost:.0f}% of its cost range (a "
            f"well-matched pair: under {100 * COST_WARNING:.0f}%): the scene's disparities may "
            f"exceed the searched range (max_disp = {max_disp}), or the pair is not rectified")
    cost_map = (win["sb"] / paths).astype(np.float32)
    return DisparityMap(disp, cost_map, np.full((h, w), cost_window, np.uint8), info)


def claims(best: np.ndarray, sb: np.ndarray, ok: np.ndarray, *, kernel=None) -> np.ndarray:
    """The right image's disparity as the left pixels claim it (the
    left–right check of OpenCV's SGBM, cheaper than a second winner search):
    at each right pixel, the best disparity of the lowest-cost left pixel
    (among ``ok``) whose winner lands there, ties to the smaller disparity;
    −1 where none lands. ``best`` int16, ``sb`` int32, ``ok`` bool, all (H, W).

    >>> claims(np.array([[0, 1, 1]], np.int16), np.array([[5, 3, 4]], np.int32),
    ...        np.ones((1, 3), bool)).tolist()
    [[1, 1, -1]]
    """
    best = np.ascontiguousarray(best, dtype=np.int16)
    sb = np.ascontiguousarray(sb, dtype=np.int32)
    okb = np.ascontiguousarray(ok, dtype=np.uint8)
    h, w = best.shape
    if kernel is not None:
        out = np.empty((h, w), np.int16)
        _call(kernel["claims"], _ptr(best), _ptr(sb), _ptr(okb), h, w, _ptr(out))
        return out
    big = np.iinfo(np.int64).max
    xr = np.arange(w)[None, :] - best.astype(np.int64)
    sel = okb.astype(bool) & (xr >= 0) & (xr < w)
    key = (np.arange(h)[:, None] * w + xr)[sel]
    c = sb.astype(np.int64)[sel]
    cost = np.full(h * w, big, np.int64)
    np.minimum.at(cost, key, c)
    won = c == cost[key]
    d = np.full(h * w, big, np.int64)
    np.minimum.at(d, key[won], best.astype(np.int64)[sel][won])
    return np.where(d == big, -1, d).reshape(h, w).astype(np.int16)


def _one_valley(S, best, sm, sp, sb, cand, uniqueness):
    """Of the pixels ``cand`` (bool (H, W)), whose runner-up outside
    ``best ± 1`` costs less than ``(1 + uniqueness)`` times the best, those
    whose runner-up clears that margin once the valley holding the sub-pixel
    minimum is left out on its side too: ``best − 1 .. best + 2`` when the
    parabola puts the minimum between ``best`` and ``best + 1`` (``sp < sm``),
    ``best − 2 .. best + 1`` when between ``best − 1`` and ``best``. Such a
    runner-up lies 1.5 px or less from the minimum: the far wall of one broad
    valley, not a second match. ``S`` (H, W, D) the aggregated costs, the
    others (H, W) as in :func:`winners` (float64)."""
    ys, xs = np.nonzero(cand)
    if not ys.size:
        return np.zeros(cand.shape, bool)
    b = best[ys, xs]
    m, p = sm[ys, xs], sp[ys, xs]
    fit = (m >= 0) & (p >= 0) & (m + p - 2 * sb[ys, xs] > 0)
    side = np.where(fit, np.sign(m - p), 0).astype(np.int64)  # +1: the minimum lies towards best + 1
    ds = np.arange(S.shape[2])[None, :]
    lo = np.minimum(b - 1, b + 2 * side)[:, None]
    hi = np.maximum(b + 1, b + 2 * side)[:, None]
    far = ((ds < lo) | (ds > hi)) & (ds <= xs[:, None])
    second = np.where(far, S[ys, xs].astype(np.int64), np.iinfo(np.int64).max).min(1)
    out = np.zeros(cand.shape, bool)
    out[ys, xs] = second >= sb[ys, xs] * (1.0 + uniqueness)
    return out


def _decide(win, *, D, uniqueness, lr_tolerance, subpixel, lr_check="winners", kernel=None,
            S=None):
    """Disparity (float32, NaN unknown) from the winners, and how many pixels
    each test rejected. With ``S`` (the aggregated costs) and ``subpixel``,
    the uniqueness test leaves out the valley of the sub-pixel minimum
    (:func:`_one_valley`)."""
    best = win["best"].astype(np.int64)
    h, w = best.shape
    xs = np.arange(w)[None, :]
    sb, sm, sp = (win[k].astype(np.float64) for k in ("sb", "sm", "sp"))
    at_max = best == D - 1
    at_edge = (best == xs) & (xs < D - 1)  # d = x: the match may lie left of the right image
    ok = ~at_max & ~at_edge
    counts = {"at_max_disp": int(at_max.sum()), "left_border": int(at_edge.sum())}
    if uniqueness > 0:
        second = win["second"].astype(np.float64)
        bad = ok & (second < sb * (1.0 + uniqueness))
        if S is not None and subpixel:
            bad &= ~_one_valley(S, best, sm, sp, sb, bad, uniqueness)
        counts["not_unique"] = int(bad.sum())
        ok &= ~bad
    d = best.astype(np.float64)
    if subpixel:
        den = sm + sp - 2 * sb
        fit = (sm >= 0) & (sp >= 0) & (den > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            d = np.where(fit, d + (sm - sp) / (2 * np.where(fit, den, 1)), d)
    if lr_tolerance >= 0:
        if lr_check == "winners":
            br = claims(win["best"], win["sb"], ok, kernel=kernel).astype(np.float64)
            br[br < 0] = np.nan
        else:
            br = win["best_r"].astype(np.float64)
        # the right pixels either side of x - d (as OpenCV's disp12MaxDiff):
        # a sub-pixel match between two right pixels agrees with either
        xr = xs - d
        agree = np.zeros(best.shape, bool)
        for xi in (np.floor(xr), np.ceil(xr)):
            xi = np.clip(xi, 0, w - 1).astype(np.int64)
            other = np.take_along_axis(br, xi, 1)
            agree |= ~(np.abs(other - d) > lr_tolerance)  # NaN: no claim, nothing to disagree with
        bad = ok & ~agree
        counts["left_right"] = int(bad.sum())
        ok &= ~bad
    disp = np.where(ok, d, np.nan).astype(np.float32)
    return disp, counts
