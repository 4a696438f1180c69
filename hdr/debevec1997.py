"""Debevec & Malik (1997): the camera response from an exposure bracket.

P. E. Debevec and J. Malik, "Recovering High Dynamic Range Radiance Maps from
Photographs", SIGGRAPH 1997, doi:10.1145/258734.258884. Reference ch. 6,
eq. 6.3-6.5.

For each channel the unknowns are ``g`` (``ln f⁻¹``) and ``ln E_i`` of the
sampled pixels; eq. 6.5 is solved as one sparse weighted least-squares system
(``scipy.sparse``), through its augmented form ``[[I, A], [Aᵀ, 0]]`` so the
normal equations (which square the condition number) are never formed.

What this adds to the paper:

- any bit depth up to 16: ``g`` lives on ``K`` knots (one per code up to 8
  bits; 256 evenly spaced knots above, interpolated linearly) instead of one
  unknown per code value;
- principled pixel sampling (:func:`hdr.samples.sample_pixels`);
- λ chosen automatically by held-out exposure prediction: the pixels are
  split in two folds; a curve fitted on one predicts, for each pixel of the
  other and each exposure ``j``, ``g(Z_ij)`` from the pixel's other
  exposures (``ln E_i`` estimated without ``j``, plus ``ln Δt_j``). The
  largest λ whose error is within one standard error of the best is chosen
  (model only what the data needs); all candidates are recorded;
- the smoothness term is scaled by the knot spacing and the data term by the
  number of observations, so one λ means the same for every bit depth and
  sample count (λ weighs ``∫ ω(u)² g''(u)² du`` against the mean squared
  weighted residual, ``u = z / z_max``);
- observations near the clipping ends are dropped (:func:`data_weight`),
  which removes the truncation bias noise causes there;
- a monotonic result (weighted isotonic regression when noise makes the
  solution dip; reported in ``warnings``).

Examples
--------
>>> rng = np.random.default_rng(0)
>>> e = np.exp(rng.uniform(-6, 0, (40, 40, 1)))
>>> t = np.array([0.05, 0.2, 0.8, 3.2])
>>> z = np.stack([np.clip(np.round(255 * np.sqrt(np.clip(e * ti, 0, 1))), 0, 255)
...               for ti in t]).astype(np.uint8)
>>> r = debevec(z, t, rng=rng)
>>> x = r.exposure_table()[0]
>>> bool(abs(x[200] / x[100] - 4.0) < 0.1)   # f⁻¹(z) = (z/255)²
True
"""

from __future__ import annotations

import math

import numpy as np

from hdr.response import ResponseCurve, normalise_g
from hdr.samples import check_stack, hat_weight, sample_pixels

LAMBDA_GRID = tuple(10.0 ** k for k in range(-12, -1))


