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
- λ chosen automatically at the corner of the L-curve (:func:`_l_curve`,
  which also says why held-out prediction and GCV are not used); every
  candidate is recorded;
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
>>> r = response_debevec1997(z, t, rng=rng)
>>> x = r.exposure_table()[0]
>>> bool(abs(x[200] / x[100] - 4.0) < 0.1)   # f⁻¹(z) = (z/255)²
True
"""

from __future__ import annotations

import math

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.hdr.response import ResponseCurve, normalise_g
from lumigraph.hdr.samples import check_samples, check_stack, hat_weight, sample_pixels

LAMBDA_GRID = tuple(10.0 ** (k / 4) for k in range(-40, -11))
MIN_SMOOTHNESS = 0.0  # λ = 0 is allowed (no smoothness term; see the warning it gives)


def check_smoothness(smoothness: float | str) -> float | str:
    """:func:`response_debevec1997`'s ``smoothness``: a finite λ >= 0, or
    ``"auto"``.

    Raises
    ------
    InputError
        Naming ``smoothness``.

    Examples
    --------
    >>> check_smoothness(0.5), check_smoothness("auto")
    (0.5, 'auto')
    >>> try:
    ...     check_smoothness(float("nan"))
    ... except InputError as e:
    ...     print(e)
    smoothness: expected λ >= 0 or auto, got nan
    """
    if isinstance(smoothness, str) and smoothness == "auto":
        return smoothness
    try:
        lam = float(smoothness)
    except (TypeError, ValueError):
        lam = math.nan
    if not math.isfinite(lam) or lam < MIN_SMOOTHNESS:
        raise InputError("smoothness", f"expected λ >= {MIN_SMOOTHNESS:g} or auto, got {smoothness}")
    return lam


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
    wk = _smooth_weights(n_knots, bit_depth)
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


class _Reduced:
    """Eq. 6.5 for one channel with the ``ln E_i`` eliminated, ready for any λ.

    Each ``ln E_i`` touches only its own pixel's rows, so for a given ``g`` its
    optimum is the weighted mean of ``g(Z_ij) − ln Δt_j``; substituting it
    projects the data rows (built with ``scipy.sparse``) onto a problem in the
    ``K`` knot values alone. One QR factorisation ``QR`` of those rows (never
    the normal equations) then serves every λ: the fit is the small
    least-squares problem ``[R; √λ S; gauge] g = [Qᵀb; 0; 0]``. The solution
    equals the full sparse system's (:func:`solve_sparse_lstsq` on
    :func:`_system`; a test checks).
    """

    def __init__(self, z, lnt, w, n_knots, bit_depth):
        import scipy.sparse as sp

        use = np.count_nonzero(w > 0, axis=1) >= 2
        if np.count_nonzero(use) < 2:
            raise np.linalg.LinAlgError("too few pixels seen in two exposures")
        self.z, self.w = z[use], w[use]
        self.lnt, self.k, self.bd = lnt, n_knots, bit_depth
        ii, jj = np.nonzero(self.w > 0)
        m = ii.size
        ws = self.w[ii, jj] / math.sqrt(m)
        k0, a = knot_basis(self.z[ii, jj], n_knots, bit_depth)
        r = np.arange(m)
        wb = sp.csr_matrix((np.concatenate([ws * (1 - a), ws * a]),
                            (np.concatenate([r, r]), np.concatenate([k0, k0 + 1]))),
                           shape=(m, n_knots))
        n_px = self.z.shape[0]
        e = sp.csr_matrix((ws, (ii, r)), shape=(n_px, m))  # pixel <- its weighted rows
        s_i = np.asarray(e.multiply(e).sum(axis=1)).ravel()
        # Rows minus their pixel's weighted mean: the projection that eliminates ln E_i.
        mean_b = sp.diags(1.0 / s_i) @ (e @ wb)
        a_red = (wb - sp.diags(ws) @ mean_b[ii]).toarray()
        b = ws * lnt[jj]
        b_red = b - ws * ((e @ b) / s_i)[ii]
        q, self.q_r = np.linalg.qr(a_red, mode="reduced")
        self.qtb = q.T @ b_red
        self.rss0 = max(float(b_red @ b_red - self.qtb @ self.qtb), 0.0)
        self.ii, self.jj, self.ws, self.e, self.s_i, self.wb, self.b = ii, jj, ws, e, s_i, wb, b
        h = 1.0 / (n_knots - 1)
        kk = np.arange(1, n_knots - 1)
        wk = _smooth_weights(n_knots, bit_depth)
        d2 = np.zeros((kk.size, n_knots))
        d2[kk - 1, kk - 1], d2[kk - 1, kk], d2[kk - 1, kk + 1] = wk, -2 * wk, wk
        self.d2 = d2 / h ** 2 * math.sqrt(h)  # ||d2 g||² = ∫ ω² g''² du
        gauge = np.zeros((1, n_knots))
        gauge[0, n_knots // 2] = 1.0
        self.gauge = gauge

    def fit(self, lam):
        """``(g at the knots, ln E per used pixel, data misfit ρ, roughness η)``."""
        import scipy.linalg

        mat = np.vstack([self.q_r, math.sqrt(lam) * self.d2, self.gauge])
        rhs = np.concatenate([self.qtb, np.zeros(self.d2.shape[0] + 1)])
        # QR with column pivoting (LAPACK gelsy): several times cheaper than the SVD.
        gk = scipy.linalg.lstsq(mat, rhs, lapack_driver="gelsy", check_finite=False)[0]
        if not np.all(np.isfinite(gk)):
            raise np.linalg.LinAlgError("singular system")
        rho = float(np.sum((self.q_r @ gk - self.qtb) ** 2)) + self.rss0
        eta = float(np.sum((self.d2 @ gk) ** 2))
        lne = (self.e @ (self.wb @ gk - self.b)) / self.s_i
        return gk, lne, rho, eta


def _fit_channel_sparse(z, lnt, w, n_knots, bit_depth, lam):
    """Eq. 6.5 solved whole (``[g, ln E]`` unknowns), the reference for :class:`_Reduced`."""
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


def _smooth_weights(n_knots, bit_depth):
    k = np.arange(1, n_knots - 1)
    wk = hat_weight(k * (2 ** bit_depth - 1) / (n_knots - 1), bit_depth)
    return np.maximum(wk, 0.05)  # keep the ends smooth too, where data are scarce


def _l_curve(red: _Reduced, grid):
    """Choose λ at the corner of the L-curve (Hansen 1992, doi:10.1137/1034115).

    For each λ of ``grid`` the fit gives a data misfit ``ρ`` (mean squared
    weighted residual of eq. 6.5) and a roughness ``η = ∫ ω² g''² du``; the
    corner of the curve ``(ln ρ, ln η)`` — its point of largest curvature —
    separates the λ that only trade roughness for fitting noise from the
    ones that bend the curve away from the data.

    Why not held-out prediction (or GCV, which estimates the same thing):
    on these brackets the exact curve predicts held-out *pixels* worse than
    a wiggly fit does (bench 8-bit, 1500 samples: held-out MSE 9.3e-4 for
    the truth against 8.9e-4 for λ = 1e-9, whose curve is 0.034 off). With
    noise added before the response, ``E[ln X | Z]`` is not ``ln f⁻¹(Z)``
    (errors in variables: it follows the radiance histogram), and a curve
    within a near-periodic ripple of one exposure step predicts as well as
    the truth; both are genuine properties of new pixels too, so an
    unbiased prediction-error estimate still prefers too small a λ, and more
    so as samples grow. The L-curve corner does not target prediction.

    Returns ``(λ, candidates)``: every candidate's ``ln ρ``, ``ln η`` and
    curvature.
    """
    rows = []
    for lam in grid:
        try:
            _, _, rho, eta = red.fit(lam)
        except np.linalg.LinAlgError:
            continue
        rows.append((lam, math.log(max(rho, 1e-300)), math.log(max(eta, 1e-300))))
    if not rows:
        from lumigraph.capture.errors import EstimationError

        raise EstimationError("images", "every smoothness candidate failed to solve")
    lam_a = np.array([r[0] for r in rows])
    x, y = np.array([r[1] for r in rows]), np.array([r[2] for r in rows])
    if len(rows) < 3:
        kap = np.zeros(len(rows))
    else:
        tt = np.log10(lam_a)
        dx, dy = np.gradient(x, tt), np.gradient(y, tt)
        ddx, ddy = np.gradient(dx, tt), np.gradient(dy, tt)
        kap = (dx * ddy - dy * ddx) / np.maximum(dx ** 2 + dy ** 2, 1e-300) ** 1.5
        kap[[0, -1]] = -np.inf  # one-sided differences at the ends are not corners
    i = int(np.argmax(kap))
    cand = [{"lambda": float(a), "ln_misfit": b, "ln_roughness": c_,
             "curvature": float(k) if math.isfinite(k) else None}
            for (a, b, c_), k in zip(rows, kap, strict=True)]
    return float(lam_a[i]), cand


def _discrepancy(red: _Reduced, cand, lam_corner, lnt, w):
    """Under heavy noise the L-curve corner is broad and sits at its low-λ end;
    there, take instead the largest λ whose misfit stays within what the noise
    predicts (Morozov's discrepancy principle).

    The noise variance is estimated from the least-smoothed fit (``m`` rows,
    ``N`` pixel unknowns, ``K`` knots): ``σ² ≈ ρ_min m / (m − N − K)``; the
    exact curve would leave ``E ρ = σ² (m − N) / m`` (only the ``ln E`` fitted),
    so λ may grow while ``ρ(λ) ≤ ρ_min (m − N) / (m − N − K)``. Applied only
    when the corner's per-observation residual says the noise is heavy
    (> 0.1 ln units, the warning below): on clean data the corner is sharp
    and kept.
    """
    gk, lne, _, _ = red.fit(lam_corner)
    ok = w > 0
    ok = ok[np.count_nonzero(ok, axis=1) >= 2]
    resid = (_g_at(gk, red.z, red.k, red.bd) - lne[:, None] - lnt[None]) * ok
    if np.sqrt((resid ** 2).sum() / max(ok.sum(), 1)) <= 0.1:
        return lam_corner
    m, n_px = red.ii.size, red.z.shape[0]
    dof = m - n_px - red.k
    if dof <= 0:
        return lam_corner
    bound = math.log(math.exp(cand[0]["ln_misfit"]) * (m - n_px) / dof)
    within = [c["lambda"] for c in cand if c["ln_misfit"] <= bound]
    lam = max([lam_corner] + within)
    for c in cand:
        c["discrepancy_bound_ln_misfit"] = bound
    return float(lam)


def _monotone(gk, counts):
    from scipy.optimize import isotonic_regression

    res = isotonic_regression(gk, weights=counts + 1.0, increasing=True)
    return np.asarray(res.x, dtype=np.float64)


def response_debevec1997(images: np.ndarray, exposure_times_s, *, bit_depth: int | None = None,
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
        it from :data:`LAMBDA_GRID` at the L-curve corner.
    samples : int
        Pixels sampled per fit (:func:`hdr.samples.sample_pixels`), at least 2
        (:func:`hdr.samples.check_samples`).
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
        L-curve point; ``fit`` the residual RMS and the sample count.

    Raises
    ------
    InputError
        Fewer than two exposures, duplicated times, too few usable pixels.
    """
    from lumigraph.capture.errors import EstimationError, InputError

    z, t, bd = check_stack(images, exposure_times_s, bit_depth=bit_depth)
    p, h, w_, c = z.shape
    if p < 2:
        raise InputError("images", "a response needs at least two exposures")
    check_samples(samples)
    smoothness = check_smoothness(smoothness)
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
        grid = (lam,)
    else:
        grid = LAMBDA_GRID
    if lam_given and lam == 0.0:
        warnings.append("λ = 0: no smoothness term; codes without samples are not constrained, "
                        "so a tiny λ = 1e-12 keeps the system solvable")
        grid = (1e-12,)
    g_out = np.empty((c, 2 ** bd))
    scores: dict[str, list] = {}
    chosen, fit_rms, monotone_fix, linked_px = [], [], [], []
    all_codes = np.arange(2 ** bd)
    for ch in range(c):
        zc = zs[..., ch].T.astype(np.int64)  # (N, P)
        wc = data_weight(zc, bd, clip_margin)
        try:
            red = _Reduced(zc, lnt, wc, n_knots, bd)
        except np.linalg.LinAlgError:
            raise EstimationError("images", f"channel {ch}: too few pixels are well exposed in "
                                            "two exposures") from None
        if len(grid) > 1:
            lam_ch, cand = _l_curve(red, grid)
            if lam_ch == grid[-1] or lam_ch == grid[0]:
                warnings.append(f"channel {ch}: λ = {lam_ch:g} is at the end of the searched "
                                "range: the data are very noisy or too few; the curve is mostly "
                                "the prior" if lam_ch == grid[-1] else
                                f"channel {ch}: λ = {lam_ch:g} is the smallest searched")
        else:
            lam_ch = grid[0]
            cand = [{"lambda": lam_ch}]
        if len(grid) > 1:
            lam_ch = _discrepancy(red, cand, lam_ch, lnt, wc)
        scores[str(ch)] = cand
        try:
            gk, lne, _, _ = red.fit(lam_ch)
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
           ("L-curve corner: largest curvature of (ln data misfit, ln roughness) over λ; "
            "under heavy noise the largest λ within the discrepancy bound"),
           "candidates": scores, "knots": n_knots}
    fit = {"samples": int(idx.size), "residual_rms_ln": fit_rms, "linked_pixels": linked_px,
           "monotone_max_change_ln": monotone_fix}
    times = tuple(float(x) for x in np.asarray(exposure_times_s, dtype=np.float64))
    return ResponseCurve("debevec", bd, normalise_g(g_out), times, sel, tuple(warnings), fit)
