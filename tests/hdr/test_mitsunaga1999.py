"""Mitsunaga-Nayar's building blocks (issue 13): the constrained solve, the
monotone constraints, the responsive code range, static pixels, the power gauge."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import lumigraph.hdr.mitsunaga1999 as mn
from lumigraph.hdr.mitsunaga1999 import (
    align_power,
    constrained_lstsq,
    evaluate,
    is_monotone,
    monotone_constraints,
    responsive_range,
    static_pixels,
)


def _active_set_optimum(a, b, g, h):
    """The exact constrained least squares by enumerating active sets (KKT of each,
    feasible ones compared): a reference with no solver tolerance in it."""
    n, best = a.shape[1], None
    for k in range(n + 1):
        for act in itertools.combinations(range(g.shape[0]), k):
            act = list(act)
            kkt = np.zeros((n + k, n + k))
            kkt[:n, :n] = 2 * a.T @ a
            kkt[:n, n:], kkt[n:, :n] = -g[act].T, g[act]
            try:
                x = np.linalg.solve(kkt, np.concatenate([2 * a.T @ b, h[act]]))[:n]
            except np.linalg.LinAlgError:
                continue
            if np.all(g @ x >= h - 1e-12) and (best is None or
                                                np.sum((a @ x - b) ** 2) < np.sum((a @ best - b) ** 2)):
                best = x
    return best


def test_constrained_lstsq_is_the_constrained_optimum():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(40, 4))
    b = rng.normal(size=40)
    g = rng.normal(size=(6, 4))
    h = g @ rng.normal(size=4) + 0.5  # feasible, and the free optimum violates some rows
    x = constrained_lstsq(a, b, g, h)
    assert np.all(g @ x >= h - 1e-9)
    ref = _active_set_optimum(a, b, g, h)
    assert np.any(g @ ref - h < 1e-9)  # a constraint is active: the case is not the free one
    # (an SLSQP reference, used before, stops a hair outside the constraints at a lower cost
    # with scipy 1.17.) Double precision of a 40x4 problem: 1e-9 relative.
    np.testing.assert_allclose(x, ref, rtol=1e-9, atol=1e-9)


def test_infeasible_constraints_raise_linalgerror():
    with pytest.raises(np.linalg.LinAlgError):
        constrained_lstsq(np.eye(2), np.zeros(2), np.array([[1.0, 0.0], [-1.0, 0.0]]),
                          np.array([1.0, 0.0]))


def test_a_curve_solved_under_the_monotone_constraints_is_monotone():
    # data that pull an order-6 polynomial into a dip: the constrained fit may not dip
    m = np.linspace(0.05, 0.95, 200)
    target = m ** 2 + 0.08 * np.sin(12 * m)  # not monotone near m = 0.4 and 0.9
    from lumigraph.hdr.mitsunaga1999 import basis

    bas = basis(m, 6)
    g, h = monotone_constraints((0.05, 0.95), 6, 255)
    free = np.linalg.lstsq(bas, target - 1.0, rcond=None)[0]
    assert not is_monotone(free, (0.05, 0.95), 255)
    a = constrained_lstsq(bas, target - 1.0, g, h)
    assert is_monotone(a, (0.05, 0.95), 255)
    assert evaluate(a, np.array([0.05]))[0] > 0


def test_responsive_range_finds_a_film_base_and_a_shoulder():
    # codes = 20 + 215 * min(x, 1): a base at 20 that no exposure moves, saturation at 235
    rng = np.random.default_rng(1)
    e = np.exp(rng.uniform(-6, 1, 3000))
    t = 2.0 ** np.arange(6)
    zs = np.stack([np.round(20 + 215 * np.minimum(e * ti / 8, 1.0)) for ti in t])[..., None] / 255
    lo, hi = responsive_range(zs, t, 255)
    # the base (20) and the code just above it move by less than 2 codes per doubling
    assert 20 / 255 < lo[0] <= 24 / 255
    assert hi[0] <= 235 / 255


def test_static_pixels_are_the_ones_that_ignore_two_stops():
    t = np.array([1.0, 2.0, 4.0, 8.0])
    moving = np.array([0.1, 0.2, 0.4, 0.8])
    still = np.full(4, 0.3)
    one_stop = np.array([0.3, 0.3, 0.99, 0.99])  # unclipped over one stop only
    zs = np.stack([moving, still, one_stop], axis=1)[..., None]
    assert static_pixels(zs, t, 0.03).tolist() == [False, True, False]


def test_power_gauge_without_with_one_and_with_two_references():
    ln_true = np.log([0.01, 0.04, 0.16, 0.64])
    data = 0.7 * ln_true + 0.3  # what the data fix: ln e up to a power and an offset
    rough = ln_true + np.array([0.05, -0.08, 0.02, 0.06])
    _, free = align_power(data, rough)
    _, one = align_power(data, rough, reference={1: ln_true[1]})
    _, two = align_power(data, rough, reference={0: ln_true[0], 3: ln_true[3]})
    assert one[1] == pytest.approx(ln_true[1], abs=1e-12)
    assert np.allclose(two, ln_true, atol=1e-12)  # two references remove the ambiguity
    assert not np.allclose(free, ln_true, atol=1e-3)


def test_ratio_of_sums_is_unbiased_where_an_ln_average_is_not():
    # Read noise a third of the signal at the dark end: E[ln x] = ln X - Var/2X^2
    # biases an ln-domain ratio by per cents; a ratio of linear sums is unbiased.
    # Tolerances: 4 of the estimate's own sandwich sd.
    rng = np.random.default_rng(3)
    x = rng.uniform(0.03, 0.3, 400_000)
    sd = 0.01
    xa = x + rng.normal(0, sd, x.size)
    xb = 4.0 * x + rng.normal(0, sd, x.size)
    v = np.full(x.size, sd ** 2)
    ln_r, var, n = mn.ratio_of_sums(xa, xb, var_a=v, var_b=v)
    assert abs(ln_r - np.log(4.0)) < 4 * np.sqrt(var)
    ok = (xa > 0) & (xb > 0)
    ln_avg = float(np.mean(np.log(xb[ok]) - np.log(xa[ok])))
    # the ln average's predicted bias, Var/2X^2 averaged (darker exposure dominates)
    predicted = float(np.mean(sd ** 2 / (2 * x ** 2) - sd ** 2 / (2 * (4 * x) ** 2)))
    assert ln_avg - np.log(4.0) > predicted / 2 > 10 * np.sqrt(var)


def _linear_sensor_bracket():
    """A 12-bit linear sensor, 4 exposures two stops apart of a scene spread evenly
    in log over 2.7 decades; read noise 30 % of the darkest exposures' signal.
    Returns ``(z, ln_e, zmax, a, b)``, ``Var x = a x + b``."""
    rng = np.random.default_rng(5)
    p, h, w = 4, 200, 300
    scene = np.exp(rng.uniform(np.log(0.002), np.log(1.0), (h, w)))
    ln_e = np.log([0.05, 0.2, 0.8, 3.2])
    zmax = 4095
    a, b = 1e-4, 1e-6
    z = np.empty((p, h, w, 1), np.uint16)
    for q in range(p):
        x = scene * np.exp(ln_e[q])
        x = x + rng.normal(0, 1, x.shape) * np.sqrt(a * np.minimum(x, 2) + b)
        z[q, ..., 0] = np.clip(np.rint(np.clip(x, 0, 1) * zmax), 0, zmax)
    return z, ln_e, zmax, a, b


def test_refine_exposures_with_the_true_curve_recovers_the_ratios():
    # A linear sensor, read noise 30 % of the darkest exposures' signal, the true
    # curve given: every adjacent ratio within 4 of its reported sd.
    z, ln_e, zmax, a, b = _linear_sensor_bracket()
    lf = np.log(np.maximum(np.arange(zmax + 1), 0.5) / zmax)
    le, rec = mn.refine_exposures(z, [lf], ln_e + [0.0, 0.03, -0.02, 0.0], np.array([0.01]),
                                  np.array([0.99]), [(a, b)], zmax)
    err = np.diff(le) - np.diff(ln_e)
    sds = np.array(rec["sd_ln_adjacent"])
    assert np.all(np.abs(err) < 4 * sds), (err, sds)


def test_refine_exposures_corrects_a_curve_wrong_at_the_dark_codes():
    # The scene and sensor above; the curve given 10 % high (ln) at code 0, falling as a
    # square to 0 at 15 % of the range: a fitted curve's dark-end error, overdone. The
    # linear sums read through it are biased beyond 4 of the sd that includes the
    # correction's own uncertainty; with the binned sums' correction the ratios (power
    # fixed by the two end exposures, as --reference-time twice does) are within it.
    z, ln_e, zmax, a, b = _linear_sensor_bracket()
    p = ln_e.size
    k = np.arange(zmax + 1)
    lf = np.log(np.maximum(k, 0.5) / zmax) + 0.10 * np.clip(1 - k / (0.15 * zmax), 0, None) ** 2
    errs = {}
    for correct in (False, True):
        le, rec = mn.refine_exposures(z, [lf], ln_e, np.array([0.01]), np.array([0.99]),
                                      [(a, b)], zmax, correct_curve=correct)
        le = align_power(le, ln_e, reference={0: ln_e[0], p - 1: ln_e[-1]})[1]
        errs[correct] = np.abs(np.diff(le) - np.diff(ln_e))
    sd_free = np.array(rec["curve_correction"]["sd_ln_adjacent_curve_free"])
    assert np.any(errs[False] > 4 * sd_free), (errs[False], sd_free)
    assert np.all(errs[True] < 4 * sd_free), (errs[True], sd_free)


def test_refine_exposures_held_at_two_references():
    # The same wrong curve, with the end exposures known exactly and given to the solve
    # (as --reference-time twice does): the correction's power is then the data's, the
    # exposures are held at the references exactly, and the ratios are within 4 of the
    # sd that includes the correction's own uncertainty.
    z, ln_e, zmax, a, b = _linear_sensor_bracket()
    p = ln_e.size
    k = np.arange(zmax + 1)
    lf = np.log(np.maximum(k, 0.5) / zmax) + 0.10 * np.clip(1 - k / (0.15 * zmax), 0, None) ** 2
    ref = {0: float(ln_e[0]), p - 1: float(ln_e[-1])}
    le, rec = mn.refine_exposures(z, [lf], ln_e + [0.0, 0.03, -0.02, 0.0], np.array([0.01]),
                                  np.array([0.99]), [(a, b)], zmax, reference=ref)
    assert rec["curve_correction"]["used"]
    assert le[0] == pytest.approx(ln_e[0], abs=1e-12) and le[-1] == pytest.approx(ln_e[-1], abs=1e-12)
    sd_free = np.array(rec["curve_correction"]["sd_ln_adjacent_curve_free"])
    err = np.abs(np.diff(le) - np.diff(ln_e))
    assert np.all(err < 4 * sd_free), (err, sd_free)
