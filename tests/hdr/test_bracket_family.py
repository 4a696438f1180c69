"""The rendered bracket family (issue 13): scene kinds, responses, splits."""

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture.render import render
from lumigraph.capture.scenes.brackets import (
    FAMILY,
    KINDS,
    RESPONSES,
    TUNED_KINDS,
    bracket_family,
    gt_log_inverse,
    kind_radiance,
    response_forward,
    response_inverse,
)
from lumigraph.hdr.merge import merge
from lumigraph.hdr.response import ResponseCurve

SIZE = (48, 36)


@pytest.mark.parametrize("resp", RESPONSES)
def test_every_response_inverts_exactly_and_its_table_increases(resp):
    y = np.linspace(0.0, 1.0, 101)
    for c in range(3):
        assert np.allclose(response_forward(response_inverse(y, resp, c), resp, c), y, atol=1e-12)
    g = gt_log_inverse(resp, 8)
    assert g.shape == (3, 256) and np.all(np.isfinite(g)) and np.all(np.diff(g, axis=1) > 0)


def test_kinds_are_different_scenes_with_positive_radiance():
    rads = {k: kind_radiance(k, *SIZE) for k in KINDS}
    for k, r in rads.items():
        assert r.shape == (SIZE[1], SIZE[0], 3) and np.all(np.isfinite(r)) and r.min() > 0, k
    for a in KINDS:
        for b in KINDS:
            if a < b:
                assert not np.allclose(rads[a], rads[b]), (a, b)
    # The night street is mostly dark: its median is far below its lights.
    night = rads["night"][..., 1]
    assert np.median(night) < 1e-3 * night.max()


def test_family_cases_cover_kinds_seeds_depths_with_a_disjoint_split():
    cases = bracket_family()
    assert len(cases) == len(KINDS) * 3 * 3
    tuned = {c.kind for c in cases if c.split == "tuned"}
    reported = {c.kind for c in cases if c.split == "reported"}
    assert tuned == set(TUNED_KINDS) and tuned.isdisjoint(reported)
    assert tuned | reported == set(KINDS) and len(reported) >= len(tuned)
    assert {c.bit_depth for c in cases} == {8, 12, 16}
    assert len({c.name for c in cases}) == len(cases)
    assert len({FAMILY[k]["response"] for k in KINDS}) == len(KINDS)  # each its own shape


@pytest.mark.parametrize("kind", [k for k in KINDS if k != "room"])
def test_family_case_renders_its_camera_with_exact_truth(kind):
    case = bracket_family(kinds=(kind,), seeds=(1,), bit_depths=(12,))[0]
    s = case.render(SIZE)
    cam = FAMILY[kind]
    assert len(s.images) == cam["exposures"] and s.images[0].dtype == np.uint16
    assert s.gt["kind"] == kind and s.gt["response"] == cam["response"]
    assert s.gt_arrays["g"].shape == (3, 4096)
    assert np.allclose(s.gt_arrays["g"], gt_log_inverse(cam["response"], 12))
    t = np.array(s.stack["exposure_times_s"])
    assert np.allclose(t[1:] / t[:-1], 2 ** cam["stops"], rtol=0.07)  # time error <= 3 % each
    assert int(np.stack(s.images).max()) <= 4095


@pytest.mark.parametrize("kind", ["walls", "night"])
def test_noise_free_family_bracket_merged_with_gt_response_reproduces_radiance(kind):
    opts = {**FAMILY[kind], "noise": 0.0, "bit_depth": 12, "kind": kind}
    s = render("bracket", size=SIZE, seed=0, **opts)
    z = np.stack(s.images)
    truth = s.gt_arrays["radiance"].astype(np.float64) * s.gt["exposure_scale"]
    m = merge(z, s.stack["exposure_times_s"], ResponseCurve("gt", 12, s.gt_arrays["g"]),
              weights="hat")
    lo, hi = int(np.ceil(0.02 * 4095)), int(0.98 * 4095)
    well = ((z > 0.05 * 4095) & (z < 0.95 * 4095)).all(axis=3).any(axis=0)
    assert well.mean() > 0.5
    rel = np.abs(m.radiance.astype(np.float64) / truth - 1)[well]
    # Quantisation only: half a code times the steepest ln f^-1 slope the merge uses.
    bound = 0.5 * float(np.max(np.diff(s.gt_arrays["g"][:, lo:hi + 1], axis=1)))
    assert rel.max() <= np.expm1(bound) * 1.01


def test_unknown_kind_exits_2(tmp_path):
    r = lumigraph("render", "bracket", "--out", tmp_path / "b", "--kind", "beach")
    assert_clean_error(r, "--kind")
