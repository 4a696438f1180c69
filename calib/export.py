"""Exports of calibrations to other tools' formats.

* OpenCV YAML (``cv2.FileStorage`` readable): ``camera_matrix``,
  ``distortion_coefficients``, ``image_width``, ``image_height`` (the names of
  OpenCV's calibration sample); for a rig also ``K1 D1 K2 D2 R T E F``.
* COLMAP ``cameras.txt``: ``PINHOLE`` for the ``none`` model, ``OPENCV``
  (fx fy cx cy k1 k2 p1 p2) for models up to k1k2p1p2, ``FULL_OPENCV`` (… k3
  k4 k5 k6) for k1k2p1p2k3 and rational. COLMAP has no skew: it must be 0.

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.camera import Camera
>>> cam = Camera(np.array([[500., 0, 321], [0, 498, 239], [0, 0, 1]]), [-0.1, 0.01, 0, 0, 0], (640, 480),
...              "k1k2")
>>> colmap_cameras([cam]).splitlines()[-1]
'1 OPENCV 640 480 500.0 498.0 321.0 239.0 -0.1 0.01 0.0 0.0'
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lumigraph.capture.camera import Camera


def opencv_yaml(camera: Camera, *, rig=None) -> str:
    """The camera (or, with ``rig``, the stereo rig) as OpenCV FileStorage YAML text."""
    import cv2

    fs = cv2.FileStorage("calib.yml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    w, h = camera.image_size
    fs.write("image_width", int(w))
    fs.write("image_height", int(h))
    if rig is None:
        fs.write("camera_matrix", camera.K)
        fs.write("distortion_coefficients", camera.dist.reshape(1, -1))
        fs.write("distortion_model", camera.model)
        if "rms_px" in camera.extra:
            fs.write("avg_reprojection_error", float(camera.extra["rms_px"]))
    else:
        for name, m in (("K1", rig.left.K), ("D1", rig.left.dist.reshape(1, -1)), ("K2", rig.right.K),
                        ("D2", rig.right.dist.reshape(1, -1)), ("R", rig.R), ("T", rig.T.reshape(3, 1)),
                        ("E", rig.E), ("F", rig.F)):
            fs.write(name, np.asarray(m, np.float64))
    return fs.releaseAndGetString()


def _num(v: float) -> str:
    return repr(float(v))  # shortest text that round-trips the float64


def colmap_cameras(cameras: Sequence[Camera]) -> str:
    """COLMAP ``cameras.txt`` text, camera ids 1..N in the given order."""
    lines = ["# Camera list with one line of data per camera:",
             "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
             f"# Number of cameras: {len(cameras)}"]
    for i, cam in enumerate(cameras, start=1):
        if abs(cam.K[0, 1]) > 1e-9:
            raise ValueError(f"cameras[{i - 1}]: COLMAP models have no skew, got K[0, 1] = {cam.K[0, 1]}")
        fx, fy, cx, cy = cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]
        d = np.zeros(8)
        d[: cam.dist.size] = cam.dist
        if cam.model == "none" and not np.any(d):
            model, params = "PINHOLE", [fx, fy, cx, cy]
        elif not np.any(d[4:]):
            model, params = "OPENCV", [fx, fy, cx, cy, *d[:4]]
        else:
            model, params = "FULL_OPENCV", [fx, fy, cx, cy, *d[:4], *d[4:8]]
        w, h = cam.image_size
        lines.append(f"{i} {model} {w} {h} " + " ".join(_num(p) for p in params))
    return "\n".join(lines) + "\n"
