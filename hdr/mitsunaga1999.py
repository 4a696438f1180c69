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
- the order (≤ 10) chosen by held-out error on a second fold of pixels:
  the lowest order within one paired standard error (per-pixel differences
  on the same held-out pixels) of the best (model only what the data need);
  every candidate recorded.

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


def _pairs(mz: np.ndarray, valid: np.ndarray):
    """All (pixel, q, q') with both exposures valid, q < q'."""
    p = mz.shape[1]
    qa, qb = np.triu_indices(p, 1)
    ok = valid[:, qa] & valid[:, qb]
    pix, k = np.nonzero(ok)
    return pix, qa[k], qb[k]


def _fit(chans, ln_e0, orders, iters=10, tol=1e-8, noise_weights=True, refine=True):
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
            a_new = scipy.linalg.lstsq((ba - r[:, None] * bb) * s[:, None], -(1.0 - r) * s,
                                       lapack_driver="gelsy", check_finite=False)[0]
            fa, fb = 1.0 + ba @ a_new, 1.0 + bb @ a_new
            pos = (fa > 1e-6) & (fb > 1e-6)
            d = np.log(fa[pos]) - np.log(fb[pos])
            wts = np.ones(d.size) if var is None else 1.0 / var[pos]
            # Normal equations of the tiny, well-conditioned exposure graph (P x P).
            ia, ib = qa[pos], qb[pos]
            np.add.at(lap, (ia, ia), wts)
            np.add.at(lap, (ib, ib), wts)
            np.add.at(lap, (ia, ib), -wts)
            np.add.at(lap, (ib, ia), -wts)
            np.add.at(rhs_e, ia, wts * d)
            np.add.at(rhs_e, ib, -wts * d)
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
        coeffs, ln_e = _gauss_newton(data, coeffs, ln_e, ln_e0, noise_weights=noise_weights)
    return coeffs, ln_e


def _gauss_newton(data, coeffs, ln_e, ln_e0, iters=8, noise_weights=True):
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


def _held_out(a, ln_e, mz, valid):
    """Each held-out pixel's summed squared ln residual over its pairs, divided by
    the fold's pair count (so the sum is the fold's mean squared residual)."""
    pix, qa, qb = _pairs(mz, valid)
    fa, fb = evaluate(a, mz[pix, qa]), evaluate(a, mz[pix, qb])
    bad = (fa <= 1e-6) | (fb <= 1e-6)
    r = np.log(np.maximum(fa, 1e-6)) - np.log(np.maximum(fb, 1e-6)) - (ln_e[qa] - ln_e[qb])
    r = np.where(bad, 1.0, r)  # a curve that goes negative on held-out data is penalised
    per = np.bincount(pix, weights=r ** 2, minlength=mz.shape[0])
    cnt = np.bincount(pix, minlength=mz.shape[0])
    return per[cnt > 0] / max(int(np.sum(cnt)), 1)


def _align_power(ln_e, ln_nominal):
    """Choose γ, c so ``γ·ln_e + c`` best matches the rough ``ln_nominal`` (least squares)."""
    x = ln_e - ln_e.mean()
    y = ln_nominal - ln_nominal.mean()
    gam = float(np.dot(x, y) / np.dot(x, x)) if np.dot(x, x) > 0 else 1.0
    return gam, gam * x + ln_nominal.mean()


def table_from_poly(a: np.ndarray, bit_depth: int) -> np.ndarray:
    """``f(z/z_max)`` over every code, made monotonic and positive: ``(2**bit_depth,)``."""
    from scipy.optimize import isotonic_regression

    zmax = 2 ** bit_depth - 1
    m = np.arange(zmax + 1) / zmax
    f = np.asarray(isotonic_regression(evaluate(a, m), increasing=True).x)
    # Below the first clearly positive value, ramp linearly to zero exposure.
    floor = 1e-4 * f[-1]
    first = int(np.argmax(f > floor))
    if first > 0:
        f[:first] = f[first] * (np.arange(first) + 0.5) / (first + 0.5)
    return np.maximum(f, 1e-12)


