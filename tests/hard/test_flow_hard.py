"""Hard cases of optical flow: textureless regions, occlusion borders, motion
beyond 40 px, brightness change. Each meets its bound or says why not."""

import numpy as np

from lumigraph.capture.render import render
from lumigraph.stereo.pyramid_flow import pyramid_flow
from lumigraph.stereo.sand2004 import video_matching


def _err(flow, gt):
    return np.hypot(*(flow - gt).transpose(2, 0, 1))


def test_textureless_region_low_confidence_not_garbage():
    s = render("flow-textureless", size=(160, 120), seed=1)
    g = s.gt_arrays
    flat, vis = g["textureless"], ~g["occluded"]
    assert flat.mean() > 0.05
    r = pyramid_flow(s.images[0], s.images[1])
    # Low confidence: the structure tensor there is noise only.
    assert r.confidence[flat].mean() < 0.1 < r.confidence[vis & ~flat].mean()
    # Not garbage: finite everywhere, and the dense variant fills the flat
    # area from its surroundings to within a third of the true motion.
    d = pyramid_flow(s.images[0], s.images[1], method="dense")
    assert np.isfinite(d.flow).all() and np.isfinite(r.flow).all()
    motion = np.hypot(*g["flow"][flat].T).mean()
    assert _err(d.flow, g["flow"])[flat].mean() < motion / 3


def test_occlusion_borders_are_flagged_and_the_rest_is_accurate():
    s = render("flow", size=(160, 120), seed=4)
    g = s.gt_arrays
    r = pyramid_flow(s.images[0], s.images[1])
    assert r.occluded[g["occluded"]].mean() > 0.9
    # Among pixels the check trusts, the error stays near that of the whole
    # visible image: the occlusion border does not leak wrong vectors in.
    trusted = ~r.occluded & ~g["occluded"]
    e = _err(r.flow, g["flow"])
    assert e[trusted].mean() < 0.4


def test_motion_beyond_40_px():
    s = render("flow-large", size=(320, 240), seed=0)
    g = s.gt_arrays
    assert s.gt["max_motion_px"] > 40
    vis = ~g["occluded"]
    r = pyramid_flow(s.images[0], s.images[1], consistency=False)
    assert r.levels >= 5  # auto depth follows the estimated motion
    # Within 10 % of the ~45-55 px motion on average (DIS-medium is ~45 px off).
    assert _err(r.flow, g["flow"])[vis].mean() < 5.0


def test_brightness_change_needs_video_matching():
    s = render("flow-brightness", size=(160, 120), seed=1)
    g = s.gt_arrays
    vis = ~g["occluded"]
    plain = _err(pyramid_flow(s.images[0], s.images[1], consistency=False).flow, g["flow"])[vis].mean()
    vm = video_matching(s.images[0], s.images[1])
    robust = _err(vm.flow, g["flow"])[vis].mean()
    assert plain > 5.0  # brightness constancy broken: the plain flow fails
    # Gain 0.6, offset and a 35 % shading ramp: the contrast-normalised
    # matching removes them; the target is DIS-medium's EPE on the
    # same pair (its bench check), and half the plain flow's.
    import cv2

    from lumigraph.stereo.luma import luma_normalised

    g = [np.clip(np.rint(luma_normalised(x) * 255), 0, 255).astype(np.uint8) for x in s.images]
    dis = _err(cv2.DISOpticalFlow_create(2).calc(g[0], g[1], None), s.gt_arrays["flow"])[vis].mean()
    assert robust < 0.5 * plain and robust <= dis, (robust, dis)


def test_default_flow_textureless_low_confidence_not_garbage():
    from lumigraph.stereo.kroeger2016 import dense_inverse_search

    s = render("flow-textureless", size=(160, 120), seed=1)
    g = s.gt_arrays
    flat, vis = g["textureless"], ~g["occluded"]
    r = dense_inverse_search(s.images[0], s.images[1])
    # The confidence file says where the flow is a guess: the structure tensor is noise only.
    assert r.confidence[flat].mean() < 0.1 < r.confidence[vis & ~flat].mean()
    # Not garbage: finite, and the flat area takes its surroundings' motion
    # (propagation + smoothness): at most half the error of the zero-flow
    # guess. (pyramid-dense fills it better, test above: a third.)
    assert np.isfinite(r.flow).all()
    motion = np.hypot(*g["flow"][flat].T).mean()
    assert _err(r.flow, g["flow"])[flat & vis].mean() < motion / 2


def test_default_flow_identical_frames_and_bad_sizes():
    import pytest

    from lumigraph.capture.errors import InputError
    from lumigraph.stereo.kroeger2016 import dense_inverse_search

    s = render("flow", size=(96, 72), seed=5)
    assert (dense_inverse_search(s.images[1], s.images[1]).flow == 0).all()
    with pytest.raises(InputError):
        dense_inverse_search(s.images[0], s.images[1][:-1])
