"""Device rows of ``lumigraph bench gpu`` for calibration's resampling:
``calib undistort`` and ``calib rectify``.

Cases (synthetic, built here; nothing was tuned on them):

- ``calib undistort``: an 8-bit RGB image of 4000x3000 (12 MP; quick:
  640x480) from a camera with strong radial and tangential distortion
  (k1 = −0.25, k2 = 0.08, p1 = 1e-3, p2 = −5e-4, k3 = −0.01). The source
  image is a smooth analytic pattern ``g(x, y)`` of the source pixel, so the
  truth of an output pixel is ``g`` at its exact (float64) source position:
  error vs truth is the RMS code error over output pixels whose source lies
  inside the image (interpolation plus 8-bit rounding).
- ``calib rectify``: a pair of 1600x1200 (quick: 320x240) 8-bit grey images
  of a verged rig with distortion; same truth construction on both views.

Rows: ``cpu`` (ours: the maps cached on the object, then ``cv2.remap``),
``torch-cpu`` (``--quick`` only: minutes at full size), ``cuda`` (the maps cached on the device, then the torch
resampler), and the peer: ``cv2.undistort`` (maps rebuilt each call) for
undistort, ``cv2.initUndistortRectifyMap`` + ``cv2.remap`` per call for
rectify. Every CPU row runs single-threaded.
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.bench_device import (
    DeviceRow,
    device_rows,
    measure,
    repeats_for,
    single_thread,
)


def _g(x, y, w, h):
    """The analytic source pattern (codes, float64), smooth at the pixel scale."""
    return (127.5 + 60 * np.sin(2 * np.pi * x / (w / 23.0)) * np.cos(2 * np.pi * y / (h / 17.0))
            + 50 * np.sin(2 * np.pi * (x + y) / (w / 7.0)))


def _source(w, h, channels):
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    base = _g(x, y, w, h)
    img = np.stack([base * (1 - 0.1 * c) + 10 * c for c in range(channels)], -1) if channels > 1 \
        else base
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _truth_maps(camera, R, P, size):
    """The exact float64 source position of every output pixel (OpenCV's map,
    unrounded), from the camera model's own distortion formula."""
    w, h = size
    iR = np.linalg.inv(np.asarray(P, np.float64)[:, :3] @ np.asarray(R, np.float64))
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    X = iR[0, 0] * u + iR[0, 1] * v + iR[0, 2]
    Y = iR[1, 0] * u + iR[1, 1] * v + iR[1, 2]
    W = iR[2, 0] * u + iR[2, 1] * v + iR[2, 2]
    xd = camera.distort_normalized(np.stack([(X / W).ravel(), (Y / W).ravel()], 1))
    K = camera.K
    return ((K[0, 0] * xd[:, 0] + K[0, 2]).reshape(h, w), (K[1, 1] * xd[:, 1] + K[1, 2]).reshape(h, w))


def _truth(img_shape, maps, size):
    w, h = size
    mx, my = maps
    inside = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
    t = _g(mx, my, w, h)
    channels = img_shape[2] if len(img_shape) == 3 else 1
    if channels > 1:
        t = np.stack([t * (1 - 0.1 * c) + 10 * c for c in range(channels)], -1)
    return t, inside


def _rms(out, truth, inside):
    d = np.asarray(out, np.float64) - truth
    return float(np.sqrt(np.mean(d[inside] ** 2)))


def rows(*, devices: tuple[str, ...], quick: bool) -> list[DeviceRow]:
    """The undistort and rectify rows (module docstring)."""
    import cv2

    from lumigraph.calib.rectify import rectify
    from lumigraph.calib.undistort import undistorter
    from lumigraph.capture.camera import Camera
    from lumigraph.capture.rig import Rig

    out_rows: list[DeviceRow] = []
    with single_thread():
        # ---- undistort
        w, h = (640, 480) if quick else (4000, 3000)
        f = 0.8 * w
        cam = Camera(np.array([[f, 0, w / 2 + 3.3], [0, f * 1.01, h / 2 - 2.1], [0, 0, 1]]),
                     np.array([-0.25, 0.08, 1e-3, -5e-4, -0.01]), (w, h))
        img = _source(w, h, 3)
        u = undistorter(cam)
        t, inside = _truth(img.shape, _truth_maps(cam, np.eye(3), u.camera.K, (w, h)), (w, h))
        stage, name = "calib undistort", f"{w}x{h} RGB 8-bit"
        # warmed on every device: the maps are built once per object and device,
        # not the per-image cost
        ref = device_rows(out_rows, stage, name, devices, lambda dev: u.apply(img, device=dev),
                          truth=lambda out: _rms(out, t, inside), quick=quick, warmup=True)
        K_new = u.camera.K
        row, _ = measure(stage, name, "opencv", lambda: cv2.undistort(img, cam.K, cam.dist,
                                                                       None, K_new),
                         reference=ref, truth=lambda out: _rms(out, t, inside),
                         repeats=repeats_for("cpu", quick),
                         peer="opencv", note="cv2.undistort: maps rebuilt every call")
        out_rows.append(row)

        # ---- rectify
        w, h = (320, 240) if quick else (1600, 1200)
        f = 0.9 * w
        left = Camera(np.array([[f, 0, w / 2 + 1.7], [0, f, h / 2 - 0.9], [0, 0, 1]]),
                      np.array([-0.18, 0.04, 5e-4, -3e-4, 0.0]), (w, h))
        right = Camera(np.array([[f * 1.02, 0, w / 2 - 2.2], [0, f * 1.02, h / 2 + 1.3], [0, 0, 1]]),
                       np.array([-0.15, 0.03, -4e-4, 2e-4, 0.0]), (w, h))
        Rr = cv2.Rodrigues(np.array([0.01, -0.06, 0.004]))[0]
        rect = rectify(Rig.from_pose(left, right, Rr, [-0.1, 0.002, 0.003]))
        imgs = (_source(w, h, 1), _source(w, h, 1))
        tl, il = _truth(imgs[0].shape, _truth_maps(left, rect.R1, rect.P1, (w, h)), (w, h))
        tr, ir = _truth(imgs[1].shape, _truth_maps(right, rect.R2, rect.P2, (w, h)), (w, h))
        truth_pair = np.stack([tl, tr])
        inside_pair = np.stack([il, ir])
        stage, name = "calib rectify", f"pair of {w}x{h} grey 8-bit"
        ref = device_rows(out_rows, stage, name, devices,
                          lambda dev: np.stack(rect.apply(*imgs, device=dev)),
                          truth=lambda out: _rms(out, truth_pair, inside_pair), quick=quick,
                          warmup=True)

        def peer():
            out = []
            for cam, R, P, im in ((left, rect.R1, rect.P1, imgs[0]), (right, rect.R2, rect.P2, imgs[1])):
                mx, my = cv2.initUndistortRectifyMap(cam.K, cam.dist, R, P[:, :3], (w, h),
                                                     cv2.CV_32FC1)
                out.append(cv2.remap(im, mx, my, cv2.INTER_LINEAR))
            return np.stack(out)

        row, _ = measure(stage, name, "opencv", peer, reference=ref,
                         truth=lambda out: _rms(out, truth_pair, inside_pair),
                         repeats=repeats_for("cpu", quick),
                         peer="opencv", note="initUndistortRectifyMap + remap every call")
        out_rows.append(row)
    return out_rows
