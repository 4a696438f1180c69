"""Ground truth of the stereo scenes, checked independently of the renderer's
own bookkeeping: warping the right image by the GT correspondence reproduces
the left image; GT points project to the GT right positions through the rig."""

import numpy as np
import pytest
from scipy import ndimage

from lumigraph.capture.render import render


def _warp_residual(s, xy):
    import cv2

    # A light blur of both images removes near-Nyquist texture, which bilinear
    # resampling cannot reproduce (the unrectified right view is rotated and
    # 2 % larger); it does not hide a wrong correspondence (1 px is a big error).
    L = cv2.GaussianBlur(s.images[0].astype(np.float32), (0, 0), 1.0)
    R = cv2.GaussianBlur(s.images[1].astype(np.float32), (0, 0), 1.0)
    mx = np.nan_to_num(xy[..., 0], nan=-10).astype(np.float32)
    my = np.nan_to_num(xy[..., 1], nan=-10).astype(np.float32)
    warped = cv2.remap(R, mx, my, cv2.INTER_LINEAR, borderValue=0)
    ok = np.isfinite(xy).all(axis=2)
    # away from depth edges: anti-aliased edge pixels mix two surfaces
    Z = s.gt_arrays["depth"]
    edge = ndimage.maximum_filter(np.nan_to_num(Z, nan=99), 5) - ndimage.minimum_filter(
        np.nan_to_num(Z, nan=99), 5) > 0.05
    ok &= ~edge
    # and away from occlusion borders (the right pixel there mixes the occluder)
    ok &= ~ndimage.binary_dilation(~np.isfinite(xy).all(axis=2), iterations=3)
    ok[:2], ok[-2:], ok[:, :2], ok[:, -2:] = False, False, False, False
    return np.abs(warped - L)[ok], ok


@pytest.mark.parametrize("layout", ["rectified", "unrectified"])
def test_gt_correspondence_warps_right_onto_left(layout):
    s = render("stereo-pair", size=(160, 120), layout=layout, noise=0.0, textureless=True)
    xy = s.gt_arrays["right_xy"]
    if layout == "rectified":
        # disparity and right_xy agree: x_right = x_left - d, same row
        ys, xs = np.mgrid[0:120, 0:160]
        d = s.gt_arrays["disparity"]
        ok = np.isfinite(d)
        assert np.allclose(xy[..., 0][ok], (xs - d)[ok], atol=1e-4)
        assert np.allclose(xy[..., 1][ok], ys[ok], atol=1e-9)
    res, ok = _warp_residual(s, xy)
    assert ok.mean() > 0.5
    # noise-free renders: what is left is bilinear interpolation of an
    # anti-aliased texture (a fraction of a code value typically)
    assert np.median(res) < 1.0 and np.percentile(res, 90) < 4.0
    # the wrong correspondence (no warp) is far worse: the check can fail
    ys, xs = np.mgrid[0:120, 0:160].astype(np.float64)
    wrong, _ = _warp_residual(s, np.stack([xs, ys], axis=-1))
    assert np.median(wrong) > 4 * max(np.median(res), 0.5)


def test_gt_points_project_through_the_rig():
    s = render("stereo-pair", size=(160, 120), layout="unrectified")
    rig = s.gt["rig"]
    R, T = np.array(rig["R"]), np.array(rig["T"])
    Kr = np.array(rig["right"]["K"])
    P = s.gt_arrays["points"]
    xy = s.gt_arrays["right_xy"]
    ok = np.isfinite(xy).all(axis=2)
    pr = P[ok] @ R.T + T
    uv = pr @ Kr.T
    uv = uv[:, :2] / uv[:, 2:]
    assert np.max(np.abs(uv - xy[ok])) < 1e-9
    # depth is the left camera's Z of the points
    assert np.allclose(P[..., 2][np.isfinite(P[..., 2])], s.gt_arrays["depth"][np.isfinite(P[..., 2])])
    # occluded points exist (the sphere hides the background from the right camera)
    assert 0.02 < s.gt["occluded_fraction"] < 0.5


def test_multiview_depths_are_consistent_between_views():
    s = render("stereo-views", size=(160, 120), views=3, noise=0.0)
    K = np.array(s.gt["camera"]["K"])
    poses = [(np.array(p["R"]), np.array(p["t"])) for p in s.gt["cam_from_world"]]
    Z0 = np.nan_to_num(s.gt_arrays["depth"][0].astype(np.float64), posinf=1e3)
    ys, xs = np.mgrid[0:120, 0:160].astype(np.float64)
    pc = np.stack([xs, ys, np.ones_like(xs)], -1) @ np.linalg.inv(K).T * Z0[..., None]
    R0, t0 = poses[0]
    Xw = (pc.reshape(-1, 3) - t0) @ R0   # world = R0^T (x_cam - t0)
    R1, t1 = poses[1]
    c1 = Xw @ R1.T + t1
    uv = c1 @ K.T
    uv = uv[:, :2] / uv[:, 2:]
    inside = (uv[:, 0] > 1) & (uv[:, 0] < 158) & (uv[:, 1] > 1) & (uv[:, 1] < 118)
    Z1 = ndimage.map_coordinates(s.gt_arrays["depth"][1].astype(np.float64),
                                 [uv[inside, 1], uv[inside, 0]], order=0)
    rel = np.abs(Z1 - c1[inside, 2]) / c1[inside, 2]
    visible = rel < 0.01
    assert visible.mean() > 0.6   # most of view 0 is seen, at the right depth, by view 1
    # and the images agree there (Lambertian scene, noise-free)
    I0 = s.images[0].astype(np.float64).reshape(-1, 3)[inside][visible]
    I1 = np.stack([ndimage.map_coordinates(s.images[1][..., c].astype(np.float64),
                                           [uv[inside, 1][visible], uv[inside, 0][visible]], order=1)
                   for c in range(3)], -1)
    assert np.median(np.abs(I0 - I1)) < 6.0
