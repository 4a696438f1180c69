"""Mitsunaga & Nayar (1999): radiometric self-calibration.

T. Mitsunaga and S. K. Nayar, "Radiometric Self Calibration", CVPR 1999,
doi:10.1109/CVPR.1999.786966. Reference ch. 6.3.1, eq. 6.6 and the ``R_q``
update.

The inverse response is a polynomial in the normalised code ``M = z/z_max``,
``f(M) = Σ c_n M^n`` with ``f(1) = 1``; for every pixel ``p`` seen unclipped in
exposures ``q`` and ``q'``, ``f(M_pq) = R_qq' f(M_pq')`` (eq. 6.6) with
``R_qq' = e_q / e_q'``. The method alternates a linear least-squares fit of
the coefficients for fixed ratios with an update of the ratios for a fixed
curve; a joint Gauss–Newton fit in ln units finishes.

What this implementation does beyond the paper (and pfstools, which fixes the
order at 3 and skips the ratio update):

- at most 10 alternations (the paper needs fewer than 10): along the
  ambiguity below the objective is flat, so more iterations only drift;
- every exposure pair, not only neighbours; saturated and black codes masked;
- a numerically stable basis: shifted Chebyshev polynomials ``T_n(2M − 1)``
  on normalised codes, solved by QR with column pivoting
  (``scipy.linalg.lstsq``, LAPACK ``gelsy``), never the
  normal equations of a raw Vandermonde matrix; the constraint ``f(1) = 1`` is
  built into the basis (``f = 1 + Σ a_n (T_n(2M−1) − 1)``);
- equations reweighted each iteration so residuals are in ln units and
  divided by their predicted noise (shot noise ∝ 1/f plus code quantisation
  ∝ (f'/f)², the two levels fitted to the residuals by NNLS): eq. 6.6 in
  irradiance units would let dark, relatively noisy samples count least
  where ln error counts them most;
- the power gauge fixed every iteration (exposures' log-span matched to the
  rough one), so the alternation cannot drift along the ambiguity below;
- the ratio update (the paper's ``R_q^(k)``) as a weighted least-squares fit
  of ``ln e_q`` to ``ln f(M_pq) − ln f(M_pq')`` over all pairs;
- the data fix the exposures only up to a common power (``f → f^γ``,
  ``R → R^γ`` leaves eq. 6.6 unchanged, the exponential ambiguity of
  Grossberg & Nayar 2003); the power is set so the refined exposures agree
  best (in log) with the rough ones given, and reported;
- the alternation's result refined by Gauss–Newton on eq. 6.6 in ln units
  (coefficients of every channel and the ln exposures together, same noise
  weights, step halving keeps ``f > 0`` at the data): the linear solve
  weights residuals by the previous curve, which lets high orders (8–10)
  run away on noisy data; the joint ln fit keeps them usable;
- curves that cannot break: every linear solve is a least-squares fit under
  linear constraints (Lawson & Hanson's LSI by NNLS) that keep ``f``
  positive and non-decreasing on every observed code, and the joint
  refinement only takes steps that keep them; a candidate order whose curve
  is still not monotone over the observed codes is rejected, with the reason;
- only codes that follow the exposure are used (:func:`responsive_range`: a
  film base or black level, a shoulder), and pixels whose code does not move
  over two stops are dropped (:func:`static_pixels`: Memorial's pure-blue
  registration borders, which the smoothness-seeking sampler favours);
- one order (≤ 10) for all channels, chosen on 3x the samples by the BIC of
  the 2-fold held-out error of predicting one exposure's code from another's
  (code units, each error divided by its predicted variance from the sensor
  noise Debevec's fit estimates from the bracket: the Gaussian likelihood; an
  ln error is ruled by the darkest codes). The likelihood's N is the number
  of independent held-out residuals (a pixel with P valid codes gives P − 1),
  not of pixels: counting pixels divided the data's evidence by the codes
  per pixel, and the walls' sRGB toe was fitted at order 3 where 4–5 is what
  the data support (docs/decisions/hdr-mitsunaga-stable.md). The best order and the next are
  scored again with the joint refinement and the better taken; every
  candidate recorded. The former rule ("lowest order within one
  standard error of the best") picked 6/9/6 and 6/9/9 on Memorial with seeds
  0 and 1 (docs/decisions/hdr-mitsunaga-stable.md);
- the final curve is bias-corrected by a parametric bootstrap (:func:`_debias`,
  as Debevec's): the noise and the floor at code 0 bias the dark codes; the
  noise it renders is measured by Debevec's fit at the exposures this fit
  found (at rough times the residuals hold the times' errors too);
- the final exposure ratios from linear sums through the corrected curve
  over every pixel (:func:`refine_exposures`): an ln-domain fit reads each
  dark code low by ``Var x / 2X²``, a per-cent bias on a read-noise-limited
  bracket whatever the weights (docs/decisions/hdr-mitsunaga-stable.md),
  solved jointly with a smooth shape correction of the curve from the sums
  in brightness bins (the polynomial is off by 0.5-1 % at some codes);
- a channel whose own exposure ratios differ from the common ones beyond its
  sampling noise and far beyond the other channels' is named in ``warnings``;
- exposures known exactly (``reference_times``) fix the scale, and with two
  or more the power the data leave free (:func:`align_power`).

Examples
--------
>>> rng = np.random.default_rng(1)
>>> e = np.exp(rng.uniform(-5, 0, (40, 40, 1)))
>>> t = np.array([0.1, 0.3, 0.9, 2.7])
>>> z = np.stack([np.round(255 * np.clip(e * ti, 0, 1) ** 0.5) for ti in t]).astype(np.uint8)
>>> r = response_mitsunaga1999(z, t * [1.0, 1.08, 0.95, 1.0], samples=300, rng=rng)
>>> x = r.exposure_table()[0]
>>> bool(abs(x[200] / x[100] - 4.0) < 0.1)
True
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from lumigraph.capture.errors import InputError
from lumigraph.hdr.response import ResponseCurve, normalise_g
from lumigraph.hdr.samples import check_samples, check_stack, sample_pixels

MAX_ORDER = 10
MIN_ORDER = 1


def check_order(order: int | str) -> int | str:
    """:func:`response_mitsunaga1999`'s ``order``: an integer
    :data:`MIN_ORDER`..:data:`MAX_ORDER`, or ``"auto"``.

    Raises
    ------
    InputError
        Naming ``order``.

    Examples
    --------
    >>> check_order(3), check_order("auto")
    (3, 'auto')
    >>> try:
    ...     check_order(2.5)
    ... except InputError as e:
    ...     print(e)
    order: expected 1..10 or auto, got 2.5
    """
    if isinstance(order, str) and order == "auto":
        return order
    if isinstance(order, bool) or not isinstance(order, int | np.integer) \
            or not MIN_ORDER <= order <= MAX_ORDER:
        raise InputError("order", f"expected {MIN_ORDER}..{MAX_ORDER} or auto, got {order!r}")
    return int(order)


def check_reference_times(reference_times, count: int) -> dict[int, float]:
    """:func:`response_mitsunaga1999`'s ``reference_times``: ``{index: exposure}``,
    indices ``0..count-1``, exposures finite and > 0.

    Raises
    ------
    InputError
        Naming ``reference_times``.

    Examples
    --------
    >>> check_reference_times({1: 0.5}, 3)
    {1: 0.5}
    >>> try:
    ...     check_reference_times({3: 0.5}, 3)
    ... except InputError as e:
    ...     print(e)
    reference_times: image index 3 is not one of the 3 images
    """
    out: dict[int, float] = {}
    for k, v in (reference_times or {}).items():
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 0 <= k < count:
            raise InputError("reference_times", f"image index {k!r} is not one of the {count} "
                                                "images")
        try:
            x = float(v)
        except (TypeError, ValueError):
            x = math.nan
        if not (math.isfinite(x) and x > 0):
            raise InputError("reference_times", f"exposure of image {k} must be a finite number "
                                                f"> 0, got {v!r}")
        out[int(k)] = x
    return out


def basis(m: np.ndarray, order: int) -> np.ndarray:
    """Constrained basis ``T_n(2M − 1) − 1``, ``n = 1..order`` (zero at ``M = 1``),
    shape ``m.shape + (order,)``.

    Examples
    --------
    >>> basis(np.array([1.0, 0.5]), 3).round(3).tolist()
    [[0.0, 0.0, 0.0], [-1.0, -2.0, -1.0]]
    """
    x = 2.0 * np.asarray(m, dtype=np.float64) - 1.0
    out = np.empty(x.shape + (order,))
    t_prev, t_cur = np.ones_like(x), x
    for n in range(1, order + 1):
        out[..., n - 1] = t_cur - 1.0
        t_prev, t_cur = t_cur, 2.0 * x * t_cur - t_prev
    return out


def evaluate(a: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``f(M) = 1 + Σ a_n (T_n(2M−1) − 1)``."""
    return 1.0 + basis(m, a.size) @ a


MAX_PAIR_GAP = 3  # exposures compared at most this many steps apart


def _pairs(mz: np.ndarray, valid: np.ndarray):
    """All (pixel, q, q') with both exposures valid, q < q' <= q + MAX_PAIR_GAP
    (farther pairs repeat what the chain of nearer ones says, at the cost of
    pairs that grow as P²: 120 per pixel on Memorial's 16 exposures)."""
    p = mz.shape[1]
    qa, qb = np.triu_indices(p, 1)
    near = qb - qa <= MAX_PAIR_GAP
    qa, qb = qa[near], qb[near]
    ok = valid[:, qa] & valid[:, qb]
    pix, k = np.nonzero(ok)
    return pix, qa[k], qb[k]


