"""Triangulation: exactness, first-order uncertainty, flags."""

import numpy as np
import pytest

from lumigraph.capture.camera import Camera
from lumigraph.stereo.triangulate import midpoint, triangulate


def _rig(n, rng, *, baseline=0.45, depth=(3, 7)):
    cams = [Camera(np.array([[610., 0, 331], [0, 598, 236], [0, 0, 1]]),
                   np.array([-0.12, 0.03, 1e-3, -5e-4, 0.0]), (640, 480)),
            Camera(np.array([[590., 0, 318], [0, 585, 244], [0, 0, 1]]),
                   np.array([-0.08, 0.01, -4e-4, 6e-4, 0.0]), (640, 480)),
            Camera(np.array([[600., 0, 320], [0, 600, 240], [0, 0, 1]]), np.zeros(5), (640, 480))]
    a = np.radians(-7.0)
    Ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    b = np.radians(4.0)
    Rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    poses = [(np.eye(3), np.zeros(3)), (Ry, np.array([-baseline, 0.02, 0.04])),
             (Rx @ Ry.T, np.array([0.3, -0.25, 0.1]))]
    X = np.column_stack([rng.uniform(-1.2, 1.2, n), rng.uniform(-0.9, 0.9, n), rng.uniform(*depth, n)])
    return cams, poses, X


@pytest.mark.parametrize("views", [2, 3])
@pytest.mark.parametrize("method", ["refined", "dlt"])
def test_noise_free_is_exact(views, method):
    cams, poses, X = _rig(300, np.random.default_rng(0))
    cams, poses = cams[:views], poses[:views]
    px = np.stack([c.project_world(X, *p) for c, p in zip(cams, poses, strict=True)])
    tri = triangulate(px, cams, poses, method=method)
    rel = np.linalg.norm(tri.points - X, axis=1) / np.linalg.norm(X, axis=1)
    assert rel.max() < 1e-6
    assert np.nanmax(tri.reprojection_rms) < 1e-6


def test_midpoint_eq_5_2_on_exact_rays():
    X = midpoint(np.zeros(3), np.array([[0.1, 0.2, 1.0]]), np.array([1.0, 0, 0]),
                 np.array([[0.1 - 0.5, 0.2, 1.0]]) * 2)
    assert np.allclose(X, [[0.2, 0.4, 2.0]])


def test_error_matches_first_order_prediction():
    # 4000 points, 0.5 px noise: the RMS 3-D error must equal the predicted
    # sqrt(trace cov) within 10 %. Sampling spread of the ratio ~ 1/sqrt(2*3*4000)
    # ~ 0.6 %, plus the spread of per-point sigmas: a few %; a wrong covariance
    # (e.g. missing the pixel noise scale or a factor 2) fails clearly.
    rng = np.random.default_rng(5)
    cams, poses, X = _rig(4000, rng)
    cams, poses = cams[:2], poses[:2]
    px = np.stack([c.project_world(X, *p) for c, p in zip(cams, poses, strict=True)])
    tri = triangulate(px + rng.normal(0, 0.5, px.shape), cams, poses, pixel_sigma=0.5)
    e = tri.points - X
    ratio = np.sqrt(np.mean(np.sum(e ** 2, 1))) / np.sqrt(np.mean(tri.sigma ** 2))
    assert 0.9 < ratio < 1.1
    maha = np.einsum("ni,nij,nj->n", e, np.linalg.inv(tri.covariance), e)
    assert 2.7 < maha.mean() < 3.3   # chi-square with 3 dof


def test_near_parallel_flagged():
    rng = np.random.default_rng(1)
    cams, poses, _ = _rig(1, rng)
    # angle subtended by a 0.45 m baseline: 0.5 deg at ~52 m
    X = np.array([[0.5, 0.2, 20.0], [0.5, 0.2, 200.0]])
    px = np.stack([c.project_world(X, *p) for c, p in zip(cams[:2], poses[:2], strict=True)])
    tri = triangulate(px, cams[:2], poses[:2])
    assert tri.angle_deg[0] > 0.5 > tri.angle_deg[1]
    assert tri.near_parallel.tolist() == [False, True]
    assert any("0.5 deg" in w for w in tri.warnings)
    assert tri.sigma[1] > 50 * tri.sigma[0]   # and its uncertainty says why


def test_track_with_one_view_refused():
    cams, poses, X = _rig(3, np.random.default_rng(2))
    px = np.stack([c.project_world(X, *p) for c, p in zip(cams[:2], poses[:2], strict=True)])
    px[1, 0] = np.nan
    with pytest.raises(ValueError, match="at least 2 views"):
        triangulate(px, cams[:2], poses[:2])
