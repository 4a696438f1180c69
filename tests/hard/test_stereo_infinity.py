"""Hard case: points at infinity (parallel rays) are reported as directions,
never as huge finite points."""

import numpy as np

from lumigraph.capture.camera import Camera
from lumigraph.stereo.triangulate import triangulate


def test_points_at_infinity_are_directions():
    cam = Camera(np.array([[500., 0, 320], [0, 510, 240], [0, 0, 1]]), np.zeros(5), (640, 480))
    poses = [(np.eye(3), np.zeros(3)), (np.eye(3), np.array([-0.3, 0.0, 0.0]))]
    dirs = np.array([[0.1, 0.05, 1.0], [-0.2, 0.1, 1.0]])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    # a point at infinity projects to the same pixel in both views (pure translation)
    px = np.stack([cam.project(dirs), cam.project(dirs)])
    tri = triangulate(px, [cam, cam], poses)
    assert tri.at_infinity.all() and tri.near_parallel.all()
    assert np.isnan(tri.points).all()
    got = tri.points_h[:, :3] / np.linalg.norm(tri.points_h[:, :3], axis=1, keepdims=True)
    assert np.allclose(got, dirs, atol=1e-9)
    assert len(tri.warnings) == 2