def knot_basis(codes: np.ndarray, n_knots: int, bit_depth: int) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation onto ``n_knots`` evenly spaced knots over ``[0, z_max]``.

    Returns ``(k0, a)``: each code lies between knots ``k0`` and ``k0 + 1`` with
    weight ``1 - a`` and ``a`` (both ``codes.shape``).

    Examples
    --------
    >>> k0, a = knot_basis(np.array([0, 1000, 65535]), 256, 16)
    >>> k0.tolist(), a.round(3).tolist()
    ([0, 3, 254], [0.0, 0.891, 1.0])
    """
    zmax = 2 ** bit_depth - 1
    pos = np.asarray(codes, dtype=np.float64) * (n_knots - 1) / zmax
    k0 = np.clip(np.floor(pos).astype(np.int64), 0, n_knots - 2)
    return k0, pos - k0


def _system(z, lnt, w, n_knots, bit_depth, lam):
    """Sparse matrix and right-hand side of eq. 6.5 for one channel.

    ``z``: (N, P) codes, ``w``: (N, P) weights; unknowns ``[g (K), ln E (N)]``.
    """
    import scipy.sparse as sp

    n, p = z.shape
    rows_i, cols, vals, rhs = [], [], [], []
    ii, jj = np.nonzero(w > 0)
    m = ii.size
    scale = 1.0 / math.sqrt(max(m, 1))
    wij = w[ii, jj] * scale
    k0, a = knot_basis(z[ii, jj], n_knots, bit_depth)
    r = np.arange(m)
    rows_i += [r, r, r]
    cols += [k0, k0 + 1, n_knots + ii]
    vals += [wij * (1 - a), wij * a, -wij]
    rhs.append(wij * lnt[jj])
    # Smoothness on interior knots: sqrt(λ h) ω (g[k-1] - 2 g[k] + g[k+1]) / h².
    h = 1.0 / (n_knots - 1)
    k = np.arange(1, n_knots - 1)
    wk = hat_weight(k * (2 ** bit_depth - 1) / (n_knots - 1), bit_depth)
    wk = np.maximum(wk, 0.05)  # keep the ends smooth too, where data are scarce
    s = math.sqrt(lam * h) / h ** 2 * wk
    rs = m + np.arange(k.size)
    rows_i += [rs, rs, rs]
    cols += [k - 1, k, k + 1]
    vals += [s, -2 * s, s]
    rhs.append(np.zeros(k.size))
    # Gauge: g at the middle knot is 0 (the free additive constant).
    rg = m + k.size
    rows_i.append(np.array([rg]))
    cols.append(np.array([n_knots // 2]))
    vals.append(np.array([1.0]))
    rhs.append(np.zeros(1))
    a_mat = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows_i), np.concatenate(cols))),
                          shape=(rg + 1, n_knots + n))
    return a_mat, np.concatenate(rhs)


def solve_sparse_lstsq(a_mat, b: np.ndarray) -> np.ndarray:
    """Least-squares solution of a sparse full-column-rank system through the
    augmented system ``[[αI, A], [Aᵀ, 0]] [r/α; x] = [b; 0]`` (sparse LU), which
    keeps the condition of ``A`` instead of squaring it as ``AᵀA x = Aᵀb`` does.

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> a = sp.csr_matrix(np.array([[1.0, 0], [1, 1], [0, 2]]))
    >>> x = solve_sparse_lstsq(a, np.array([1.0, 2, 2]))
    >>> np.allclose(x, np.linalg.lstsq(a.toarray(), [1.0, 2, 2], rcond=None)[0])
    True
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    m, n = a_mat.shape
    alpha = float(np.sqrt(np.mean(a_mat.multiply(a_mat).sum(axis=0)))) or 1.0
    aug = sp.bmat([[alpha * sp.identity(m), a_mat], [a_mat.T, None]], format="csc")
    sol = spla.spsolve(aug, np.concatenate([b, np.zeros(n)]))
    x = sol[m:]
    if not np.all(np.isfinite(x)):
        raise np.linalg.LinAlgError("singular system")
    return x


def data_weight(z: np.ndarray, bit_depth: int, clip_margin: float) -> np.ndarray:
    """Weight of each observation in eq. 6.5: the hat ω(z), and zero within
    ``clip_margin·z_max`` of either end.

    Near 0 and ``z_max`` clipping truncates the noise: a code just below
    ``z_max`` is more often a pixel whose noise happened to be negative
    (the others clipped and were discarded), so its mean is biased low, and
    likewise at the bottom. Through the chain of exposure ratios that bias
    becomes a ripple in ``g`` of period one exposure step, which the
    held-out prediction cannot see (the held-out data carry the same bias).

    Examples
    --------
    >>> data_weight(np.array([3, 10, 128, 250]), 8, 0.03).round(2).tolist()
    [0.0, 0.08, 1.0, 0.0]
    """
    zmax = 2 ** bit_depth - 1
    zf = np.asarray(z, dtype=np.float64)
    keep = (zf >= clip_margin * zmax) & (zf <= (1 - clip_margin) * zmax)
    return np.where(keep, hat_weight(zf, bit_depth), 0.0)


def _fit_channel(z, lnt, w, n_knots, bit_depth, lam):
    # A pixel needs two weighted observations to say anything about g (and one
    # to have a determined ln E at all).
    use = np.count_nonzero(w > 0, axis=1) >= 2
    if np.count_nonzero(use) < 2:
        raise np.linalg.LinAlgError("too few pixels seen in two exposures")
    z, w = z[use], w[use]
    a_mat, b = _system(z, lnt, w, n_knots, bit_depth, lam)
    x = solve_sparse_lstsq(a_mat, b)
    return x[:n_knots], x[n_knots:]


def _g_at(gk, codes, n_knots, bit_depth):
    k0, a = knot_basis(codes, n_knots, bit_depth)
    return gk[k0] * (1 - a) + gk[k0 + 1] * a


