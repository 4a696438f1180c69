"""Corner refinement in the board's local flat frame, tried on the ChArUco
family of ``lumigraph bench calib`` (docs/decisions/calibration-model-choice.md,
"charuco 320 blur 0.6 s12: local-frame refinement"). Not adopted; kept so the
figures there can be re-run.

For every corner with at least five non-collinear neighbours in its 3x3
neighbourhood (board ids), a homography from the board (in squares, origin at
the corner) to the image is fitted to the detected corners; a tile around the
corner is resampled through it (one ``cv2.remap`` for all corners, bicubic)
into a fronto-parallel mosaic, ``cornerSubPix`` refines all tiles at once, and
the result is mapped back through the homography. A move of more than
``MAX_MOVE_PX`` from the first refinement is refused (a tile whose homography
rests on four or five corners can put the saddle elsewhere).

Usage (sets as board:width:seed:blur[:distortion, default normal]; ``old`` = ``calib.detect`` as is,
``new`` = plus this refinement, ``lens`` = ``new``, calibrate, refine again through
the calibrated lens, calibrate; ``LF_SCALE`` = tile pixels per image pixel of
square spacing, ``LF_IT`` = passes, ``LF_WF`` = window as a share of a square)::

    OPENBLAS_NUM_THREADS=1 python docs/decisions/charuco_local_frame.py new charuco:320:12:0.6 charuco:320:4:0.6

Prints per set: corner RMS against the rendered ground truth, the mean error
component along the radius from the principal point (± its standard error),
the focal error of ``calibrate(model="auto")`` in % and in its reported σ, the
principal point error, the chosen model and the detection time.
"""

import os
import sys
import time

import numpy as np

MAX_MOVE_PX = 0.25


