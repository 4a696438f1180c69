"""Sand-Teller video matching (stereo/sand2004.py) on the lighting-change
family (capture/scenes/flow_lighting.py): invariance by construction, the
issue's accuracy target against the peer on the same pair, its probability
output, and its argument checks."""

import numpy as np
import pytest

from lumigraph.capture.errors import InputError
from lumigraph.capture.scenes.flow_lighting import KINDS, VARIANTS, render_lighting
from lumigraph.stereo.sand2004 import normalise_contrast, video_matching, weighted_regression

SIZE = (160, 120)


def _epe(flow, gt, mask):
    return float(np.hypot(*(flow - gt).transpose(2, 0, 1))[mask].mean())


def _dis(pair):
    import cv2

    from lumigraph.stereo.luma import luma_normalised

    g = [np.clip(np.rint(luma_normalised(x) * 255), 0, 255).astype(np.uint8) for x in pair.frames]
    return cv2.DISOpticalFlow_create(2).calc(g[0], g[1], None)


@pytest.mark.parametrize("kind", ["natural", "noise"])
def test_a_global_gain_and_offset_do_not_change_the_field(kind):
    # Invariance by construction: the same second take, once as it is and
    # once at half gain plus an offset (float images, no clipping or codes).
    p = render_lighting(kind, size=SIZE, seed=3, noise=0.0)
    a = p.frames[0].astype(np.float32) / 255
    b = p.frames[1].astype(np.float32) / 255
    f1 = video_matching(a, b).flow
    f2 = video_matching(a, 0.5 * b + 0.2).flow
    # The normalisation's floor (eps, ~1 code) is the only term that sees the
    # gain; it nudges the cost where the local contrast is near it. Same
    # match: within half of the cost's one-pixel granularity at 95 % of the
    # pixels.
    d = np.hypot(*(f1 - f2).transpose(2, 0, 1))
    assert np.quantile(d, 0.95) < 0.5
    x = np.random.default_rng(0).random((30, 30)).astype(np.float32)
    # Uniform noise has local std ~0.29 >> eps: equal to well under 1 %.
    assert np.allclose(normalise_contrast(0.5 * x + 0.2), normalise_contrast(x), atol=0.01)


@pytest.mark.parametrize("kind", ["layers", "cartoon", "materials"])
def test_reported_pair_beats_dis_medium_and_half_the_plain_flow(kind):
    # The target on one reported-on pair per kind (seed 1 was not
    # looked at while tuning; materials was never run while tuning); the
    # plain flow is our default (dense inverse search, what `lumigraph flow`
    # runs without --method).
    from lumigraph.stereo.kroeger2016 import dense_inverse_search

    # The bench's size: at 160x120 a layer is a few patches wide.
    p = render_lighting(kind, size=(320, 240), seed=1, **VARIANTS["mixed"])
    ours = _epe(video_matching(*p.frames).flow, p.flow, p.valid)
    dis = _epe(_dis(p), p.flow, p.valid)
    plain = _epe(dense_inverse_search(*p.frames, consistency=False).flow, p.flow, p.valid)
    assert ours <= dis and ours <= 0.5 * plain, (ours, dis, plain)


def test_pyramid_search_still_beats_dis_medium_and_iterates():
    # The paper's own coarse-to-fine search (search="pyramid", the default
    # before the DIS start): still lighting-invariant, so below DIS-medium's
    # EPE on a reported-on pair, and it runs match/regress rounds.
    p = render_lighting("noise", size=SIZE, seed=1, **VARIANTS["mixed"])
    r = video_matching(*p.frames, search="pyramid")
    assert _epe(r.flow, p.flow, p.valid) <= _epe(_dis(p), p.flow, p.valid)
    assert r.info["search"] == "pyramid" and len(r.info["iterations"]) >= 2


def test_probability_is_low_on_a_removed_object_and_high_on_matched_texture():
    from lumigraph.stereo.luma import luma_normalised
    from lumigraph.stereo.sand2004 import texture_weight

    p = render_lighting("natural", size=SIZE, seed=2, **VARIANTS["removed"])
    r = video_matching(*p.frames)
    assert p.changed.mean() > 0.02
    textured = texture_weight(luma_normalised(p.frames[0])) > 0.5
    # Nothing in the second take matches the removed object: its pixels are
    # below even odds on average, matched textured pixels above.
    assert r.confidence[p.changed].mean() < 0.5 < r.confidence[p.valid & textured].mean()
    assert r.occluded[p.changed].mean() > r.occluded[p.valid].mean()
    assert r.confidence.dtype == np.float32 and 0 <= r.confidence.min() <= r.confidence.max() <= 1


def test_identical_frames_give_zero_flow_exactly():
    p = render_lighting("layers", size=(96, 72), seed=0)
    r = video_matching(p.frames[0], p.frames[0])
    assert not r.flow.any()


def test_regression_on_a_coarser_grid_reproduces_affine_fields():
    # Bilinear interpolation of an affine function is exact, so the coarse
    # solve loses nothing on an affine field away from the border rows.
    yy, xx = np.mgrid[0:64, 0:80].astype(np.float32)
    d = np.stack([0.02 * xx - 0.01 * yy + 1.0, 0.015 * yy - 0.5], -1)
    w = (np.random.default_rng(1).random((64, 80)) > 0.5).astype(np.float32)
    fine = weighted_regression(d, w, sigma=8.0)
    coarse = weighted_regression(d, w, sigma=8.0, step=4)
    assert np.abs(fine - d).max() < 1e-3
    assert np.abs(coarse - d)[4:-4, 4:-4].max() < 1e-2


def test_every_kind_renders_with_exact_flow_where_visible():
    for kind in KINDS:
        p = render_lighting(kind, size=(48, 32), seed=0, noise=0.0)
        assert p.frames[0].shape == (32, 48, 3) and p.valid.mean() > 0.5, kind
    with pytest.raises(ValueError, match="kind"):
        render_lighting("nope", size=(48, 32))


@pytest.mark.parametrize("kw, where", [
    (dict(moving=np.zeros((20, 21))), "moving"),
    (dict(reference=np.zeros((0, 0)), moving=np.zeros((0, 0))), "reference"),
    (dict(region=4), "region"),
    (dict(radius=0), "radius"),
    (dict(regression_sigma=0.0), "regression_sigma"),
    (dict(levels=0), "levels"),
    (dict(search="census"), "search"),
])
def test_bad_arguments_name_themselves(kw, where):
    args = {"reference": np.zeros((20, 20)), "moving": np.zeros((20, 20)), **kw}
    ref, mov = args.pop("reference"), args.pop("moving")
    with pytest.raises(InputError) as e:
        video_matching(ref, mov, **args)
    assert e.value.where == where
