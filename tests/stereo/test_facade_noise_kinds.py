"""Hand marks and automatic marking's proposals solved together
(stereo/debevec1996/solve.py, ``separate_noise``): each kind's endpoint
noise is estimated (Helmert's variance components) and the marks weighted
by it. The bench's house (a tuning scene), four hand marks per photograph
at σ = 0.5 px and every other visible edge as a proposal at σ = 0.15 px
(about what the detector's proposals show), 40 noise draws."""

from __future__ import annotations

import numpy as np
import pytest

from lumigraph.stereo import bench_facade as BF
from lumigraph.stereo.debevec1996.edges import EdgeMarks
from lumigraph.stereo.debevec1996.solve import solve_facade

HAND, PROPOSED, DRAWS = 0.5, 0.15, 40


def _noisy_marks(model, cams, exact, rng, *, shift_px=0.0):
    """Four hand marks per photograph at HAND px, every other visible edge
    a proposal at PROPOSED px; the first proposal moved ``shift_px`` across
    its edge. Returns the marks and that proposal's (photo, edge)."""
    ph, first = {}, None
    for p, v in exact.items():
        hand = {h["edge"] for h in BF.four_hand_marks(model, v)}
        ph[p] = []
        for m in v:
            seg = np.array(m["segment"]) + rng.normal(0, HAND if m["edge"] in hand else PROPOSED, 4)
            e = {"edge": m["edge"]}
            if m["edge"] not in hand:
                e["proposed"] = True
                if first is None:
                    d = seg[2:] - seg[:2]
                    seg += np.tile(np.array([-d[1], d[0]]) / np.hypot(*d) * shift_px, 2)
                    first = (p, m["edge"])
            e["segment"] = seg.tolist()
            ph[p].append(e)
    return EdgeMarks.from_dict({"photographs": ph}, model=model, photographs=list(cams)), first


@pytest.fixture(scope="module")
def draws():
    model, cams = BF.scene("house", 1)
    exact, _ = BF._marks(model, cams, noise=0.0)
    tv = model.named_values()
    out = {False: ([], []), True: ([], [])}
    kinds = []
    for d in range(DRAWS):
        marks, _ = _noisy_marks(model, cams, exact, np.random.default_rng(d))
        for sep in (False, True):
            sol = solve_facade(model, marks, BF._K(cams), noise_px=HAND, separate_noise=sep)
            out[sep][0].append([sol.params[n] - tv[n] for n in model.parameter_names])
            out[sep][1].append([sol.std[n] for n in model.parameter_names])
            if sep:
                kinds.append([sol.sigma_px_by_kind["hand"], sol.sigma_px_by_kind["proposed"]])
            else:
                assert sol.sigma_px_by_kind == {}
    return out, np.array(kinds)


def test_each_kinds_noise_is_estimated(draws):
    _, kinds = draws
    # one draw's estimate rests on ~2 residuals a mark less the fit's share:
    # relative sd ~1/sqrt(2 dof), 0.05 px for the 32 hand marks, 0.008 px
    # for the 110 proposals; the mean of 40 within ~5 sd of it
    assert kinds[:, 0].mean() == pytest.approx(HAND, abs=0.04)
    assert kinds[:, 1].mean() == pytest.approx(PROPOSED, abs=0.006)


def test_sigma_holds_and_error_falls(draws):
    out, _ = draws
    E, S = (np.array(a) for a in out[True])
    keep = np.mean(S, 0) > 0                                 # free parameters
    ratio = np.sqrt(np.mean(E[:, keep] ** 2, 0)) / np.mean(S[:, keep], 0)
    # the bench's σ criterion; 40 draws measure an RMS to ~11 %
    assert 0.67 <= ratio.min() and ratio.max() <= 1.5, ratio
    # weights that follow each kind's noise are the better estimator
    # (Gauss-Markov): a lower error than one pooled noise over the same draws
    Ep = np.array(out[False][0])
    assert np.sqrt(np.mean(E[:, keep] ** 2)) < np.sqrt(np.mean(Ep[:, keep] ** 2))


def test_too_few_of_a_kind_pool_one_noise():
    # fewer than VARIANCE_COMPONENTS_MIN_MARKS proposals: one noise, as before
    from lumigraph.stereo.debevec1996.solve import VARIANCE_COMPONENTS_MIN_MARKS

    model, cams = BF.scene("house", 1)
    exact, _ = BF._marks(model, cams, noise=0.0)
    rng = np.random.default_rng(0)
    ph, left = {}, VARIANCE_COMPONENTS_MIN_MARKS - 1
    for p, v in exact.items():
        ph[p] = []
        for m in v:
            e = {"edge": m["edge"], "segment": (np.array(m["segment"])
                                                + rng.normal(0, HAND, 4)).tolist()}
            if left:
                e["proposed"], left = True, left - 1
            ph[p].append(e)
    marks = EdgeMarks.from_dict({"photographs": ph}, model=model, photographs=list(cams))
    sep = solve_facade(model, marks, BF._K(cams), noise_px=HAND)
    pooled = solve_facade(model, marks, BF._K(cams), noise_px=HAND, separate_noise=False)
    assert sep.sigma_px_by_kind == {}
    assert sep.params == pooled.params and sep.sigma_px == pooled.sigma_px


