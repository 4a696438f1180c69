"""Corner refinement by fitting a blurred X-junction model to the pixels.

Follows K. Rohr, "Recognizing corners by fitting parametric models",
IJCV 9(3):213-230, 1992 (doi:10.1007/BF00133702): a corner's grey values are
modelled as an ideal junction of straight edges convolved with a Gaussian, and
its position is found by least squares on the pixels of a small window (Rohr
fits wedges and vertices; here the checkerboard's X-junction: two straight
lines through the corner, at free angles since a tilted board's squares are
not right-angled in the image). The model's equation is below (the
equation numbers of the paper are not quoted: the model here is its own).

Model of a pixel centred at ``x`` (OpenCV's convention: pixel centres at
integers, ``x = (col, row)``)::

    I(x) = a + b * F(h, k, rho)
    h = n1 . (x - c) / s,  k = n2 . (x - c) / s,  n_i = (cos alpha_i, sin alpha_i),
    rho = n1 . n2,  F = 4 Phi2(h, k; rho) - 2 Phi(h) - 2 Phi(k) + 1

``F`` is the product of the two edges' signs, sign(n1.(x-c)) sign(n2.(x-c)),
convolved with an isotropic Gaussian of standard deviation ``s``
(``Phi2`` the bivariate normal distribution, since ``n1.z`` and ``n2.z`` of a
Gaussian ``z`` are normal with correlation ``rho``). ``s`` stands for the
optics' blur and the pixel's box together: the box's projection onto any
direction has variance 1/12 px^2, so ``s^2 = sigma^2 + 1/12`` matches both
second moments along every edge; ``s`` is fitted per corner. What the
Gaussian misses of the box's shape is even about each edge; it moves a corner
only through the sampling's sub-pixel phase (noise-free, axis-aligned: up to
0.02 px at a 0.6 px blur, 0.008 px at 1.0, no mean over phases;
docs/decisions/charuco-marker-removal.md). ``a, b`` (level, contrast) are
free per corner.

``Phi2`` is evaluated by Drezner & Wesolowsky's integral (J. Statist. Comput.
Simul. 35:101-107, 1990; written out in :func:`_phi2_integral`) with
Gauss-Legendre nodes; its derivatives are
closed-form (``dPhi2/dh = phi(h) Phi((k - rho h)/sqrt(1 - rho^2))``,
``dPhi2/drho`` the bivariate density), so each Levenberg-Marquardt step needs
one model evaluation, for all corners of an image at once (arrays of
corners x window pixels, 7x7 normal equations solved batched).

The model is point-symmetric about ``c`` like the blurred, box-sampled image
of a real X-junction, and it is evaluated at the pixel centres (no
interpolation of the image), so the fit has neither of ``cornerSubPix``'s
biases (bilinear resampling of a sub-pixel-sharp edge, the window's lean
toward where more gradient falls inside it).

Units: pixels; ``alpha`` radians; images in any grey unit (the fit's
residual is reported in it).

Examples
--------
>>> import numpy as np
>>> y, x = np.mgrid[0:15, 0:15].astype(float)
>>> box = lambda t: np.clip(2 * t, -1, 1)  # a step's mean over the pixel's box
>>> img = 128 - 100 * box(x - 7.3) * box(y - 6.8)  # an X-junction at (7.3, 6.8)
>>> import cv2
>>> img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 1.0)
>>> f = fit_corners(img, np.array([[7.0, 7.0]]), radius=4)
>>> bool(f.ok[0]), bool(np.abs(f.points[0] - (7.3, 6.8)).max() < 0.01)
(True, True)
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

# Gauss-Legendre nodes for Phi2's integral over [0, asin rho]: the integrand is smooth
# for |rho| <= MAX_ABS_RHO, where 6 nodes reach 2e-6 (8: 2e-7; test_rohr1992.py checks
# 1e-5 against scipy), i.e. 1e-3 codes of a 100-code contrast
_NODES = 6
# a fit that ends with the lines closer than this (|cos| of their angle) is no X-junction
MAX_ABS_RHO = 0.95
# moved farther than this from its start: the fit found something else (fall back)
MAX_MOVE_PX = 0.5
# converged: a centre step below this (px), a tenth of the fitted corners' own scatter
# (>= 0.01 px on the rendered boards, docs/decisions/charuco-marker-removal.md)
STEP_TOL_PX = 1e-3
# the fit has 7 parameters: a window with fewer than twice as many usable pixels is not fitted
MIN_PIXELS = 14
# a fit whose residual RMS exceeds this many times the median corner's fails: the RMS of
# P >= MIN_PIXELS residuals of iid noise varies by at most 1/sqrt(2 * 7) = 19 % (relative
# sd), so 4x the typical corner's is not noise but something the model lacks (an
# occlusion, an unmasked marker, no X-junction)
RESIDUAL_GATE = 4.0


@dataclass(frozen=True)
class CornerFit:
    """Fitted X-junctions.

    Attributes
    ----------
    points : ndarray, (N, 2) float64
        Fitted centres ``(x, y)`` px; the start point where ``ok`` is False.
    ok : ndarray, (N,) bool
        The window had ``MIN_PIXELS`` usable pixels, the fit converged within
        ``iterations``, kept its lines apart (``|rho| < MAX_ABS_RHO``), moved
        less than ``max_move`` px, its blur stayed in (0.05, radius) px and its
        residual within ``RESIDUAL_GATE`` times the median corner's.
    blur : ndarray, (N,) float64
        Fitted ``s`` (blur and pixel box together), px.
    contrast : ndarray, (N,) float64
        ``|b|``, half the step between the squares, grey units.
    rms : ndarray, (N,) float64
        Residual RMS over the window, grey units.
    iterations : int
        Levenberg-Marquardt steps taken.
    """

    points: np.ndarray
    ok: np.ndarray
    blur: np.ndarray
    contrast: np.ndarray
    rms: np.ndarray
    iterations: int


@lru_cache(maxsize=1)
def _gauss_legendre():
    t, w = np.polynomial.legendre.leggauss(_NODES)
    return 0.5 * (t + 1.0), 0.5 * w  # on [0, 1]


def _phi2_integral(hh, hk, rho):
    """Drezner & Wesolowsky's integral term of ``Phi2(h, k; rho)``:
    ``1/(2 pi) int_0^asin(rho) exp(-(h^2 + k^2 - 2 h k sin t) / (2 cos^2 t)) dt``
    from ``hh = h^2 + k^2`` and ``hk = h k`` (N, P), ``rho`` (N, 1): one
    correlation per corner, so the nodes' sines and cosines are per corner;
    the integrand in float32 (its 6e-8 relative rounding is far below the
    model's other errors)."""
    t, w = _gauss_legendre()
    A = np.arcsin(rho)  # (N, 1)
    th = A * t  # (N, Q)
    cs2 = np.cos(th) ** 2
    u = (-0.5 / cs2).astype(np.float32)[:, None, :]  # (N, 1, Q)
    v = (np.sin(th) / cs2).astype(np.float32)[:, None, :]
    integ = np.exp(hh.astype(np.float32)[..., None] * u + hk.astype(np.float32)[..., None] * v) @ w.astype(np.float32)
    return A * integ / (2.0 * np.pi)


def _phi2(h, k, rho):
    """Bivariate standard normal ``P(X < h, Y < k)`` with correlation ``rho``
    (``h, k`` (N, P), ``rho`` (N, 1)): ``Phi(h) Phi(k)`` plus
    :func:`_phi2_integral`.

    >>> z = np.zeros((1, 1))
    >>> round(float(_phi2(z, z, z + 0.5)[0, 0]), 6)  # 1/4 + asin(.5)/(2 pi)
    0.333333
    """
    from scipy.special import ndtr

    return ndtr(h) * ndtr(k) + _phi2_integral(h * h + k * k, h * k, rho)


_SQRT1_2 = np.sqrt(0.5)
_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)