def _fit(chans, ln_e0, orders, ranges, code_max, iters=10, tol=1e-8, noise_weights=True,
         refine=True):
    """Alternate eq. 6.6 (coefficients, per channel) and the ratio update
    (pooled over channels: the exposures are common to all of them).

    ``chans``: list of ``(mz (N, P), valid (N, P))``; returns ``(coeffs, ln_e)``.
    """
    p = ln_e0.size
    data = []
    for (mz, valid), order in zip(chans, orders, strict=True):
        pix, qa, qb = _pairs(mz, valid)
        if pix.size < order + 2:
            raise np.linalg.LinAlgError("too few pixel pairs")
        ma, mb = mz[pix, qa], mz[pix, qb]
        data.append([qa, qb, basis(ma, order), basis(mb, order), np.maximum(ma, 1e-3),
                     np.maximum(mb, 1e-3), ma, mb, None])
    cons = [monotone_constraints(m_range, order, code_max)
            for m_range, order in zip(ranges, orders, strict=True)]
    ln_e = ln_e0.copy()
    coeffs = [np.zeros(o) for o in orders]
    for _ in range(iters):
        lap = np.zeros((p, p))
        rhs_e = np.zeros(p)
        change = 0.0
        for k, (qa, qb, ba, bb, fa_prev, fb_prev, ma, mb, var) in enumerate(data):
            r = np.exp(ln_e[qa] - ln_e[qb])
            # (fa - r fb) / (fa + r fb) is half the ln residual; divided by the
            # predicted sd of that ln residual (shot + quantisation noise) when known.
            s = 2.0 / (fa_prev + r * fb_prev)
            if var is not None:
                s = s / np.sqrt(var)
            # QR with column pivoting (LAPACK gelsy): stable, and far cheaper than SVD.
            a_new = constrained_lstsq((ba - r[:, None] * bb) * s[:, None], -(1.0 - r) * s,
                                      *cons[k])
            fa, fb = 1.0 + ba @ a_new, 1.0 + bb @ a_new
            pos = (fa > 1e-6) & (fb > 1e-6)
            d = np.log(fa[pos]) - np.log(fb[pos])
            wts = np.ones(d.size) if var is None else 1.0 / var[pos]
            # Normal equations of the tiny, well-conditioned exposure graph (P x P).
            ia, ib = qa[pos], qb[pos]
            # the graph Laplacian and its right side by bincount (np.add.at is 10x slower)
            lap += (np.bincount(ia * p + ia, wts, p * p) + np.bincount(ib * p + ib, wts, p * p)
                    - np.bincount(ia * p + ib, wts, p * p)
                    - np.bincount(ib * p + ia, wts, p * p)).reshape(p, p)
            rhs_e += np.bincount(ia, wts * d, p) - np.bincount(ib, wts * d, p)
            change = max(change, float(np.max(np.abs(a_new - coeffs[k]))))
            coeffs[k] = a_new
            if noise_weights:
                var = _noise_var(a_new, ma, mb, np.maximum(fa, 1e-6), np.maximum(fb, 1e-6),
                                 d, pos, ln_e[qa] - ln_e[qb])
            data[k] = [qa, qb, ba, bb, np.maximum(fa, 1e-6), np.maximum(fb, 1e-6), ma, mb, var]
        lap[0, :] = 0.0
        lap[0, 0] = 1.0  # gauge: the first exposure keeps its given value
        rhs_e[0] = ln_e0[0]
        # Eq. 6.6 is unchanged by f -> f^γ, R -> R^γ: without a gauge for the power the
        # alternation drifts along that valley (towards a curve flat near zero). Fix it
        # each iteration: the exposures' log-span agrees best with the rough one.
        ln_new = _align_power(np.linalg.solve(lap, rhs_e), ln_e0)[1]
        change = max(change, float(np.max(np.abs(ln_new - ln_e))))
        ln_e = ln_new
        if change < tol:
            break
    if refine:
        coeffs, ln_e = _gauss_newton(data, coeffs, ln_e, ln_e0, noise_weights=noise_weights,
                                     cons=cons)
    return coeffs, ln_e


def _gauss_newton(data, coeffs, ln_e, ln_e0, iters=8, noise_weights=True, cons=None):
    """Eq. 6.6 fitted directly in ln units: coefficients of every channel and
    the ln exposures together, weighted by the predicted noise of each ln residual,
    started from the alternation's solution.

    Residual of a pair: ``ln f(M_pq) − ln f(M_pq') − (ln e_q − ln e_q')``; its
    Jacobian w.r.t. the coefficients is ``basis(M_pq)/f(M_pq) − basis(M_pq')/f(M_pq')``.
    Gauges: ``ln e_0`` fixed, and the power (f → f^γ, e → e^γ) by one heavily
    weighted row ``y·ln e = y·ln e_rough`` (``y`` the centred rough ln exposures).
    """
    p = ln_e.size
    sizes = [a.size for a in coeffs]
    offs = np.concatenate([[0], np.cumsum(sizes)])
    ncol = int(offs[-1]) + p - 1
    y = ln_e0 - ln_e0.mean()

    def state(cs, le):
        parts = []
        if cons is not None and any(np.any(g @ a < h - 1e-12)
                                    for a, (g, h) in zip(cs, cons, strict=True)):
            return None  # a step may not leave the monotone, positive curves
        for (qa, qb, ba, bb, *_rest), a in zip(data, cs, strict=True):
            fa, fb = 1.0 + ba @ a, 1.0 + bb @ a
            if np.any(fa <= 1e-6) or np.any(fb <= 1e-6):
                return None
            parts.append((fa, fb, np.log(fa) - np.log(fb) - (le[qa] - le[qb])))
        return parts

    def cost(parts, sds):
        return sum(float(np.sum((r / sd) ** 2))
                   for (_fa, _fb, r), sd in zip(parts, sds, strict=True))

    cur = state(coeffs, ln_e)
    if cur is None:
        return coeffs, ln_e
    sds = [np.ones(r.size) if d[-1] is None else np.sqrt(d[-1])
           for d, (_a, _b, r) in zip(data, cur, strict=True)]
    for _ in range(iters):
        rows, rhs = [], []
        for k, ((qa, qb, ba, bb, *_rest), (fa, fb, r), sd) in enumerate(
                zip(data, cur, sds, strict=True)):
            jk = np.zeros((r.size, ncol))
            jk[:, offs[k]:offs[k + 1]] = (ba / fa[:, None] - bb / fb[:, None])
            e_cols = int(offs[-1]) - 1
            ia, ib = np.nonzero(qa)[0], np.nonzero(qb)[0]
            jk[ia, e_cols + qa[ia]] -= 1.0
            jk[ib, e_cols + qb[ib]] += 1.0
            rows.append(jk / sd[:, None])
            rhs.append(-r / sd)
        scale = math.sqrt(sum(x.shape[0] for x in rows)) * 1e3
        gauge = np.zeros((1, ncol))
        gauge[0, int(offs[-1]):] = y[1:] * scale
        rows.append(gauge)
        rhs.append(np.array([(float(y @ ln_e0) - float(y @ ln_e)) * scale]))
        step = scipy.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), lapack_driver="gelsy",
                                  check_finite=False)[0]
        c0 = cost(cur, sds)
        t = 1.0
        for _h in range(12):
            cs = [a + t * step[offs[k]:offs[k + 1]] for k, a in enumerate(coeffs)]
            le = ln_e.copy()
            le[1:] += t * step[int(offs[-1]):]
            nxt = state(cs, le)
            if nxt is not None and cost(nxt, sds) <= c0:
                break
            t *= 0.5
        else:
            break
        coeffs, ln_e, cur = cs, le, nxt
        if noise_weights:
            sds = []
            for (qa, qb, _ba, _bb, _fa, _fb, ma, mb, _v), a, (fa, fb, r) in zip(data, coeffs, cur,
                                                                                 strict=True):
                pos = np.ones(fa.size, bool)
                sds.append(np.sqrt(_noise_var(a, ma, mb, fa, fb, r + (ln_e[qa] - ln_e[qb]), pos,
                                              ln_e[qa] - ln_e[qb])))
        if float(np.max(np.abs(t * step))) < 1e-9:
            break
    return coeffs, ln_e


# f at the darkest observed code stays above this (f(1) = 1): the table's own
# floor (table_from_poly), so ln f is finite wherever there are data.
F_FLOOR = 1e-4
CONSTRAINT_POINTS = 256


def code_grid(m_range: tuple[float, float], code_max: int) -> np.ndarray:
    """The normalised codes from ``m_range[0]`` to ``m_range[1]``: every code, or
    :data:`CONSTRAINT_POINTS` evenly spaced ones when there are more."""
    lo, hi = round(m_range[0] * code_max), round(m_range[1] * code_max)
    if hi - lo + 1 <= CONSTRAINT_POINTS:
        return np.arange(lo, hi + 1) / code_max
    return np.linspace(lo, hi, CONSTRAINT_POINTS) / code_max


