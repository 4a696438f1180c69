"""The bench's deep-vs-8-bit check (issue 13, "12- and 16-bit <= the 8-bit
figure"): the paired per-scene ratio and its standard error, on synthetic
numbers, and the check built from bench rows."""

import math

import numpy as np

from lumigraph.capture.bench import Results, Row
from lumigraph.hdr.bench import (
    PAIRED_SE_TARGET,
    PAIRED_SEEDS,
    TUNED_RATIO_SD,
    _family_checks,
    _family_name,
    paired_ratio,
    seeds_for_se,
)


def test_paired_ratio_pairs_by_seed_and_reports_mean_se_median_worst():
    deep = {3: 0.9, 0: 1.6, 7: 4.0, 1: 0.5}  # seed 7 has no 8-bit partner: ignored
    base = {0: 2.0, 1: 1.0, 3: 1.0, 5: 1.0}
    r = paired_ratio(deep, base)
    ratios = np.array([0.8, 0.5, 0.9])  # seeds 0, 1, 3
    assert r.n == 3
    assert math.isclose(r.mean, ratios.mean())
    assert math.isclose(r.se, ratios.std(ddof=1) / math.sqrt(3))
    assert math.isclose(r.median, 0.8)
    assert (r.worst, r.worst_seed) == (0.9, 3)
    assert math.isclose(r.figures, np.median([1.6, 0.5, 0.9]) / np.median([2.0, 1.0, 1.0]))


def test_paired_ratio_se_is_the_scatter_of_the_mean_over_draws():
    # Ratios drawn with a known per-scene sd: the mean of se² over many draws is
    # sd²/n (s² is unbiased), within 4 standard errors of that average
    # (Var s² = 2 sd⁴/(n-1) for normal draws).
    rng = np.random.default_rng(0)
    n, sd, draws = len(PAIRED_SEEDS), TUNED_RATIO_SD, 2000
    se2 = []
    for _ in range(draws):
        r = 0.9 + sd * rng.standard_normal(n)
        se2.append(paired_ratio(dict(enumerate(r)), dict.fromkeys(range(n), 1.0)).se ** 2)
    rel = math.sqrt(2 / (n - 1) / draws)
    assert abs(np.mean(se2) / (sd ** 2 / n) - 1) <= 4 * rel


def test_the_chosen_seed_count_is_the_smallest_meeting_the_se_target():
    n = seeds_for_se(TUNED_RATIO_SD, PAIRED_SE_TARGET)
    assert len(PAIRED_SEEDS) == n
    assert TUNED_RATIO_SD / math.sqrt(n) <= PAIRED_SE_TARGET < TUNED_RATIO_SD / math.sqrt(n - 1)
    assert seeds_for_se(0.1, 0.05) == 4  # exact squares are not rounded up


def _row(case, errors):
    seeds = list(range(len(errors)))
    return Row("hdr", case, "debevec (ours)", None, "", None, 0.0, (0.0,),
               float(np.median(errors[:3])), "ok",
               {"worst": max(errors[:3]), "paired_seeds": seeds, "paired_errors": errors})


def test_the_deep_check_passes_on_the_paired_mean_where_the_3_seed_median_fails():
    # 8-bit error 1.0 on every seed; deep: seeds 0-2 unlucky (ratio 1.05, the
    # 3-seed median figure fails), the other 21 at 0.9: the mean ratio 0.919 <= 1.
    n = len(PAIRED_SEEDS)
    deep = [1.05] * 3 + [0.9] * (n - 3)
    rows = [_row(_family_name("room", 8), [1.0] * n), _row(_family_name("room", 12), deep)]
    (c,) = [c for c in _family_checks(Results(rows)) if "12-bit" in c.target]
    assert c.passed and math.isclose(c.measured, np.mean(deep)) and c.reference == 1.0
    assert "[tuned]" in c.target and f"over {n} scene seeds" in c.target
    assert "worst 1.050 (seed 0)" in c.detail
    # and a deep error above the 8-bit one on average fails
    rows[1] = _row(_family_name("room", 12), [1.02] * n)
    (c,) = [c for c in _family_checks(Results(rows)) if "12-bit" in c.target]
    assert not c.passed
