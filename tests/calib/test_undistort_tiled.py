"""``calib undistort`` by bands of rows gives the whole image's pixels.

The map is computed per pixel from its own coordinates (the same bits as
OpenCV's ``initUndistortRectifyMap``, checked here), a band reads only the
source rows its map samples (plus one on each side for OpenCV's 1/32-pixel
rounding), so every output pixel is the whole image's, to the bit.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile

from lumigraph.calib.undistort import undistorter
from lumigraph.capture.camera import Camera
from lumigraph.capture.io import read_image
from tests.conftest import lumigraph

CAM = Camera(np.array([[300.0, 0, 131], [0, 290, 97], [0, 0, 1]]),
             [-0.35, 0.12, 0.002, -0.003, 0], (253, 187))


def test_maps_are_opencvs_and_bands_are_the_whole_image():
    import cv2

    rng = np.random.default_rng(0)
    img = rng.integers(0, 65535, (187, 253, 3), dtype=np.uint16)
    grey = rng.random((187, 253), dtype=np.float32)
    for keep_all in (False, True):
        u = undistorter(CAM, keep_all=keep_all)
        cx, cy = cv2.initUndistortRectifyMap(CAM.K, CAM.dist, np.eye(3), u.camera.K,
                                             CAM.image_size, cv2.CV_32FC1)
        mx, my = u.maps()
        assert mx.tobytes() == cx.tobytes() and my.tobytes() == cy.tobytes()
        for a in (img, grey):
            whole = u.apply(a)
            for rows in (1, 6, 50):
                got = np.concatenate([u.apply_rows(lambda r0, r1, a=a: a[r0:r1], y,
                                                   min(y + rows, 187))
                                      for y in range(0, 187, rows)])
                assert got.reshape(whole.shape).tobytes() == whole.tobytes(), (keep_all, rows)


@pytest.mark.parametrize("bits", [8, 16])
def test_cli_undistort_by_rows_matches_whole(tmp_path, bits):
    rng = np.random.default_rng(bits)
    dtype = np.uint8 if bits == 8 else np.uint16
    img = rng.integers(0, 2 ** bits - 1, (187, 253, 3)).astype(dtype)
    tifffile.imwrite(tmp_path / "shot.tif", img, rowsperstrip=5, photometric="rgb")
    CAM.save(tmp_path / "camera.json")
    for tag, extra in (("whole", []), ("rows", ["--tile", "7"])):
        r = lumigraph("calib", "undistort", "--camera", tmp_path / "camera.json",
                      tmp_path / "shot.tif", "--out", tmp_path / tag, *extra)
        assert r.returncode == 0, r.stderr
    a, b = read_image(tmp_path / "whole" / "shot.png"), read_image(tmp_path / "rows" / "shot.png")
    assert a.dtype == b.dtype == dtype and a.tobytes() == b.tobytes()
    meta = json.loads((tmp_path / "rows" / "camera.json.meta.json").read_text())
    assert meta["tiles"]["tiled"] and meta["tiles"]["bands"] == 27