def _model(p, dx, dy):
    """Model values and Jacobian. ``p`` (N, 7) = (a, b, cx, cy, alpha1,
    alpha2, s); ``dx, dy`` (N, P) pixel centres minus the window's origin
    (the corner's start). Returns ``(I (N, P), J (N, 7, P))``."""
    from scipy.special import erf

    a, b, cx, cy, a1, a2, s = (p[:, i:i + 1] for i in range(7))
    c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
    ux, uy = dx - cx, dy - cy
    h = (c1 * ux + s1 * uy) / s
    k = (c2 * ux + s2 * uy) / s
    rho = np.clip(c1 * c2 + s1 * s2, -0.999, 0.999)  # (N, 1)
    r = np.sqrt(1.0 - rho * rho)
    q = _SQRT1_2 / r
    h2, k2, hk = h * h, k * k, h * k
    # the four error functions in one call: Phi(h), Phi(k) and the conditional ones
    E = erf(np.stack([h * _SQRT1_2, k * _SQRT1_2, (k - rho * h) * q, (h - rho * k) * q]))
    Ph, Pk = 0.5 * (1.0 + E[0]), 0.5 * (1.0 + E[1])
    F = 4.0 * (Ph * Pk + _phi2_integral(h2 + k2, hk, rho)) - 2.0 * (Ph + Pk) + 1.0
    Fh = (2.0 * _INV_SQRT_2PI) * np.exp(-0.5 * h2) * E[2]
    Fk = (2.0 * _INV_SQRT_2PI) * np.exp(-0.5 * k2) * E[3]
    Fr = (2.0 / np.pi) / r * np.exp((2.0 * rho * hk - h2 - k2) / (2.0 * r * r))
    drho = s1 * c2 - c1 * s2  # d rho / d alpha2 = sin(a1 - a2) = -d rho / d alpha1
    bs = b / s
    bFr = b * drho * Fr
    J = np.empty((h.shape[0], 7, h.shape[1]))
    J[:, 0] = 1.0
    J[:, 1] = F
    J[:, 2] = -bs * (Fh * c1 + Fk * c2)
    J[:, 3] = -bs * (Fh * s1 + Fk * s2)
    J[:, 4] = bs * Fh * (c1 * uy - s1 * ux) - bFr
    J[:, 5] = bs * Fk * (c2 * uy - s2 * ux) + bFr
    J[:, 6] = -bs * (Fh * h + Fk * k)
    return a + b * F, J


