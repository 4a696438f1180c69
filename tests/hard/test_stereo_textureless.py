"""Hard cases for block matching: a textureless card (unknown, not garbage)
and occlusion borders (refused by the left-right check, not smeared)."""

import numpy as np
from scipy import ndimage

from lumigraph.capture.render import render
from lumigraph.stereo.block_matching import match


def test_textureless_card_is_unknown_not_garbage():
    s = render("stereo-pair", size=(240, 180), textureless=True)
    card = ndimage.binary_erosion(np.abs(s.gt_arrays["depth"] - 2.6) < 1e-9, iterations=8)
    assert card.sum() > 500
    gt = s.gt_arrays["disparity"]
    for window in (5, 9, "auto"):
        d = match(s.images[0], s.images[1], max_disp=47, window=window).disparity
        wrong = np.abs(d[card] - gt[card]) > 2
        # a flat grey card has no information: at most 10 % of it may carry a
        # (necessarily chance) value; everything else must be NaN
        assert np.isnan(d[card]).mean() > 0.9, window
        assert wrong.mean() < 0.1, window
        # while the textured rest of the image is matched
        rest = np.isfinite(gt) & ~ndimage.binary_dilation(card, iterations=16)
        assert np.isfinite(d[rest]).mean() > 0.75


def test_occlusion_borders():
    s = render("stereo-pair", size=(240, 180), occluders=2)
    gt = s.gt_arrays["disparity"]
    d = match(s.images[0], s.images[1], max_disp=47, window=9).disparity
    maxd = int(np.nanmax(gt)) + 2
    occluded = ~np.isfinite(gt)
    occluded[:, :maxd] = False
    assert occluded.sum() > 300
    # occluded pixels: mostly refused
    assert np.isnan(d[occluded]).mean() > 0.6
    # A 9x9 window straddling a depth edge sees two surfaces, so errors
    # ("fattening") are confined to 4 px (the window radius) of the edge: within
    # 3 px at most half the pixels may be wrong (one side of the edge), beyond
    # the radius almost none.
    Z = np.nan_to_num(s.gt_arrays["depth"], nan=99)
    edge = (ndimage.maximum_filter(Z, 3) - ndimage.minimum_filter(Z, 3)) > 0.3
    dist = ndimage.distance_transform_edt(~edge)
    vis = np.isfinite(gt)
    near = vis & (dist <= 3)
    far = vis & (dist > 5)
    assert (np.abs(d[near] - gt[near]) > 2).mean() < 0.5
    assert (np.abs(d[far] - gt[far]) > 2).mean() < 0.05
