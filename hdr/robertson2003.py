"""Robertson, Borman & Stevenson (2003): the response by alternating
maximum-likelihood estimation.

M. A. Robertson, S. Borman and R. L. Stevenson, "Estimation-theoretic approach
to dynamic range enhancement using multiple exposures", J. Electronic Imaging
12(2), 2003, doi:10.1117/1.1557695; first in "Dynamic range improvement
through multiple exposures", ICIP 1999, doi:10.1109/ICIP.1999.817091.
(The shared reference chapters do not cover this method; equations are
named by what they do.)

Model: code ``y_ij = f(t_j x_i + N_ij)``; the unknowns are the inverse
response values ``I_m = f⁻¹(m)`` and the radiances ``x_i``. With weights
``w_ij = w(y_ij)`` the objective ``Σ w_ij (I_{y_ij} − t_j x_i)²`` is minimised
by alternating its two closed-form partial minimisers:

- radiance, ``I`` fixed: ``x_i = Σ_j w_ij t_j I_{y_ij} / Σ_j w_ij t_j²``
  (weighted least squares over the exposures);
- response, ``x`` fixed: ``I_m = mean of t_j x_i over the observations with
  y_ij = m`` (one ``np.bincount``);
- normalise ``I`` so the middle code maps to 1 (the scale is free),

until the largest change of ``ln I`` between iterations is below ``tol``.
The papers' weight is a Gaussian-like certainty function
``w(y) = exp(−4 (y − y_mid)² / y_mid²)`` (``y_mid = z_max / 2``), standing
in for the inverse noise variance their estimator derives (used here by
default, below).

What this implementation adds:

- observations within ``clip_margin·z_max`` of 0 or ``z_max`` take no part
  (weight 0 in the radiance step, no response update from them): clipping
  truncates the noise there and biases the per-code means (the same reason
  as :func:`hdr.debevec1997.data_weight`); those codes, and any code no
  sample visits, get ``ln I`` by linear interpolation between visited codes
  and linear extrapolation at the ends;
- any bit depth up to 16: above 8 bits the codes are pooled into ``bins``
  equal-width bins (default 256, so 16 codes a bin at 12 bits, 256 at 16);
  each bin's ``I`` is the mean of ``t_j x_i`` over its observations and
  belongs at the mean code of those observations; between bin centres
  ``I`` is interpolated linearly. One unknown per code would leave a 16-bit
  bin a handful of observations (or none);
- principled pixel sampling (:func:`hdr.samples.sample_pixels`, pixels
  unclipped in two exposures: one seen once only pulls its own code towards
  the current curve), stratified over radiance; ``samples`` default 5000;
- the fixed point solved directly (:func:`_fixed_point`, the Perron vector
  of the alternation's linear map) and polished by the alternation to
  ``tol`` 1e-6 in ``ln I`` (at most 2000 iterations; from a linear start
  500-1000 were typical, from the fixed point a handful);
- the weights are the inverse noise variances the papers' estimator asks
  for (``weight="noise"``, :func:`noise_weight`): ``1 / Var(I_y)`` with
  ``Var = a I + b + (dI/dy)²/12`` (shot, read, rounding), ``a, b`` estimated
  from a first fit with the certainty weight (:func:`_noise`, the Debevec
  fit's :func:`hdr.debevec1997.estimate_noise`); ``weight="certainty"``
  keeps the Gaussian-like weight;
- the response step leaves each observation out of its own radiance
  (``leave_one_out``): ``I_m`` averages ``t_j x_i^(−j)``, the radiance from
  the pixel's *other* exposures, so an observation's noise does not pull the
  radiance it is compared with (the self-inclusion half of the
  errors-in-variables bias; still linear, so still solved as a fixed point);
- bias-corrected (:func:`_debias`): the estimate's remaining
  errors-in-variables bias, measured on renders of the fitted bracket with
  the noise estimated from it, is subtracted;
- a smoothness prior (``smooth``, :func:`smooth_gcv`): the per-code means are
  independent estimates with a known sampling variance (their observations'
  scatter), so the curve is their penalised least-squares fit with a
  roughness penalty in ``ln z`` (zero for a power law), ``λ`` by generalised
  cross-validation — the MAP curve under a smooth prior, not early stopping.
  Bench family, 8-bit, median over seeds 0–2, ours / OpenCV
  CalibrateRobertson default (``docs/decisions/hdr-robertson.md``): room
  0.0076 / 0.0131, studio 0.0036 / 0.0077 (tuned); walls 0.0049 / 0.0056,
  outdoor 0.0133 / 0.0595, night 0.066 / 0.086 (reported).

What convergence shows (bench ``8-bit`` bracket, film response, shot + read
noise, ln-response RMS against the exact curve over 5-95 % of the codes):
the fixed point of the alternation is biased. The response step is
``E[t x | y = m]``, and with noise before the response that conditional mean
follows the radiance histogram (errors in variables), leaving a ripple of
period one exposure step. Stratified sampling flattens the histogram:
converged error 0.020 at 5000 stratified pixels against 0.034 with every
pixel; OpenCV's CalibrateRobertson run to convergence (1000 iterations,
threshold 1e-7) gives 0.037, while its default (30 iterations, threshold
0.01) stops early at 0.014: early stopping regularises. We report the
converged estimate the method defines, and its convergence;
- each channel fitted over the codes that follow the exposure
  (:func:`hdr.mitsunaga1999.responsive_range`: a film base, a black level or a
  shoulder below/above them; ``fit["responsive_codes"]``), and pixels that are
  not scene points (a code that does not move over two stops) dropped from the
  sample (``fit["static_pixels_dropped"]``): Memorial's film base otherwise
  reverses green's low codes;
- the refinements kept only where the data bear them: when the refined
  estimate is not increasing (beyond ``MONOTONE_TOL_LN``), the bias
  correction, leave-one-out and noise weights are dropped in turn, each
  variant recorded in ``fit["variants"]`` and the fallback warned (a phone's
  per-frame processing, a channel that does not follow one response);
- a monotonic result (weighted isotonic regression, reported in ``fit``);
- convergence recorded: iterations, the final change and the objective at
  the first and last iteration (``fit["convergence"]``).

Examples
--------
>>> rng = np.random.default_rng(0)
>>> e = np.exp(rng.uniform(-6, 0, (40, 40, 1)))
>>> t = np.array([0.05, 0.2, 0.8, 3.2])
>>> z = np.stack([np.clip(np.round(255 * np.sqrt(np.clip(e * ti, 0, 1))), 0, 255)
...               for ti in t]).astype(np.uint8)
>>> r = response_robertson2003(z, t, rng=rng)
>>> x = r.exposure_table()[0]
>>> c = r.fit["convergence"][0]
>>> bool(abs(x[200] / x[100] - 4.0) < 0.1), c["converged"]
(True, True)
"""