def _start(img, pts, ox, oy, vals, mask, blur):
    """Starting parameters: level and contrast from the window, the lines
    orthogonal at the orientation of the second harmonic of a ring of samples
    round the corner (an X-junction is a period-pi pattern on any circle
    about it: its phase is the lines' mean direction), s = ``blur``."""
    import cv2

    n = len(pts)
    phi = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    rr = 2.0
    rx = (pts[:, 0:1] + rr * np.cos(phi)).astype(np.float32)
    ry = (pts[:, 1:2] + rr * np.sin(phi)).astype(np.float32)
    ring = cv2.remap(img, rx, ry, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
    z = (ring - ring.mean(axis=1, keepdims=True)) @ np.exp(2j * phi)
    # the ring follows cos(2 (phi - beta)): beta bisects the bright sectors, the lines lie
    # 45 deg either side of it
    beta = 0.5 * np.angle(z)
    p = np.zeros((n, 7))
    lo = np.where(mask, vals, np.inf).min(axis=1)
    hi = np.where(mask, vals, -np.inf).max(axis=1)
    p[:, 0] = 0.5 * (lo + hi)
    # with normals n1 = beta + 45, n2 = beta - 45 deg the bisector direction beta has
    # n1.u > 0 and n2.u > 0: F = +1 there, the bright side: b > 0
    p[:, 1] = 0.5 * (hi - lo)
    p[:, 2] = pts[:, 0] - ox
    p[:, 3] = pts[:, 1] - oy
    p[:, 4] = beta + np.pi / 4
    p[:, 5] = beta - np.pi / 4
    p[:, 6] = blur
    return p


def fit_corners(image: np.ndarray, points: np.ndarray, *, radius: int = 3, iterations: int = 12,
                max_move: float = MAX_MOVE_PX, valid: np.ndarray | None = None,
                blur: float = 1.0) -> CornerFit:
    """Refine X-junction corners by the blurred-junction model (module docstring).

    Parameters
    ----------
    image : ndarray, (H, W)
        Grey image (uint8 or float); pixel centres at integer ``(x, y)``.
    points : ndarray, (N, 2)
        Start positions ``(x, y)`` px, within ~0.5 px (e.g. ``cornerSubPix``'s).
    radius : int
        The window: pixels within ``radius + 0.5`` px of the rounded start
        (keep it inside the corner's squares, e.g. ``cornerSubPix``'s half-window).
    iterations : int
        Levenberg-Marquardt steps (all corners step together).
    max_move : float
        A fit that ends farther than this from its start fails (px).
    valid : ndarray, (H, W) bool, optional
        Pixels the model may use (False: something else is there, e.g. a marker).
    blur : float
        Start value of ``s`` (the optics' blur and the pixel box together), px.

    Returns
    -------
    CornerFit
        ``points`` are the start points where ``ok`` is False.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    img = np.asarray(image)
    img = img.astype(np.float32) if img.dtype != np.float32 else img
    n = len(pts)
    h, w = img.shape
    R = int(radius)
    oy_, ox_ = np.mgrid[-R:R + 1, -R:R + 1]
    disc = (ox_ ** 2 + oy_ ** 2) <= (R + 0.5) ** 2
    offx, offy = ox_[disc].astype(np.float64), oy_[disc].astype(np.float64)
    base = np.round(pts).astype(np.int64)
    X = base[:, 0:1] + offx.astype(np.int64)
    Y = base[:, 1:2] + offy.astype(np.int64)
    mask = (X >= 0) & (X < w) & (Y >= 0) & (Y < h)
    if valid is not None:
        mask &= np.asarray(valid, bool)[np.clip(Y, 0, h - 1), np.clip(X, 0, w - 1)]
    vals = img[np.clip(Y, 0, h - 1), np.clip(X, 0, w - 1)].astype(np.float64)
    wgt = mask.astype(np.float64)
    dx = np.broadcast_to(offx, X.shape)
    dy = np.broadcast_to(offy, X.shape)
    ox, oy = base[:, 0].astype(np.float64), base[:, 1].astype(np.float64)
    if n == 0:
        z = np.zeros(0)
        return CornerFit(pts.copy(), np.zeros(0, bool), z, z, z, 0)
    npx = wgt.sum(axis=1)
    enough = npx >= MIN_PIXELS
    # windows without enough pixels are not fitted (their start values only need to be finite)
    p = _start(img, pts, ox, oy, np.where(enough[:, None], vals, 0.0), mask | ~enough[:, None], float(blur))
    lam = np.full(n, 1e-3)
    model, J = _model(p, dx, dy)
    res = (vals - model) * wgt
    cost = (res * res).sum(axis=1)
    active = np.flatnonzero(enough)  # the corners still moving: converged ones drop out
    eye = np.eye(7)
    steps = 0
    while steps < iterations and active.size:
        steps += 1
        a_ = active
        Ja = J[a_]
        Jw = Ja * wgt[a_, None, :]
        A = Jw @ Ja.transpose(0, 2, 1)
        g = (Jw @ res[a_, :, None])[..., 0]
        d = np.diagonal(A, axis1=1, axis2=2)
        Ad = A + (lam[a_, None] * (d + 1e-9))[:, :, None] * eye
        step = np.linalg.solve(Ad, g[..., None])[..., 0]
        pn = p[a_] + step
        pn[:, 6] = np.abs(pn[:, 6])
        mn, Jn = _model(pn, dx[a_], dy[a_])
        rn = (vals[a_] - mn) * wgt[a_]
        cn = (rn * rn).sum(axis=1)
        better = cn < cost[a_]
        up = a_[better]
        p[up], res[up], cost[up], J[up] = pn[better], rn[better], cn[better], Jn[better]
        lam[a_] = np.where(better, lam[a_] * 0.3, lam[a_] * 10.0)
        # done: a taken step below STEP_TOL_PX (Gauss-Newton's last step overstates the
        # distance to the minimum, which it nears quadratically), or no descent left
        done = (better & (np.abs(step[:, 2:4]).max(axis=1) < STEP_TOL_PX)) | (lam[a_] > 1e4)
        active = a_[~done]
    c = np.column_stack([p[:, 2] + ox, p[:, 3] + oy])
    rho = np.cos(p[:, 4] - p[:, 5])
    rms = np.sqrt(cost / np.maximum(npx, 1))
    converged = enough.copy()
    converged[active] = False
    ok = (converged & np.all(np.isfinite(c), axis=1) & (np.abs(rho) < MAX_ABS_RHO)
          & (np.linalg.norm(c - pts, axis=1) < max_move) & (p[:, 6] > 0.05) & (p[:, 6] < R))
    if ok.any():
        ok &= rms <= RESIDUAL_GATE * np.median(rms[ok])
    out = np.where(ok[:, None], c, pts)
    return CornerFit(out, ok, np.abs(p[:, 6]), np.abs(p[:, 1]), rms, steps)
