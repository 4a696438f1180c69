"""A mark's own noise (``spread_px`` in edges.json): the solver weighs each
mark by the larger of it and ``noise_px`` (``stereo/debevec1996/solve.py``).

The checks are exact equivalences of weighted least squares, not figures:
one weight for every mark changes no estimate and no σ; a mark at twice the
noise weighs as the others entered four times; and with marks of two noise
levels, each told its own, the reported σ still predicts the error.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from facade_checks import fixture_cameras, fixture_model

from lumigraph.capture.errors import InputError
from lumigraph.capture.scenes.facade_edges import project_edges
from lumigraph.stereo.debevec1996.edges import EdgeMarks
from lumigraph.stereo.debevec1996.solve import solve_facade

NOISE = 0.5


@pytest.fixture(scope="module")
def model():
    return fixture_model()


@pytest.fixture(scope="module")
def cams():
    return fixture_cameras()


def _marks(model, cams, rng, noise=NOISE):
    return EdgeMarks.from_dict({"photographs": project_edges(model, cams, noise_px=noise, rng=rng)},
                               model=model, photographs=list(cams))


def _K(cams):
    return {p: c["K"] for p, c in cams.items()}


def _with_spread(marks, spread_of):
    return replace(marks, marks=tuple(replace(m, spread_px=spread_of(i, m))
                                      for i, m in enumerate(marks.marks)))


def _close(a, b, rtol):
    return all(abs(a[n] - b[n]) <= rtol * max(abs(b[n]), 1e-12) for n in b)


def test_a_spread_at_or_below_the_noise_changes_nothing(model, cams):
    marks = _marks(model, cams, np.random.default_rng(3))
    plain = solve_facade(model, marks, _K(cams), noise_px=NOISE, robust=False)
    low = solve_facade(model, _with_spread(marks, lambda i, m: NOISE * (i % 3) / 2), _K(cams),
                       noise_px=NOISE, robust=False)
    assert plain.params == low.params and plain.std == low.std


def test_one_spread_for_every_mark_changes_no_estimate_and_no_sigma(model, cams):
    # a common weight scales the objective: the same minimum; the residual
    # scale is estimated in the marks' own units (σ̂ / 3), and the covariance,
    # σ̂² in those units times the weighted normal matrix's inverse, is the same
    marks = _marks(model, cams, np.random.default_rng(4))
    plain = solve_facade(model, marks, _K(cams), noise_px=NOISE, robust=False)
    wide = solve_facade(model, _with_spread(marks, lambda i, m: 3 * NOISE), _K(cams),
                        noise_px=NOISE, robust=False)
    assert _close(wide.params, plain.params, 1e-9)
    assert _close(wide.std, plain.std, 1e-6)
    assert wide.sigma_px == pytest.approx(plain.sigma_px / 3, rel=1e-9)


def test_a_mark_at_twice_the_noise_weighs_as_the_others_entered_four_times(model, cams):
    # eq. 5.3's weight of a mark is √(L/3) / rel, its squared error's L/3 / rel²:
    # rel = 2 on the odd marks is the even marks' errors counted four times
    marks = _marks(model, cams, np.random.default_rng(5))
    half = _with_spread(marks, lambda i, m: 2 * NOISE if i % 2 else None)
    four = replace(marks, marks=tuple(m for i, m in enumerate(marks.marks)
                                      for _ in range(1 if i % 2 else 4)))
    a = solve_facade(model, half, _K(cams), noise_px=NOISE, robust=False)
    b = solve_facade(model, four, _K(cams), noise_px=NOISE, robust=False)
    assert _close(a.params, b.params, 1e-8)


def test_marks_told_their_own_noise_have_a_sigma_that_predicts_the_error(model, cams):
    # every third mark 3 px noisy (a weak edge the image barely shows), and
    # saying so; over 40 draws each parameter's RMS error within 1.5x (and no
    # less than 0.67x) of the reported σ, the bench's band; the RMS of 40
    # Gaussian errors is within ±25 % of its σ at 3 standard errors (1/√80)
    truth = model.named_values()
    errs, stds = [], []
    for d in range(40):
        rng = np.random.default_rng(100 + d)
        clean = _marks(model, cams, rng, noise=0.0)
        noisy = tuple(replace(m, segment=m.segment + rng.normal(0, 3.0 if i % 3 == 0 else NOISE, 4),
                              spread_px=3.0 if i % 3 == 0 else None)
                      for i, m in enumerate(clean.marks))
        sol = solve_facade(model, replace(clean, marks=noisy), _K(cams), noise_px=NOISE,
                           robust=False)
        errs.append([sol.params[n] - truth[n] for n in truth if sol.std[n] > 0])
        stds.append([sol.std[n] for n in truth if sol.std[n] > 0])
    ratio = np.sqrt(np.mean(np.square(errs), 0)) / np.sqrt(np.mean(np.square(stds), 0))
    assert np.all((ratio > 0.67) & (ratio < 1.5)), ratio


def test_the_spread_round_trips_and_a_negative_one_is_refused(model):
    body = {"photographs": {"a.png": [{"edge": "house/top-front", "segment": [1, 2, 30, 2],
                                       "spread_px": 0.8},
                                      {"edge": "house/top-back", "segment": [1, 5, 30, 5]}]}}
    marks = EdgeMarks.from_dict(body, model=model, photographs=["a.png"])
    assert [m.spread_px for m in marks.marks] == [0.8, None]
    out = marks.to_dict()["photographs"]["a.png"]
    assert out[0]["spread_px"] == 0.8 and "spread_px" not in out[1]
    body["photographs"]["a.png"][0]["spread_px"] = -1
    with pytest.raises(InputError, match=r"photographs\.a\.png\[0\]\.spread_px"):
        EdgeMarks.from_dict(body, model=model, photographs=["a.png"], where="edges.json")


def test_a_scattered_mark_far_off_is_still_left_out_as_mis_marked(model, cams):
    # the spread says how well the image shows the edge, not how far off a
    # mark may be: the mis-mark test stays in pixels (5 x noise_px)
    marks = _marks(model, cams, np.random.default_rng(6))
    i = max(range(len(marks.marks)), key=lambda k: np.hypot(*(marks.marks[k].segment[2:]
                                                             - marks.marks[k].segment[:2])))
    bad = marks.marks[i]
    off = replace(bad, segment=bad.segment + np.array([0.0, 6.0, 0.0, 6.0]), spread_px=3.0)
    sol = solve_facade(model, replace(marks, marks=marks.marks[:i] + (off,) + marks.marks[i + 1:]),
                       _K(cams), noise_px=NOISE)
    assert [(p, e) for p, e, _ in sol.outliers] == [(bad.photo, bad.edge)]


def test_deleted_residuals_in_a_marks_own_noise_or_in_the_solves(model, cams):
    from lumigraph.stereo.debevec1996.automark import deleted_residuals

    # one spread for every mark: against each mark's own noise the scores are
    # the plain solve's (every σ scales together); against the solve's noise
    # (σ̂ / 3 here) a mark's disagreement counts for more
    marks = _marks(model, cams, np.random.default_rng(7))
    plain = solve_facade(model, marks, _K(cams), noise_px=NOISE, robust=False)
    wide_marks = _with_spread(marks, lambda i, m: 3 * NOISE)
    wide = solve_facade(model, wide_marks, _K(cams), noise_px=NOISE, robust=False)
    t0 = deleted_residuals(plain, marks.marks)
    own = deleted_residuals(wide, wide_marks.marks)
    solve_units = deleted_residuals(wide, wide_marks.marks, own_noise=False)
    finite = np.isfinite(t0)
    assert finite.sum() > len(t0) // 2
    np.testing.assert_allclose(own[finite], t0[finite], rtol=1e-6)
    assert np.all(solve_units[finite] > t0[finite])
