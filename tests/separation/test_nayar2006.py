"""Closed forms and estimators on synthetic stacks with exact direct/global."""

import numpy as np
import pytest

from lumigraph.capture.patterns import checker_set, sinusoid_set
from lumigraph.separation import nayar2006, separate


@pytest.mark.parametrize("alpha,b", [(0.5, 0.0), (0.5, 0.15), (0.3, 0.0), (0.7, 0.2), (0.5, 0.6)])
def test_b_corrected_pair_inverts_the_model(alpha, b):
    rng = np.random.default_rng(1)
    d, g = rng.uniform(0, 1, 50), rng.uniform(0, 1, 50)
    ap, am = b + (1 - b) * alpha, b + (1 - b) * (1 - alpha)
    lp, lm = d + ap * g, b * d + am * g  # pattern and complement (eqs. 8.13-8.14 with b)
    sd, sg = nayar2006.solve(lp, lm, alpha=alpha, b=b)
    np.testing.assert_allclose(sd, d, atol=2e-6)
    np.testing.assert_allclose(sg, g, atol=2e-6)


def test_uncorrected_formulas_are_wrong_when_b_is_not_zero():
    d, g, b = 0.6, 0.3, 0.15
    lp, lm = d + (1 + b) / 2 * g, b * d + (1 + b) / 2 * g
    sd, _ = nayar2006.solve(np.array([lp]), np.array([lm]), b=0.0)
    assert abs(sd[0] - d) > 0.05


def _checker_stack(d, g, sigma, rng, b=0.0):
    ps = checker_set((32, 32), square=4, shifts=4)  # 16 shifts + 16 complements
    ims = np.stack([d * (b + (1 - b) * p) + (1 + b) / 2 * g for p in ps.images])
    return (ims + rng.normal(0, sigma, ims.shape))[..., None].astype(np.float32), ps


def test_pairs_estimator_is_unbiased_where_maxmin_is_not():
    rng = np.random.default_rng(2)
    d, g, sigma = 0.5, 0.2, 0.03
    ims, ps = _checker_stack(d, g, sigma, rng)
    pairs = separate(ims, method="checker", complement_of=ps.complement_of, estimator="pairs")
    tb = separate(ims, method="checker", complement_of=ps.complement_of, estimator="maxmin")
    # interior pixels only (away from square edges the pattern is exact here)
    # max of 16 normal samples is ~ +1.77 sigma, the min ~ -1.77 sigma:
    # max/min global = 2 L- is biased by about -3.5 sigma = -0.106.
    assert abs(tb.global_.mean() - g) > 2.5 * sigma
    # pairs: unbiased; the standard error of the mean over 1024 pixels is tiny,
    # so 0.5 sigma bounds any bias with a wide margin.
    assert abs(pairs.global_.mean() - g) < 0.5 * sigma
    assert abs(pairs.direct.mean() - d) < 0.5 * sigma
    err_p = np.abs(pairs.global_ - g).mean()
    err_t = np.abs(tb.global_ - g).mean()
    assert 0 < err_p < 0.5 * err_t


def test_sinusoid_exact_and_single_on_a_smooth_scene():
    ps = sinusoid_set((64, 64), period=8)
    x = np.linspace(0, 1, 64)
    d = (0.4 + 0.3 * x)[None, :] * np.ones((64, 1))
    g = (0.2 + 0.1 * x)[:, None] * np.ones((1, 64))
    ims = np.stack([d * p + 0.5 * g for p in ps.images])[..., None].astype(np.float32)
    s = separate(ims, method="sinusoid")
    np.testing.assert_allclose(s.direct[..., 0], d, atol=1e-5)
    np.testing.assert_allclose(s.global_[..., 0], g, atol=1e-5)
    stripe = (np.arange(64) % 4 < 2).astype(float)[None, :]
    one = (d * stripe + 0.5 * g)[None, ..., None].astype(np.float32)
    r = separate(one, method="single", tile=8)
    # the scene changes by at most 0.3/64*8 = 0.04 across a tile: errors stay below that
    inner = (slice(8, -8), slice(8, -8))
    assert 0 < np.abs(r.direct[..., 0] - d)[inner].mean() < 0.04
    assert 0 < np.abs(r.global_[..., 0] - g)[inner].mean() < 0.04


def test_occluder_and_black_level():
    rng = np.random.default_rng(3)
    d, g = rng.uniform(0.3, 0.8, (8, 8)), rng.uniform(0.1, 0.3, (8, 8))
    n = 6
    frames = np.stack([d + (1 - 1 / n) * g] * n)
    for k in range(n):
        frames[k, :, k::n] = (1 - 1 / n) * g[:, k::n]
    s = separate(frames[..., None].astype(np.float32), method="occluder")
    np.testing.assert_allclose(s.direct[..., 0], d, atol=1e-5)
    np.testing.assert_allclose(s.global_[..., 0], g, atol=1e-5)
    white = d + g
    assert abs(nayar2006.black_level(0.2 * white, white, floor=1e-4) - 0.2) < 1e-6


def test_bad_arguments():
    ims = np.ones((2, 4, 4, 1), np.float32)
    with pytest.raises(ValueError, match="needs at least 3"):
        separate(ims, method="sinusoid")
    with pytest.raises(ValueError, match="alpha"):
        separate(ims, method="checker", alpha=1.0)
    with pytest.raises(ValueError, match="all-dark"):
        separate(np.zeros((2, 4, 4, 1), np.float32), method="checker", quant_step=1 / 255)
    with pytest.raises(ValueError, match="method"):
        separate(ims, method="nope")


def test_one_registry_drives_dispatch_help_and_image_counts(run_cli):
    from lumigraph.capture.errors import InputError
    from lumigraph.capture.registry import Registry
    from lumigraph.separation import METHODS, MIN_IMAGES

    assert isinstance(METHODS, Registry) and set(MIN_IMAGES) == set(METHODS.names)
    with pytest.raises(InputError) as e:
        separate(np.ones((2, 4, 4, 1), np.float32), method="nope")
    assert e.value.where == "method" and "checker" in e.value.problem
    r = run_cli("separate", "--help")
    assert r.returncode == 0
    for m in METHODS.values():
        assert m.help in r.stdout
