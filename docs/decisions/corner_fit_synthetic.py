"""Harness of docs/decisions/charuco-marker-removal.md, "The model fit":
single X-junctions rendered as the boards scene renders them (each pixel's
box average from 16x16 samples, then ``cv2.GaussianBlur`` and 1 code of read
noise, 8-bit), random sub-pixel centres and line angles (90 deg +- 34 deg
apart), fitted by ``calib/rohr1992.py`` and by ``cornerSubPix`` with the same
half-window, from the same start (+- 0.3 px).

Usage::

    OPENBLAS_NUM_THREADS=1 python docs/decisions/corner_fit_synthetic.py [noise]

Prints per blur and radius: RMS and mean error of both (px) and the fits that
fell back. ``noise 0`` gives the model's own floor (the pixel box's shape,
which the Gaussian of the same variance misses).
"""

import sys

import numpy as np


def junction(size, c, a1, a2, blur, ss=16, lo=20, hi=220):
    import cv2

    off = (np.arange(ss) + 0.5) / ss - 0.5
    ys = (np.arange(size)[:, None] + off).ravel()
    X, Y = np.meshgrid(ys, ys)
    sgn = (np.sign(np.cos(a1) * (X - c[0]) + np.sin(a1) * (Y - c[1]))
           * np.sign(np.cos(a2) * (X - c[0]) + np.sin(a2) * (Y - c[1])))
    r = (0.5 * (lo + hi) + 0.5 * (hi - lo) * sgn).reshape(size, ss, size, ss).mean(axis=(1, 3))
    return cv2.GaussianBlur(r.astype(np.float32), (0, 0), blur)


def main(argv):
    import cv2

    from lumigraph.calib.rohr1992 import fit_corners

    noise = float(argv[0]) if argv else 1.0
    rng = np.random.default_rng(1)
    for blur in (0.4, 0.6, 1.0):
        for R in (2, 3, 4):
            fit, csp, fails = [], [], 0
            for _ in range(60):
                c = np.array([20.0, 20.0]) + rng.uniform(-0.5, 0.5, 2)
                a1 = rng.uniform(0, np.pi)
                a2 = a1 + np.pi / 2 + rng.uniform(-0.6, 0.6)
                im = junction(41, c, a1, a2, blur)
                im = np.clip(np.round(im + rng.normal(0, noise, im.shape)), 0, 255).astype(np.uint8)
                st = c + rng.uniform(-0.3, 0.3, 2)
                f = fit_corners(im, st[None], radius=R)
                if f.ok[0]:
                    fit.append(f.points[0] - c)
                else:
                    fails += 1
                cs = cv2.cornerSubPix(im, st[None, None].astype(np.float32), (R, R), (-1, -1), (3, 40, 1e-3))
                csp.append(cs.reshape(2) - c)
            e, ec = np.array(fit), np.array(csp)
            print(f"blur {blur} radius {R}: fit RMS {np.sqrt((e ** 2).sum(1).mean()):.4f} mean {e.mean(0).round(4)} "
                  f"fell back {fails}/60 | cornerSubPix RMS {np.sqrt((ec ** 2).sum(1).mean()):.4f} "
                  f"mean {ec.mean(0).round(4)}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