from __future__ import annotations

import math

import numpy as np

from lumigraph.hdr.mitsunaga1999 import responsive_range, static_pixels
from lumigraph.hdr.response import ResponseCurve, normalise_g
from lumigraph.hdr.samples import check_samples, check_stack, sample_pixels


def certainty_weight(z: np.ndarray, bit_depth: int) -> np.ndarray:
    """Robertson et al.'s Gaussian-like weight ``exp(−4 (z − z_mid)² / z_mid²)``,
    ``z_mid = z_max / 2`` (1 at mid-range, ``e⁻⁴`` at either end).

    Examples
    --------
    >>> certainty_weight(np.array([0, 64, 127, 255]), 8).round(3).tolist()
    [0.018, 0.371, 1.0, 0.018]
    """
    half = (2 ** bit_depth - 1) / 2.0
    u = (np.asarray(z, dtype=np.float64) - half) / half
    return np.exp(-4.0 * u * u)


def _fill(ln_i: np.ndarray, centres: np.ndarray, known: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``ln I`` at codes ``at`` from the ``known`` bins: linear between their centres,
    extrapolated with the slope of the last two at either end."""
    c, v = centres[known], ln_i[known]
    out = np.interp(at, c, v)
    if c.size >= 2:
        lo, hi = at < c[0], at > c[-1]
        out[lo] = v[0] + (at[lo] - c[0]) * (v[1] - v[0]) / (c[1] - c[0])
        out[hi] = v[-1] + (at[hi] - c[-1]) * (v[-1] - v[-2]) / (c[-1] - c[-2])
    return out


def _fixed_point(y, use, w, t, bu, cnt, known, k0, k1, a, den, n_bins, loo):
    """The alternation's fixed point in one step: with ``I`` interpolated
    linearly between bins, the radiance step is a linear map ``x = B I`` and
    the response step ``I = A x``, so the normalised iteration is the power
    method on the non-negative ``A B`` (bins × bins) and converges to its
    Perron vector — computed here directly (``numpy.linalg.eig``), instead of
    the hundreds of slow iterations the second eigenvalue near 1 costs.
    With ``loo`` each observation's radiance leaves that observation out
    (:func:`_fit_channel`), still linear in ``I``: ``A B`` minus each
    observation's own term. Returns ``ln I`` per bin (NaN where unvisited)
    or None when the Perron vector is not positive.
    """
    import scipy.sparse as sp

    p, n = y.shape
    jj, ii = np.nonzero(np.ones_like(y, dtype=bool))
    wt = (w * t[:, None])[jj, ii]
    aa = a[jj, ii]
    # R I = Σ_j w_ij t_j I(y_ij) per pixel (x = R I / den).
    r_mat = sp.csr_matrix((np.concatenate([wt * (1 - aa), wt * aa]),
                           (np.concatenate([ii, ii]), np.concatenate([k0[jj, ii], k1[jj, ii]]))),
                          shape=(n, n_bins))
    ju, iu = np.nonzero(use)
    own, dnm, ok = _leave_out(w, t[:, None], den, ju, iu, loo)
    c = t[ju] / (cnt[bu] * dnm)
    m = sp.csr_matrix((c, (bu, iu)), shape=(n_bins, n)) @ r_mat
    if loo:
        cs = np.where(ok, c * own, 0.0)
        au = a[ju, iu]
        m = m - sp.csr_matrix((np.concatenate([cs * (1 - au), cs * au]),
                               (np.concatenate([bu, bu]),
                                np.concatenate([k0[ju, iu], k1[ju, iu]]))),
                              shape=(n_bins, n_bins))
    kc = np.flatnonzero(known)
    m = m.toarray()[np.ix_(kc, kc)]
    vals, vecs = np.linalg.eig(m)
    v = np.real(vecs[:, int(np.argmax(np.real(vals)))])
    v = v * np.sign(v[np.argmax(np.abs(v))])
    if not np.all(v > 0):
        return None
    out = np.full(n_bins, np.nan)
    out[kc] = np.log(v)
    return out


def _leave_out(w, tt, den, ju, iu, loo):
    """For the used observations ``(ju, iu)``: their own term ``w t`` of the
    radiance sum, the denominator of their radiance (``Σ w t²`` without their
    own ``w t²`` when ``loo``; the whole sum where they are the pixel's only
    weighted observation) and where leaving out was possible."""
    own = (w * tt)[ju, iu]
    full = den[iu]
    if not loo:
        return own, full, np.zeros(ju.size, dtype=bool)
    rest = full - own * tt[ju, 0]
    ok = rest > 1e-9 * full
    return own, np.where(ok, rest, full), ok


def _fit_channel(y, tt, bd, n_bins, lo, hi, max_iter, tol, wtab=None, loo=False):
    """One channel's alternation (module docstring) from codes ``y`` (P, N):
    ``g`` over every code, the radiances ``x`` (N,), the weights and the
    convergence; None when fewer than 4 code bins are well exposed."""
    n_codes = 2 ** bd
    zmax = n_codes - 1
    use = (y >= lo) & (y <= hi)
    w = np.where(use, certainty_weight(y, bd) if wtab is None else wtab[y], 0.0)
    b = (y * n_bins) // n_codes  # equal-width code bins (the identity at <= 8 bits)
    bu = b[use]
    den = np.maximum((w * tt ** 2).sum(axis=0), 1e-300)
    cnt = np.bincount(bu, minlength=n_bins).astype(np.float64)
    known = cnt > 0
    if np.count_nonzero(known) < 4:
        return None
    # Each bin's I belongs at the mean code of its observations.
    centres = np.where(known, np.bincount(bu, weights=y[use], minlength=n_bins)
                       / np.maximum(cnt, 1), (np.arange(n_bins) + 0.5) * n_codes / n_bins)
    # Linear interpolation of ln I from bin centres to each observation's code,
    # fixed through the iterations: position k0 + a among the visited centres.
    kc = np.flatnonzero(known)
    pos = np.clip(np.searchsorted(centres[kc], y, side="right") - 1, 0, kc.size - 2)
    k0, k1 = kc[pos], kc[pos + 1]
    a = np.clip((y - centres[k0]) / (centres[k1] - centres[k0]), 0.0, 1.0)
    mid_bin = int(np.argmin(np.abs(centres - zmax / 2.0) + np.where(known, 0, np.inf)))
    # Start at the fixed point itself (:func:`_fixed_point`), else from a linear
    # response; the alternation then only polishes it (interpolation in ln I).
    ln_i = _fixed_point(y, use, w, tt[:, 0], bu, cnt, known, k0, k1, a, den, n_bins, loo)
    if ln_i is None or not np.all(np.isfinite(ln_i[known])):
        ln_i = np.log(np.maximum(centres, 0.5) / zmax)
    else:
        ln_i[~known] = _fill(ln_i, centres, known, centres[~known])
    ln_i -= ln_i[mid_bin]
    ju, iu = np.nonzero(use)
    own, dnm, ok = _leave_out(w, tt, den, ju, iu, loo)
    change, obj0, obj, it = math.inf, math.nan, math.nan, 0
    for it in range(1, max_iter + 1):
        i_obs = np.exp(ln_i[k0] * (1 - a) + ln_i[k1] * a)
        x = (w * tt * i_obs).sum(axis=0) / den  # radiance step
        obj = float((w * (i_obs - tt * x) ** 2).sum() / w.sum())
        if it == 1:
            obj0 = obj
        tx = (tt * x)[use]
        if loo:  # each observation's radiance from the pixel's other exposures
            s_i = (x * den)[iu]
            tx = np.where(ok, tt[ju, 0] * (s_i - own * i_obs[ju, iu]) / dnm, tx)
        new = np.bincount(bu, weights=tx, minlength=n_bins)
        ln_new = np.full(n_bins, np.nan)
        ln_new[known] = np.log(np.maximum(new[known] / cnt[known], 1e-300))  # response step
        ln_new -= ln_new[mid_bin]  # I at mid-code = 1
        change = float(np.max(np.abs(ln_new[known] - ln_i[known])))
        ln_i = ln_new
        ln_i[~known] = _fill(ln_i, centres, known, centres[~known])
        if change < tol:
            break
    g_ch = _fill(ln_i, centres, known, np.arange(n_codes, dtype=np.float64))
    # Sampling variance of each bin's ln I: the scatter of its observations' ln(t x).
    r = np.log(np.maximum(tx, 1e-300)) - ln_i[bu]
    ss = np.bincount(bu, weights=r * r, minlength=n_bins)
    var_bin = np.where(cnt > 1, ss / np.maximum(cnt, 1) / np.maximum(cnt - 1, 1), np.inf)
    return {"g": g_ch, "var_bin": var_bin, "x": x, "w": w, "it": it, "change": change,
            "obj0": obj0, "obj": obj, "known": known, "centres": centres, "cnt": cnt, "kc": kc}


def _noise(fc, y, tt, bd, lo, hi, rng):
    """``(a, b)`` of ``Var X = a X + b`` (``X = I``, the mid code's exposure 1)
    from a fit's residuals (:func:`hdr.debevec1997.estimate_noise`, calibrated
    on renders of the fitted bracket)."""
    from lumigraph.hdr.debevec1997 import estimate_noise

    def wfun(zz):
        return np.where((zz >= lo) & (zz <= hi), certainty_weight(zz, bd), 0.0)

    x = np.maximum(fc["x"], 1e-300)
    return estimate_noise(fc["g"], np.log(x), y.T, fc["w"].T, np.log(tt[:, 0]), 2 ** bd, bd,
                          wfun=wfun, rng=rng)


def noise_weight(g: np.ndarray, noise, lo: float, hi: float) -> np.ndarray:
    """Inverse variance of ``I_y`` as a measurement of the exposure ``t x``,
    per code: ``1 / (a I + b + (dI/dy)²/12)`` with ``I = exp g`` (shot, read
    and rounding noise; Robertson et al. 2003's weights are inverse noise
    variances), zero outside ``[lo, hi]``, scaled to a maximum of 1.

    Examples
    --------
    >>> g = np.log(np.maximum(np.arange(256.0), 0.5) / 128)
    >>> w = noise_weight(g, (1e-3, 1e-5), 8, 247)
    >>> float(w[0]), bool(w[20] > w[200] > 0)
    (0.0, True)
    """
    from scipy.optimize import isotonic_regression

    i = np.exp(np.asarray(isotonic_regression(g, increasing=True).x))
    var = noise[0] * i + noise[1] + np.gradient(i) ** 2 / 12.0
    codes = np.arange(g.size)
    w = np.where((codes >= lo) & (codes <= hi), 1.0 / np.maximum(var, 1e-300), 0.0)
    return w / w.max()


def smooth_gcv(v: np.ndarray, var: np.ndarray, at: np.ndarray,
               grid=None) -> tuple[np.ndarray, float]:
    """Penalised least squares (Whittaker): ``Σ (s − v)² / var + λ ∫ (d²s/du²)² du``
    over bins at codes ``at`` (increasing), ``u = ln z``: the prior is that the
    response is locally a power law (``g = γ ln z + c``, which it costs
    nothing), so a gamma or sRGB toe is not flattened the way a roughness
    penalty in ``z`` flattens it. ``λ`` is chosen by generalised
    cross-validation (Craven & Wahba 1979, doi:10.1007/BF01404567) over
    ``grid`` (in units of the mean weight). Bins with infinite variance are
    filled by the prior. Returns ``(s, λ)``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> k = np.arange(1.0, 256.0); true = 2.2 * np.log(k / 128)
    >>> s, lam = smooth_gcv(true + rng.normal(0, 0.02, k.size), np.full(k.size, 0.02 ** 2), k)
    >>> bool(np.std(s - true) < 0.01)
    True
    """
    from scipy.linalg import solveh_banded

    n = v.size
    ok = np.isfinite(var) & (var > 0) & np.isfinite(v)
    if n < 4 or np.count_nonzero(ok) < 4:
        return v, 0.0
    wv = np.where(ok, 1.0 / np.where(ok, var, 1.0), 0.0)
    # Second differences in u = ln z on the uneven grid, scaled so that
    # ||D s||² = ∫ (d²s/du²)² du: zero for a power law (s = γ ln z + c).
    u = np.log(np.maximum(at, 0.5))
    h1, h2 = np.diff(u)[:-1], np.diff(u)[1:]
    sc = 2.0 / (h1 + h2) * np.sqrt((h1 + h2) / 2.0)
    d = np.zeros((n - 2, n))
    r = np.arange(n - 2)
    d[r, r], d[r, r + 1], d[r, r + 2] = sc / h1, -sc * (1 / h1 + 1 / h2), sc / h2
    dtd = d.T @ d * float(wv[ok].mean())
    # (W + λ DᵀD) is pentadiagonal: banded Cholesky, upper form for solveh_banded.
    band = np.zeros((3, n))
    for k in range(3):
        band[2 - k, k:] = np.diagonal(dtd, k)
    vv = np.where(ok, v, 0.0)
    m = np.count_nonzero(ok)
    cols = np.flatnonzero(ok)
    rhs = np.zeros((n, m))
    rhs[cols, np.arange(m)] = wv[cols]
    best = (math.inf, v, 0.0)
    for lam in (10.0 ** np.arange(-4.0, 6.01, 0.5) if grid is None else grid):
        ab = lam * band
        ab[2] += wv
        h = solveh_banded(ab, rhs)  # columns of H = (W + λ DᵀD)⁻¹ W at the data
        s = h @ vv[cols]
        rss = float(np.sum(wv[ok] * (s[ok] - v[ok]) ** 2))
        score = m * rss / max(m - float(np.trace(h[cols])), 1e-9) ** 2
        if score < best[0]:
            best = (score, s, float(lam))
    return best[1], best[2]


def _splice(g, at, v):
    """``g`` with its values between ``at[0]`` and ``at[-1]`` replaced by ``v``
    interpolated, and the ends outside shifted to meet it (no step)."""
    if at.size < 2:
        return g
    codes = np.arange(g.size, dtype=np.float64)
    out = np.interp(codes, at, v)
    lo, hi = codes < at[0], codes > at[-1]
    out[lo] = g[lo] - np.interp(at[0], codes, g) + v[0]
    out[hi] = g[hi] - np.interp(at[-1], codes, g) + v[-1]
    return out


def _debias(fc, y, tt, bd, n_bins, lo, hi, max_iter, tol, rng, draws, noise, wtab, loo):
    """Parametric-bootstrap bias correction, as for Debevec
    (:func:`hdr.debevec1997._debias`): the bracket the fit describes
    (radiances ``x``, times, the response quantised and clipped, the noise
    ``a X + b`` before it) rendered ``draws`` times as more pixels and
    fitted the same way; the refit's departure from the fit is the
    estimator's bias at the fitted curve (the errors-in-variables ripple the
    module docstring describes), and is subtracted. Returns
    ``(g, max |bias|)``."""
    from scipy.optimize import isotonic_regression

    n_codes = 2 ** bd
    g = fc["g"]
    x = np.maximum(fc["x"], 1e-300)
    gm = np.asarray(isotonic_regression(g, increasing=True).x)
    edges = np.exp(0.5 * (gm[1:] + gm[:-1]))
    ex = tt * x[None]  # (P, N)
    sd = np.sqrt(np.maximum(noise[0] * ex + noise[1], 0.0))
    sim = np.tile(ex, (1, draws)) + np.tile(sd, (1, draws)) * rng.standard_normal(
        (ex.shape[0], ex.shape[1] * draws))
    ys = np.searchsorted(edges, sim).astype(np.int64)
    f2 = _fit_channel(ys, tt, bd, n_bins, lo, hi, max_iter, tol, wtab, loo)
    if f2 is None:
        return g, 0.0
    mid = n_codes // 2
    bias = (f2["g"] - f2["g"][mid]) - (g - g[mid])
    return g - bias, float(np.max(np.abs(bias)))


MONOTONE_TOL_LN = 0.05
"""Largest departure from an increasing curve (ln units, isotonic regression)
a kept estimate may have; beyond it the next simpler variant is tried, and a
warning says when none is within it."""


def _variants(noise_w: bool, loo: bool, debias: bool):
    """The variants to try, the requested one first, then each refinement
    dropped in turn (bias correction, leave-one-out, noise weights), down to
    the papers' plain alternation; no repeats.

    Examples
    --------
    >>> _variants(True, True, True)
    [(True, True, True), (True, True, False), (True, False, False), (False, False, False)]
    >>> _variants(False, False, False)
    [(False, False, False)]
    """
    out = [(noise_w, loo, debias), (noise_w, loo, False), (noise_w, False, False),
           (False, False, False)]
    seen: list[tuple[bool, bool, bool]] = []
    for v in out:
        if v not in seen:
            seen.append(v)
    return seen


def _variant_name(v: dict) -> str:
    parts = [k.replace("_", " ") for k in ("noise_weight", "leave_one_out", "bias_correction")
             if v[k]]
    return "with " + ", ".join(parts) if parts else "plain (the papers' certainty weight)"


def _estimate(fc0, y, tt, bd, n_bins, lo, hi, max_iter, tol, rng, bias_draws, nz, wtab, loo,
              debias, smooth):
    """One variant of a channel's estimate from the certainty-weighted fit
    ``fc0``: refit with ``wtab``/``loo`` when either is set, the bias
    correction, the smoothing; and how far it is from increasing."""
    from scipy.optimize import isotonic_regression

    n_codes = 2 ** bd
    fc = fc0
    if wtab is not None or loo:
        fc = _fit_channel(y, tt, bd, n_bins, lo, hi, max_iter, tol, wtab, loo) or fc0
    centres, known, cnt, kc = fc["centres"], fc["known"], fc["cnt"], fc["kc"]
    g_ch, bmax, lam = fc["g"], None, None
    if debias:
        g_ch, bmax = _debias(fc, y, tt, bd, n_bins, lo, hi, max_iter, tol, rng, bias_draws,
                             nz, wtab, loo)
    if smooth:
        # The bias correction adds its refit's variance (draws x the pixels).
        var = fc["var_bin"] * (1.0 + (1.0 / bias_draws if debias else 0.0))
        at = np.where(known, centres, (np.arange(n_bins) + 0.5) * n_codes / n_bins)
        inside = (at >= lo) & (at <= hi)
        all_codes = np.arange(n_codes, dtype=np.float64)
        sm, lam = smooth_gcv(np.interp(at, all_codes, g_ch), np.where(inside, var, np.inf), at)
        g_ch = _splice(g_ch, at[inside], sm[inside])
    wts = np.interp(np.arange(n_codes, dtype=np.float64), centres[kc], cnt[kc]) + 1.0
    g_mono = np.asarray(isotonic_regression(g_ch, weights=wts, increasing=True).x)
    return {"fc": fc, "g": g_ch, "g_mono": g_mono, "bias_max": bmax, "lam": lam,
            "monotone_change": float(np.max(np.abs(g_mono - g_ch)))}



def response_robertson2003(images: np.ndarray, exposure_times_s, *, bit_depth: int | None = None,
              samples: int = 5000, bins: int | None = None, max_iter: int = 2000,
              tol: float = 1e-6, clip_margin: float = 0.03, bias_draws: int = 4,
              weight: str = "noise", leave_one_out: bool = True, smooth: bool = True,
              rng: np.random.Generator | None = None) -> ResponseCurve:
    """Recover ``g = ln f⁻¹`` per channel by Robertson et al.'s alternating estimation.

    Parameters
    ----------
    images : ndarray, ``(P, H, W, C)`` or ``(P, H, W)``, uint8/uint16 codes
        The bracket, registered, static scene.
    exposure_times_s : sequence of float, ``(P,)``
        Exposure times (or relative exposures), seconds, distinct.
    bit_depth : int, optional
        True bit depth of the codes (default: the dtype's).
    samples : int
        Pixels used (:func:`hdr.samples.sample_pixels`), at least 2
        (:func:`hdr.samples.check_samples`).
    bins : int, optional
        Response unknowns per channel; default ``min(2**bit_depth, 256)``
        (one per code up to 8 bits, equal-width code bins above).
    max_iter : int
        Iterations at most (a warning says when they run out).
    tol : float
        Convergence: the largest change of ``ln I`` over the visited bins
        between two iterations.
    clip_margin : float
        Fraction of the code range at each end left out of the fit.
    bias_draws : int
        Renders of the fitted bracket for the bias correction (0: none).
    weight : {"noise", "certainty"}
        Inverse noise variance per code (estimated from the bracket) or the
        papers' Gaussian-like certainty function.
    leave_one_out : bool
        Response step on each observation's radiance from the other exposures.
    smooth : bool
        Penalised least-squares smoothing of the per-code means, ``λ`` by GCV.
    rng : numpy.random.Generator, optional
        For the pixel sampling's tie-breaking (default seeded 0).

    Returns
    -------
    ResponseCurve
        ``method="robertson"``; ``fit["convergence"]`` per channel holds
        ``iterations``, ``final_change_ln``, ``converged`` and the objective
        ``Σ w (I − t x)²`` (mean per weighted observation, ``I`` normalised)
        at the first and last iteration; ``selection`` the bins and weight.

    Raises
    ------
    InputError
        Fewer than two exposures, duplicated times, too few usable pixels.
    EstimationError
        A channel with too few visited codes to define a curve.
    """
    from lumigraph.capture.errors import EstimationError, InputError

    z, t, bd = check_stack(images, exposure_times_s, bit_depth=bit_depth)
    p, h, w_, c = z.shape
    if p < 2:
        raise InputError("images", "a response needs at least two exposures")
    check_samples(samples)
    n_codes = 2 ** bd
    n_bins = int(bins) if bins is not None else min(n_codes, 256)
    if not 4 <= n_bins <= n_codes:
        raise ValueError(f"bins: expected 4..{n_codes}, got {bins}")
    if not (isinstance(max_iter, int | np.integer) and max_iter >= 1):
        raise ValueError(f"max_iter: expected a positive integer, got {max_iter!r}")
    if weight not in ("noise", "certainty"):
        raise ValueError(f"weight: expected 'noise' or 'certainty', got {weight!r}")
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol: expected a positive number, got {tol!r}")
    rng = np.random.default_rng(0) if rng is None else rng
    # Sample first, then order the small sample by time (no copy of the stack).
    idx = sample_pixels(z, n=samples, bit_depth=bd, rng=rng)
    order = np.argsort(t)
    t = t[order]
    zmax = n_codes - 1
    # Pixels that are not scene points (a code that does not move over two stops: a
    # matte, a registration border, a dead pixel; Memorial's pure-blue border) break
    # the model y = f(t x) in a way no weight repairs. When the sample holds any, it is
    # drawn again at three times the size without them and thinned evenly along
    # radiance (as Mitsunaga-Nayar's, :func:`hdr.mitsunaga1999.static_pixels`).
    n_static = 0
    flat = z.reshape(p, h * w_, c)
    if static_pixels(flat[:, idx][order] / zmax, t, clip_margin).any():
        idx = sample_pixels(z, n=3 * samples, bit_depth=bd, rng=rng)
        drop = static_pixels(flat[:, idx][order] / zmax, t, clip_margin)
        n_static = int(np.count_nonzero(drop))
        idx = idx[~drop]
        if idx.size > samples:
            idx = idx[np.round(np.linspace(0, idx.size - 1, samples)).astype(np.int64)]
    zs = z[:, idx // w_, idx % w_][order].astype(np.int64)  # (P, N, C)
    lo, hi = clip_margin * zmax, (1 - clip_margin) * zmax
    # Codes that do not follow the exposure (a film base, a black level, a shoulder)
    # carry no response information, and their per-code means mix every radiance that
    # sits there: each channel's fitted range stops at them
    # (:func:`hdr.mitsunaga1999.responsive_range`; the whole range when every code
    # responds).
    floor, ceil = responsive_range(zs / zmax, t, zmax)
    los = np.maximum(lo, floor * zmax)
    his = np.minimum(hi, ceil * zmax)
    tt = t[:, None]
    g_out = np.empty((c, n_codes))
    warnings: list[str] = []
    conv, mono, visited = [], [], []
    noise_ab, bias_max, lams, variants_log = [], [], [], []
    for ch in range(c):
        y = zs[..., ch]  # (P, N)
        lo, hi = float(los[ch]), float(his[ch])
        fc = _fit_channel(y, tt, bd, n_bins, lo, hi, max_iter, tol)
        if fc is None:
            raise EstimationError("images", f"channel {ch}: too few code levels are well exposed; "
                                            "no curve can be estimated")
        nz = None
        if weight == "noise" or bias_draws > 0:
            nz = _noise(fc, y, tt, bd, lo, hi, rng)
            noise_ab.append((float(nz[0]), float(nz[1])))
        # (no noise measured, e.g. a noise-free render: the certainty weight)
        wtab = (noise_weight(fc["g"], nz, lo, hi)
                if weight == "noise" and (nz[0] > 0 or nz[1] > 0) else None)
        # The refinements (noise weights, leave-one-out, bias correction) correct small
        # biases of a bracket that follows one response; on one that does not (a phone's
        # per-frame processing, a channel with little signal) they can amplify the misfit
        # into a broken curve. A response is increasing: the first variant, in the order
        # below, whose estimate is monotone within MONOTONE_TOL_LN is kept, and every
        # variant tried is recorded with the reason the earlier ones were passed over.
        tried, chosen = [], None
        for v_w, v_loo, v_deb in _variants(wtab is not None, leave_one_out, bias_draws > 0):
            est = _estimate(fc, y, tt, bd, n_bins, lo, hi, max_iter, tol, rng, bias_draws,
                            nz, wtab if v_w else None, v_loo, v_deb, smooth)
            est["variant"] = {"noise_weight": v_w, "leave_one_out": v_loo,
                              "bias_correction": v_deb}
            tried.append(est)
            if est["monotone_change"] <= MONOTONE_TOL_LN:
                chosen = est
                break
        if chosen is None:
            chosen = min(tried, key=lambda e: e["monotone_change"])
        if chosen is not tried[0]:
            warnings.append(
                f"channel {ch}: the full estimate was not monotonic (max change "
                f"{tried[0]['monotone_change']:.3g} in ln units); kept the variant "
                f"{_variant_name(chosen['variant'])} (max change "
                f"{chosen['monotone_change']:.3g}): the bracket does not follow one response "
                "closely in this channel")
        variants_log.append([{**e["variant"], "monotone_max_change_ln": e["monotone_change"],
                              "kept": e is chosen} for e in tried])
        fc = chosen["fc"]
        if chosen["bias_max"] is not None:
            bias_max.append(chosen["bias_max"])
        if chosen["lam"] is not None:
            lams.append(chosen["lam"])
        it, change, obj0, obj = fc["it"], fc["change"], fc["obj0"], fc["obj"]
        known = fc["known"]
        converged = change < tol
        if not converged:
            warnings.append(f"channel {ch}: not converged after {max_iter} iterations (last change "
                            f"{change:.2g} in ln units); raise max_iter")
        conv.append({"iterations": it, "final_change_ln": change, "converged": bool(converged),
                     "objective_first": obj0, "objective_last": obj})
        g_mono, change_mono = chosen["g_mono"], chosen["monotone_change"]
        mono.append(change_mono)
        if change_mono > MONOTONE_TOL_LN:
            warnings.append(f"channel {ch}: the fit was not monotonic (max change "
                            f"{change_mono:.3f} in ln units when made so); noisy data or too "
                            "few samples")
        visited.append(int(np.count_nonzero(known)))
        g_out[ch] = g_mono
    sel = {"parameter": "bins", "chosen": n_bins, "rule": "given" if bins is not None else
           "one per code up to 8 bits, else 256 equal-width code bins",
           "weight": ("1 / (a I + b + (dI/dz)^2/12), a, b estimated from the bracket"
                      if weight == "noise" else "exp(-4 (z - z_mid)^2 / z_mid^2)")
           + ", zero within clip_margin of either end",
           "clip_margin": clip_margin, "leave_one_out": bool(leave_one_out),
           "smoothing": {"penalty": "integral of (d2 g / d(ln z)2)^2", "rule": "GCV",
                         "lambda": lams} if smooth else None}
    fit = {"samples": int(idx.size), "static_pixels_dropped": n_static,
           "responsive_codes": [[float(a), float(b)] for a, b in zip(los, his, strict=True)],
           "bins_visited": visited, "convergence": conv,
           "noise": {"model": "Var X = a X + b (X = exp g) + quantisation", "a_b": noise_ab,
                     "source": "estimated from the bracket"},
           "bias_correction": {"draws": int(bias_draws), "max_abs_ln": bias_max},
           "monotone_max_change_ln": mono, "variants": variants_log, "tol_ln": tol,
           "max_iter": int(max_iter)}
    times = tuple(float(x) for x in np.asarray(exposure_times_s, dtype=np.float64))
    return ResponseCurve("robertson", bd, normalise_g(g_out), times, sel, tuple(warnings), fit)
