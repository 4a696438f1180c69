"""Harness of docs/decisions/charuco-marker-removal.md, "The model fit": every
board set of the bench's family (``calib/bench.py`` FAMILY, tuned and
reported) detected with ``cornerSubPix`` as the last step (``FIT_MODEL =
False``) and with the X-junction model fit (``calib/rohr1992.py``), calibrated
by the bench's own ``ours auto``; bare OpenCV (k1k2p1p2k3) from the same run.

Usage::

    OPENBLAS_NUM_THREADS=1 python docs/decisions/corner_model_fit.py [name-substring ...]

Per set and variant: corner RMS against the rendered corners (px), focal error
(%), its σ (%), the larger error in σ (focal, principal point), the principal
point error (px), the check "≤ OpenCV + σ", the chosen model, the corners whose
fit fell back to ``cornerSubPix`` (``Detection.fallbacks``) and the detection
time per view (one pass, loaded machine: indicative only). ``cSP`` is the
previous pipeline (painted ``cornerSubPix``, markers rendered and subtracted,
``cornerSubPix`` again).
"""

import sys
import time

import numpy as np


def main(argv):
    import cv2

    from lumigraph.calib import bench as B
    from lumigraph.calib import detect as D

    cv2.setNumThreads(1)
    for name, board, size, blur, dist, seed, role in B.FAMILY:
        if argv and not any(a in name for a in argv):
            continue
        data = B._family(board, size, blur, dist, seed)()
        gt = data["gt_corners"]
        o = B._error(data, B._opencv(data, "k1k2p1p2k3"))
        print(f"{name} ({role}) OpenCV: f {o['error']:.3f}% pp {o['pp_px']:.2f}", flush=True)
        for flag in (False, True):
            D.FIT_MODEL = flag
            t0 = time.perf_counter()
            dets = [D.detect(im, data["board"]) for im in data["images"]]
            t = (time.perf_counter() - t0) / len(dets)
            e = np.concatenate([d.image_points - gt[k][d.ids] for k, d in enumerate(dets) if len(d)])
            run = B._ours("auto")
            r = B._error(data, run(data, None))
            zf = r["error"] / r["fx_sigma_pct"]
            zc = max(r["cx_err_px"] / r["cx_sigma_px"], r["cy_err_px"] / r["cy_sigma_px"])
            vs = "ok" if r["error"] <= o["error"] + r["fx_sigma_pct"] else "MISS"
            print(f"  {'fit ' if flag else 'cSP '} rms {np.sqrt((e ** 2).sum(1).mean()):.4f} "
                  f"f {r['error']:.3f}% σ {r['fx_sigma_pct']:.3f}% in σ {max(zf, zc):.1f} "
                  f"pp {r['pp_px']:.2f} vsCV {vs} {r['model']} fell back {sum(d.fallbacks for d in dets)}/"
                  f"{sum(len(d) for d in dets)} "
                  f"t {1000 * t:.0f} ms/view", flush=True)
        D.FIT_MODEL = True


if __name__ == "__main__":
    main(sys.argv[1:])
