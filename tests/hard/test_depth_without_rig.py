"""``stereo depth`` of a rectified pair known only by focal length and
baseline (Middlebury's calib.txt convention), and its refusals."""

import numpy as np
from conftest import assert_clean_error, lumigraph

from lumigraph.capture import io


def test_points_follow_the_calib_txt_convention(tmp_path):
    h, w = 12, 16
    d = np.full((h, w), 20.0, np.float32)
    d[0, 0] = np.inf  # unknown: no point
    d[1, 1] = -30.0   # d + doffs < 0: behind the camera, no point
    io.write_pfm(tmp_path / "d.pfm", d)
    f, b, cx, cy, doffs = 100.0, 0.5, 7.0, 5.0, 5.0
    r = lumigraph("stereo", "depth", tmp_path / "d.pfm", "--focal-px", f, "--baseline", b, "--cx", cx,
                  "--cy", cy, "--doffs", doffs, "--out", tmp_path / "p.ply", "-q")
    assert r.returncode == 0, r.stderr
    pts, _ = io.read_ply(tmp_path / "p.ply")
    assert len(pts) == h * w - 2
    z = b * f / (20.0 + doffs)  # Z = baseline f / (d + doffs) = 2.0
    assert np.allclose(pts[:, 2], z)
    # pixel (x, y) = (15, 11), the last one: X = (x - cx) Z / f, Y = (y - cy) Z / f
    assert np.allclose(pts[-1], [(15 - cx) * z / f, (11 - cy) * z / f, z])


def test_without_rig_or_focal_is_refused(tmp_path):
    io.write_pfm(tmp_path / "d.pfm", np.full((8, 8), 3.0, np.float32))
    r = lumigraph("stereo", "depth", tmp_path / "d.pfm", "--baseline", "1", "--out", tmp_path / "p.ply")
    assert_clean_error(r, "--focal-px")
    io.write_image(tmp_path / "im.png", np.zeros((9, 8), np.uint8))
    r = lumigraph("stereo", "depth", tmp_path / "d.pfm", "--focal-px", "10", "--baseline", "1",
                  "--image", tmp_path / "im.png", "--out", tmp_path / "p.ply")
    assert_clean_error(r, "differs from the disparity")
    assert not (tmp_path / "p.ply").exists()
