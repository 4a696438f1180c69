"""The blurred X-junction fit (calib/rohr1992.py) on corners with exact ground truth.

An exact corner: two straight lines through a known centre at known,
non-orthogonal angles, the product of their sides convolved with a Gaussian
of known sigma, its bivariate normal probabilities from scipy (not the
module's quadrature), at the pixel centres; level and contrast unequal so a
swapped axis, a flipped sign or a transposed centre cannot fit. Bounds come
from the injected noise through the fit's own Cramér-Rao covariance."""

import numpy as np
import pytest

from lumigraph.calib import rohr1992 as R


def _exact(shape, c, a1, a2, sigma, level=117.0, contrast=-83.0):
    """The blurred junction at every pixel centre: level + contrast * F."""
    from scipy.stats import multivariate_normal, norm

    h_, w_ = shape
    y, x = np.mgrid[0:h_, 0:w_].astype(float)
    n1, n2 = np.array([np.cos(a1), np.sin(a1)]), np.array([np.cos(a2), np.sin(a2)])
    h = (n1[0] * (x - c[0]) + n1[1] * (y - c[1])) / sigma
    k = (n2[0] * (x - c[0]) + n2[1] * (y - c[1])) / sigma
    rho = float(n1 @ n2)
    p2 = multivariate_normal(mean=[0, 0], cov=[[1, rho], [rho, 1]]).cdf(np.column_stack([h.ravel(), k.ravel()]))
    F = 4 * p2.reshape(shape) - 2 * norm.cdf(h) - 2 * norm.cdf(k) + 1
    return level + contrast * F


CASES = [  # centre, line angles (rad), blur sigma (px)
    ((10.37, 9.81), np.radians(20.0), np.radians(95.0), 0.9),
    ((9.62, 10.28), np.radians(-35.0), np.radians(70.0), 0.7),
]


def _crlb(shape, c, a1, a2, sigma, noise, radius):
    """Standard deviations of the fitted centre (x, y) for iid noise of sd
    ``noise``: sigma^2 (J^T J)^-1 of the model's pixels in the window, J by
    central differences of the exact image in all 7 parameters."""
    base = np.round(c).astype(int)
    y, x = np.mgrid[0:shape[0], 0:shape[1]]
    win = (x - base[0]) ** 2 + (y - base[1]) ** 2 <= (radius + 0.5) ** 2
    args = [117.0, -83.0, c[0], c[1], a1, a2, sigma]
    cols = []
    for i, step in enumerate((1e-3, 1e-3, 1e-4, 1e-4, 1e-5, 1e-5, 1e-5)):
        lo, hi = list(args), list(args)
        lo[i] -= step
        hi[i] += step

        def img(a):
            return _exact(shape, (a[2], a[3]), a[4], a[5], a[6], a[0], a[1])[win]
        cols.append((img(hi) - img(lo)) / (2 * step))
    J = np.column_stack(cols)
    cov = noise ** 2 * np.linalg.inv(J.T @ J)
    return np.sqrt(np.diag(cov)[2:4])


@pytest.mark.parametrize("case", CASES)
def test_exact_corner_without_noise(case):
    c, a1, a2, sigma = case
    img = _exact((21, 21), c, a1, a2, sigma).astype(np.float32)
    start = np.array([c]) + (0.31, -0.22)
    f = R.fit_corners(img, start, radius=4)
    assert f.ok[0]
    # the fit stops on a step below 1e-4 px; the image is the model itself
    assert np.abs(f.points[0] - c).max() < 1e-3, f.points[0] - c
    assert abs(f.blur[0] - sigma) < 1e-3 and abs(f.contrast[0] - 83.0) < 1e-2


@pytest.mark.parametrize("case", CASES)
def test_exact_corner_with_noise_within_its_crlb(case):
    c, a1, a2, sigma = case
    noise, radius = 2.0, 4
    clean = _exact((21, 21), c, a1, a2, sigma)
    sd = _crlb((21, 21), c, a1, a2, sigma, noise, radius)
    rng = np.random.default_rng(7)
    errs = []
    for _ in range(8):
        img = (clean + rng.normal(0, noise, clean.shape)).astype(np.float32)
        f = R.fit_corners(img, np.array([c]) + rng.uniform(-0.3, 0.3, 2), radius=radius)
        assert f.ok[0]
        errs.append(f.points[0] - c)
    e = np.array(errs)
    # each draw within 4 of its standard deviations, and no bias: the mean of 8
    # within 4 standard errors
    assert np.all(np.abs(e) <= 4 * sd), (e, sd)
    assert np.all(np.abs(e.mean(axis=0)) <= 4 * sd / np.sqrt(len(e))), (e.mean(axis=0), sd)