def response_mitsunaga1999(images: np.ndarray, exposure_times_s, *, bit_depth: int | None = None,
                    order: int | str = "auto", samples: int = 600, clip_margin: float = 0.03,
                    rng: np.random.Generator | None = None) -> ResponseCurve:
    """Recover the inverse response as a polynomial and refine the exposure ratios.

    Parameters
    ----------
    images : ndarray, ``(P, H, W, C)`` or ``(P, H, W)``, integer codes
    exposure_times_s : sequence of float, ``(P,)``
        Rough exposures (times, or any numbers proportional to the
        exposure); distinct.
    bit_depth : int, optional
    order : int or "auto"
        Polynomial order ``N`` (1..10); ``"auto"`` chooses by held-out error.
    samples : int
        Pixels sampled (:func:`hdr.samples.sample_pixels`), at least 2
        (:func:`hdr.samples.check_samples`).
    clip_margin : float
        Codes within this fraction of either end are masked.
    rng : numpy.random.Generator, optional

    Returns
    -------
    ResponseCurve
        ``method="mitsunaga-nayar"``; ``exposure_times_s`` are the refined
        exposures (in the units given); ``fit`` holds the coefficients (shifted
        Chebyshev), the refined adjacent ratios and the common power γ;
        ``selection`` the order and each candidate's held-out error.
    """
    from lumigraph.capture.errors import EstimationError, InputError

    z, t, bd = check_stack(images, exposure_times_s, bit_depth=bit_depth)
    p, h, w_, c = z.shape
    if p < 2:
        raise InputError("images", "a response needs at least two exposures")
    check_samples(samples)
    order = check_order(order)
    rng = np.random.default_rng(0) if rng is None else rng
    perm = np.argsort(t)
    z, t = z[perm], t[perm]
    ln_nom = np.log(t)
    idx = sample_pixels(z, n=samples, bit_depth=bd, rng=rng)
    zmax = 2 ** bd - 1
    zs = z.reshape(p, h * w_, c)[:, idx].astype(np.float64) / zmax  # (P, N, C)
    # A given order is still compared with the others by held-out error, so an
    # order the data cannot support is reported, not silently used.
    orders = list(range(1, MAX_ORDER + 1))
    fold = np.arange(idx.size) % 2
    g = np.empty((c, zmax + 1))
    warnings: list[str] = []
    sel_scores, chosen, chans = {}, [], []
    for ch in range(c):
        mz = zs[..., ch].T  # (N, P)
        valid = (mz >= clip_margin) & (mz <= 1 - clip_margin)
        per_pixel = {}
        for n in orders:
            parts = []
            for f in (0, 1):
                try:
                    (a,), le = _fit([(mz[fold != f], valid[fold != f])], ln_nom, [n])
                    parts.append(_held_out(a, le, mz[fold == f], valid[fold == f]) / 2)
                except np.linalg.LinAlgError:
                    parts = None
                    break
            per_pixel[n] = None if parts is None else np.concatenate(parts)
        fitted = [n for n in orders if per_pixel[n] is not None]
        if not fitted:
            raise EstimationError("images", f"channel {ch}: no polynomial order could be fitted")
        n_best = min(fitted, key=lambda n: float(np.sum(per_pixel[n])))

        # Orders are compared on the same held-out pixels: the standard error of the
        # per-pixel difference from the best, far smaller than either mean's own.
        cand = [(n, float(np.sum(per_pixel[n])),
                 float(np.std(per_pixel[n] - per_pixel[n_best], ddof=1)
                       * math.sqrt(per_pixel[n].size))) if per_pixel[n] is not None
                else (n, math.inf, math.inf) for n in orders]
        best = next(x for x in cand if x[0] == n_best)
        n_ch = min(x[0] for x in cand if x[1] <= best[1] + x[2])
        if order != "auto":
            given = next(x for x in cand if x[0] == int(order))
            if not given[1] <= best[1] + 2 * given[2]:
                warnings.append(f"channel {ch}: order {int(order)} does not fit held-out pixels "
                                f"(error {given[1]:.3g} against {best[1]:.3g} at order {best[0]}): "
                                "it follows the noise; use --order auto")
            n_ch = int(order)
        sel_scores[str(ch)] = [{"order": n, "held_out_mse": e, "se_of_difference_from_best": s}
                                for n, e, s in cand]
        chosen.append(n_ch)
        chans.append((mz, valid))
    try:
        coeffs, le = _fit(chans, ln_nom, chosen)
    except np.linalg.LinAlgError:
        raise EstimationError("images", "too few pixels seen unclipped in two exposures for "
                                        "Mitsunaga-Nayar") from None
    gam, ln_e = _align_power(le, ln_nom)
    if abs(gam - 1.0) > 0.1:
        warnings.append(f"the data's exposure ratios are the given ones to the power {1 / gam:.3f}; "
                        "check the rough times")
    for ch in range(c):
        # Exposures rescaled as e -> e^γ pair with the curve f -> f^γ (eq. 6.6 is unchanged).
        g[ch] = gam * np.log(table_from_poly(coeffs[ch], bd))
    refined = np.empty(p)
    refined[perm] = np.exp(ln_e)
    ratios = np.exp(np.diff(ln_e))  # e_{q+1}/e_q in ascending exposure order
    sel = {"parameter": "order", "chosen": chosen, "candidates": sel_scores,
           "rule": "given" if order != "auto" else
           "lowest order within one paired standard error of the best held-out error"}
    fit = {"basis": "shifted Chebyshev T_n(2M-1) - 1, f = 1 + sum a_n (...)",
           "coefficients": [a.tolist() for a in coeffs], "power_gamma": gam,
           "refined_ratios_ascending": ratios.tolist(),
           "given_ratios_ascending": np.exp(np.diff(ln_nom)).tolist(),
           "samples": int(idx.size)}
    return ResponseCurve("mitsunaga-nayar", bd, normalise_g(g), tuple(refined.tolist()), sel,
                         tuple(warnings), fit)
