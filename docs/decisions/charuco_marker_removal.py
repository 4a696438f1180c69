"""Harness of docs/decisions/charuco-marker-removal.md: ChArUco corners with
and without the marker removal of ``calib/detect.py`` (``REMOVE_MARKERS``),
and bare OpenCV on the same images.

Usage (sets as board:width:seed:blur[:distortion])::

    OPENBLAS_NUM_THREADS=1 python docs/decisions/charuco_marker_removal.py charuco:320:12:0.6 charuco:640:9:0.8:strong

Prints per set and refinement: corner RMS against the rendered corners, the
mean error component along each view's depth gradient (+ = towards the far
side; ± its standard error), the focal error of ``calibrate(model="auto")`` in
% and the larger of its focal / principal-point errors in their reported σ,
the principal-point error in px, the chosen model and the detection time; then
bare OpenCV's (``CharucoDetector`` corners as returned, ``calibrateCamera``
k1k2p1p2k3) focal and principal-point errors.
"""

import sys
import time

import numpy as np


def evaluate(scene, refine_markers):
    from lumigraph.calib import detect as D
    from lumigraph.calib.calibrate import calibrate

    bs = D.BoardSpec.parse(scene.stack["board"])
    gt = scene.gt_arrays["corners"]
    Kt = np.array(scene.gt["camera"]["K"])
    D.REMOVE_MARKERS = refine_markers
    t0 = time.perf_counter()
    dets = [D.detect(im, bs) for im in scene.images]
    t = time.perf_counter() - t0
    errs, lean = [], []
    for k, d in enumerate(dets):
        if not len(d):
            continue
        e = d.image_points - gt[k][d.ids]
        pose = scene.gt["cam_from_world"][k]
        z = (d.object_points @ np.array(pose["R"]).T + np.array(pose["t"]))[:, 2]
        g = np.linalg.lstsq(np.column_stack([gt[k][d.ids], np.ones(len(d))]), z, rcond=None)[0][:2]
        lean.append(e @ (g / np.linalg.norm(g)))
        errs.append(e)
    cam = calibrate(dets, model="auto")
    K, sd = cam.K, cam.extra["std"]
    fe = 100 * max(abs(K[0, 0] / Kt[0, 0] - 1), abs(K[1, 1] / Kt[1, 1] - 1))
    z = max(abs(K[0, 0] - Kt[0, 0]) / sd["fx"], abs(K[1, 1] - Kt[1, 1]) / sd["fy"],
            abs(K[0, 2] - Kt[0, 2]) / sd["cx"], abs(K[1, 2] - Kt[1, 2]) / sd["cy"])
    pp = float(np.hypot(*(K[:2, 2] - Kt[:2, 2])))
    e, lean = np.concatenate(errs), np.concatenate(lean)
    return (f"rms {np.sqrt((e ** 2).sum(1).mean()):.4f} lean {lean.mean():+.4f}±{lean.std() / np.sqrt(lean.size):.4f} "
            f"f {fe:.3f}% ({z:.1f}σ, fx σ {100 * sd['fx'] / Kt[0, 0]:.4f}%) pp {pp:.2f} {cam.model} t {t:.2f}s")


def main(argv):
    import cv2

    from lumigraph.calib.bench import _opencv_charuco
    from lumigraph.calib.detect import BoardSpec
    from lumigraph.capture.render import render

    cv2.setNumThreads(1)
    for spec in argv:
        board, width, seed, blur, *lens = spec.split(":")
        size = (int(width), int(width) * 3 // 4)
        s = render("boards", size=size, seed=int(seed), views=15, board=board, blur=float(blur),
                   distortion=lens[0] if lens else "normal")
        for flag in (False, True):
            print(f"{spec} {'removed' if flag else 'painted'}: {evaluate(s, flag)}", flush=True)
        out = _opencv_charuco({"images": list(s.images), "board": BoardSpec.parse(s.stack["board"]),
                               "size": size}, "k1k2p1p2k3")
        K, Kt = out["K"], np.array(s.gt["camera"]["K"])
        print(f"{spec} OpenCV: f {100 * max(abs(K[0, 0] / Kt[0, 0] - 1), abs(K[1, 1] / Kt[1, 1] - 1)):.3f}% "
              f"pp {np.hypot(*(K[:2, 2] - Kt[:2, 2])):.2f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