def test_box_sampled_corners_sharper_than_cornersubpix_and_unbiased():
    """Corners rendered as the boards scene renders them (each pixel's box
    average, 16x16 samples, then a Gaussian blur of 0.6 px and 1 code of read
    noise), random centres and angles: the fit's errors are smaller than
    cornerSubPix's on the same images, and their mean is within 3 standard
    errors of zero."""
    import cv2

    rng = np.random.default_rng(3)
    ss, n = 16, 40
    off = (np.arange(ss) + 0.5) / ss - 0.5
    grid = (np.arange(25)[:, None] + off).ravel()
    X, Y = np.meshgrid(grid, grid)
    fit_e, csp_e = [], []
    for _ in range(n):
        c = 12 + rng.uniform(-0.5, 0.5, 2)
        a1 = rng.uniform(0, np.pi)
        a2 = a1 + np.pi / 2 + rng.uniform(-0.6, 0.6)  # the tilted board's skewed squares
        sgn = (np.sign(np.cos(a1) * (X - c[0]) + np.sin(a1) * (Y - c[1]))
               * np.sign(np.cos(a2) * (X - c[0]) + np.sin(a2) * (Y - c[1])))
        rad = (120 + 95 * sgn).reshape(25, ss, 25, ss).mean(axis=(1, 3)).astype(np.float32)
        img = np.clip(np.round(cv2.GaussianBlur(rad, (0, 0), 0.6) + rng.normal(0, 1, rad.shape)), 0, 255)
        img = img.astype(np.uint8)
        start = c + rng.uniform(-0.3, 0.3, 2)
        f = R.fit_corners(img, start[None], radius=4)
        assert f.ok[0]
        fit_e.append(f.points[0] - c)
        cs = cv2.cornerSubPix(img, start[None, None].astype(np.float32), (4, 4), (-1, -1), (3, 40, 1e-3))
        csp_e.append(cs.reshape(2) - c)
    fe, ce = np.array(fit_e), np.array(csp_e)
    rms_f, rms_c = np.sqrt((fe ** 2).sum(1).mean()), np.sqrt((ce ** 2).sum(1).mean())
    assert rms_f < rms_c, (rms_f, rms_c)
    assert np.all(np.abs(fe.mean(axis=0)) <= 3 * fe.std(axis=0) / np.sqrt(n)), fe.mean(axis=0)


def test_no_junction_falls_back_to_the_start():
    """A straight edge (no second line) and a window of too few usable pixels
    are not fitted: the start point comes back and ok is False."""
    import cv2

    y, x = np.mgrid[0:21, 0:21].astype(float)
    edge = cv2.GaussianBlur((120 + 90 * np.sign(x - 10.3)).astype(np.float32), (0, 0), 0.8)
    flat_but_junction = _exact((21, 21), (10.3, 9.8), 0.3, 1.9, 0.8).astype(np.float32)
    start = np.array([[10.0, 10.0]])
    f = R.fit_corners(edge, start, radius=4)
    assert not f.ok[0] and np.array_equal(f.points, start)
    valid = np.zeros((21, 21), bool)
    valid[:2] = True  # the window holds none of these rows
    g = R.fit_corners(flat_but_junction, start, radius=4, valid=valid)
    assert not g.ok[0] and np.array_equal(g.points, start)


def test_phi2_matches_scipy():
    from scipy.stats import multivariate_normal

    for rho in (-0.9, -0.4, 0.0, 0.5, 0.94):
        hk = np.array([[0.0, 0.0], [1.0, -0.5], [-2.0, 1.5], [0.3, 0.2], [3.0, 3.0]])
        ref = multivariate_normal(mean=[0, 0], cov=[[1, rho], [rho, 1]]).cdf(hk)
        got = R._phi2(hk[:, 0][None], hk[:, 1][None], np.array([[rho]]))[0]
        # the integrand is evaluated in float32 (relative rounding 6e-8 over 12 nodes)
        assert np.abs(got - ref).max() < 1e-5, (rho, got - ref)
