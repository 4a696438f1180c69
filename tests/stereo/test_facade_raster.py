"""The z-buffer rasteriser and a model's depth: exact against analytic depth."""

from __future__ import annotations

import numpy as np
import pytest

from lumigraph.capture.errors import InputError
from lumigraph.capture.raster import pixel_rays, rasterize
from lumigraph.stereo.debevec1996.raster import model_depth, visible

K = np.array([[60.0, 0, 31.5], [0, 55.0, 23.5], [0, 0, 1]])
SIZE = (64, 48)


def _box(lo, hi):
    """An axis-aligned box: 8 corners and 12 triangles (outward normals)."""
    from scipy.spatial import ConvexHull

    V = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])],
                 float)
    return V, ConvexHull(V).simplices


def _look_at(C, target):
    f = (target - C) / np.linalg.norm(target - C)
    r = np.cross(f, [0, 0, 1.0])
    r /= np.linalg.norm(r)
    R = np.stack([r, np.cross(f, r), f])
    return R, -R @ C


def test_plane_depth_exact_under_rotation():
    # a slanted world plane n.X = d seen by a rotated camera: depth along
    # each ray is d' / (n' . ray) in the camera frame, to rounding
    V = np.array([[-8.0, -8, 0], [8, -8, 0], [8, 8, 0.0], [-8, 8, 0]]) @ np.array(
        [[1, 0, 0], [0, np.cos(0.5), np.sin(0.5)], [0, -np.sin(0.5), np.cos(0.5)]]).T
    F = np.array([[0, 1, 2], [0, 2, 3]])
    R, t = _look_at(np.array([1.0, -12.0, 3.0]), np.array([0.0, 0.0, 0.0]))
    r = rasterize(V, F, K, R, t, SIZE)
    Vc = V @ R.T + t
    n = np.cross(Vc[1] - Vc[0], Vc[2] - Vc[0])
    rays = pixel_rays(K, SIZE)
    z = (n @ Vc[0]) / (rays @ n)
    assert r.hit.mean() > 0.5
    np.testing.assert_allclose(r.depth[r.hit], z[r.hit], rtol=1e-12)
    # barycentrics reproduce the hit point
    X = r.points(V, F)[r.hit]
    Xc = X @ R.T + t
    np.testing.assert_allclose(Xc[:, 2], r.depth[r.hit], rtol=1e-12)


def test_box_depth_and_face_ids():
    V, F = _box((-1, -1, 0), (1, 1, 2))
    R, t = _look_at(np.array([3.0, -4.0, 3.5]), np.array([0.0, 0.0, 1.0]))
    r = rasterize(V, F, K, R, t, SIZE)
    # analytic: the nearest of the box's six planes each ray meets inside the box
    C = -R.T @ t
    D = pixel_rays(K, SIZE) @ R  # world directions with unit camera z
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (np.array([-1, -1, 0]) - C) / D
        t1 = (np.array([1, 1, 2]) - C) / D
    tn = np.minimum(t0, t1).max(-1)
    tf = np.maximum(t0, t1).min(-1)
    hit = (tn <= tf) & (tn > 0)
    # pixels whose ray grazes an edge may go either way; all others agree
    assert (hit == r.hit).mean() > 0.99
    both = hit & r.hit
    np.testing.assert_allclose(r.depth[both], tn[both], rtol=1e-9)
    # each pixel's face contains its point: the face's plane passes through it
    X = r.points(V, F)[r.hit]
    tri = V[F[r.face[r.hit]]]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.abs(np.einsum("ij,ij->i", X - tri[:, 0], nrm)).max() < 1e-9
    # the camera sees three faces of the box (six triangles at most), never the bottom
    seen = set(np.unique(r.face[r.hit]).tolist())
    assert 3 <= len(seen) <= 6
    assert all(V[F[f]][:, 2].max() > 0 for f in seen)


def test_occlusion_nearest_wins_and_visibility():
    near = np.array([[-0.5, -0.5, 3.0], [0.5, -0.5, 3.0], [0.5, 0.5, 3.0], [-0.5, 0.5, 3.0]])
    far = near * [4, 4, 1] + [0, 0, 3]
    V = np.concatenate([far, near])
    F = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    z = model_depth((V, F), K, np.eye(3), np.zeros(3), SIZE)
    assert z.dtype == np.float32
    assert z[23, 31] == 3.0 and z[23, 42] == 6.0 and np.isnan(z[2, 2])
    centre_far = np.array([[0.0, 0.0, 6.0]])  # behind the near square
    side_far = np.array([[1.5, 0.0, 6.0]])
    depth = np.where(np.isnan(z), np.inf, z)
    assert not visible(centre_far, K, np.eye(3), np.zeros(3), depth)[0][0]
    assert visible(side_far, K, np.eye(3), np.zeros(3), depth)[0][0]


def test_triangle_behind_and_across_the_camera():
    # a ground plane reaching behind the camera is rasterised without clipping
    V = np.array([[-50.0, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]])
    F = np.array([[0, 1, 2], [0, 2, 3]])
    R, t = _look_at(np.array([0.0, 0.0, 2.0]), np.array([0.0, 10.0, 0.0]))
    r = rasterize(V, F, K, R, t, SIZE)
    rays = pixel_rays(K, SIZE) @ R  # world direction per unit camera z
    C = -R.T @ t
    with np.errstate(divide="ignore"):
        lam = -C[2] / rays[..., 2]
    P = C + lam[..., None] * rays
    inside = (lam > 0) & (np.abs(P[..., 0]) < 50) & (np.abs(P[..., 1]) < 50)
    assert (r.hit == inside).all()
    np.testing.assert_allclose(r.depth[inside], lam[inside], rtol=1e-9)
    # wholly behind: nothing
    r2 = rasterize(V, F, K, np.diag([1.0, -1, -1]), np.array([0, 0, -5.0]), SIZE)
    assert not r2.hit.any()


def test_bad_mesh_is_input_error():
    with pytest.raises(InputError, match="mesh"):
        rasterize(np.zeros((3, 2)), [[0, 1, 2]], K, np.eye(3), np.zeros(3), SIZE)
    with pytest.raises(InputError, match="outside"):
        rasterize(np.zeros((3, 3)), [[0, 1, 3]], K, np.eye(3), np.zeros(3), SIZE)


def test_labels_replace_the_triangle_ids():
    # labels[m] where triangle m is seen, -1 elsewhere; depth, barycentrics and
    # per-triangle coverage as without them
    V, F = _box((-1, -1, 0), (1, 1, 2))
    R, t = _look_at(np.array([3.0, -4.0, 3.5]), np.array([0.0, 0.0, 1.0]))
    labels = np.arange(len(F)) // 2 + 100  # two triangles a side: one label a side
    a = rasterize(V, F, K, R, t, SIZE)
    b = rasterize(V, F, K, R, t, SIZE, labels=labels)
    np.testing.assert_array_equal(b.face, np.where(a.hit, labels[np.maximum(a.face, 0)], -1))
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.bary, b.bary)
    np.testing.assert_array_equal(a.covered, b.covered)
