"""Device rows of ``lumigraph bench gpu`` for stereo: the SSD block-matching
scan (``stereo match --method ssd``) and flow warping.

Cases (synthetic, built here; nothing was tuned on them):

- ``stereo match (ssd)``: a rectified 8-bit grey pair of 1280x960 (quick:
  320x240), a blurred random texture with a background at disparity 12 and a
  fronto-parallel box at 40 (quick: 6 and 20); 64 disparities searched
  (quick: 32), window 9. The left view is the right one shifted by the true
  disparity per pixel (the box occludes the background), plus Gaussian
  noise σ = 2 codes. Error vs truth: bad-2.0, the share of non-occluded
  pixels (right of the search range's strip) whose disparity is off by more
  than 2 px or unknown, in %. Rows: ``cpu`` (ours: the compiled kernel,
  one thread), ``torch-cpu``, ``cuda`` (the scan on torch, the decision on
  numpy), and the peers ``cv2.StereoBM`` (9x9, its texture and uniqueness
  tests) and ``cv2.StereoSGBM`` (block 5, its default smoothness), which
  solve the same problem with their own rules: their error column compares
  methods, their time the library calls.
- ``stereo match (sgm)``: the same pair through semi-global matching (census,
  defaults), the aggregation on the device; peer ``cv2.StereoSGBM``.
- ``flow warp``: bicubic backward warp (replicate border) of a 2048x1536
  (quick: 512x384) float32 grey image by a smooth flow of up to ±6 px. The
  image is an analytic pattern, so the truth is the pattern at ``x + flow``:
  error vs truth is the RMS over pixels whose sample stays 2 px inside.
  Rows: ``cpu`` (ours, ``cv2.remap``), ``torch-cpu``, ``cuda``, and the peer
  ``scipy.ndimage.map_coordinates`` (cubic spline, order 3).

Every CPU row runs single-threaded.
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.bench_device import DeviceRow, measure


def _pair(quick: bool):
    from scipy.ndimage import gaussian_filter

    w, h = (320, 240) if quick else (1280, 960)
    d_bg, d_box = (6, 20) if quick else (12, 40)
    rng = np.random.default_rng(40)
    tex = gaussian_filter(rng.uniform(0, 255, (h, w + 2 * d_box)), 1.2)
    tex = (tex - tex.min()) / (tex.max() - tex.min()) * 235 + 10
    box_tex = gaussian_filter(rng.uniform(0, 255, (h, w + 2 * d_box)), 1.2)
    box_tex = (box_tex - box_tex.min()) / (box_tex.max() - box_tex.min()) * 235 + 10
    y0, y1, x0, x1 = h // 4, 3 * h // 4, w // 3, 2 * w // 3  # the box in the left view
    gt = np.full((h, w), float(d_bg))
    gt[y0:y1, x0:x1] = d_box
    # right view: background at x_r, box at x_r where the box projects (x_l - d_box)
    right = tex[:, d_box:d_box + w].copy()
    right[y0:y1, x0 - d_box:x1 - d_box] = box_tex[y0:y1, x0:x1]
    xs = np.arange(w)[None, :] - gt.astype(int)
    left = np.where(xs >= 0, np.take_along_axis(right, np.clip(xs, 0, w - 1), 1), 0.0)
    # background pixels the box hides in the right view are occluded
    occluded = np.zeros((h, w), bool)
    occluded[y0:y1, max(0, x1 - d_box + d_bg):x1] = True
    occluded[y0:y1, x0:x1] = False
    rng2 = np.random.default_rng(41)
    left = np.clip(np.round(left + rng2.normal(0, 2, left.shape)), 0, 255).astype(np.uint8)
    right = np.clip(np.round(right + rng2.normal(0, 2, right.shape)), 0, 255).astype(np.uint8)
    return left, right, gt, occluded


def _bad2(disp, gt, mask):
    bad = ~(np.abs(disp - gt) <= 2.0)  # unknown (NaN, or -1 for the peers) is bad
    return float(100.0 * bad[mask].mean())


def rows(*, devices: tuple[str, ...], quick: bool) -> list[DeviceRow]:
    """The block-matching and flow-warp rows (module docstring)."""
    import cv2

    from lumigraph.capture.bench_device import device_rows, repeats_for, single_thread
    from lumigraph.stereo.block_matching import match
    from lumigraph.stereo.hirschmuller2008 import match as sgm_match
    from lumigraph.stereo.pyramid import warp

    out_rows: list[DeviceRow] = []
    with single_thread():
        # ---- ssd block matching
        left, right, gt, occ = _pair(quick)
        h, w = left.shape
        D = 32 if quick else 64
        mask = ~occ
        mask[:, :D] = False
        stage, name = "stereo match (ssd)", f"{w}x{h} grey 8-bit, {D} disparities, window 9"

        def ours(dev):
            r = match(left, right, max_disp=D - 1, window=9, device=dev, threads=1)
            return np.where(np.isfinite(r.disparity), r.disparity, -1.0)

        ref = device_rows(out_rows, stage, name, devices, ours,
                          truth=lambda o: _bad2(o, gt, mask), quick=quick,
                          note="unknown stored as -1 in the difference")
        bm = cv2.StereoBM_create(numDisparities=D, blockSize=9)
        sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=D, blockSize=5,
                                     P1=8 * 25, P2=32 * 25, uniquenessRatio=5)
        for label, m in (("opencv StereoBM", bm), ("opencv StereoSGBM", sgbm)):
            def peer(m=m):
                d = m.compute(left, right).astype(np.float32) / 16.0
                return np.where(d >= 0, d, -1.0)

            row, _ = measure(stage, name, label, peer, reference=ref,
                             truth=lambda o: _bad2(o, gt, mask), repeats=repeats_for("cpu", quick), peer="opencv",
                             note="another method: its difference is not rounding")
            out_rows.append(row)

        # ---- sgm (the aggregation on the device), same pair
        stage, name = "stereo match (sgm)", f"{w}x{h} grey 8-bit, {D} disparities, census"

        def ours_sgm(dev):
            r = sgm_match(left, right, max_disp=D - 1, device=dev)
            return np.where(np.isfinite(r.disparity), r.disparity, -1.0)

        ref = device_rows(out_rows, stage, name, devices, ours_sgm,
                          truth=lambda o: _bad2(o, gt, mask), quick=quick,
                          note="aggregation on the device; census, costs, checks on the CPU")

        def sgbm_peer():
            d = sgbm.compute(left, right).astype(np.float32) / 16.0
            return np.where(d >= 0, d, -1.0)

        row, _ = measure(stage, name, "opencv StereoSGBM", sgbm_peer, reference=ref,
                         truth=lambda o: _bad2(o, gt, mask), repeats=repeats_for("cpu", quick), peer="opencv",
                         note="another SGM: its difference is not rounding")
        out_rows.append(row)

        # ---- flow warp
        w, h = (512, 384) if quick else (2048, 1536)
        y, x = np.mgrid[0:h, 0:w].astype(np.float64)

        def pattern(px, py):
            return np.sin(px / 7.3) * np.cos(py / 5.1) + 0.5 * np.sin((px + 2 * py) / 17.0)

        img = pattern(x, y).astype(np.float32)
        flow = np.stack([6 * np.sin(y / 97.0) * np.cos(x / 131.0), 4 * np.cos(x / 83.0)],
                        -1).astype(np.float32)
        sx, sy = x + flow[..., 0], y + flow[..., 1]
        truth_img = pattern(sx, sy)
        inner = (sx >= 2) & (sx <= w - 3) & (sy >= 2) & (sy <= h - 3)
        stage, name = "flow warp", f"{w}x{h} grey float32, bicubic"

        def rms(o):
            return float(np.sqrt(np.mean((o - truth_img)[inner] ** 2)))

        ref = device_rows(out_rows, stage, name, devices, lambda dev: warp(img, flow, device=dev),
                          truth=rms, quick=quick)

        def scipy_peer():
            from scipy.ndimage import map_coordinates

            return map_coordinates(img, [sy.astype(np.float32), sx.astype(np.float32)], order=3,
                                   mode="nearest")

        row, _ = measure(stage, name, "scipy map_coordinates", scipy_peer, reference=ref,
                         truth=rms, repeats=repeats_for("cpu", quick), peer="scipy",
                         note="cubic B-spline (prefiltered), another kernel")
        out_rows.append(row)
    return out_rows
