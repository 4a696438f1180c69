"""Mitsunaga-Nayar hard cases of issue 13: Memorial with sampling seeds 0-4
(monotone on every channel, one order on at least 4 of 5), a channel that
disagrees with the others, exposures known exactly, and the local tone
mapper's memory per pixel."""

from __future__ import annotations

import tracemalloc
from fractions import Fraction

import numpy as np
import pytest

from lumigraph.capture.bench import shared_data
from lumigraph.capture.render import render
from lumigraph.hdr.mitsunaga1999 import response_mitsunaga1999

MEMORIAL = shared_data("data", "hdr-real", "memorial")


@pytest.mark.slow
@pytest.mark.skipif(not (MEMORIAL / "shutter_times.txt").exists(), reason="no Memorial data")
def test_memorial_seeds_0_to_4_give_monotone_curves_and_one_order():
    from lumigraph.capture.io import read_stack

    t = [float(Fraction(x)) for x in (MEMORIAL / "shutter_times.txt").read_text().split()]
    stack = read_stack(sorted(MEMORIAL.glob("memorial0*.png")), times=t)
    z = stack.images[:, ::4, ::4]  # 128x192: the same bracket, 16x cheaper to sample
    orders = []
    for seed in range(5):
        r = response_mitsunaga1999(z, t, samples=200, rng=np.random.default_rng(seed))
        # strictly increasing over every code: no flat run (codes merged), no reversal
        assert np.all(np.diff(r.g, axis=1) > 0), (seed, r.selection["chosen"])
        assert len(set(r.selection["chosen"])) == 1
        orders.append(r.selection["chosen"][0])
        assert not r.warnings, r.warnings
    assert max(orders.count(o) for o in orders) >= 4, orders


def test_a_channel_whose_exposures_disagree_is_warned():
    s = render("bracket", size=(96, 72), seed=2)
    z = np.stack(s.images).copy()
    t = s.stack["exposure_times_s"]
    z[2, ..., 2], z[3, ..., 2] = z[3, ..., 2].copy(), z[2, ..., 2].copy()  # blue: two swapped
    r = response_mitsunaga1999(z, t, samples=300)
    assert any(w.startswith("channel 2:") for w in r.warnings), r.warnings
    assert not any(w.startswith(("channel 0:", "channel 1:")) for w in r.warnings), r.warnings
    clean = response_mitsunaga1999(np.stack(s.images), t, samples=300)
    assert not any(w.startswith("channel") for w in clean.warnings), clean.warnings


def test_two_exposures_known_exactly_fix_the_ratios_one_fixes_the_scale():
    s = render("bracket", size=(96, 72), seed=3, time_error=0.10, stack_times="nominal")
    z = np.stack(s.images)
    rough = np.array(s.stack["exposure_times_s"])
    exact = np.array(s.gt["exposure_times_exact_s"])
    last = exact.size - 1
    true = np.exp(np.diff(np.log(exact)))
    two = response_mitsunaga1999(z, rough, samples=300,
                                 reference_times={0: exact[0], last: exact[last]})
    ratio_err = np.abs(np.array(two.fit["refined_ratios_ascending"]) / true - 1)
    # a tenth of the injected time error (10 %): the power is no longer taken from it
    assert ratio_err.max() < 0.01, ratio_err
    got = np.array(two.exposure_times_s)
    assert np.allclose(got[[0, last]], exact[[0, last]], rtol=1e-9)
    one = response_mitsunaga1999(z, rough, samples=300, reference_times={1: exact[1]})
    assert one.exposure_times_s[1] == pytest.approx(exact[1], rel=1e-9)
    assert one.fit["power_fixed_by"] == "the rough times through the reference exposure"


def test_reference_times_are_checked():
    from lumigraph.capture.errors import InputError

    z = np.stack(render("bracket", size=(48, 36), seed=0).images)
    with pytest.raises(InputError, match="reference_times"):
        response_mitsunaga1999(z, [1, 2, 4, 8, 16, 32, 64][:z.shape[0]],
                               reference_times={z.shape[0]: 1.0})