def test_deleted_residuals_measure_a_proposal_by_its_kinds_noise():
    # the marking page's "marks to check": a proposal 1.2 px off (eight
    # times the proposals' 0.15 px, two and a half times the hand marks'
    # 0.5 px) stands out when judged by its own kind's noise
    from lumigraph.stereo.debevec1996.automark import deleted_residuals

    model, cams = BF.scene("house", 1)
    exact, _ = BF._marks(model, cams, noise=0.0)
    marks, bad = _noisy_marks(model, cams, exact, np.random.default_rng(7), shift_px=1.2)
    sol = solve_facade(model, marks, BF._K(cams), noise_px=HAND, robust=False)
    t = deleted_residuals(sol, marks.marks)
    i = [(m.photo, m.edge) for m in marks.marks].index(bad)
    others = np.delete(t, i)
    # ~1 for a mark as good as its kind (a chi statistic with 2 dof: median 0.83)
    assert 0.6 < np.median(others) < 1.2
    assert t[i] > 4 and t[i] == np.max(t)


@pytest.mark.parametrize("shift_px", [0.0, 1.2])
def test_automatic_marking_drops_the_contradicted_proposal_and_only_it(shift_px):
    # automatic marking's last step: the proposal the other marks contradict
    # beyond 3 of its kind's σ goes. On noise alone a proposal's score passes
    # 3 with probability e^-9 (χ²₂/2), ~1.7 % for all 110 together: none goes
    from lumigraph.stereo.debevec1996.automark import _contradicted

    model, cams = BF.scene("house", 1)
    exact, _ = BF._marks(model, cams, noise=0.0)
    marks, bad = _noisy_marks(model, cams, exact, np.random.default_rng(7), shift_px=shift_px)
    sol = solve_facade(model, marks, BF._K(cams), noise_px=HAND, hold_unconstrained=True)
    mine = {(m.photo, m.edge) for m in marks.marks if m.proposed}
    key, alt = _contradicted(model, marks, BF._K(cams), sol, rough=model, trust=0.3,
                             candidates=mine, noise_px=HAND)
    if shift_px:
        assert key == bad
        assert len(alt.mark_rms_px) == len(marks.marks) - 1
    else:
        assert key is None and alt is sol
    # proposals the user accepted earlier (marks given to automatic marking) are not its to drop
    key, alt = _contradicted(model, marks, BF._K(cams), sol, rough=model, trust=0.3,
                             candidates=set(), noise_px=HAND)
    assert key is None and alt is sol


def test_marks_noisier_than_the_noise_given_are_said():
    # hand marks at 0.5 px said to be at 0.5 px: within the χ² 0.1 % limit (a
    # false alarm one solve in a thousand); said to be at 0.3 px: the hand
    # kind is beyond it, the proposals (0.15 px) are not
    model, cams = BF.scene("house", 1)
    exact, _ = BF._marks(model, cams, noise=0.0)
    marks, _ = _noisy_marks(model, cams, exact, np.random.default_rng(3))

    def said(noise):
        sol = solve_facade(model, marks, BF._K(cams), noise_px=noise)
        return [w for w in sol.warnings if "beyond the" in w]

    assert said(HAND) == []
    got = said(0.3)
    assert len(got) == 1 and got[0].startswith("hand marks fit at") and "0.3 px" in got[0]


def test_a_group_far_more_precise_than_the_rest_still_gets_its_own_noise():
    # 30 marks at 0.5 px and 20 at 0.02 px, 12 unknowns: the hand marks'
    # noise leaking into the precise ones' residuals explains them, and
    # Helmert's component for the precise group comes out at or below zero
    # in about half the draws. Pooling one noise then weighed them as the
    # hand marks (precise proposals among hand marks, the rendered
    # building); their own residuals bound their variance from above
    import lumigraph.stereo.debevec1996.solve as S

    none, ratio = 0, []
    for seed in range(100):
        rng = np.random.default_rng(seed)
        groups = np.r_[np.zeros(30, int), np.ones(20, int)]
        X = rng.normal(size=(100, 12))
        noise = rng.normal(size=(50, 2)) * np.where(groups, 0.02, 0.5)[:, None]
        e = (noise.ravel() - X @ np.linalg.lstsq(X, noise.ravel(), rcond=None)[0]).reshape(-1, 2)
        W = np.repeat(np.eye(2)[None], 50, 0)
        S._OWN_RESIDUALS_BOUND = False
        try:
            failed = S.group_variances(X, W, e, groups) is None
        finally:
            S._OWN_RESIDUALS_BOUND = True
        none += failed
        s = np.sqrt(S.group_variances(X, W, e, groups))
        # where Helmert failed, the bound: never below the truth; always
        # well below the other group's
        assert 0 < s[1] < s[0] / 2 and (s[1] >= 0.02 or not failed), s
        ratio.append(s[0] / 0.5)
    assert none >= 20                       # the premise: Helmert alone fails often
    # the imprecise group's estimate is Helmert's: ~60 residuals less the
    # fit's share, relative sd ~0.1 a draw; the mean of 100 within 0.05
    assert np.mean(ratio) == pytest.approx(1.0, abs=0.05)
