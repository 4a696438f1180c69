"""Ground truth of the ``bracket`` scenes (capture issue, family 2)."""

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture.render import render
from lumigraph.capture.scenes.brackets import gt_log_inverse, response_forward, response_inverse
from lumigraph.hdr.merge import merge
from lumigraph.hdr.response import ResponseCurve


def test_noise_free_bracket_merged_with_gt_response_reproduces_gt_radiance():
    s = render("bracket", noise=0.0, bit_depth=12)
    z = np.stack(s.images)
    t = s.stack["exposure_times_s"]
    truth = s.gt_arrays["radiance"].astype(np.float64) * s.gt["exposure_scale"]
    m = merge(z, t, ResponseCurve("gt", 12, s.gt_arrays["g"]), weights="hat")
    zmax = 4095
    well = ((z > 0.05 * zmax) & (z < 0.95 * zmax)).all(axis=3).any(axis=0)
    rel = np.abs(m.radiance.astype(np.float64) / truth - 1)[well]
    # Only quantisation remains: a code is within 0.5 of the exact value, so each
    # exposure's relative error is at most 0.5 * max d ln f^-1 / dz over the codes
    # the merge uses (2-98 % of the range), and a weighted mean cannot exceed it.
    g = s.gt_arrays["g"]
    bound = 0.5 * float(np.max(np.diff(g[:, 82:4014], axis=1)))
    assert 0 < rel.max() <= np.expm1(bound) * 1.01
    assert m.flags.any()  # the emitters clip in every exposure: flagged, not silent


def test_scene_is_high_dynamic_range_and_responses_invert():
    s = render("bracket")
    assert s.gt["dynamic_range"] >= 1e4
    y = np.linspace(0.01, 0.99, 50)
    for kind in ("film", "gamma", "linear"):
        for c in range(3):
            assert np.allclose(response_forward(response_inverse(y, kind, c), kind, c), y)
    g = gt_log_inverse("film", 8)
    assert np.all(np.diff(g, axis=1) > 0) and not np.allclose(g[0], g[2])  # channels differ


def test_nominal_times_are_few_percent_off_and_stack_carries_the_chosen_ones():
    s = render("bracket", stack_times="nominal", time_error=0.05)
    ex, nom = np.array(s.gt["exposure_times_exact_s"]), np.array(s.gt["exposure_times_nominal_s"])
    assert np.allclose(s.stack["exposure_times_s"], nom)
    assert 0 < np.max(np.abs(ex / nom - 1)) <= 0.05
    a = render("bracket", vary="aperture")
    assert len(set(a.stack["exposure_times_s"])) == 1 and "f_numbers" in a.stack


def test_video_variant_alternates_exposures_with_radiance_per_frame():
    s = render("bracket_video", frames=4)
    t = s.stack["exposure_times_s"]
    assert t[1] / t[0] == pytest.approx(8.0) and t[2] == t[0]
    assert s.gt_arrays["radiance"].shape == (4, 120, 160, 3)
    assert not np.allclose(s.gt_arrays["radiance"][0], s.gt_arrays["radiance"][1])


@pytest.mark.parametrize("opt", [("--bit-depth", "7"), ("--min-time", "-0.01"),
                                 ("--exposures", "0")])
def test_bad_options_exit_2(tmp_path, opt):
    r = lumigraph("render", "bracket", "--out", tmp_path / "b", *opt)
    assert_clean_error(r, opt[0])
    assert not (tmp_path / "b").exists()