def monotone_constraints(m_range: tuple[float, float], order: int,
                         code_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Linear constraints ``G a >= h`` that make ``f`` positive and non-decreasing
    over the observed normalised codes ``m_range``: ``f(M_lo) >= F_FLOOR`` and
    ``f(M_k+1) - f(M_k) >= 0`` on every code between (:func:`code_grid`).

    Examples
    --------
    >>> g, h = monotone_constraints((0.1, 0.9), 2, 10)
    >>> g.shape, float(h[0])
    ((9, 2), -0.9999)
    """
    m = code_grid(m_range, code_max)
    if m.size < 2:
        m = np.array([m_range[0], max(m_range[1], m_range[0] + 1.0 / code_max)])
    b = basis(m, order)
    g = np.vstack([b[:1], np.diff(b, axis=0)])
    h = np.concatenate([[F_FLOOR - 1.0], np.zeros(m.size - 1)])
    return g, h


def constrained_lstsq(a: np.ndarray, b: np.ndarray, g: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``min ||a x - b||`` subject to ``g x >= h`` (Lawson & Hanson 1974, ch. 23:
    the problem reduced to least distance programming and solved by NNLS).

    The unconstrained solution is returned when it already satisfies the
    constraints; when no ``x`` satisfies them, ``LinAlgError``.

    Examples
    --------
    >>> x = constrained_lstsq(np.eye(2), np.array([1.0, -1.0]), np.array([[0.0, 1.0]]),
    ...                       np.array([0.5]))
    >>> x.round(6).tolist()
    [1.0, 0.5]
    """
    from scipy.optimize import nnls

    x = scipy.linalg.lstsq(a, b, lapack_driver="gelsy", check_finite=False)[0]
    if np.all(g @ x >= h - 1e-12):
        return x
    q, r = np.linalg.qr(a)
    c = q.T @ b
    try:
        gt = scipy.linalg.solve_triangular(r, g.T, trans="T", check_finite=False).T  # g R^-1
    except np.linalg.LinAlgError:
        raise np.linalg.LinAlgError("rank-deficient constrained fit") from None
    ht = h - gt @ c
    n = r.shape[0]
    e = np.vstack([gt.T, ht[None, :]])
    f = np.zeros(n + 1)
    f[-1] = 1.0
    u = nnls(e, f, maxiter=50 * e.shape[1])[0]
    res = e @ u - f
    if abs(res[-1]) < 1e-12:
        raise np.linalg.LinAlgError("the constraints admit no solution")
    y = -res[:n] / res[-1]
    x = scipy.linalg.solve_triangular(r, y + c, check_finite=False)
    return x


def _noise_var(a, ma, mb, fa, fb, d, pos, ln_r):
    """Predicted variance of each pair's ln residual: shot noise (∝ 1/f) plus
    code quantisation (∝ (f'/f)²), the two coefficients fitted to the squared
    residuals by non-negative least squares (so the noise level comes from the data)."""
    from scipy.optimize import nnls

    h = 1e-4
    da = (evaluate(a, ma + h) - evaluate(a, ma - h)) / (2 * h) / fa
    db = (evaluate(a, mb + h) - evaluate(a, mb - h)) / (2 * h) / fb
    shot = 1.0 / fa + 1.0 / fb
    quant = da ** 2 + db ** 2
    res2 = np.zeros(fa.size)
    res2[pos] = (d - ln_r[pos]) ** 2
    x = np.stack([shot, quant], axis=1)
    ok = pos & np.isfinite(quant)
    coef = nnls(x[ok], res2[ok])[0]
    var = x @ coef
    floor = 1e-3 * max(float(np.median(var[ok])), 1e-12)
    return np.where(np.isfinite(var), np.maximum(var, floor), floor)


def _held_out_codes(a, ln_e, mz, valid, m_range, noise=None, code_max=255):
    """Each held-out pixel's summed squared error of predicting one exposure's code
    from another's (``M_q' = f^-1(f(M_q) e_q'/e_q)``, both directions, in codes of
    the unit range), divided by the fold's count of predictions.

    The code domain is where the noise is roughly even: an ln-domain error is
    dominated by the darkest codes, where ``ln f`` is steep and no order fits
    better than another (Memorial's film base: codes 17-19 over ten stops).
    With a sensor ``noise = (a, b)`` (``Var X = a X + b``, ``X`` relative to the
    top code's) each squared error is divided by its predicted variance (both
    codes' noise through the curve's slope, plus a code's rounding), so the
    score is the Gaussian likelihood's: codes in the toe, where read noise is a
    fraction of a code, are not drowned by the shot noise of the bright ones.
    """
    pix, qa, qb = _pairs(mz, valid)
    grid = np.linspace(m_range[0], m_range[1], 1024)
    fg = np.maximum.accumulate(np.maximum(evaluate(a, grid), F_FLOOR))
    fa = np.interp(mz[pix, qa], grid, fg)
    fb = np.interp(mz[pix, qb], grid, fg)
    dl = ln_e[qb] - ln_e[qa]
    rb = np.interp(fa * np.exp(dl), fg, grid) - mz[pix, qb]
    ra = np.interp(fb * np.exp(-dl), fg, grid) - mz[pix, qa]
    if noise is not None:
        # code variance at M: (a f + b) / f'(M)^2 + rounding, in units of the code range
        slope = np.maximum(np.gradient(fg, grid), 1e-12)
        sa, sb = np.interp(mz[pix, qa], grid, slope), np.interp(mz[pix, qb], grid, slope)
        rnd = 1.0 / (12.0 * code_max ** 2)
        va = (noise[0] * fa + noise[1]) / sa ** 2 + rnd
        vb = (noise[0] * fb + noise[1]) / sb ** 2 + rnd
        k = np.exp(dl)  # dM_b/dM_a = k f'(M_a) / f'(M_b)
        ra, rb = ra / np.sqrt(va + (sb / (k * sa)) ** 2 * vb), rb / np.sqrt(vb + (k * sa / sb) ** 2 * va)
    per = np.bincount(pix, weights=ra ** 2 + rb ** 2, minlength=mz.shape[0])
    cnt = np.bincount(pix, minlength=mz.shape[0])
    return per[cnt > 0] / max(2 * int(np.sum(cnt)), 1)


def _align_power(ln_e, ln_nominal):
    """Choose γ, c so ``γ·ln_e + c`` best matches the rough ``ln_nominal`` (least squares)."""
    x = ln_e - ln_e.mean()
    y = ln_nominal - ln_nominal.mean()
    gam = float(np.dot(x, y) / np.dot(x, x)) if np.dot(x, x) > 0 else 1.0
    return gam, gam * x + ln_nominal.mean()


def align_power(ln_e: np.ndarray, ln_rough: np.ndarray, *,
                reference: dict[int, float] | None = None) -> tuple[float, np.ndarray]:
    """Fix the data's free power and scale: ``γ, γ·ln_e + c``.

    The data determine the ln exposures only up to ``γ·ln_e + c`` (eq. 6.6 is
    unchanged by ``f → f^γ``, ``e → e^γ``; the radiance scale is free too).
    Without references both come from the rough times (least squares in log);
    one reference exposure (``{index: ln seconds}``) is met exactly and the
    power still comes from the rough times; two or more fix the power and the
    scale themselves (least squares over them), so rough times no longer matter.

    Examples
    --------
    >>> x = np.log([1.0, 2.0, 4.0])
    >>> gam, le = align_power(0.5 * x, np.log([1.0, 2.2, 3.9]), reference={0: 0.0, 2: np.log(4.0)})
    >>> round(gam, 6), np.exp(le).round(6).tolist()
    (2.0, [1.0, 2.0, 4.0])
    """
    ref = reference or {}
    if not ref:
        return _align_power(ln_e, ln_rough)
    k = np.array(sorted(ref), dtype=np.int64)
    y = np.array([ref[i] for i in k])
    if k.size == 1:
        x = ln_e - ln_e[k[0]]
        yy = ln_rough - ln_rough[k[0]]
        gam = float(np.dot(x, yy) / np.dot(x, x)) if np.dot(x, x) > 0 else 1.0
        return gam, gam * x + y[0]
    x = ln_e[k] - ln_e[k].mean()
    gam = float(np.dot(x, y - y.mean()) / np.dot(x, x)) if np.dot(x, x) > 0 else 1.0
    return gam, gam * (ln_e - ln_e[k].mean()) + y.mean()


def is_monotone(a: np.ndarray, m_range: tuple[float, float], code_max: int) -> bool:
    """``f`` positive and non-decreasing over the codes of ``m_range`` (:func:`code_grid`).

    Examples
    --------
    >>> is_monotone(np.array([0.5]), (0.1, 0.9), 255), is_monotone(np.array([0.0, 0.5]), (0.0, 1.0), 255)
    (True, False)
    """
    f = evaluate(a, code_grid(m_range, code_max))
    return bool(f[0] > 0 and np.all(np.diff(f) >= -1e-9 * max(abs(float(f[-1])), 1.0)))


DISAGREE_LIMIT = 9.0  # (RMS of a channel's ln-exposure difference / its sampling sd)^2: 3 sigma


def _channel_disagreement(chans, fold_le, ln_nom, le_joint, n, ranges, code_max):
    """Per channel: mean over exposures of ``(ln e_channel − ln e_joint)² / σ²``,
    ``ln e_channel`` the channel's own fit (at order ``n``, same gauge), ``σ²`` its
    sampling variance from the two half-sample fits (``(le_a − le_b)² / 4``, pooled
    over exposures). Every channel sees the same exposures, so a channel whose data
    imply other ratios beyond its noise is not following the shared model."""
    out = []
    _, ref_joint = _align_power(le_joint, ln_nom)
    for ch, (mz, valid) in enumerate(chans):
        les = fold_le.get((n, ch))
        if not les or len(les) != 2:
            out.append((0.0, 0.0))
            continue
        try:
            _, le_c = _fit([(mz, valid)], ln_nom, [n], [ranges[ch]], code_max, refine=False)
        except np.linalg.LinAlgError:
            out.append((0.0, 0.0))
            continue
        a0 = _align_power(les[0], ln_nom)[1]
        a1 = _align_power(les[1], ln_nom)[1]
        var = float(np.mean((a0 - a1) ** 2)) / 4 + 1e-12
        d = _align_power(le_c, ln_nom)[1] - ref_joint
        out.append((float(np.mean(d ** 2)) / var, float(np.sqrt(np.mean(d ** 2)))))
    return out


STATIC_STOPS = 2.0  # exposure span over which an unclipped scene point must change code
STATIC_RANGE = 0.01  # ... by more than this fraction of the code range (2.5 codes at 8 bits)


def static_pixels(zs: np.ndarray, t: np.ndarray, clip_margin: float) -> np.ndarray:
    """Pixels whose code does not move (by more than :data:`STATIC_RANGE` of the
    range) between their first and last unclipped exposures although these are
    :data:`STATIC_STOPS` or more stops apart, in any channel: ``(N,)`` bool.

    ``zs``: ``(P, N, C)`` normalised codes, exposures ascending; ``t``: ``(P,)``.

    Examples
    --------
    >>> zs = np.array([[[0.1], [0.5]], [[0.3], [0.5]], [[0.9], [0.5]]])
    >>> static_pixels(zs, np.array([1.0, 3.0, 9.0]), 0.03).tolist()
    [False, True]
    """
    valid = (zs >= clip_margin) & (zs <= 1 - clip_margin)
    p = zs.shape[0]
    first = np.argmax(valid, axis=0)
    last = p - 1 - np.argmax(valid[::-1], axis=0)
    zf = np.take_along_axis(zs, first[None], 0)[0]
    zl = np.take_along_axis(zs, last[None], 0)[0]
    span = np.log2(t[last] / t[first])
    bad = valid.any(axis=0) & (span >= STATIC_STOPS) & (zl - zf <= STATIC_RANGE)
    return bad.any(axis=1)


def responsive_range(zs: np.ndarray, t: np.ndarray, zmax: int) -> tuple[np.ndarray, np.ndarray]:
    """Per channel, the codes that follow the exposure: ``(floor, ceiling)``, each
    ``(C,)`` in normalised codes.

    ``floor`` is the highest code (below the median) at which most pixels do not
    brighten by 2 codes when the exposure grows 1.5× or more to the next one (a
    film base, a black level, the toe where noise beats the signal); ``ceiling``
    the lowest code (above the median) at which most do not darken by 2 codes
    when it shrinks (saturation, a shoulder). Codes outside carry no ratio
    information and dominate an ln fit; 0 and 1 when every code responds.

    ``zs``: ``(P, N, C)`` normalised codes, exposures ascending; ``t``: ``(P,)``.

    Examples
    --------
    >>> e = np.geomspace(0.01, 1, 200)
    >>> zs = np.stack([np.clip(np.round(255 * (0.1 + e * k)), 0, 255) / 255
    ...                for k in (0.25, 0.5, 1.0)])[..., None]
    >>> lo, hi = responsive_range(zs, np.array([0.25, 0.5, 1.0]), 255)
    >>> round(float(lo[0]) * 255), round(float(hi[0]) * 255)
    (27, 255)
    """
    p, n, c = zs.shape
    step = 2.0 / zmax
    codes = np.round(zs * zmax).astype(np.int64)
    floor, ceil = np.zeros(c), np.ones(c)
    adj = np.flatnonzero(t[1:] / t[:-1] >= 1.5)
    if adj.size == 0:
        return floor, ceil
    for ch in range(c):
        lo_z = codes[adj, :, ch].ravel()  # shorter exposure of each adjacent pair
        hi_z = codes[adj + 1, :, ch].ravel()
        d = (hi_z - lo_z) / zmax
        med = int(np.median(codes[..., ch]))
        stuck = np.bincount(lo_z, weights=(d < step), minlength=zmax + 1)
        seen = np.bincount(lo_z, minlength=zmax + 1)
        bad = (seen >= 20) & (stuck > 0.5 * seen)
        below = np.flatnonzero(bad[:med])
        if below.size:
            floor[ch] = (below[-1] + 1) / zmax
        stuck = np.bincount(hi_z, weights=(d < step), minlength=zmax + 1)
        seen = np.bincount(hi_z, minlength=zmax + 1)
        bad = (seen >= 20) & (stuck > 0.5 * seen)
        above = np.flatnonzero(bad[med + 1:])
        if above.size:
            ceil[ch] = (med + above[0]) / zmax
    return floor, ceil


def table_from_poly(a: np.ndarray, bit_depth: int,
                    m_range: tuple[float, float] | None = None) -> np.ndarray:
    """``f(z/z_max)`` over every code, strictly increasing and positive: ``(2**bit_depth,)``.

    Over ``m_range`` (the fitted codes) the polynomial, made monotone where the
    constraints left a rounding-level dip; outside it, where no data say anything,
    ``ln f`` continued along a straight line with the slope at that end (at least
    the fitted range's mean slope / 10): a curve that cannot flatten (codes merged)
    or jump where the polynomial would wander.

    Examples
    --------
    >>> f = table_from_poly(np.array([0.5]), 8, (0.1, 0.9))
    >>> bool(np.all(np.diff(np.log(f)) > 0)), float(f[-1]) > float(f[128])
    (True, True)
    """
    from scipy.optimize import isotonic_regression

    zmax = 2 ** bit_depth - 1
    m = np.arange(zmax + 1) / zmax
    if m_range is None:
        m_range = (0.0, 1.0)
    lo = max(int(math.ceil(m_range[0] * zmax - 1e-9)), 0)
    hi = min(int(math.floor(m_range[1] * zmax + 1e-9)), zmax)
    f = np.asarray(isotonic_regression(np.maximum(evaluate(a, m[lo:hi + 1]), F_FLOOR),
                                       increasing=True).x)
    lf = np.log(f)
    n = lf.size
    mean_slope = (lf[-1] - lf[0]) / max(n - 1, 1)
    min_slope = max(mean_slope, 1e-6) / 10
    # strictly increasing inside: a flat run (an active constraint) gets the minimum slope
    lf = lf + min_slope * 1e-3 * np.arange(n)
    lf = np.maximum.accumulate(lf)
    k = min(max(n // 20, 1), n - 1)
    s_lo = max((lf[k] - lf[0]) / k, min_slope) if n > 1 else min_slope
    s_hi = max((lf[-1] - lf[-1 - k]) / k, min_slope) if n > 1 else min_slope
    out = np.empty(zmax + 1)
    out[lo:hi + 1] = lf
    out[:lo] = lf[0] - s_lo * (lo - np.arange(lo))
    out[hi + 1:] = lf[-1] + s_hi * (np.arange(hi + 1, zmax + 1) - hi)
    return np.exp(out)


NOISE_COMPARE_X = 0.25  # the two noise readings compared at a quarter of the top code's X
BIAS_DRAWS = 4  # renders of the fitted bracket stacked in the bias correction's refit


def _debias(a, m_range, lo, hi, order, mz, valid, ln_e, noise, bit_depth, rng, draws):
    """Parametric-bootstrap bias of one channel's ``ln f`` table (as
    :func:`hdr.debevec1997._debias` does for Debevec): render the bracket the
    fit describes (each sampled pixel's exposure from its observations through
    the curve, the refined exposures, noise ``Var X = a X + b`` before the
    response, quantised to the curve's codes and clipped at 0 and ``z_max``),
    fit it at the same order and code range, and return the refit's ``ln f``
    minus that of the same render without noise. Near the ends of the range,
    shot and read noise, the rounding and the floor at 0 move the mean code
    off ``f⁻¹`` of the mean exposure, and eq. 6.6 fitted to codes inherits it.
    """
    zmax = 2 ** bit_depth - 1
    lf = np.log(table_from_poly(a, bit_depth, m_range))
    edges = np.exp(0.5 * (lf[1:] + lf[:-1]))  # X where the code steps up
    codes = np.rint(mz * zmax).astype(np.int64)
    n_obs = valid.sum(axis=1)
    use = n_obs > 0
    lnx = ((lf[codes] - ln_e[None]) * valid).sum(axis=1)[use] / n_obs[use]
    x = np.exp(lnx[:, None] + ln_e[None])  # (N, P)
    sd = np.sqrt(np.maximum(noise[0] * x + noise[1], 0.0))
    xn = np.tile(x, (draws, 1)) + np.tile(sd, (draws, 1)) * rng.standard_normal(
        (draws * x.shape[0], x.shape[1]))
    out = []
    for xx in (xn, x):
        m = np.searchsorted(edges, xx) / zmax
        v = (m >= lo) & (m <= hi)
        (a_s,), le_s = _fit([(m, v)], ln_e, [order], [m_range], zmax)
        # the refit's power aligned to the exposures it was rendered with
        gam = _align_power(le_s, ln_e)[0]
        out.append(gam * np.log(table_from_poly(a_s, bit_depth, m_range)))
    return out[0] - out[1]


RATIO_PIXELS = 1 << 18  # pixels (at most) the final ratio estimate reads, evenly spaced
# The darker value of a pair at least this many noise sd above the responsive floor:
# where the ln-domain curve fit's own bias, Var x / 2X², is under 1 % (σ/X ≤ 1/√0.02).
# Below it the fitted curve itself is least reliable (night: ln f off by −0.25 at codes
# 16–20 with the true times), and a linear sum reads it there.
RATIO_FLOOR_LN_BIAS = 0.01
RATIO_FLOOR_MARGIN = 1.0 / math.sqrt(2.0 * RATIO_FLOOR_LN_BIAS)
# The brighter value at least this many noise sd below the responsive ceiling: clear of the
# clip (at 4σ the clipped tail moves the mean by under 1e-5 of it); near the top the curve
# is well determined, and a wider margin starves pairs with few mid-range pixels.
RATIO_MARGIN = 4.0
RATIO_PRIOR_SD = 0.05  # ln sd given the fit's adjacent ratios in the final graph
RATIO_ITERS = 6  # selection-ratio fixed-point iterations
RATIO_OUTLIER = 6.0  # robust z-score beyond which a pixel's ratio is dropped (motion, flare)
# The joint correction of the curve from binned sums (_binned_sums): the fitted polynomial
# is off by 0.5-1 % at the codes some pairs can only be read through (outdoor: the shadows
# at exposure 4's codes 15-35, where the sky clips at exposure 5), and the sums inherit it.
CURVE_KNOTS = 12  # hat functions over each channel's usable codes (0: no correction)
CURVE_BINS = 6  # brightness bins per (pair, channel), by the third exposure's reading
CURVE_PRIOR_SD = 0.05  # ln sd of each knot's correction
CURVE_ITERS = 3  # relinearisations (the bins' selection follows the exposures)
CURVE_MAX_LN = 0.15  # 3 prior sd: beyond it the first-order rows no longer hold; channel held
CURVE_STEP_TOL = 1e-3  # ln: a correction whose last relinearisation moved more is not used


def ratio_of_sums(xa: np.ndarray, xb: np.ndarray, *, var_a: np.ndarray | None = None,
                  var_b: np.ndarray | None = None) -> tuple[float, float, int]:
    """The exposure ratio ``R = e_b/e_a`` from one scene's exposures ``xa, xb``
    (``(N,)``, linear, ``xb ≈ R·xa``) as ``Σ xb / Σ xa``, after dropping pixels whose
    residual ``xb − R·xa`` is beyond :data:`RATIO_OUTLIER` robust sd.

    In linear units zero-mean sensor noise stays zero-mean, so the estimate is
    unbiased (an ln-domain average is not: ``E[ln x] ≈ ln X − Var x / 2X²``,
    a per-cent bias where read noise is a third of the signal). Returns ``ln R``,
    its sandwich variance ``Σ r² / (R Σ xa)²`` and the pixels kept. ``var_a,
    var_b`` (the noise model's variance of each value) normalise the
    residuals for the outlier test; without them ``x`` stands in (shot noise).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> x = rng.uniform(0.05, 0.2, 5000)
    >>> xa, xb = x + rng.normal(0, 0.02, x.size), 4 * x + rng.normal(0, 0.02, x.size)
    >>> v = np.full(x.size, 0.02 ** 2)
    >>> ln_r, var, n = ratio_of_sums(xa, xb, var_a=v, var_b=v)
    >>> bool(abs(ln_r - np.log(4)) < 4 * np.sqrt(var)), n
    (True, 5000)
    >>> xb[:10] = 50.0  # ten pixels that moved
    >>> ratio_of_sums(xa, xb, var_a=v, var_b=v)[2]
    4990
    """
    keep = _sums_keep(xa, xb, var_a, var_b)
    if keep is None:
        return math.nan, math.inf, 0
    xa = np.asarray(xa, dtype=np.float64)[keep]
    xb = np.asarray(xb, dtype=np.float64)[keep]
    r = float(np.sum(xb) / np.sum(xa))
    var = float(np.sum((xb - r * xa) ** 2) / (r * np.sum(xa)) ** 2)
    return math.log(r), var, int(keep.sum())


def _sums_keep(xa, xb, var_a, var_b) -> np.ndarray | None:
    """:func:`ratio_of_sums`' pixels kept (robust z within :data:`RATIO_OUTLIER`),
    or None when fewer than two with positive sums are left."""
    xa = np.asarray(xa, dtype=np.float64)
    xb = np.asarray(xb, dtype=np.float64)
    va = np.maximum(xa, 1e-12) if var_a is None else var_a
    vb = np.maximum(xb, 1e-12) if var_b is None else var_b
    keep = np.ones(xa.size, dtype=bool)
    for _ in range(2):
        if keep.sum() < 2 or np.sum(xa[keep]) <= 0:
            return None
        r = float(np.sum(xb[keep]) / np.sum(xa[keep]))
        s = (xb - r * xa) / np.sqrt(vb + r * r * va)
        med = float(np.median(s[keep]))
        mad = 1.4826 * float(np.median(np.abs(s[keep] - med)))
        new = np.abs(s - med) <= RATIO_OUTLIER * max(mad, 1e-12)
        if np.array_equal(new, keep):
            break
        keep = new
    if keep.sum() < 2 or np.sum(xa[keep]) <= 0 or np.sum(xb[keep]) <= 0:
        return None
    return keep


def refine_exposures(z: np.ndarray, lfs, ln_e: np.ndarray, lo, hi, noise, code_max: int,
                     *, min_pixels: int = 50, correct_curve: bool = True,
                     reference: dict | None = None) -> tuple[np.ndarray, dict]:
    """The final adjacent exposure ratios from every pixel (up to
    :data:`RATIO_PIXELS`) through the fitted curves, unbiased by noise.

    ``z``: ``(P, H, W, C)`` codes, exposures ascending; ``lfs``: each channel's
    ``ln f`` table (the fit's gauge); ``ln_e``: ``(P,)`` the fit's ln exposures;
    ``lo, hi``: ``(C,)`` the responsive code range (normalised); ``noise``: per
    channel ``(a, b)`` with ``Var X = a X + b`` in the curve's units, or None.

    The fit's ratios come from an ln-domain least squares on 600 sampled
    pixels, and each ln value of a dark code is low by ``Var X / 2X²``
    (night brackets: −1.7 … +1.5 % ratio errors with exact times). Here each
    adjacent pair's ratio is :func:`ratio_of_sums` per channel, inverse-variance
    averaged over channels, on the pixels whose darker exposure is
    :data:`RATIO_FLOOR_MARGIN` noise sd above the responsive floor and whose
    brighter one :data:`RATIO_MARGIN` below the ceiling. Each condition is
    tested on a third exposure where there is one (the next brighter for the
    floor, the next darker for the ceiling), else on the pair's other one,
    scaled by the ratios: a value selected on its own noise is biased by the
    selection. A pair with fewer than
    ``min_pixels`` keeps the fit's ratio. With ``correct_curve`` (default) the
    exposures are then solved again jointly with a smooth correction of each
    channel's curve, from the same sums split into brightness bins
    (:func:`_binned_sums`): a pair read only through a few codes (outdoor's
    shadows at the dark end, where its sky clips in the next exposure)
    otherwise inherits the fitted curve's error there. ``reference``
    (``{index: ln exposure}``, two or more, in the units of ``lfs`` and
    ``ln_e``: exposures known exactly) holds the correction's solve at them
    (:func:`_binned_sums`). Returns the ln exposures (same gauge and mean as
    ``ln_e``; at ``reference`` when the correction is used) and a record: per pair, the
    adjacent ratios' sd with the curve held (``sd_ln_adjacent``) and, under
    ``curve_correction``, the correction and the sd with it free.
    """
    p, h, w, c = z.shape
    n = h * w
    flat = z.reshape(p, n, c)
    if n > RATIO_PIXELS:
        flat = flat[:, np.round(np.linspace(0, n - 1, RATIO_PIXELS)).astype(np.int64)]
    codes = np.arange(code_max + 1)
    tables = []
    for ch in range(c):
        x_tab = np.exp(lfs[ch])
        a, b = (noise[ch] if noise is not None else (0.0, 0.0))
        sd = np.sqrt(np.maximum(a * x_tab + b, 0.0))
        k_lo = int(math.ceil(lo[ch] * code_max - 1e-9))
        k_hi = int(math.floor(hi[ch] * code_max + 1e-9))
        inside = (codes >= k_lo) & (codes <= k_hi)
        floor_ok = inside & (x_tab - RATIO_FLOOR_MARGIN * sd >= x_tab[min(k_lo, code_max)])
        ceil_ok = inside & (x_tab + RATIO_MARGIN * sd <= x_tab[max(k_hi, 0)])
        if k_hi <= k_lo or not floor_ok.any() or not ceil_ok.any():
            tables.append(None)
            continue
        k_f, k_c = int(np.flatnonzero(floor_ok)[0]), int(np.flatnonzero(ceil_ok)[-1])
        tables.append((x_tab, a, b, x_tab[k_f], x_tab[k_c], k_f, k_c))
    rows, rhs, wts, record, usable = [], [], [], [], []
    for qa in range(p - 1):
        for qb in range(qa + 1, min(qa + MAX_PAIR_GAP, p - 1) + 1):
            ests, vars_, kept, used = [], [], [], []
            d0 = float(ln_e[qb] - ln_e[qa])
            # Each condition is tested on a third exposure where there is one, whose
            # noise is independent of both values summed: the floor (the darker value's
            # truth above it) on the next brighter than the darker one, the ceiling on
            # the next darker than the brighter one; at the bracket's ends, on the pair's
            # other value. A clipped third value errs on the safe side.
            q_fl = qa + 1 if qa + 1 < qb else (qb + 1 if qb + 1 < p else qb)
            q_ce = qb - 1 if qb - 1 > qa else (qa - 1 if qa >= 1 else qa)
            for ch, tab in enumerate(tables):
                if tab is None:
                    continue
                x_tab, a, b, x_floor, x_ceil = tab[:5]
                xa, xb = x_tab[flat[qa, :, ch]], x_tab[flat[qb, :, ch]]
                x_fl, x_ce = x_tab[flat[q_fl, :, ch]], x_tab[flat[q_ce, :, ch]]
                # the selection uses the ratios: iterated to a fixed point, and a channel
                # whose estimate moves its own selection away (a toe the curve cannot
                # read: film base, codes 15 and 25 ten stops apart) is not used
                ln_r, converged, var, k = d0, False, math.inf, 0
                for _ in range(RATIO_ITERS):
                    # ln of each selecting exposure over the pair's darker/brighter one
                    s_fl = ln_r if q_fl == qb else float(ln_e[q_fl] - ln_e[qa])
                    s_ce = ln_r if q_ce == qa else float(ln_e[qb] - ln_e[q_ce])
                    sel = (x_fl >= math.exp(s_fl) * x_floor) & (x_ce * math.exp(s_ce) <= x_ceil)
                    if sel.sum() < min_pixels:
                        break
                    va = vb = None
                    if a > 0 or b > 0:
                        va, vb = a * xa[sel] + b, a * xb[sel] + b
                    new, var, k = ratio_of_sums(xa[sel], xb[sel], var_a=va, var_b=vb)
                    if not np.isfinite(new):
                        break
                    if abs(new - ln_r) < 1e-4:
                        ln_r, converged = new, True
                        break
                    ln_r = new
                if converged and k >= min_pixels and 0 < var < math.inf:
                    ests.append(ln_r)
                    vars_.append(var)
                    kept.append(k)
                    used.append(ch)
                    usable.append((qa, qb, q_fl, q_ce, ch))
                    row = np.zeros(p)
                    row[qb], row[qa] = 1.0, -1.0
                    rows.append(row)
                    rhs.append(ln_r)
                    wts.append(1.0 / var)
            if qb == qa + 1 or ests:
                record.append({"exposures": [qa, qb], "channels": used, "pixels": kept,
                               "ln_ratio_per_channel": ests, "fit_ln_ratio": d0})
    # The exposure graph by weighted least squares (the fit's own gauge: the mean ln
    # exposure kept). The fit's adjacent ratios enter with an sd of 0.05 in ln, so a
    # pair no channel could read keeps the fit's ratio and the graph stays connected;
    # against a measured pair's sd (0.0001-0.003) their weight is under 0.4 %.
    _fit_ratio_prior(ln_e, p, rows, rhs, wts)
    a_m = np.array(rows) * np.sqrt(np.array(wts))[:, None]
    b_v = np.array(rhs) * np.sqrt(np.array(wts))
    gauge = np.full((1, p), 1.0 / p) * math.sqrt(max(wts))
    sol = np.linalg.lstsq(np.vstack([a_m, gauge]),
                          np.concatenate([b_v, [float(ln_e.mean()) * math.sqrt(max(wts))]]),
                          rcond=None)[0]
    cov = np.linalg.pinv(a_m.T @ a_m + gauge.T @ gauge)
    out = {"pairs": record, "sd_ln_adjacent": _adjacent_sd(cov, p)}
    if usable and correct_curve and CURVE_KNOTS >= 3:
        sol, sd_held, out["curve_correction"] = _binned_sums(flat, tables, usable, sol, ln_e,
                                                             min_pixels, reference=reference)
        if sd_held is not None:
            out["sd_ln_adjacent"] = sd_held
    return sol, out


def _fit_ratio_prior(ln_e_fit, n_u: int, rows: list, rhs: list, wts: list) -> None:
    """Append the fit's adjacent ln ratios as rows of sd :data:`RATIO_PRIOR_SD`
    (over ``n_u`` unknowns, the exposures first)."""
    for q in range(len(ln_e_fit) - 1):
        row = np.zeros(n_u)
        row[q + 1], row[q] = 1.0, -1.0
        rows.append(row)
        rhs.append(float(ln_e_fit[q + 1] - ln_e_fit[q]))
        wts.append(1.0 / RATIO_PRIOR_SD ** 2)


def hat_basis(k: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Piecewise-linear hat functions of codes ``k`` (``(N,)``) on ascending
    ``knots`` (``(M,)``, codes), clamped outside them: ``(N, M)``, each row
    summing to 1.

    >>> hat_basis(np.array([0, 5, 10, 20]), np.array([0.0, 10.0, 20.0]))
    array([[1. , 0. , 0. ],
           [0.5, 0.5, 0. ],
           [0. , 1. , 0. ],
           [0. , 0. , 1. ]])
    """
    k = np.clip(np.asarray(k, dtype=np.float64), knots[0], knots[-1])
    j = np.clip(np.searchsorted(knots, k, side="right") - 1, 0, knots.size - 2)
    w = (k - knots[j]) / (knots[j + 1] - knots[j])
    out = np.zeros((k.size, knots.size))
    out[np.arange(k.size), j] = 1.0 - w
    out[np.arange(k.size), j + 1] = w
    return out


def _binned_sums(flat, tables, usable, ln_e, ln_e_fit, min_pixels, *, reference=None):
    """The exposures and a per-channel correction of the curve, jointly, from
    linear sums over brightness bins (see :func:`refine_exposures`).

    Each usable (pair, channel) of :func:`refine_exposures` is split into up
    to :data:`CURVE_BINS` bins of equal count by its third exposure's reading
    (independent of both values summed; a pair without a third exposure is one
    bin). The channel's curve is corrected by ``ln f + Σ c_m h_m(k)``, ``h_m``
    hat functions on :data:`CURVE_KNOTS` codes over its usable range; each bin
    gives one row, linear in the ln exposures and ``c`` (the sums' first
    order in ``c``): ``ln ΣXb − ln ΣXa + (Σ Xa h(za)/ΣXa − Σ Xb h(zb)/ΣXb)·c =
    e_b − e_a``, weighted by the bin's sandwich variance. The gauges: the
    correction's scale (``ln f + β``, which no ratio of sums sees) by ``c``
    summing to 0 over the knots; without ``reference`` the mean ln exposure
    is ``ln_e_fit``'s and the correction's power (``ln f → γ ln f``, which a
    single pixel's ratio cannot see) by ``c`` orthogonal to ``ln f`` over the
    knots. With ``reference`` (``{index: ln exposure}``, two or more, in the
    curve's units) the exposures are held at them instead, and the
    correction's component along ``ln f`` is left to the data: the references
    fix the power, so holding that component at 0 is no longer a gauge but a
    constraint, and not even an exact gauge without them (the hat functions
    interpolate ``ln f`` linearly between knots, worst at the dark codes where
    ``ln f`` bends most: for ``ln f = ln z``, 0.08 at code 25 between knots
    at 17 and 38).
    Every ``c`` has prior sd
    :data:`CURVE_PRIOR_SD`, the fit's adjacent ratios :data:`RATIO_PRIOR_SD`.
    Relinearised :data:`CURVE_ITERS` times (the bins' selection moves with the
    exposures). A channel whose correction exceeds :data:`CURVE_MAX_LN` or
    leaves its curve not increasing is held (named in the record) and the
    rest solved again; a solve whose last step exceeds :data:`CURVE_STEP_TOL`
    is not used. Returns the ln exposures, the adjacent ln ratios' sd with the
    curves held (None when the correction is not used: ``ln_e`` is returned)
    and a record.
    """
    p = flat.shape[0]
    codes = np.arange(next(t for t in tables if t is not None)[0].size)
    chans = sorted({u[4] for u in usable})
    knots = {}
    for ch in chans:
        k_f, k_c = tables[ch][5], tables[ch][6]
        kn = np.unique(np.round(np.linspace(k_f, k_c, CURVE_KNOTS)).astype(np.float64))
        if kn.size >= 3:
            knots[ch] = kn
    # A channel whose correction leaves the small-correction regime the rows are
    # linearised in (beyond CURVE_MAX_LN, or a curve no longer increasing) is held and
    # the rest solved again: Memorial's blue, read through few bright pixels, ran to
    # ln corrections of ±9 with the iterations diverging.
    held: dict[str, str] = {}
    while True:
        e, c_all, cov, cov_fixed, step, n_rows = _binned_sums_solve(
            flat, tables, usable, ln_e, ln_e_fit, min_pixels, knots, codes, reference=reference)
        bad = {}
        for ch, cc in c_all.items():
            corrected = np.log(tables[ch][0]) + hat_basis(codes, knots[ch]) @ cc
            k0, k1 = int(knots[ch][0]), int(knots[ch][-1])
            if float(np.max(np.abs(cc))) > CURVE_MAX_LN:
                bad[ch] = f"|ln correction| {float(np.max(np.abs(cc))):.3g} > {CURVE_MAX_LN}"
            elif not np.all(np.diff(corrected[k0:k1 + 1]) > 0):
                bad[ch] = "the corrected curve is not increasing"
        if not bad:
            break
        for ch, why in bad.items():
            held[str(ch)] = why
            del knots[ch]
    record = {"rows": n_rows, "last_step_ln": step, "held_channels": held}
    if not knots or step > CURVE_STEP_TOL:
        record["used"] = False
        record["why"] = ("no channel's correction stayed small" if not knots else
                         f"not converged: last step {step:.3g} ln > {CURVE_STEP_TOL}")
        return np.array(ln_e, dtype=np.float64), None, record
    record.update({"used": True, "sd_ln_adjacent_curve_free": _adjacent_sd(cov, p),
                   "channels": {str(ch): {"knots": knots[ch].astype(int).tolist(),
                                          "ln_correction": c_all[ch].tolist()}
                                for ch in knots}})
    return e, _adjacent_sd(cov_fixed, p), record


def _binned_sums_solve(flat, tables, usable, ln_e, ln_e_fit, min_pixels, knots, codes, *,
                       reference=None):
    """:func:`_binned_sums` for one set of corrected channels (``knots``: channel ->
    knot codes); the others' curves held. Returns the ln exposures, each corrected
    channel's ``c``, the covariances with the curves free and held, the last
    step and the number of data rows."""
    p = flat.shape[0]
    off, n_u = {}, p
    for ch in knots:
        off[ch], n_u = n_u, n_u + knots[ch].size
    lfs = {ch: np.log(tables[ch][0]) for ch in knots}
    h_codes = {ch: hat_basis(codes, knots[ch]) for ch in knots}
    e = np.array(ln_e, dtype=np.float64)
    c_all = {ch: np.zeros(knots[ch].size) for ch in knots}
    n_rows, step = 0, math.inf
    held_at_refs = reference is not None and len(reference) >= 2
    for _ in range(CURVE_ITERS):
        rows, rhs, wts = [], [], []
        for qa, qb, q_fl, q_ce, ch in usable:
            x_tab, a, b, x_floor, x_ceil = tables[ch][:5]
            if ch in knots:
                x_tab = np.exp(lfs[ch] + h_codes[ch] @ c_all[ch])
            za, zb = flat[qa, :, ch], flat[qb, :, ch]
            xa, xb = x_tab[za], x_tab[zb]
            x_fl = x_tab[flat[q_fl, :, ch]]
            sel = ((x_fl >= math.exp(e[q_fl] - e[qa]) * x_floor)
                   & (x_tab[flat[q_ce, :, ch]] * math.exp(e[qb] - e[q_ce]) <= x_ceil))
            idx = np.flatnonzero(sel)
            if idx.size < min_pixels:
                continue
            third = q_fl not in (qa, qb)
            nb = min(CURVE_BINS, idx.size // min_pixels) if third else 1
            groups = np.array_split(idx[np.argsort(x_fl[idx], kind="stable")], nb) if nb > 1 else [idx]
            for gi in groups:
                keep = _sums_keep(xa[gi], xb[gi], a * xa[gi] + b, a * xb[gi] + b)
                if keep is None:
                    continue
                gi = gi[keep]
                sa, sb = float(xa[gi].sum()), float(xb[gi].sum())
                r = sb / sa
                var = float(np.sum((xb[gi] - r * xa[gi]) ** 2) / (r * sa) ** 2)
                if not 0 < var < math.inf:
                    continue
                row = np.zeros(n_u)
                row[qb], row[qa] = 1.0, -1.0
                lin = math.log(r)
                if ch in knots:
                    k = knots[ch].size
                    ha = np.bincount(za[gi], weights=xa[gi], minlength=codes.size) @ h_codes[ch] / sa
                    hb = np.bincount(zb[gi], weights=xb[gi], minlength=codes.size) @ h_codes[ch] / sb
                    row[off[ch]:off[ch] + k] = ha - hb
                    lin += float((ha - hb) @ c_all[ch])  # the row is linearised at the current c
                rows.append(row)
                rhs.append(lin)
                wts.append(1.0 / var)
        n_rows = len(rows)
        _fit_ratio_prior(ln_e_fit, n_u, rows, rhs, wts)
        for ch in knots:
            for m in range(knots[ch].size):
                row = np.zeros(n_u)
                row[off[ch] + m] = 1.0
                rows.append(row)
                rhs.append(0.0)
                wts.append(1.0 / CURVE_PRIOR_SD ** 2)
        a_m = np.array(rows) * np.sqrt(np.array(wts))[:, None]
        b_v = np.array(rhs) * np.sqrt(np.array(wts))
        # the gauges, exactly: the mean ln exposure; per channel the correction carries no
        # scale and no power (c orthogonal to 1 and to ln f over the knots), so the
        # exposures stay in the curve's gauge
        if held_at_refs:
            # exposures known exactly fix the scale and the power: the exposures at them,
            # and the correction free in power (only its scale, which no sum sees, held)
            refs = sorted(reference)
            cons = np.zeros((len(refs) + len(knots), n_u))
            d = np.zeros(cons.shape[0])
            for j, k in enumerate(refs):
                cons[j, k] = 1.0
                d[j] = float(reference[k])
            for i, ch in enumerate(knots):
                cons[len(refs) + i, off[ch]:off[ch] + knots[ch].size] = 1.0 / knots[ch].size
        else:
            cons = np.zeros((1 + 2 * len(knots), n_u))
            d = np.zeros(cons.shape[0])
            cons[0, :p] = 1.0 / p
            d[0] = float(np.mean(ln_e_fit))
            for i, ch in enumerate(knots):
                sl = slice(off[ch], off[ch] + knots[ch].size)
                ln_k = lfs[ch][knots[ch].astype(np.int64)]
                cons[1 + 2 * i, sl] = 1.0 / knots[ch].size
                cons[2 + 2 * i, sl] = (ln_k - ln_k.mean()) / max(float(np.ptp(ln_k)), 1e-12)
        sol, cov = _lstsq_eq(a_m, b_v, cons, d)
        step = float(np.max(np.abs(sol[:p] - e)))
        e = sol[:p]
        for ch in knots:
            c_all[ch] = sol[off[ch]:off[ch] + knots[ch].size]
    # the sd with the curves held: the last relinearisation's rows, the exposures' columns
    nc = len(reference) if held_at_refs else 1
    cov_fixed = _lstsq_eq(a_m[:, :p], b_v, cons[:nc, :p], d[:nc])[1]
    return e, c_all, cov, cov_fixed, step, n_rows


def _adjacent_sd(cov: np.ndarray, p: int) -> list[float]:
    """The sd of each adjacent difference ``e[q+1] − e[q]`` from ``cov``."""
    return [float(math.sqrt(max(cov[q, q] + cov[q + 1, q + 1] - 2 * cov[q, q + 1], 0.0)))
            for q in range(p - 1)]


def _lstsq_eq(a: np.ndarray, b: np.ndarray, cons: np.ndarray, d: np.ndarray):
    """``min |a x − b|²`` subject to ``cons x = d`` (null-space method), and the
    solution's covariance (``a`` already whitened)."""
    q, _ = np.linalg.qr(cons.T, mode="complete")
    r = cons.shape[0]
    x0 = np.linalg.lstsq(cons, d, rcond=None)[0]
    nb = q[:, r:]
    y = np.linalg.lstsq(a @ nb, b - a @ x0, rcond=None)[0]
    an = a @ nb
    cov = nb @ np.linalg.pinv(an.T @ an) @ nb.T
    return x0 + nb @ y, cov


def response_mitsunaga1999(images: np.ndarray, exposure_times_s, *, bit_depth: int | None = None,
                    order: int | str = "auto", samples: int = 600, clip_margin: float = 0.03,
                    rng: np.random.Generator | None = None,
                    reference_times: dict[int, float] | None = None,
                    bias_draws: int = BIAS_DRAWS, noise_weighted: bool = True,
                    refine_ratios: bool = True) -> ResponseCurve:
    """Recover the inverse response as a polynomial and refine the exposure ratios.

    Parameters
    ----------
    images : ndarray, ``(P, H, W, C)`` or ``(P, H, W)``, integer codes
    exposure_times_s : sequence of float, ``(P,)``
        Rough exposures (times, or any numbers proportional to the
        exposure); distinct.
    bit_depth : int, optional
    order : int or "auto"
        Polynomial order ``N`` (1..10), one for every channel; ``"auto"``
        chooses by the BIC of the held-out code-prediction error, among the
        candidates whose curves are monotone (see the module docstring).
    samples : int
        Pixels sampled (:func:`hdr.samples.sample_pixels`), at least 2
        (:func:`hdr.samples.check_samples`).
    clip_margin : float
        Codes within this fraction of either end are masked, and so are
        codes that do not follow the exposure (:func:`responsive_range`).
    rng : numpy.random.Generator, optional
    reference_times : dict, optional
        ``{image index: exact exposure}`` (same units as the times) for
        exposures known exactly: one fixes the scale of the refined exposures,
        two or more also the power the data leave free (:func:`align_power`).
    bias_draws : int
        Renders of the fitted bracket for the bias correction (:func:`_debias`),
        with the noise estimated from the bracket
        (:func:`hdr.debevec1997.estimate_noise`); 0 turns it off.
    noise_weighted : bool
        Held-out scores divided by their predicted noise (the order selection).
    refine_ratios : bool
        The final ratios from linear sums over every pixel
        (:func:`refine_exposures`); False keeps the joint fit's.

    Returns
    -------
    ResponseCurve
        ``method="mitsunaga-nayar"``; ``exposure_times_s`` are the refined
        exposures (in the units given); ``fit`` holds the coefficients (shifted
        Chebyshev), the refined adjacent ratios and the common power γ, the
        responsive and monotone code ranges, the static pixels dropped;
        ``selection`` the order, the rule, each candidate's held-out error
        (or why it was rejected) and BIC, each channel's disagreement.
    """
    from lumigraph.capture.errors import EstimationError, InputError

    z, t, bd = check_stack(images, exposure_times_s, bit_depth=bit_depth)
    p, h, w_, c = z.shape
    if p < 2:
        raise InputError("images", "a response needs at least two exposures")
    check_samples(samples)
    order = check_order(order)
    rng = np.random.default_rng(0) if rng is None else rng
    ref = check_reference_times(reference_times, t.size)
    perm = np.argsort(t)
    z, t = z[perm], t[perm]
    ln_nom = np.log(t)
    inv = np.argsort(perm)
    ref = {int(inv[k]): math.log(v) for k, v in ref.items()}
    zmax = 2 ** bd - 1
    # Oversampled, then pixels that are not scene points dropped (a code that does not
    # move over two stops: a matte, a registration border, a dead pixel; Memorial's
    # pure-blue borders are smooth, so the sampler favours them), then thinned evenly
    # along radiance back to `samples`.
    idx = sample_pixels(z, n=3 * samples, bit_depth=bd, rng=rng)
    zs = z.reshape(p, h * w_, c)[:, idx].astype(np.float64) / zmax  # (P, N, C)
    keep = ~static_pixels(zs, t, clip_margin)
    n_static = int(np.sum(~keep))
    idx, zs = idx[keep], zs[:, keep]
    floor, ceil = responsive_range(zs, t, zmax)
    zs_sel = zs  # the order is chosen on every oversampled pixel: 3x the data, less noise
    if idx.size > samples:
        pick = np.round(np.linspace(0, idx.size - 1, samples)).astype(np.int64)
        idx, zs = idx[pick], zs[:, pick]
    lo = np.maximum(clip_margin, floor)
    hi = np.minimum(1.0 - clip_margin, ceil)
    # A given order is still compared with the others by held-out error, so an
    # order the data cannot support is reported, not silently used.
    orders = list(range(1, MAX_ORDER + 1))
    fold = np.arange(zs_sel.shape[1]) % 2
    g = np.empty((c, zmax + 1))
    warnings: list[str] = []
    chans, ranges, chans_sel = [], [], []
    for ch in range(c):
        mz = zs[..., ch].T  # (N, P)
        valid = (mz >= lo[ch]) & (mz <= hi[ch])
        chans.append((mz, valid))
        mz = zs_sel[..., ch].T
        valid = (mz >= lo[ch]) & (mz <= hi[ch])
        chans_sel.append((mz, valid))
        ranges.append((float(mz[valid].min()), float(mz[valid].max())) if valid.any()
                      else (0.0, 1.0))
    # Every candidate order fitted on one half of the pixels and scored on the other
    # (both ways), per channel, by the error of predicting one exposure's code from
    # another's; a candidate whose curve is not monotone over the observed codes, or
    # whose fit fails, is rejected with the reason.
    noise_top = None
    if noise_weighted or bias_draws > 0:
        from lumigraph.hdr.debevec1997 import response_debevec1997

        # The sensor noise (X relative to the top code's), estimated from the bracket
        # by Debevec's fit at the rough times (its own bias correction not needed).
        noise_top = response_debevec1997(
            z, t, bit_depth=bd, samples=samples, bias_draws=0,
            rng=np.random.default_rng(0)).fit["noise"]["a_b_top"]
    def _score(i, n, refine, mse, bic, reasons, fold_le):
        for ch, ((mz, valid), m_range) in enumerate(zip(chans_sel, ranges, strict=True)):
            total, les = 0.0, []
            for f in (0, 1):
                try:
                    # the alternation alone (no joint ln refinement): 5x cheaper, and
                    # orders whose linear solve runs away are scored as they are
                    (a,), le = _fit([(mz[fold != f], valid[fold != f])], ln_nom, [n],
                                    [m_range], zmax, refine=refine)
                except np.linalg.LinAlgError as e:
                    reasons[n, ch] = f"fit failed ({e})"
                    break
                if not is_monotone(a, m_range, zmax):
                    reasons[n, ch] = ("not monotone over the observed codes "
                                      f"{round(m_range[0] * zmax)}..{round(m_range[1] * zmax)}")
                    break
                total += float(np.sum(_held_out_codes(
                    a, le, mz[fold == f], valid[fold == f], m_range,
                    noise_top[ch] if noise_weighted else None, zmax))) / 2
                les.append(le)
            else:
                mse[i, ch] = total
                fold_le[n, ch] = les
        # BIC per channel, N its independent held-out residuals (not its pixels: a
        # pixel seen in P exposures gives P - 1 code predictions that share no noise)
        with np.errstate(divide="ignore"):
            bic[i] = float(np.sum(n_obs * np.log(mse[i]))) + n * float(np.sum(np.log(n_obs)))

    # independent held-out residuals per channel: each pixel's valid codes less one,
    # averaged over the two folds
    n_obs = np.array([max(float(np.sum(np.maximum(v.sum(axis=1) - 1, 0))) / 2, 2.0)
                      for _, v in chans_sel])
    mse = np.full((len(orders), c), np.inf)
    reasons: dict[tuple[int, int], str] = {}
    fold_le: dict[tuple[int, int], list] = {}
    bic = np.full(len(orders), np.inf)
    for i, n in enumerate(orders):
        # BIC rises past the best order; three orders in a row above it end the search
        # (a given order is still scored, to be compared with the best)
        best = int(np.argmin(bic))
        if i - best > 3 and np.isfinite(bic[best]) and (order == "auto" or n > int(order)):
            break
        _score(i, n, False, mse, bic, reasons, fold_le)
    # One order for all channels, by an information criterion on the held-out errors
    # (BIC: N ln MSE + k ln N per channel, N the held-out pixels): an order must
    # earn ln N / N relative error per coefficient. The raw "lowest within one standard
    # error of the best" rule flipped between 6 and 9 with the sampling seed on
    # Memorial, where the held-out error is flat above order 3-5.
    ok = np.all(np.isfinite(mse), axis=1)
    if not ok.any():
        why = "; ".join(f"order {n} channel {ch}: {r}" for (n, ch), r in sorted(reasons.items()))
        raise EstimationError("images", "no polynomial order gives a monotone response over the "
                                        f"observed codes ({why[:300]})")
    n_auto = orders[int(np.argmin(np.where(ok, bic, np.inf)))]
    # The alternation alone under-rates the next order where the curve has a toe (the
    # walls' sRGB curve: order 4 fits 2-3x better than 3 once jointly refined, but
    # scores worse unrefined). The best order and the next are scored again with the
    # joint refinement, and the better of the two by that BIC is chosen.
    bic_refined = {}
    if order == "auto" and n_auto < MAX_ORDER and ok[orders.index(n_auto) + 1]:
        i0 = orders.index(n_auto)
        mse_r, bic_r = np.full((len(orders), c), np.inf), np.full(len(orders), np.inf)
        for i in (i0, i0 + 1):
            _score(i, orders[i], True, mse_r, bic_r, {}, {})
            bic_refined[orders[i]] = float(bic_r[i]) if np.isfinite(bic_r[i]) else None
        if np.isfinite(bic_r[i0 + 1]) and bic_r[i0 + 1] < bic_r[i0]:
            n_auto = orders[i0 + 1]
    n_use = n_auto
    if order != "auto":
        n_use = int(order)
        i = orders.index(n_use)
        if not ok[i]:
            bad = [f"channel {ch}: {reasons[n_use, ch]}" for ch in range(c)
                   if (n_use, ch) in reasons]
            warnings.append(f"order {n_use} was rejected on held-out pixels ({bad[0]}); its "
                            "curve is kept monotone by constraint: use --order auto "
                            f"(chooses {n_auto})")
        elif bic[i] > bic[orders.index(n_auto)] + float(np.sum(np.log(n_obs))):
            warnings.append(f"order {n_use} does not fit held-out pixels as well as order "
                            f"{n_auto} (BIC {bic[i]:.1f} against {bic[orders.index(n_auto)]:.1f}): "
                            "use --order auto")
    chosen = [n_use] * c
    try:
        coeffs, le = _fit(chans, ln_nom, chosen, ranges, zmax)
    except np.linalg.LinAlgError:
        raise EstimationError("images", "too few pixels seen unclipped in two exposures for "
                                        "Mitsunaga-Nayar") from None
    noise_rough = noise_top
    if noise_top is not None and (bias_draws > 0 or refine_ratios):
        # The noise again, by Debevec's fit at the exposures this fit found: at rough times
        # the residuals hold the times' errors too (outdoor, ±10 %: the shot-noise level
        # read 1.3-5x too high), and the bias correction and the sums' margins scale with it.
        # Time errors and curve misfit only add to the residuals, so per channel the
        # lower of the two readings is kept (a film scan's joint fit, with its ratios
        # 0.5-1.3 stops for Memorial's 1-stop steps, reads higher than the given times).
        at_fit = response_debevec1997(
            z, np.exp(align_power(le, ln_nom, reference=ref)[1]), bit_depth=bd,
            samples=samples, bias_draws=0, rng=np.random.default_rng(0)).fit["noise"]["a_b_top"]
        noise_top = [min(nr, nf, key=lambda ab: ab[0] * NOISE_COMPARE_X + ab[1])
                     for nr, nf in zip(noise_rough, at_fit, strict=True)]
    monotone = [is_monotone(a, m_range, zmax) for a, m_range in zip(coeffs, ranges, strict=True)]
    bias_max, lfs = [], []
    for ch in range(c):
        if not monotone[ch]:  # the constraints make this unreachable; say so if not
            warnings.append(f"channel {ch}: the joint fit is not monotone over codes "
                            f"{round(ranges[ch][0] * zmax)}..{round(ranges[ch][1] * zmax)}")
        lf = np.log(table_from_poly(coeffs[ch], bd, ranges[ch]))
        if noise_top is not None and bias_draws > 0:
            try:
                bias = _debias(coeffs[ch], ranges[ch], lo[ch], hi[ch], n_use, *chans[ch], le,
                               noise_top[ch], bd, rng, bias_draws)
                lf_c = lf - bias
                # kept only if it leaves the curve strictly increasing (the guarantee)
                if np.all(np.diff(lf_c) > 0):
                    lf = lf_c
                    bias_max.append(float(np.max(np.abs(bias))))
                else:
                    bias_max.append(None)
            except np.linalg.LinAlgError:
                bias_max.append(None)
        lfs.append(lf)
    le_fit = le
    ratio_record = None
    gam0 = 1.0  # the power applied before the refinement (two or more references)
    if refine_ratios:
        ref_in = None
        if len(ref) >= 2:
            # the references' units from the start: f -> f^γ0, e -> γ0 e + c (eq. 6.6
            # unchanged), so the solve below can hold the exposures at them. The noise
            # model stays in the fitted units (Var X = aX + b is not of that form in X^γ0):
            # it sets only the sums' weights and margins, and γ0 is near 1: 0.97-1.06 on
            # the bracket family (seeds 1 and 3, exact and rough times), 0.93 on Memorial
            gam0, le = align_power(le, ln_nom, reference=ref)
            lfs = [gam0 * lf for lf in lfs]
            ref_in = ref
        le, ratio_record = refine_exposures(z, lfs, le, lo, hi, noise_top, zmax, reference=ref_in)
    gam, ln_e = align_power(le, ln_nom, reference=ref)
    if not ref and abs(gam - 1.0) > 0.1:
        warnings.append(f"the data's exposure ratios are the given ones to the power {1 / gam:.3f}; "
                        "check the rough times")
    disagree = _channel_disagreement(chans_sel, fold_le, ln_nom, le_fit, n_use, ranges, zmax)
    typical = float(np.median([x for _, x in disagree])) if disagree else 0.0
    for ch, (stat, rms) in enumerate(disagree):
        # beyond its sampling noise (3 sigma), and an outlier among the channels (three times
        # the median channel's distance: film dyes and colour filters differ in shape, and an
        # order that suits all of them leaves each a small bias of its own)
        if c > 1 and stat > DISAGREE_LIMIT and rms > 3.0 * typical:
            warnings.append(f"channel {ch}: its own exposure ratios differ from the common ones by "
                            f"{rms:.3f} ln RMS, {math.sqrt(stat):.1f}x its sampling noise and over "
                            "3x the median channel's: "
                            "a clipped, misregistered or non-linear channel; check its curve")
    for ch in range(c):
        # Exposures rescaled as e -> e^γ pair with the curve f -> f^γ (eq. 6.6 is unchanged).
        g[ch] = gam * lfs[ch]
    sel_scores = {str(ch): [{"order": n, "held_out_code_mse": float(mse[i, ch]),
                             "rejected": reasons.get((n, ch))}
                            for i, n in enumerate(orders)] for ch in range(c)}
    sel_scores["bic"] = [float(x) if np.isfinite(x) else None for x in bic]
    sel_scores["bic_n_per_channel"] = [float(x) for x in n_obs]
    sel_scores["bic_jointly_refined"] = {str(k): v for k, v in bic_refined.items()}
    refined = np.empty(p)
    refined[perm] = np.exp(ln_e)
    ratios = np.exp(np.diff(ln_e))  # e_{q+1}/e_q in ascending exposure order
    sel = {"parameter": "order", "chosen": chosen, "candidates": sel_scores, "auto": n_auto,
           "rule": "given" if order != "auto" else
           "one order for all channels: least BIC (sum over channels of N ln MSE + k ln N, "
           "N the channel's independent held-out residuals: per pixel its valid codes - 1) of "
           "the 2-fold held-out code-prediction error (noise-weighted); the best and the next "
           "order re-scored with the joint refinement; non-monotone candidates rejected",
           "channel_disagreement_rms_sigma": [math.sqrt(x) for x, _ in disagree],
           "channel_disagreement_rms_ln": [x for _, x in disagree]}
    fit = {"basis": "shifted Chebyshev T_n(2M-1) - 1, f = 1 + sum a_n (...)",
           "coefficients": [a.tolist() for a in coeffs], "power_gamma": gam * gam0,
           "refined_ratios_ascending": ratios.tolist(),
           "given_ratios_ascending": np.exp(np.diff(ln_nom)).tolist(),
           "samples": int(idx.size), "static_pixels_dropped": n_static,
           "ratio_refinement": ratio_record,
           "bias_correction": {"draws": int(bias_draws), "noise_a_b_top": noise_top,
                               "noise_a_b_top_at_rough_times": noise_rough,
                               "max_abs_ln": bias_max},
           "responsive_codes": [[round(float(a) * zmax), round(float(b) * zmax)]
                                for a, b in zip(lo, hi, strict=True)],
           "monotone_over_codes": [[round(a * zmax), round(b * zmax)] if m else None
                                   for (a, b), m in zip(ranges, monotone, strict=True)],
           "reference_exposures": {str(int(perm[k])): float(np.exp(v)) for k, v in ref.items()},
           "power_fixed_by": ("the rough times (least squares in log)" if not ref else
                              "the rough times through the reference exposure" if len(ref) == 1
                              else "the reference exposures")}
    return ResponseCurve("mitsunaga-nayar", bd, normalise_g(g), tuple(refined.tolist()), sel,
                         tuple(warnings), fit)
