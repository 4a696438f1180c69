"""Refocusing on torch's CPU device equals the numpy result within float32
rounding: shift-and-add (every kernel, both border rules) and Fourier slice.
The bounds are derived from the arithmetic below, not measured."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("kornia")

from lumigraph.lightfield import ng2005  # noqa: E402
from lumigraph.lightfield.field import LightField  # noqa: E402
from lumigraph.lightfield.refocus import (  # noqa: E402
    KERNELS,
    _taps,
    focal_stack,
    refocus,
    shift_and_add,
)
from lumigraph.lightfield.refocus_torch import shift_and_add_stack_torch  # noqa: E402

U32 = 2.0 ** -24  # float32 unit roundoff


def _lf(shape, seed=0):
    return LightField(np.random.default_rng(seed).random(shape).astype(np.float32))


def _shift_add_bound(kernel: str, n_views: int, m: float) -> float:
    """|torch - numpy| for shift-and-add. Per view both compute the same
    float32 products with the same weights; an x pass then a y pass each sum
    T taps (error <= T u S M per pass, S = the largest sum of |weights| over
    the fractions, M = max |input|; the first pass's output is at most S M).
    The views are then summed (numpy in order, torch by its own reduction:
    <= N u of the sum's magnitude N S^2 M) and divided by N (u). Both sides
    carry these errors, hence the factor 2."""
    t = len(_taps(kernel, 0.5)[1])
    s = max(np.abs(_taps(kernel, f)[1]).sum() for f in np.linspace(0, 1, 65))
    if kernel == "bspline3":
        # both sides interpolate the same prefiltered coefficients (scipy, on
        # the host): at most 3 M per axis, the l1 norm of the inverse of the
        # filter (1, 4, 1) / 6 (its taps alternate in sign, so it is the gain
        # at Nyquist, 1 / |1/6 - 4/6 + 1/6|)
        m = 9.0 * m
    return 2 * (2 * t + n_views + 1) * U32 * s * s * m


@pytest.mark.parametrize("kernel", KERNELS)
def test_shift_and_add_matches_numpy(kernel):
    # 5x4 views (even V: half-integer offsets), H != W; slopes with
    # fractional, integer and negative shifts; one so large that the numpy
    # code switches to edge padding for the outer views (pad >= min(H, W)).
    lf = _lf((5, 4, 14, 19, 3))
    slopes = [0.0, 0.37, -1.0, -0.81, 2.5, 6.0]
    got = shift_and_add_stack_torch(lf, slopes, kernel=kernel, device="torch-cpu")
    for k, s in enumerate(slopes):
        want = shift_and_add(lf, s, kernel=kernel)
        bound = _shift_add_bound(kernel, 20, float(np.abs(lf.data).max()))
        assert np.abs(got[k] - want).max() <= bound, (kernel, s)


def _fourier_bound(spec_geom, lf) -> float:
    """Relative L2 error ||torch - numpy|| / ||numpy|| of a Fourier slice.
    A radix FFT of length n has a normwise relative error <= log2(n) eta,
    eta = u + 4 u (sqrt 2 + u) ~ 6.7 u (Higham, Accuracy and Stability of
    Numerical Algorithms, 2nd ed., Thm 24.2); the forward and the inverse
    2-D FFT: 2 x 6.7 u (log2 Hp + log2 Wp). The angular DFTs are complex
    inner products of U and V terms (<= 4 (U + V) u normwise, columns of the
    zero-padded DFT being orthogonal); the slice sums 2 aliases x k taps per
    axis (<= 4 (2 k) u), each weighted by at most the roll-off correction's
    largest gain G (the views are divided by the kernel's transform, the taps
    of the Kaiser-Bessel kernel sum to about its transform at 0). Both sides
    carry it: factor 2."""
    pad, hp, wp, nu, nv = spec_geom
    u, v = lf.grid
    k = 5
    osr = min(nu / u, nv / v)
    beta = math.pi * math.sqrt(max((k / osr) ** 2 * (osr - 0.5) ** 2 - 0.8, 1.0))
    pu = np.arange(u) - (u - 1) / 2
    hat = ng2005._kb_hat(np.r_[0.0, pu / nu], k, beta)
    gain = float(hat[0] / hat[1:].min()) ** 2
    eta = 6.7 * U32
    return 2 * gain * (2 * eta * (math.log2(hp) + math.log2(wp)) + 4 * (u + v) * U32
                       + 4 * 2 * k * U32 * 2)


@pytest.mark.parametrize("shape", [(3, 3, 16, 21, 1), (4, 5, 22, 17, 3)])
def test_fourier_slice_matches_numpy(shape):
    lf = _lf(shape, seed=3)
    slopes = [0.0, 0.45, -1.2]
    got = focal_stack(lf, slopes, method="fourier", device="torch-cpu", max_slope=1.5)
    want = focal_stack(lf, slopes, method="fourier", max_slope=1.5)
    bound = _fourier_bound(ng2005._geometry(lf, 1.5, 1.5, 5), lf)
    for k in range(len(slopes)):
        rel = np.linalg.norm(got[k] - want[k]) / np.linalg.norm(want[k])
        assert rel <= bound, (slopes[k], rel, bound)


def test_refocus_routes_the_device():
    lf = _lf((3, 3, 9, 11, 1), seed=5)
    a = refocus(lf, 0.3, device="torch-cpu")
    b = refocus(lf, 0.3)
    assert a.shape == b.shape == (9, 11, 1)
    assert np.abs(a - b).max() <= _shift_add_bound("lanczos3", 9, 1.0)


def test_cpu_device_is_the_numpy_code():
    lf = _lf((3, 3, 9, 11, 1), seed=5)
    assert np.array_equal(focal_stack(lf, [0.3], device="cpu"), focal_stack(lf, [0.3]))
