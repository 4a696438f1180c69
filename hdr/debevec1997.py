"""Debevec & Malik (1997): the camera response from an exposure bracket.

P. E. Debevec and J. Malik, "Recovering High Dynamic Range Radiance Maps from
Photographs", SIGGRAPH 1997, doi:10.1145/258734.258884. Reference ch. 6,
eq. 6.3-6.5.

For each channel the unknowns are ``g`` (``ln f⁻¹``) and ``ln E_i`` of the
sampled pixels. The ``ln E_i`` are eliminated (each touches only its own
pixel's rows), leaving a ``K × K`` quadratic in the knot values assembled
with ``np.bincount`` and ``scipy.sparse``; one generalised symmetric
eigendecomposition per channel then gives every λ's solution, misfit and
roughness at once (:class:`_Reduced`; the full sparse system,
:func:`_system` with :func:`solve_sparse_lstsq`, is kept as the reference a
test compares against).

What this adds to the paper:

- any bit depth up to 16: ``g`` lives on ``K`` knots (default
  :data:`DEFAULT_KNOTS` = 128 evenly spaced, interpolated linearly; as
  accurate as one per code on the bench family, a quarter of the cost);
- principled pixel sampling (:func:`hdr.samples.sample_pixels`) from a grid
  whose size follows the sample count, not the frames';
- λ chosen automatically at the corner of the L-curve (:func:`_l_curve`,
  which also says why held-out prediction and GCV are not used); every
  candidate is recorded; above 8 bits the corner is taken on the codes read
  at 8-bit resolution (:func:`_binned8`) and λ scaled by the ratio of the
  noise per observation (:func:`_noise_ratio`), so a deeper file of the same
  scene is smoothed the same and 8-bit data stored as ``z · 257`` give the
  8-bit curve (the noise model and the bias correction quantise to the
  data's :func:`code_step`);
- the smoothness term is scaled by the knot spacing and the data term by the
  number of observations, so one λ means the same for every bit depth and
  sample count (λ weighs ``∫ ω(u)² g''(u)² du`` against the mean squared
  weighted residual, ``u = z / z_max``);
- noise-aware at the dark and bright ends: rows weighted ``√ω`` down to code
  1 (:func:`data_weight`), the sensor noise ``Var X = a X + b`` estimated
  from the bracket (:func:`estimate_noise`, or given as ``noise``), and the
  bias that noise, quantisation and clipping at 0 and ``z_max`` give the
  fit removed by a parametric bootstrap (:func:`_debias`);
- a monotonic result (weighted isotonic regression when noise makes the
  solution dip; reported in ``warnings``).

Research notes and figures: ``docs/decisions/hdr-debevec-noise.md``.

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

import functools
import math

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.hdr.response import ResponseCurve, normalise_g
from lumigraph.hdr.samples import check_samples, check_stack, hat_weight, sample_pixels

LAMBDA_GRID = tuple(10.0 ** (k / 4) for k in range(-40, -11))
# Knots per channel: 128 (two 8-bit codes apart) is as accurate as one per code
# on the bench family (8-bit median over seeds: outdoor 0.0045 vs 0.0044, walls
# 0.0054 vs 0.0052, night 0.0340 vs 0.0353; 512 at 12 bits no better than 256)
# and the eigendecomposition costs (K)³: a quarter of the time at 8 bits.
DEFAULT_KNOTS = 128
BIAS_ROUNDS = 1
HEAVY_NOISE = 0.02  # ln units of response error per knot the noise alone implies  # bias-correction iterations (bench: a second one did not help, 8-bit outdoor 0.0044 -> 0.0051)
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


def data_weight(z: np.ndarray, bit_depth: int, clip_margin: float = 0.0) -> np.ndarray:
    """Row weight of each observation in eq. 6.5: ``√ω(z)`` (the hat), zero
    within one 8-bit step (``z_max/255``) of 0 and ``z_max`` — the censored
    codes 0 and 255 at 8 bits — and within ``clip_margin·z_max`` of either end.

    The paper weights each row by ω, i.e. trusts an observation in
    proportion to ω²; near the ends that leaves the curve to the smoothness
    prior, which cannot follow a toe's curvature (bench ``walls``: +0.13 ln
    at z = 10). With the row weight √ω (inverse variance ∝ ω) the low and
    high codes speak for themselves; what noise and clipping do to them
    there — a code just above 0 is more often a pixel whose noise happened
    to be positive — is then removed by the bias correction
    (:func:`_debias`), so no margin is needed (``clip_margin`` 0).

    Examples
    --------
    >>> data_weight(np.array([0, 3, 10, 128, 250, 255]), 8).round(2).tolist()
    [0.0, 0.15, 0.28, 1.0, 0.2, 0.0]
    """
    return _weight_table(bit_depth, float(clip_margin))[np.asarray(z, dtype=np.int64)]


@functools.lru_cache(maxsize=16)
def _weight_table(bit_depth, clip_margin):
    zmax = 2 ** bit_depth - 1
    zf = np.arange(zmax + 1, dtype=np.float64)
    # The censored band is one 8-bit step wide at every depth (codes 0 and 255
    # at 8 bits, where the hat is 0 there anyway; 0..16 of 4095 at 12 bits), so
    # a deeper file of the same scene is fitted on the same share of its range,
    # only finer: below z_max/255 a deep code is read noise truncated at 0, and
    # its log pulls the toe (docs/decisions/hdr-debevec-noise.md, "deep codes").
    edge = max(clip_margin * zmax, zmax / 255)
    keep = (zf >= edge) & (zf <= zmax - edge)
    out = np.where(keep, np.sqrt(_hat_u(zf, bit_depth)), 0.0)
    out.setflags(write=False)
    return out


class _Reduced:
    """Eq. 6.5 for one channel with the ``ln E_i`` eliminated, every λ from
    one factorisation.

    Each ``ln E_i`` touches only its own pixel's rows, so for a given ``g`` its
    optimum is the weighted mean of ``g(Z_ij) − ln Δt_j``; substituting it
    leaves a quadratic in the ``K`` knot values alone: data ``gᵀHg − 2gᵀh +
    c₀`` (``H`` assembled with ``np.bincount``: each observation touches two
    adjacent knots, each pixel one row of ``M`` in ``H = D − Mᵀ S⁻¹ M``) and
    smoothness ``λ gᵀLg``. One generalised symmetric eigendecomposition
    ``L V = (H + G + λ_r L) V diag(μ)`` (``G`` the gauge, ``λ_r`` a mid-grid
    reference so both terms are of like size) diagonalises every λ's system
    at once: ``g(λ) = V diag(1 / (1 + (λ − λ_r) μ)) Vᵀ h``, and the misfit and
    roughness of each λ follow from ``μ`` and ``Vᵀh`` in ``O(K)``. The
    solution equals the full sparse system's (:func:`solve_sparse_lstsq` on
    :func:`_system`; a test checks).
    """

    LAM_REF = 1e-7

    def __init__(self, z, lnt, w, n_knots, bit_depth):
        use = np.count_nonzero(w > 0, axis=1) >= 2
        if np.count_nonzero(use) < 2:
            raise np.linalg.LinAlgError("too few pixels seen in two exposures")
        self.z, self.w = z[use], w[use]
        self.lnt, self.k, self.bd = lnt, n_knots, bit_depth
        self.use = use
        kk = n_knots
        ii, jj = np.nonzero(self.w > 0)
        m = ii.size
        self.m, self.ii = m, ii
        w2 = self.w[ii, jj] ** 2 / m  # squared row weights (data term = mean)
        k0, a = knot_basis(self.z[ii, jj], kk, bit_depth)
        y = lnt[jj]
        b0, b1 = w2 * (1 - a), w2 * a
        d = (np.bincount(k0 * kk + k0, b0 * (1 - a), kk * kk)
             + np.bincount(k0 * kk + k0 + 1, b0 * a, kk * kk)
             + np.bincount((k0 + 1) * kk + k0 + 1, b1 * a, kk * kk)).reshape(kk, kk)
        d = d + np.triu(d, 1).T
        n_px = self.z.shape[0]
        # M: pixel i's weighted knot loads (dense N x K from bincount; one BLAS
        # product beats building and multiplying sparse matrices at these sizes).
        mm = (np.bincount(ii * kk + k0, b0, n_px * kk)
              + np.bincount(ii * kk + k0 + 1, b1, n_px * kk)).reshape(n_px, kk)
        s_i = np.bincount(ii, w2, n_px)
        q = np.bincount(ii, w2 * y, n_px)
        ms = mm / s_i[:, None]
        self.h_mat = d - ms.T @ mm
        self.h_vec = np.bincount(k0, b0 * y, kk) + np.bincount(k0 + 1, b1 * y, kk) - ms.T @ q
        self.c0 = float(np.sum(w2 * y * y) - np.sum(q * q / s_i))
        self.mm, self.s_i, self.q = mm, s_i, q
        self.l_mat = _smoothness_matrix(kk, bit_depth)
        self.a0 = self.h_mat.copy()
        self.a0[kk // 2, kk // 2] += 1.0  # gauge: g at the middle knot is 0
        self._eig = None

    def _decompose(self):
        import scipy.linalg

        if self._eig is None:
            mu, v = scipy.linalg.eigh(self.l_mat, self.a0 + self.LAM_REF * self.l_mat,
                                      driver="gvd", check_finite=False)
            self._eig = (np.maximum(mu, 0.0), v, v.T @ self.h_vec)
        return self._eig

    def curve(self, grid):
        """``(ρ, η)`` for every λ of ``grid``: mean squared weighted residual and
        roughness, from the one eigendecomposition."""
        mu, _, c = self._decompose()
        lam = np.asarray(grid, dtype=np.float64)[:, None]
        den = 1.0 + (lam - self.LAM_REF) * mu
        if np.any(den <= 0):
            raise np.linalg.LinAlgError("singular system")
        y = c / den
        eta = np.sum(mu * y * y, axis=1)
        rho = np.sum((1.0 - self.LAM_REF * mu) * y * y, axis=1) - 2 * np.sum(c * y, axis=1) + self.c0
        return np.maximum(rho, 1e-300), eta

    def fit(self, lam):
        """``(g at the knots, ln E per used pixel, data misfit ρ, roughness η)``."""
        import scipy.linalg

        try:
            cf = scipy.linalg.cho_factor(self.a0 + lam * self.l_mat, check_finite=False)
        except np.linalg.LinAlgError:
            raise np.linalg.LinAlgError("singular system") from None
        gk = scipy.linalg.cho_solve(cf, self.h_vec, check_finite=False)
        if not np.all(np.isfinite(gk)):
            raise np.linalg.LinAlgError("singular system")
        rho = max(float(gk @ self.h_mat @ gk - 2 * gk @ self.h_vec + self.c0), 1e-300)
        eta = float(gk @ self.l_mat @ gk)
        lne = (self.mm @ gk - self.q) / self.s_i
        return gk, lne, rho, eta


@functools.lru_cache(maxsize=8)
def _smoothness_matrix(n_knots, bit_depth):
    """``Dᵀ D`` of the weighted second differences, ``||D g||² = ∫ ω² g''² du``
    (the same for every fit of a bit depth, so built once). Read-only."""
    h = 1.0 / (n_knots - 1)
    ki = np.arange(1, n_knots - 1)
    wk = _smooth_weights(n_knots, bit_depth)
    d2 = np.zeros((ki.size, n_knots))
    d2[ki - 1, ki - 1], d2[ki - 1, ki], d2[ki - 1, ki + 1] = wk, -2 * wk, wk
    d2 *= math.sqrt(h) / h ** 2
    out = d2.T @ d2
    out.setflags(write=False)
    return out


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
    wk = _hat_u(k * (2 ** bit_depth - 1) / (n_knots - 1), bit_depth)
    return np.maximum(wk, 0.05)  # keep the ends smooth too, where data are scarce


def _hat_u(z, bit_depth):
    """The 8-bit hat ω (:func:`hdr.samples.hat_weight` at 8 bits, peak at codes
    127 and 128) on the normalised axis ``u = z / z_max``: the same weight for
    the same share of the range at every depth. The hat of the declared depth
    peaks at ``floor(z_max / 2)``, 0.4 % of its height away from this one at 16
    bits, enough to give the same information stored deeper (``z · 257``) a
    different curve. Identical to ``hat_weight(z, 8)`` at 8 bits (the scale is 1.0).

    >>> bool(np.array_equal(_hat_u(np.arange(256.0), 8), hat_weight(np.arange(256.0), 8)))
    True
    """
    zmax = 2 ** bit_depth - 1
    z = np.asarray(z, dtype=np.float64)
    return np.clip(np.minimum(z, zmax - z) * (255 / zmax) / 127.0, 0.0, 1.0)


def _noise_ratio(gk, lne, z, w, lnt, noise, n_knots, bit_depth, step):
    """Mean weighted noise variance of ``ln X`` per observation with the data's
    own rounding (``step`` codes) over the same with 8-bit rounding
    (``z_max/255`` codes): ``Σ w² (a X + b + q) / X²`` each; ≤ 1, and 1 for
    8-bit data stored deeper."""
    a, b = noise
    ii, jj = np.nonzero(w > 0)
    x = np.exp(lne[ii] + lnt[jj])
    k0, _ = knot_basis(z[ii, jj], n_knots, bit_depth)
    ex = np.exp(gk)
    zmax = 2 ** bit_depth - 1
    dxdz = (ex[k0 + 1] - ex[k0]) * ((n_knots - 1) / zmax)
    w2 = w[ii, jj] ** 2 / x ** 2
    v = np.maximum(a * x + b, 0.0)
    num = np.sum(w2 * (v + (dxdz * step) ** 2 / 12))
    den = np.sum(w2 * (v + (dxdz * (zmax / 255)) ** 2 / 12))
    return float(min(num / den, 1.0)) if den > 0 else 1.0


def _binned8(zc, lnt, clip_margin, n_knots, bit_depth):
    """:class:`_Reduced` of the same observations read at 8-bit resolution
    (``round(z · 255 / z_max)``), on at most 256 knots: the problem λ is
    chosen on at every depth."""
    z8 = np.rint(zc * (255 / (2 ** bit_depth - 1))).astype(np.int64)
    try:
        return _Reduced(z8, lnt, data_weight(z8, 8, clip_margin), min(n_knots, 256), 8)
    except np.linalg.LinAlgError:
        from lumigraph.capture.errors import EstimationError

        raise EstimationError("images", "too few pixels are well exposed in two exposures at "
                                        "8-bit resolution to choose λ; give smoothness") from None


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
    try:
        rho, eta = red.curve(grid)
        rows = [(float(lam), math.log(r), math.log(max(e, 1e-300)))
                for lam, r, e in zip(grid, rho, eta, strict=True)]
    except np.linalg.LinAlgError:
        rows = []
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
    wu = red.w  # the used pixels' row weights: the ends count as little as in the fit
    resid = (_g_at(gk, red.z, red.k, red.bd) - lne[:, None] - lnt[None]) * wu
    if np.sqrt((resid ** 2).sum() / max(float((wu ** 2).sum()), 1e-300)) <= 0.1:
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


def _noise_bins(gk, lne, z, w, lnt, n_knots, bit_depth, edges=None, code_step=1):
    """Per bin of ``ln X`` (log-spaced quantiles of the observations unless
    ``edges`` given): robust residual variance (median of the squared
    residuals over the χ²₁ median 0.455), median quantisation variance
    ``(code_step · dX/dz)²/12``, median ``X`` and count. The fit's own error at a code
    (largest at the ends before the bias correction) is common to every
    observation of that code and is removed first, keeping the scatter."""
    ii, jj = np.nonzero(w > 0)
    zz = z[ii, jj]
    x = np.exp(lne[ii] + lnt[jj])
    lx = np.log(x)
    e = _g_at(gk, zz, n_knots, bit_depth) - lx
    kc = np.rint(zz * (n_knots - 1) / (2 ** bit_depth - 1)).astype(np.int64)
    cnt = np.bincount(kc, minlength=n_knots)
    mean_e = np.bincount(kc, e, n_knots) / np.maximum(cnt, 1)
    r2 = (x * (e - mean_e[kc])) ** 2 * (cnt[kc] / np.maximum(cnt[kc] - 1, 1))
    step = (2 ** bit_depth - 1) / (n_knots - 1)  # codes per knot cell
    k0, _ = knot_basis(zz, n_knots, bit_depth)
    ex = np.exp(gk)
    quant = ((ex[k0 + 1] - ex[k0]) * (code_step / step)) ** 2 / 12.0
    if edges is None:
        nb = int(min(12, max(4, ii.size // 50)))
        edges = np.quantile(lx, np.linspace(0, 1, nb + 1))
    nb = edges.size - 1
    b = np.clip(np.searchsorted(edges, lx, side="right") - 1, 0, nb - 1)
    out = np.full((4, nb), np.nan)
    cnt_b = np.bincount(b, minlength=nb)
    out[3] = cnt_b
    start = np.concatenate([[0], np.cumsum(cnt_b)[:-1]])
    lo_i, hi_i = start + (cnt_b - 1) // 2, start + cnt_b // 2
    good = cnt_b >= 10
    for row, v in enumerate((r2, quant, x)):  # per-bin medians from one sort each
        # (one float key: bin + value scaled into [0, 1), so the bins stay apart)
        sv = v[np.argsort(b + v / (2.0 * max(float(v.max()), 1e-300)))]
        out[row, good] = 0.5 * (sv[lo_i[good]] + sv[hi_i[good]])
    out[0] /= 0.455
    return out, edges


def _fit_ab(var, quant, xm):
    """``a, b >= 0`` of ``var − quant ≈ a X + b``, each bin relative (NNLS)."""
    from scipy.optimize import nnls

    ok = np.isfinite(var) & np.isfinite(xm)
    if np.count_nonzero(ok) < 2:
        return 0.0, 0.0
    v, q, x = var[ok] - quant[ok], quant[ok], xm[ok]
    sd = np.maximum(np.maximum(v, q), 1e-30)
    coef = nnls(np.stack([x / sd, 1.0 / sd], axis=1), np.maximum(v, 0.0) / sd)[0]
    return float(coef[0]), float(coef[1])


def estimate_noise(gk, lne, z, w, lnt, n_knots, bit_depth, *, wfun=None, rng=None, rounds=4,
                   code_step=1):
    """Sensor noise of the bracket, from a fit's own residuals.

    Model (in the fit's relative exposure units ``X = exp g``): an
    observation's exposure scatters with variance ``a X + b`` (shot noise
    ``a``, read noise ``b``) before quantisation, which adds ``(dX/dz)²/12``.
    The residuals' robust variance per bin of ``X`` (:func:`_noise_bins`)
    gives a first ``a, b`` (non-negative least squares). That statistic is
    not the noise variance where the noise meets the floor at code 0 or the
    top code, or where a pixel has few exposures (its ``ln E`` follows its
    own noise): so, with ``wfun`` (the fit's weight function) and ``rng``,
    the bracket the fit describes is rendered at the current ``a, b``, the
    same statistic taken on it, and each bin's ratio of statistic to true
    variance divides the observed one before ``a, b`` are refitted
    (``rounds`` times; indirect inference). ``code_step``: the spacing of the
    codes the data can take (:func:`code_step`; 257 for 8-bit data stored as
    ``z · 257``), which sets the quantisation both in the statistic and in the
    render.

    Returns ``(a, b)``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> k = np.arange(256.0); gk = np.log(np.maximum(k, 0.5) / 255)
    >>> x = np.exp(rng.uniform(-5, -0.2, 4000)); lnt = np.zeros(1)
    >>> z = np.clip(np.round(255 * (x + rng.normal(0, np.sqrt(1e-4 * x + 1e-6)))), 0, 255)
    >>> a, b = estimate_noise(gk, np.log(x), z[:, None].astype(int), np.ones((4000, 1)), lnt, 256, 8)
    >>> bool(0.5e-4 < a < 2e-4)
    True
    """
    if np.count_nonzero(w > 0) < 20:
        return 0.0, 0.0
    obs, edges = _noise_bins(gk, lne, z, w, lnt, n_knots, bit_depth, code_step=code_step)
    a, b = _fit_ab(obs[0], obs[1], obs[2])
    if wfun is None or rng is None or rounds <= 0 or z.shape[1] < 2:
        return a, b
    gm = _monotone(gk, np.ones_like(gk))
    codes, gc, cut = _code_ladder(gm, n_knots, bit_depth, code_step)
    x = np.exp(lne[:, None] + lnt[None])
    for _ in range(rounds):
        zs = codes[np.searchsorted(cut, x + np.sqrt(np.maximum(a * x + b, 0.0))
                                   * rng.standard_normal(x.shape))]
        ws = wfun(zs)
        w2 = ws ** 2
        keep = np.count_nonzero(ws > 0, axis=1) >= 2
        if np.count_nonzero(keep) < 10:
            break
        lne_s = (np.sum(w2 * (gc[zs // code_step] - lnt[None]), axis=1) / np.maximum(w2.sum(axis=1), 1e-300))
        sim, _ = _noise_bins(gk, lne_s[keep], zs[keep], ws[keep], lnt, n_knots, bit_depth,
                             edges, code_step)
        true = a * sim[2] + b + sim[1]
        ratio = sim[0] / np.maximum(true, 1e-300)
        ok = np.isfinite(ratio) & (ratio > 0.05)
        if np.count_nonzero(ok) < 2:
            break
        corr = np.where(ok, obs[0] / np.where(ok, ratio, 1.0), np.nan)
        a_new, b_new = _fit_ab(corr, obs[1], obs[2])
        # Stop when both settle to 2 % (the mid-range variance alone settles
        # before the read noise does: stopping on it cost the night kind 0.034 -> 0.043).
        settled = (abs(a_new - a) <= 0.02 * max(a_new, 1e-30)
                   and abs(b_new - b) <= 0.02 * max(b_new, 1e-30))
        a, b = a_new, b_new
        if settled:
            break
    return a, b


def code_step(z: np.ndarray) -> int:
    """The spacing of the codes the data can take: the greatest common divisor
    of the codes seen (1 for any real 12- or 16-bit capture; 257 for 8-bit data
    stored as ``z · 257``, 16 for 12-bit data shifted left by 4). The noise
    model and the bias correction quantise to it, so the same information
    stored at a finer declared depth is modelled as what it is.

    >>> code_step(np.array([0, 257, 514, 65535])), code_step(np.array([3, 5])), code_step(np.zeros(3, int))
    (257, 1, 1)
    """
    return max(int(np.gcd.reduce(np.asarray(z, dtype=np.int64).ravel())), 1)


def _code_ladder(gm, n_knots, bit_depth, step):
    """``(codes, g at them, X where the code steps up)`` for the codes
    ``0, step, 2·step, … ≤ z_max`` of a monotone knot curve ``gm``."""
    codes = np.arange(0, 2 ** bit_depth, step, dtype=np.int64)
    gc = _g_at(gm, codes, n_knots, bit_depth)
    return codes, gc, np.exp(0.5 * (gc[1:] + gc[:-1]))


def _debias(gk, lne, zc, wfun, lnt, noise, lam, n_knots, bit_depth, rng, draws, step=1):
    """Parametric-bootstrap bias of the fit at ``lam``: render the bracket
    the fit describes (exposures ``E_i Δt_j`` of the used pixels, the noise
    ``a X + b`` before the response, the response ``exp g`` quantised and
    clipped at 0 and ``z_max`` exactly as a camera does), fit it the same
    way (``draws`` renders stacked as more pixels), and return the refit's
    difference from the fit of the same render without noise: what the
    noise does to the estimator.

    Near the ends of the code range this bias is what the noise and the
    clipping do to eq. 6.5 (the code a dark exposure gives is not ``f`` of
    its mean: shot and read noise, the rounding and the floor at 0 shift
    it); subtracting it is the first-order bias-corrected estimator.
    """
    a, b = noise
    gm = _monotone(gk, np.ones_like(gk))
    codes, _, edges = _code_ladder(gm, n_knots, bit_depth, step)  # X where the code steps up
    x = np.exp(lne[:, None] + lnt[None])
    sd = np.sqrt(np.maximum(a * x + b, 0.0))
    # The draws stacked as more pixels: one system whose solution is the refit of
    # all draws at once (the same as averaging single-draw refits to first order,
    # at a fraction of the cost).
    xn = np.tile(x, (draws, 1)) + np.tile(sd, (draws, 1)) * rng.standard_normal(
        (draws * x.shape[0], x.shape[1]))
    zs = codes[np.searchsorted(edges, xn)]
    red = _Reduced(zs, lnt, wfun(zs), n_knots, bit_depth)
    # The reference is the same render without noise, fitted the same way: what
    # the refit does to the fit's own wiggles (smoothing them) is then not
    # counted as bias, else the correction adds the fit's noise back (bench,
    # tuned kinds: room 0.0035 -> 0.0027, studio 0.0024 -> 0.0015).
    z0 = codes[np.searchsorted(edges, x)]
    ref = _Reduced(z0, lnt, wfun(z0), n_knots, bit_depth).fit(lam)[0]
    return red.fit(lam)[0] - ref


def _monotone(gk, counts):
    from scipy.optimize import isotonic_regression

    res = isotonic_regression(gk, weights=counts + 1.0, increasing=True)
    return np.asarray(res.x, dtype=np.float64)


def response_debevec1997(images: np.ndarray, exposure_times_s, *, bit_depth: int | None = None,
            smoothness: float | str = "auto", samples: int = 600, knots: int | None = None,
            clip_margin: float = 0.0, noise: tuple[float, float] | None = None,
            bias_draws: int = 2, rng: np.random.Generator | None = None) -> ResponseCurve:
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
        Unknowns per channel; default ``min(2**bit_depth, DEFAULT_KNOTS)``.
    clip_margin : float
        Fraction of the code range at each end left out of the fit
        (:func:`data_weight`); default 0 (the bias correction handles the ends).
    noise : (full_well_e, read_noise_e), optional
        The sensor's noise (electrons at the top code, read noise RMS); by
        default estimated from the bracket (:func:`estimate_noise`).
    bias_draws : int
        Renders of the fitted bracket for the bias correction (:func:`_debias`);
        0 turns it off.
    rng : numpy.random.Generator, optional
        For the pixel sampling's tie-breaking (default seeded 0).

    Returns
    -------
    ResponseCurve
        ``method="debevec"``; ``selection`` holds λ and every candidate's
        L-curve point; ``fit`` the residual RMS (plain and robust), the
        sample count, the noise (``a, b`` per channel, its source, the
        relative noise at mid-range) and the bias correction.

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
    if noise is not None:
        from lumigraph.hdr.merge import check_noise

        if len(noise) != 2:
            raise InputError("noise", f"expected (full_well_e, read_noise_e), got {noise!r}")
        noise = check_noise("variance", *noise)  # InputError naming the bad one
    rng = np.random.default_rng(0) if rng is None else rng
    n_knots = int(knots) if knots is not None else min(2 ** bd, DEFAULT_KNOTS)
    if not 4 <= n_knots <= 2 ** bd:
        raise ValueError(f"knots: expected 4..{2 ** bd}, got {knots}")
    # Sample first, then order the small sample by time: reordering (or
    # reshaping a non-contiguous) stack would copy every frame.
    idx = sample_pixels(z, n=samples, bit_depth=bd, rng=rng)
    order = np.argsort(t)
    t = t[order]
    lnt = np.log(t)
    warnings: list[str] = []
    if idx.size * (p - 1) < n_knots:
        warnings.append(f"only {idx.size} usable pixels for {n_knots} unknowns per channel: "
                        "the curve leans on the smoothness term")
    zs = z[:, idx // w_, idx % w_][order]  # (P, N, C)
    step = code_step(zs)
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
    robust_rms, noise_ab, bias_max, rel_noise, noise_top = [], [], [], [], []
    noise_src = ""
    lam8, ratio = [], []  # above 8 bits: the 8-bit-resolution corner and the noise ratio
    all_codes = np.arange(2 ** bd)
    for ch in range(c):
        zc = zs[..., ch].T.astype(np.int64)  # (N, P)
        wc = data_weight(zc, bd, clip_margin)
        try:
            red = _Reduced(zc, lnt, wc, n_knots, bd)
        except np.linalg.LinAlgError:
            raise EstimationError("images", f"channel {ch}: too few pixels are well exposed in "
                                            "two exposures") from None
        # λ is chosen on the problem read at 8-bit resolution at every depth
        # (the codes rounded to steps of z_max/255, the same knots on the same
        # u = z/z_max axis, where one λ means the same smoothing): the L-curve's
        # corner moves with the quantisation noise, so a deeper file of the same
        # scene got a smaller λ and a rougher curve (studio, same pixels: 6e-7 at
        # 8 bits, 2-3e-7 deeper). With λ fixed the deeper codes only refine the
        # data term (docs/decisions/hdr-debevec-noise.md, "seventh pass").
        sel = red if bd <= 8 else _binned8(zc, lnt, clip_margin, n_knots, bd)
        if len(grid) > 1:
            lam_ch, cand = _l_curve(sel, grid)
            if lam_ch == grid[-1] or lam_ch == grid[0]:
                warnings.append(f"channel {ch}: λ = {lam_ch:g} is at the end of the searched "
                                "range: the data are very noisy or too few; the curve is mostly "
                                "the prior" if lam_ch == grid[-1] else
                                f"channel {ch}: λ = {lam_ch:g} is the smallest searched")
        else:
            lam_ch = grid[0]
            cand = [{"lambda": lam_ch}]
        if len(grid) > 1:
            lam_ch = _discrepancy(sel, cand, lam_ch, lnt, sel.w)
        scores[str(ch)] = cand
        try:
            gk, lne, _, _ = red.fit(lam_ch)
            keep = np.count_nonzero(wc > 0, axis=1) >= 2
            zc, wc = zc[keep], wc[keep]
        except np.linalg.LinAlgError:
            raise EstimationError("images", f"channel {ch}: the response system is singular "
                                            "(too few distinct codes; use a larger λ)") from None
        if noise is None:
            nz = estimate_noise(gk, lne, zc, wc, lnt, n_knots, bd, rng=rng, code_step=step,
                                wfun=lambda zz: data_weight(zz, bd, clip_margin))
            noise_src = "estimated from the bracket (robust residual variance a X + b)"
        else:
            xs = math.exp(float(gk[-1]))  # the top code: the full well, in the fit's units
            nz = (xs / noise[0], (xs * noise[1] / noise[0]) ** 2)
            noise_src = "given (full_well_e, read_noise_e)"
        if bd > 8 and len(grid) > 1:
            # The 8-bit λ carried over in proportion to the noise per observation:
            # λ weighs roughness against the mean squared residual, whose noise
            # part here lacks the 8-bit rounding the λ was chosen with.
            lam8.append(lam_ch)
            ratio.append(_noise_ratio(gk, lne, zc, wc, lnt, nz, n_knots, bd, step))
            lam_ch *= ratio[-1]
            gk, lne, _, _ = red.fit(lam_ch)
        resid = (_g_at(gk, zc, n_knots, bd) - lne[:, None] - lnt[None]) * (wc > 0)
        fit_rms.append(float(np.sqrt((resid ** 2).sum() / max((wc > 0).sum(), 1))))
        robust_rms.append(float(1.4826 * np.median(np.abs(resid[wc > 0]))))
        noise_ab.append(nz)
        # the same model with X relative to the top code's exposure (X_sat = 1), the unit
        # of a curve normalised at the top code (Mitsunaga-Nayar's bias correction uses it)
        xs = math.exp(float(gk[-1]))
        noise_top.append((nz[0] / xs, nz[1] / xs ** 2))
        if bias_draws > 0:
            try:
                g_obs, g_cur = gk, gk
                for _ in range(BIAS_ROUNDS):
                    bias = _debias(g_cur, lne, zc, lambda zz: data_weight(zz, bd, clip_margin),
                                   lnt, nz, lam_ch, n_knots, bd, rng, bias_draws, step)
                    g_cur = g_obs - bias
                bias_max.append(float(np.max(np.abs(bias))))
                gk = g_cur
            except np.linalg.LinAlgError:
                warnings.append(f"channel {ch}: the bias correction's refit was singular; the "
                                "curve is not bias-corrected")
        # Only pixels seen well exposed in two exposures link codes to each other
        # (well: hat >= 0.2, the middle 80 % of the codes; the low-weight ends
        # cannot pin a curve); where few knots are linked, the smoothness prior
        # draws the curve.
        lo, hi = int(0.05 * (n_knots - 1)), int(0.95 * (n_knots - 1))
        well = hat_weight(zc, bd) >= 0.2
        two = np.count_nonzero(well, axis=1) >= 2
        linked = np.zeros(n_knots, bool)
        linked[knot_basis(zc[two][well[two]], n_knots, bd)[0]] = True
        coverage = float(linked[lo:hi + 1].mean())
        n_two = int(np.count_nonzero(two))
        linked_px.append(n_two)
        if coverage < 0.6 or n_two < 50:
            warnings.append(f"channel {ch}: only {n_two} pixels are well exposed in two "
                            f"exposures, covering {100 * coverage:.0f} % of the code range: the "
                            "curve is poorly constrained (exposures too far apart or too few)")
        # Heavy noise: judged from the noise model at mid-range (robust: film grain,
        # misregistered edges and moving pixels in a few observations do not count).
        xm = math.exp(float(_g_at(gk, np.array([2 ** (bd - 1)]), n_knots, bd)[0]))
        rel_noise.append(math.sqrt(max(nz[0] * xm + nz[1], 0.0)) / xm)
        # What the noise does to the curve: per knot, the relative noise over the
        # root of the observations a knot gets; "heavy" when that reaches 2 %
        # (several percent once the ends' fewer observations are counted).
        per_knot = rel_noise[-1] / math.sqrt(max(np.count_nonzero(wc > 0) / n_knots, 1.0))
        if per_knot > HEAVY_NOISE:
            warnings.append(f"channel {ch}: heavy noise ({rel_noise[-1]:.2f} relative at "
                            f"mid-range, estimated from the bracket; {per_knot:.3f} ln per "
                            "knot): expect response errors of several percent; average frames, "
                            "add exposures or sample more pixels")
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
    if lam8:
        sel["rule"] += ("; above 8 bits: the corner of the codes read at 8-bit resolution, "
                        "times the noise variance per observation at the data's rounding over "
                        "that at 8-bit rounding")
        sel["lambda_8bit"], sel["noise_ratio"] = lam8, ratio
    fit = {"samples": int(idx.size), "code_step": step, "residual_rms_ln": fit_rms,
           "residual_robust_rms_ln": robust_rms, "linked_pixels": linked_px,
           "monotone_max_change_ln": monotone_fix,
           "noise": {"model": "Var X = a X + b (X = exp g, relative exposure) + quantisation",
                     "a_b": [list(v) for v in noise_ab], "source": noise_src,
                     "a_b_top": [list(v) for v in noise_top],
                     "relative_at_mid": rel_noise},
           "bias_correction": {"draws": int(bias_draws), "max_abs_ln": bias_max}}
    times = tuple(float(x) for x in np.asarray(exposure_times_s, dtype=np.float64))
    return ResponseCurve("debevec", bd, normalise_g(g_out), times, sel, tuple(warnings), fit)