def test_local_tone_mapping_memory_per_pixel_fits_the_phone_budget():
    from lumigraph.hdr.reinhard2002 import tonemap

    # Issue 13: <= 0.8 GB for the 12.19 MP iPhone merge, 65.6 bytes a pixel in all. The
    # float32 RGB radiance and the EXR reader's staging copy take 24 of them: the tone
    # mapper's own working memory must grow by at most 41 bytes a pixel (the slope between
    # two sizes, so the fixed cost of its row bands does not count).
    rng = np.random.default_rng(0)
    peaks = []
    for h in (400, 800):
        x = np.exp(rng.normal(0, 2, (h, 1000, 3))).astype(np.float32)
        tracemalloc.start()
        tonemap(x, method="reinhard-local")
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    slope = (peaks[1] - peaks[0]) / (400 * 1000)
    assert 0 < slope <= 41, slope


def test_bias_correction_keeps_the_curve_increasing_on_a_night_bracket():
    # The night kind: most codes dark, read noise 10 e- on a 5000 e- well, so the floor at
    # code 0 biases the dark codes and the bootstrap's correction is largest. Whatever it
    # does, the curve must stay strictly increasing on every channel (the guarantee), and
    # the record must say whether each channel was corrected (a float) or not (None).
    from lumigraph.capture.scenes.brackets import bracket_family

    c = bracket_family(kinds=("night",), seeds=(0,), bit_depths=(8,))[0]
    s = c.render((96, 72))
    z, t = np.stack(s.images), np.asarray(s.stack["exposure_times_s"], np.float64)
    r = response_mitsunaga1999(z, t)
    assert np.all(np.diff(r.g, axis=1) > 0)
    bc = r.fit["bias_correction"]
    assert bc["draws"] > 0 and len(bc["max_abs_ln"]) == z.shape[-1]
    assert all(a > 0 and b >= 0 for a, b in bc["noise_a_b_top"])
    off = response_mitsunaga1999(z, t, bias_draws=0)
    assert off.fit["bias_correction"]["max_abs_ln"] == []


def test_walls_toe_gets_the_order_its_data_support():
    # The walls kind's sRGB toe: with the BIC's N counted in pixels (not in independent
    # held-out residuals) order 3 was chosen and MN read 2.4x our Debevec. The issue's
    # target is MN error <= 1.5x our Debevec with exact times; the BIC's N must be the
    # residual count (each pixel's valid codes less one, per fold).
    from lumigraph.capture.scenes.brackets import bracket_family
    from lumigraph.hdr.bench import ln_response_rms_range
    from lumigraph.hdr.debevec1997 import response_debevec1997

    case = next(iter(bracket_family(kinds=("walls",), seeds=(0,), bit_depths=(8,))))
    s = case.render((160, 120))
    z, t = np.stack(s.images), np.asarray(s.stack["exposure_times_s"])
    r = response_mitsunaga1999(z, t, bit_depth=8)
    cand = r.selection["candidates"]
    assert all(n > 1.5 * r.fit["samples"] for n in cand["bic_n_per_channel"])
    gt = s.gt_arrays["g"]
    mn = ln_response_rms_range(r.g, gt, 8, 10 / 255, 0.95)
    deb = ln_response_rms_range(response_debevec1997(z, t, bit_depth=8).g, gt, 8, 10 / 255, 0.95)
    assert np.all(np.diff(r.g, axis=1) > 0)
    assert mn <= 1.5 * deb, (mn, deb, r.selection["chosen"])


@pytest.mark.skipif(not (MEMORIAL / "shutter_times.txt").exists(), reason="no Memorial data")
def test_robertson_on_memorial_keeps_the_full_estimate_on_every_channel():
    # Memorial's film base (codes below ~20 that do not follow the exposure) used to pull
    # the per-code means of green into a reversal (14 ln units when made monotone). With
    # the fitted range stopped at the codes that respond, every channel's refined estimate
    # is increasing on its own: no fallback, no warning.
    from lumigraph.capture.io import read_stack
    from lumigraph.hdr.robertson2003 import response_robertson2003

    t = [float(Fraction(x)) for x in (MEMORIAL / "shutter_times.txt").read_text().split()]
    stack = read_stack(sorted(MEMORIAL.glob("memorial0*.png")), times=t)
    r = response_robertson2003(stack.images, t)
    assert not r.warnings, r.warnings
    assert all(len(ch) == 1 and ch[0]["kept"] for ch in r.fit["variants"])
    assert all(lo > 0.03 * 255 for lo, _ in r.fit["responsive_codes"])  # the film base