def refine_local_frame(gray, pts, obj, square, *, scale=1.0, passes=1, window=0.4, camera=None):
    """Refined corners ``(N, 2)`` px from corners ``pts`` ``(N, 2)`` px whose
    board points are ``obj`` ``(N, 3)`` (mm, spacing ``square`` mm). With
    ``camera`` (K, dist) from a first calibration the homographies are fitted
    in undistorted normalised coordinates and the tiles pass through the lens
    (Datta et al. 2009), so the square's edges are straight in the tile."""
    import cv2

    lens = None
    if camera is not None:
        Kc, dc = camera

        def lens(xy):  # normalised -> distorted pixels
            z = np.zeros(3)
            return cv2.projectPoints(np.column_stack([xy, np.ones(len(xy))]), z, z, Kc, dc)[0].reshape(-1, 2)
        und = cv2.undistortPoints(np.asarray(pts, np.float64).reshape(-1, 1, 2), Kc, dc,
                                  criteria=(3, 50, 1e-12)).reshape(-1, 2)

    g32 = gray.astype(np.float32)
    pts = np.asarray(pts, np.float64).copy()
    start = pts.copy()
    ob = obj[:, :2] / square
    n = len(pts)
    near = np.linalg.norm(ob[:, None] - ob[None], axis=2) <= 1.5  # 3x3 incl. itself
    # tile scale: the image spacing of board-adjacent corners
    adj = np.abs(np.linalg.norm(ob[:, None] - ob[None], axis=2) - 1) < 1e-6
    spacing = float(np.median(np.linalg.norm(pts[:, None] - pts[None], axis=2)[adj]))
    S = max(scale * spacing, 8.0)
    win = max(2, int(np.floor(window * S)))
    c = win + 3
    T = 2 * c + 1
    u = (np.arange(T) - c) / S
    U, V = np.meshgrid(u, u)
    ok = np.zeros(n, bool)
    for i in range(n):
        j = np.flatnonzero(near[i])
        if j.size >= 5:
            sv = np.linalg.svd(ob[j] - ob[j].mean(0), compute_uv=False)
            ok[i] = sv[-1] > 0.3 * np.sqrt(j.size)
    quad = os.environ.get("LF_QUAD") == "1"
    full = near.sum(axis=1) == 9
    for _ in range(passes):
        Hs, idx = [], []
        for i in np.flatnonzero(ok):
            j = np.flatnonzero(near[i])
            if quad and full[i]:
                # a quadratic map: bends with the lens (a homography keeps lines straight)
                a, b = (ob[j] - ob[i]).T
                A = np.column_stack([np.ones_like(a), a, b, a * a, a * b, b * b])
                Hs.append(np.linalg.lstsq(A, pts[j], rcond=None)[0].T)  # (2, 6)
                idx.append(i)
                continue
            H, _ = cv2.findHomography(ob[j] - ob[i], pts[j] if lens is None else und[j], 0)
            if H is not None:
                Hs.append(H)
                idx.append(i)
        if not idx:
            return pts
        idx = np.array(idx)
        maps = [_tile_map(H, U, V) for H in Hs]
        mx = np.concatenate([m[0] for m in maps])
        my = np.concatenate([m[1] for m in maps])
        if lens is not None:
            q = lens(np.column_stack([mx.ravel(), my.ravel()]))
            mx, my = q[:, 0].reshape(mx.shape), q[:, 1].reshape(my.shape)
        mx, my = mx.astype(np.float32), my.astype(np.float32)
        mosaic = cv2.remap(g32, mx, my, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        init = np.column_stack([np.full(idx.size, c), c + T * np.arange(idx.size)]).astype(np.float32)
        # cornerSubPix refines its argument in place: hand it a copy
        r = cv2.cornerSubPix(mosaic, init.copy().reshape(-1, 1, 2), (win, win), (-1, -1),
                             (3, 40, 1e-3)).reshape(-1, 2)
        d = (r - init) / S
        new = np.array([_tile_map(H, d[k, 0], d[k, 1]) for k, H in enumerate(Hs)])
        if lens is not None:
            new = lens(new)
        keep = np.linalg.norm(new - start[idx], axis=1) < MAX_MOVE_PX
        pts[idx[keep]] = new[keep]
    return pts


def _tile_map(H, U, V):
    """Image (x, y) of board offsets (U, V) squares through a homography
    (3, 3) or a quadratic map (2, 6)."""
    if H.shape == (2, 6):
        B = np.stack([np.ones_like(U), U, V, U * U, U * V, V * V], axis=-1)
        return B @ H[0], B @ H[1]
    w = H[2, 0] * U + H[2, 1] * V + H[2, 2]
    return (H[0, 0] * U + H[0, 1] * V + H[0, 2]) / w, (H[1, 0] * U + H[1, 1] * V + H[1, 2]) / w


def main(argv):
    import cv2

    from lumigraph.calib import detect as D
    from lumigraph.calib.calibrate import calibrate
    from lumigraph.capture.render import render

    cv2.setNumThreads(1)
    mode = argv[0]
    opts = {"scale": float(os.environ.get("LF_SCALE", 1)), "passes": int(os.environ.get("LF_IT", 1)),
            "window": float(os.environ.get("LF_WF", 0.4))}
    for spec in argv[1:]:
        board, width, seed, blur, *lens = spec.split(":")
        size = (int(width), int(width) * 3 // 4)
        s = render("boards", size=size, seed=int(seed), views=15, board=board, blur=float(blur),
                   distortion=lens[0] if lens else "normal")
        bs = D.BoardSpec.parse(s.stack["board"])
        gt = s.gt_arrays["corners"]
        Kt = np.array(s.gt["camera"]["K"])
        dets, rad, errs = [], [], []
        t0 = time.perf_counter()
        for k, im in enumerate(s.images):
            d = D.detect(im, bs)
            if mode in ("new", "lens") and len(d):
                g = D.to_gray8(im)
                if bs.kind == "charuco":
                    _, _, mc, _ = cv2.aruco.CharucoDetector(bs._charuco()).detectBoard(g)
                    g = D._paint_out_markers(g, mc, bs.square / bs.marker)
                p = refine_local_frame(g, d.image_points, d.object_points, bs.square, **opts)
                d = D.Detection(d.ids, p, d.object_points, d.image_size)
            dets.append(d)
            if len(d):
                e = d.image_points - gt[k][d.ids]
                rv = d.image_points - Kt[:2, 2]
                rad.append(np.sum(e * rv, 1) / np.linalg.norm(rv, axis=1))
                errs.append(e)
        if mode == "lens":
            cam0 = calibrate(dets, model="auto")
            dist0 = np.zeros(5) if not np.size(cam0.dist) else np.asarray(cam0.dist, np.float64)
            rad, errs = [], []
            for k, im in enumerate(s.images):
                d = dets[k]
                if not len(d):
                    continue
                g = D.to_gray8(im)
                if bs.kind == "charuco":
                    _, _, mc, _ = cv2.aruco.CharucoDetector(bs._charuco()).detectBoard(g)
                    g = D._paint_out_markers(g, mc, bs.square / bs.marker)
                p = refine_local_frame(g, d.image_points, d.object_points, bs.square,
                                       camera=(np.asarray(cam0.K), dist0), **opts)
                dets[k] = d = D.Detection(d.ids, p, d.object_points, d.image_size)
                e = d.image_points - gt[k][d.ids]
                rv = d.image_points - Kt[:2, 2]
                rad.append(np.sum(e * rv, 1) / np.linalg.norm(rv, axis=1))
                errs.append(e)
        t = time.perf_counter() - t0
        cam = calibrate(dets, model="auto")
        K = cam.K
        fe = 100 * max(abs(K[0, 0] / Kt[0, 0] - 1), abs(K[1, 1] / Kt[1, 1] - 1))
        pp = float(np.hypot(*(K[:2, 2] - Kt[:2, 2])))
        rad, e = np.concatenate(rad), np.concatenate(errs)
        print(f"{mode} {spec}: rms {np.sqrt((e ** 2).sum(1).mean()):.4f} "
              f"radial {rad.mean():+.4f}±{rad.std() / np.sqrt(rad.size):.4f} f {fe:.3f}% "
              f"({abs(K[0, 0] - Kt[0, 0]) / cam.extra['std']['fx']:.1f}σ) pp {pp:.3f} "
              f"model {cam.model} t {t:.2f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
