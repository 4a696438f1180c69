"""Dense inverse search (the default flow): exactness on constructed motion,
options checked and named, the large-motion seed and its warning."""

import numpy as np
import pytest

from lumigraph.capture.errors import InputError
from lumigraph.capture.render import render
from lumigraph.stereo.bench_flow import cloth_scene
from lumigraph.stereo.kroeger2016 import (
    PRESETS,
    check_options,
    coarsest_scale,
    dense_inverse_search,
    initial_flow,
    reach_px,
)


def _err(flow, gt):
    return np.hypot(*(flow - gt).transpose(2, 0, 1))


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_each_preset_recovers_the_rendered_flow(preset):
    s = render("flow", size=(160, 120), seed=3)
    g = s.gt_arrays
    vis = ~g["occluded"]
    r = dense_inverse_search(s.images[0], s.images[1], preset=preset)
    assert r.flow.shape == (120, 160, 2) and r.flow.dtype == np.float32
    assert np.isfinite(r.flow).all()
    # A rendered, noise-free scene: sub-pixel on the visible pixels (half a
    # pixel is the bilinear-warp accuracy any sub-pixel method must beat).
    assert np.median(_err(r.flow, g["flow"])[vis]) < 0.5
    # The forward-backward check finds most of the true occlusions.
    assert r.occluded[g["occluded"]].mean() > 0.5
    assert 0 <= r.confidence.min() and r.confidence.max() <= 1


def test_accurate_preset_fills_occluded_pixels_from_their_surface():
    # Occluded pixels have no match: the search alone leaves them about half
    # their motion off (the default's 2-3 px of 6 px on this scene); the
    # accurate preset fills the forward-backward inconsistent pixels from
    # the consistent flow of their colour region. Bound from the ground
    # truth: a quarter of the true motion there, on average.
    s = render("flow", size=(160, 120), seed=4)
    g = s.gt_arrays
    occ = g["occluded"] & np.isfinite(g["flow"]).all(axis=2)
    assert occ.mean() > 0.05
    r = dense_inverse_search(s.images[0], s.images[1], preset="accurate")
    motion = np.hypot(*g["flow"][occ].T).mean()
    assert _err(r.flow, g["flow"])[occ].mean() < 0.25 * motion
    assert r.info["settings"]["fill_occlusions"] and r.occluded[occ].mean() > 0.5


def test_cloth_scene_ground_truth_is_exact():
    # The tuning scene of the accurate preset's refinement: frame 1 sampled
    # at x + gt reproduces frame 0 up to the injected noise (sigma 2 codes in
    # each frame: the mean |difference| of two is 2 sigma / sqrt(pi)), plus
    # half a code of rounding.
    import cv2

    d = cloth_scene(5, size=(194, 292))
    h, w = d["gt"].shape[:2]
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    back = cv2.remap(d["i1"].astype(np.float32), x + d["gt"][..., 0], y + d["gt"][..., 1],
                     cv2.INTER_LINEAR)
    res = np.abs(back - d["i0"])[d["valid"]].mean()
    assert res < 2 * 2.0 / np.sqrt(np.pi) + 0.5
    assert res < np.abs(d["i1"].astype(np.float32) - d["i0"])[d["valid"]].mean()


def test_accurate_preset_recovers_smooth_motion_on_noisy_low_texture():
    # A cloth with faint weave and sensor noise (the Dimetrodon kind): the
    # full-size patches see the noise; the accurate preset's pre-smoothing and
    # converged smoothness term must reach the target, 0.75x the EPE
    # of OpenCV's DIS-medium (which stops at half size) on the same pair.
    import cv2

    d = cloth_scene(5, size=(194, 292))
    g0, g1 = (cv2.cvtColor(d[k], cv2.COLOR_RGB2GRAY) for k in ("i0", "i1"))
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(g0, g1, None)
    ours = dense_inverse_search(d["i0"], d["i1"], preset="accurate", consistency=False).flow
    e_dis, e_ours = (_err(f, d["gt"])[d["valid"]].mean() for f in (dis, ours))
    assert e_ours <= 0.75 * e_dis


def test_refinement_options_are_checked_and_named():
    assert check_options(preset="accurate").presmooth > 0
    assert check_options(preset="default").presmooth == 0  # the default preset is unchanged
    for kw in (dict(presmooth=-1.0), dict(refine_smoothness=0.0), dict(refine_sor_iterations=0)):
        with pytest.raises(InputError) as e:
            check_options(preset="accurate", **kw)
        assert e.value.where == next(iter(kw))


def test_identical_frames_give_zero_flow_exactly():
    s = render("flow", size=(96, 72), seed=1)
    r = dense_inverse_search(s.images[0], s.images[0].copy())
    assert (r.flow == 0).all() and not r.occluded.any()


def test_bad_input_names_the_argument():
    a = np.zeros((32, 40, 3), np.uint8)
    for b, where in ((np.zeros((32, 41, 3), np.uint8), "moving"),
                     (np.zeros((0, 0, 3), np.uint8), "moving")):
        with pytest.raises(InputError) as e:
            dense_inverse_search(a, b)
        assert e.value.where == where
    for kw, where in ((dict(preset="slow"), "preset"), (dict(patch_stride=8), "patch_stride"),
                      (dict(median=4), "median"), (dict(patch_size=2), "patch_size")):
        with pytest.raises(InputError) as e:
            dense_inverse_search(a, a, **kw)
        assert e.value.where == where


def test_reach_follows_opencv_coarsest_scale():
    # OpenCV's rule: log2(max side / (4 patch)) rounded, at most log2(min side / patch).
    assert coarsest_scale((388, 584), 8) == 4 and reach_px((388, 584), 8) == 64.0
    assert coarsest_scale((64, 4096), 8) == 3  # the short side bounds it


def test_seed_picks_each_region_its_own_translation():
    rng = np.random.default_rng(0)
    a = (rng.random((120, 160)) * 255).astype(np.uint8)
    b = np.empty_like(a)
    b[:, :80] = np.roll(a, 20, axis=1)[:, :80]   # left half moves +20 px
    b[:, 80:] = np.roll(a, -30, axis=1)[:, 80:]  # right half moves -30 px
    f = initial_flow(a, b, [(20.0, 0.0), (-30.0, 0.0)])
    assert np.median(f[:, 30:60, 0]) == 20 and np.median(f[:, 110:130, 0]) == -30


def test_large_motion_beyond_the_coarsest_level_is_seeded():
    s = render("flow-large", size=(320, 240), seed=0)
    g = s.gt_arrays
    vis = ~g["occluded"]
    motion = s.gt["max_motion_px"]
    assert motion > reach_px((240, 320), 8)  # beyond what DIS alone reaches here
    r = dense_inverse_search(s.images[0], s.images[1], consistency=False)
    assert r.info["seed_shifts_px"]
    # Within a tenth of the motion on average (DIS-medium is ~14 px off, bench).
    assert _err(r.flow, g["flow"])[vis].mean() < motion / 10


def test_motion_out_of_reach_is_said():
    rng = np.random.default_rng(1)
    a = (rng.random((64, 96)) * 255).astype(np.uint8)
    # a given motion far beyond the reach and tiles that find nothing: a warning, not silence
    r = dense_inverse_search(a, (rng.random((64, 96)) * 255).astype(np.uint8),
                             max_motion_px=500, consistency=False)
    assert r.info["warnings"] and "reach" in r.info["warnings"][0]