def held_out_error(gk, z, lnt, w, n_knots, bit_depth) -> tuple[float, float]:
    """Held-out exposure prediction error of a curve on pixels it was not fitted to.

    For each pixel ``i`` and exposure ``j`` (with ``ω > 0``), ``ln E_i`` is
    estimated from the pixel's *other* exposures, and ``g(Z_ij)`` is compared
    with ``ln E_i + ln Δt_j``. Returns the weighted mean squared error and its
    standard error (over pixels).
    """
    gz = _g_at(gk, z, n_knots, bit_depth) - lnt[None, :]
    sw = w.sum(axis=1, keepdims=True)
    swx = (w * gz).sum(axis=1, keepdims=True)
    rest = sw - w
    ok = (w > 0) & (rest > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        lne = (swx - w * gz) / rest
    r2 = np.where(ok, (gz - lne) ** 2 * w, 0.0)
    per_px_w = np.where(ok, w, 0).sum(axis=1)
    use = per_px_w > 0
    if not use.any():
        return math.inf, math.inf
    per_px = r2.sum(axis=1)[use] / per_px_w[use]
    return float(np.average(per_px, weights=per_px_w[use])), \
        float(per_px.std(ddof=1) / math.sqrt(max(per_px.size, 2))) if per_px.size > 1 else math.inf


def _monotone(gk, counts):
    from scipy.optimize import isotonic_regression

    res = isotonic_regression(gk, weights=counts + 1.0, increasing=True)
    return np.asarray(res.x, dtype=np.float64)


def debevec(images: np.ndarray, exposure_times_s, *, bit_depth: int | None = None,
            smoothness: float | str = "auto", samples: int = 600, knots: int | None = None,
            clip_margin: float = 0.03, rng: np.random.Generator | None = None) -> ResponseCurve:
    """Recover ``g = ln f⁻¹`` per channel from a bracket (eq. 6.5).

    Parameters
    ----------
    images : ndarray, ``(P, H, W, C)`` or ``(P, H, W)``, uint8/uint16 codes
        The bracket, registered, static scene.
    exposure_times_s : sequence of float, ``(P,)``
        Exposure times (or relative exposures), seconds, distinct.
    bit_depth : int, optional
        True bit depth of the codes (default: the dtype's).
    smoothness : float or "auto"
        λ of eq. 6.5 (scaled as in the module docstring); ``"auto"`` chooses
        it from :data:`LAMBDA_GRID` by held-out exposure prediction.
    samples : int
        Pixels sampled per fit (:func:`hdr.samples.sample_pixels`).
    knots : int, optional
        Unknowns per channel; default ``min(2**bit_depth, 256)``.
    clip_margin : float
        Fraction of the code range at each end left out of the fit
        (:func:`data_weight`).
    rng : numpy.random.Generator, optional
        For the pixel sampling's tie-breaking (default seeded 0).

    Returns
    -------
    ResponseCurve
        ``method="debevec"``; ``selection`` holds λ and every candidate's
        held-out error; ``fit`` the residual RMS and the sample count.

    Raises
    ------
    InputError
        Fewer than two exposures, duplicated times, too few usable pixels.
    """
    from capture.errors import EstimationError, InputError

    z, t, bd = check_stack(images, exposure_times_s, bit_depth=bit_depth)
    p, h, w_, c = z.shape
    if p < 2:
        raise InputError("images", "a response needs at least two exposures")
    rng = np.random.default_rng(0) if rng is None else rng
    n_knots = int(knots) if knots is not None else min(2 ** bd, 256)
    if not 4 <= n_knots <= 2 ** bd:
        raise ValueError(f"knots: expected 4..{2 ** bd}, got {knots}")
    order = np.argsort(t)
    z, t = z[order], t[order]
    lnt = np.log(t)
    idx = sample_pixels(z, n=samples, bit_depth=bd, rng=rng)
    warnings: list[str] = []
    if idx.size * (p - 1) < n_knots:
        warnings.append(f"only {idx.size} usable pixels for {n_knots} unknowns per channel: "
                        "the curve leans on the smoothness term")
    zs = z.reshape(p, h * w_, c)[:, idx]  # (P, N, C)
    lam_given = smoothness != "auto"
    if lam_given:
        lam = float(smoothness)
        if not math.isfinite(lam) or lam < 0:
            raise InputError("--smoothness", f"expected λ >= 0, got {smoothness}")
        grid = (lam,)
    else:
        grid = LAMBDA_GRID
    if lam_given and lam == 0.0:
        warnings.append("λ = 0: no smoothness term; codes without samples are not constrained, "
                        "so a tiny λ = 1e-12 keeps the system solvable")
        grid = (1e-12,)
    fold = np.arange(idx.size) % 2  # alternate along radiance: both folds span the range
    g_out = np.empty((c, 2 ** bd))
    scores: dict[str, list] = {}
    chosen, fit_rms, monotone_fix, linked_px = [], [], [], []
    all_codes = np.arange(2 ** bd)
    for ch in range(c):
        zc = zs[..., ch].T.astype(np.int64)  # (N, P)
        wc = data_weight(zc, bd, clip_margin)
        cand = []
        for lam_k in grid:
            if len(grid) == 1:
                cand.append((lam_k, math.nan, math.nan))
                continue
            errs, ses = [], []
            for f in (0, 1):
                tr, te = fold != f, fold == f
                try:
                    gk, _ = _fit_channel(zc[tr], lnt, wc[tr], n_knots, bd, lam_k)
                except np.linalg.LinAlgError:
                    errs.append(math.inf)
                    ses.append(math.inf)
                    continue
                e, se = held_out_error(gk, zc[te], lnt, wc[te], n_knots, bd)
                errs.append(e)
                ses.append(se)
            cand.append((lam_k, float(np.mean(errs)), float(np.sqrt(np.sum(np.square(ses))) / 2)))
        if len(grid) > 1:
            best = min(cand, key=lambda x: x[1])
            if not math.isfinite(best[1]):
                raise EstimationError("images", "every smoothness candidate failed to solve")
            ok = [x for x in cand if x[1] <= best[1] + best[2]]
            lam_ch = max(ok, key=lambda x: x[0])[0]
            if lam_ch == grid[-1]:
                warnings.append(f"channel {ch}: λ = {lam_ch:g} is the largest searched: the data "
                                "are very noisy or too few; the curve is mostly the prior")
        else:
            lam_ch = grid[0]
        scores[str(ch)] = [{"lambda": a, "held_out_mse": b, "se": s} for a, b, s in cand]
        try:
            gk, lne = _fit_channel(zc, lnt, wc, n_knots, bd, lam_ch)
            keep = np.count_nonzero(wc > 0, axis=1) >= 2
            zc, wc = zc[keep], wc[keep]
        except np.linalg.LinAlgError:
            raise EstimationError("images", f"channel {ch}: the response system is singular "
                                            "(too few distinct codes; use a larger λ)") from None
        resid = (_g_at(gk, zc, n_knots, bd) - lne[:, None] - lnt[None]) * (wc > 0)
        fit_rms.append(float(np.sqrt((resid ** 2).sum() / max((wc > 0).sum(), 1))))
        # Only pixels seen well exposed in two exposures link codes to each other;
        # where few knots are linked, the smoothness prior draws the curve.
        lo, hi = int(0.05 * (n_knots - 1)), int(0.95 * (n_knots - 1))
        linked = np.zeros(n_knots, bool)
        linked[knot_basis(zc[wc > 0], n_knots, bd)[0]] = True
        coverage = float(linked[lo:hi + 1].mean())
        linked_px.append(int(zc.shape[0]))
        if coverage < 0.6 or zc.shape[0] < 50:
            warnings.append(f"channel {ch}: only {zc.shape[0]} pixels are well exposed in two "
                            f"exposures, covering {100 * coverage:.0f} % of the code range: the "
                            "curve is poorly constrained (exposures too far apart or too few)")
        if fit_rms[-1] > 0.1:
            warnings.append(f"channel {ch}: heavy noise ({fit_rms[-1]:.2f} ln units per "
                            "observation): expect response errors of several percent; average "
                            "frames or add exposures")
        k0, _ = knot_basis(zc[wc > 0], n_knots, bd)
        counts = np.bincount(k0, minlength=n_knots).astype(np.float64)
        gm = _monotone(gk, counts)
        change = float(np.max(np.abs(gm - gk)))
        monotone_fix.append(change)
        if change > 0.05:
            warnings.append(f"channel {ch}: the fit was not monotonic (max change {change:.3f} in "
                            "ln units when made so); noisy data or too small a λ")
        g_out[ch] = _g_at(gm, all_codes, n_knots, bd)
        chosen.append(lam_ch)
    # Codes strictly outside the sampled range keep the smoothness extrapolation.
    sel = {"parameter": "lambda", "chosen": chosen, "rule": "given" if lam_given else
           "largest λ within one standard error of the best held-out exposure prediction",
           "candidates": scores, "knots": n_knots}
    fit = {"samples": int(idx.size), "residual_rms_ln": fit_rms, "linked_pixels": linked_px,
           "monotone_max_change_ln": monotone_fix}
    times = tuple(float(x) for x in np.asarray(exposure_times_s, dtype=np.float64))
    return ResponseCurve("debevec", bd, normalise_g(g_out), times, sel, tuple(warnings), fit)
