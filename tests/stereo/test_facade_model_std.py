"""Model-based stereo following a fitted model's depth σ (``model_std``) and
the σ itself (``model_depth_sigma``): pixels whose model can be off by more
than the search are not answered; a σ of 0 changes nothing."""

import numpy as np
import pytest

from lumigraph.capture.errors import InputError
from lumigraph.capture.render import render
from lumigraph.capture.rig import Rig
from lumigraph.stereo.debevec1996 import model_stereo
from lumigraph.stereo.debevec1996.model import BlockModel
from lumigraph.stereo.debevec1996.raster import model_depth, model_depth_sigma


@pytest.fixture(scope="module")
def pair():
    s = render("model-stereo", size=(160, 120))
    return s, Rig.from_dict(s.gt["rig"]), s.gt_arrays["model_depth"]


def test_zero_sigma_is_the_exact_model(pair):
    s, rig, zm = pair
    a = model_stereo(s.images[0], s.images[1], zm, rig, max_offset=0.35, left_right=None)
    b = model_stereo(s.images[0], s.images[1], zm, rig, max_offset=0.35, left_right=None,
                     model_std=np.zeros(zm.shape))
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_array_equal(a.depth[a.valid], b.depth[b.valid])


def test_uncertain_pixels_are_not_answered(pair):
    s, rig, zm = pair
    std = np.zeros(zm.shape)
    std[:, :60] = np.inf  # the model may leave these pixels
    std[:, 60:80] = 0.35 / 3 * 1.01  # 3 σ just beyond the search
    r = model_stereo(s.images[0], s.images[1], zm, rig, max_offset=0.35, left_right=None,
                     model_std=std)
    assert not r.valid[:, :80].any() and r.valid[:, 80:].any()
    with pytest.raises(InputError, match="^model_std"):
        model_stereo(s.images[0], s.images[1], zm, rig, max_offset=0.35, model_std=std[:-1])
    with pytest.raises(InputError, match="^model_std"):
        model_stereo(s.images[0], s.images[1], zm, rig, max_offset=0.35,
                     model_std=np.full(zm.shape, np.inf))


def test_depth_sigma_of_a_box_face():
    # a box seen square-on from y = -8: its front face is at y = -depth/2, so the
    # face's depth moves by half the depth's σ; the top edge pixels can leave the model
    m = BlockModel.from_dict({"blocks": [{"name": "b", "kind": "box", "params": {
        "width": {"value": 2, "fixed": True}, "depth": 2, "height": 2}}]})
    K = np.array([[40.0, 0, 15.5], [0, 40.0, 11.5], [0, 0, 1]])
    R = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    t = -R @ np.array([0, -8.0, 1])
    sd_depth, sd_height = 0.01, 0.02
    s = model_depth_sigma(m, {"b/depth": 2.0, "b/height": 2.0},
                          np.diag([sd_depth ** 2, sd_height ** 2]), K, R, t, (32, 24))
    z = model_depth(m.mesh(), K, R, t, (32, 24))
    assert np.array_equal(np.isnan(s), np.isnan(z))
    front = np.abs(z - 7.0) < 1e-6  # the front face, at y = -1
    assert np.allclose(s[front & np.isfinite(s)], sd_depth / 2, rtol=1e-9)
    # the height's σ moves the top edge: pixels just below it may see the sky
    assert np.isinf(s).any()
