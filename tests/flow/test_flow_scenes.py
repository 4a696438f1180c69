"""Ground truth of the flow scenes, checked independently: warping frame 1 by
the exact flow reproduces frame 0 outside occlusions, within bounds derived
from quantisation, bilinear interpolation and the injected noise."""

import numpy as np
import pytest

from lumigraph.capture.render import render

SIZE = (160, 120)


def _pull_back(img1, flow):
    import cv2

    h, w = flow.shape[:2]
    X, Y = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return cv2.remap(img1.astype(np.float32), X + flow[..., 0], Y + flow[..., 1],
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def _checkable(g):
    """Visible, single-surface pixels whose bilinear footprint (target +- 1 px)
    lies inside frame 1."""
    f = g["flow"]
    h, w = f.shape[:2]
    X, Y = np.meshgrid(np.arange(w), np.arange(h))
    tx, ty = X + f[..., 0], Y + f[..., 1]
    inside = (tx >= 1) & (tx <= w - 2) & (ty >= 1) & (ty <= h - 2)
    return inside & ~g["occluded"] & ~g["boundary"] & np.isfinite(f).all(axis=2)


def _interp_bound(img1, flow):
    """Bilinear interpolation error bound (h^2/8)(|f_xx| + |f_yy|) with h = 1 px,
    per channel. The second derivatives come from the largest second
    differences of frame 1 around the target (3x3 max), scaled by pi^2/4: a
    component of frequency w <= pi has |f''| = w^2 A but second difference
    4 sin^2(w/2) A >= (4/pi^2) w^2 A, so differences underestimate |f''| by at
    most that factor."""
    import cv2

    a = img1.astype(np.float32)
    dxx = np.abs(cv2.filter2D(a, -1, np.float32([[1, -2, 1]])))
    dyy = np.abs(cv2.filter2D(a, -1, np.float32([[1], [-2], [1]])))
    k = np.ones((3, 3), np.uint8)
    b = (np.pi ** 2 / 4) * (cv2.dilate(dxx, k) + cv2.dilate(dyy, k)) / 8.0
    return _pull_back(b, flow)


@pytest.mark.parametrize("scene", ["flow", "flow-large", "flow-textureless", "flow-video"])
def test_warping_frame1_by_gt_flow_reproduces_frame0(scene):
    s = render(scene, size=SIZE, seed=3, noise=0.0)
    g = s.gt_arrays
    ok = _checkable(g)
    assert ok.mean() > 0.5
    img0 = s.images[0].astype(np.float32)
    r = np.abs(_pull_back(s.images[1], g["flow"]) - img0)
    if scene == "flow-video":
        return  # lighting differs between frames there: see the photometric test below
    # Per pixel: two roundings (<= 0.5 code each; the bilinear mix of frame 1's
    # roundings is still <= 0.5) plus the interpolation bound.
    bound = 1.0 + _interp_bound(s.images[1], g["flow"])
    frac = float(np.mean((r <= bound)[ok]))
    assert frac >= 0.99, frac
    # Two-sided: the residual is not zero (frames are independently rendered),
    # and the opposite flow does far worse (the sign convention is right).
    assert 0.05 < r[ok].mean() < 3.0
    wrong = np.abs(_pull_back(s.images[1], -g["flow"]) - img0)[ok].mean()
    assert wrong > 4 * r[ok].mean()


def test_photometric_change_is_the_declared_one():
    s = render("flow-brightness", size=SIZE, seed=3, noise=0.0)
    g = s.gt_arrays
    ok = _checkable(g)
    p = s.gt["photometric"]
    w = SIZE[0]
    # The illumination ramp belongs to frame 1: evaluate it at the target x.
    tx = np.arange(w)[None, :] + g["flow"][..., 0]
    ramp = (-1.0 + 2.0 * tx / (w - 1))[..., None]
    img0 = s.images[0].astype(np.float64)
    # Frame 1 = (gain (1 + illumination ramp) I + offset) in [0, 1] units, so
    # undoing it on the pulled-back frame 1 must give frame 0 again.
    back = (_pull_back(s.images[1], g["flow"]) - 255 * p["offset"]) / (p["gain"] * (1 + p["illumination"] * ramp))
    unclipped = ok & (s.images[1].max(axis=2) < 255) & (s.images[1].min(axis=2) > 0)
    r = np.abs(back - img0)[unclipped]
    # Rounding of frame 1 is divided by the gain (>= 0.6*0.65): <= 0.5/0.39 + 0.5 codes,
    # plus the interpolation bound, scaled likewise.
    bound = (1.0 / (p["gain"] * (1 - p["illumination"])) + 0.5
             + _interp_bound(s.images[1], g["flow"]) / (p["gain"] * (1 - p["illumination"])))
    frac = float(np.mean(r <= bound[unclipped]))
    assert frac >= 0.99, frac


def test_noise_adds_the_declared_spread():
    clean = render("flow", size=SIZE, seed=3, noise=0.0)
    noisy = render("flow", size=SIZE, seed=3, noise=3.0)
    g = clean.gt_arrays
    ok = _checkable(g)
    rc = _pull_back(clean.images[1], g["flow"]) - clean.images[0]
    rn = _pull_back(noisy.images[1], g["flow"]) - noisy.images[0]
    d = (rn - rc)[ok]
    # Noise sigma in each frame; bilinear weights w_i give frame 1's share
    # sigma^2 sum w_i^2 in [sigma^2/4, sigma^2]: std of d in [sigma*sqrt(1.25),
    # sigma*sqrt(2)], widened by 10 % for sampling and rounding.
    assert 3.0 * np.sqrt(1.25) * 0.9 < d.std() < 3.0 * np.sqrt(2.0) * 1.1


def test_occlusion_and_large_motion_variants():
    big = render("flow-large", size=SIZE, seed=0)
    assert big.gt["max_motion_px"] > 40
    assert big.gt_arrays["occluded"].mean() > 0.1  # a large motion uncovers a lot
    vid = render("flow-video", size=SIZE, seed=0)
    occ = vid.gt_arrays["occluded"]
    assert 0.02 < occ.mean() < 0.3  # the added box hides part of the background


def test_sequence_flows_chain():
    s = render("flow-sequence", size=SIZE, seed=0, moving_object=False)
    f = s.gt_arrays["flows"]
    assert f.shape == (4, SIZE[1], SIZE[0], 2)
    assert np.array_equal(f[0], s.gt_arrays["flow"])
