"""The best any per-pixel blend of the visible photographs can do on a VDTM
view (docs/decisions/facade-vdtm.md, fourth round): an upper bound on PSNR.

Usage::

    OPENBLAS_NUM_THREADS=1 python docs/decisions/facade_vdtm_oracle.py SEED VIEW [SEED VIEW ...]

For each model pixel of the glossy facade's novel view (640x480), the
samples of every photograph that sees the point (the blend's visibility and
bilinear sampling, ``vdtm._sample``) span a convex hull; the oracle knows
the truth and takes, per pixel, the convex weights (one set for the three
channels) nearest to it. Frank-Wolfe with exact line search, 300 steps; its
duality gap gives a lower bound on the oracle's error, so the printed
``bound`` is a PSNR no blend of these samples can exceed (pixels no
photograph sees keep the blend's hole fill). Printed beside the blend, the
uniform average and the nearest photograph of ``lumigraph bench facade``.
"""

import sys

import numpy as np

from lumigraph.capture.raster import rasterize
from lumigraph.capture.render import render
from lumigraph.capture.scenes.facade import Building
from lumigraph.stereo.debevec1996 import vdtm as V

SIZE = (640, 480)


def psnr_of(sq, n):
    return 10 * np.log10(255.0 ** 2 / (sq.sum() / (3 * n)))


def oracle(seed, view):
    s = render("facade", size=SIZE, seed=seed)
    b = Building(s.gt["parameters"]).mesh()
    mesh = (b.vertices, b.faces)
    photos = V.prepare_photographs(mesh, [
        V.Photograph(im.astype(np.float32), np.array(c["K"]), np.array(c["R"]), np.array(c["t"]))
        for im, c in zip(s.images, s.gt["cameras"].values(), strict=True)])
    k = list(s.gt["novel_cameras"]).index(view)
    cam = s.gt["novel_cameras"][view]
    K, R, t = (np.array(cam[x]) for x in ("K", "R", "t"))
    C = -R.T @ t
    gt, m = s.gt_arrays[f"novel_{k}"], s.gt_arrays[f"novel_model_{k}"]
    blend = V.render_vdtm(mesh, photos, K, R, t, SIZE).image
    uniform = V.render_vdtm(mesh, photos, K, R, t, SIZE, power=1e-9, neighbours=0).image
    j = int(np.argmin([np.linalg.norm(p.centre - C) for p in photos]))
    nearest = V.render_vdtm(mesh, [photos[j]], K, R, t, SIZE).image
    r = rasterize(*mesh, K, R, t, SIZE, bary=False)
    idx = np.flatnonzero(r.hit.ravel() & m.ravel())
    X = (V._rays(K, SIZE).reshape(-1, 3)[idx] * r.depth.ravel()[idx, None] - t) @ R
    S, OK = zip(*(V._sample(p, X, 0.01) for p in photos), strict=True)
    S = np.stack(S, 2).astype(np.float64)  # (n, 3, photographs)
    OK = np.stack(OK, 1)
    g = gt.reshape(-1, 3)[idx].astype(np.float64)
    n = len(idx)
    seen = OK.any(1)
    err = ((S - g[:, :, None]) ** 2).sum(1)
    err[~OK] = np.inf
    w = np.zeros(OK.shape)
    w[np.arange(n), np.argmin(err, 1)] = 1  # the best single photograph first
    w[~seen] = 0
    lower = np.zeros(n)
    for _ in range(300):
        res = np.einsum("nck,nk->nc", S, w) - g
        f = (res ** 2).sum(1)
        grad = 2 * np.einsum("nck,nc->nk", S, res)
        gm = np.where(OK, grad, np.inf)
        v = np.argmin(gm, 1)
        gap = (grad * w).sum(1) - gm[np.arange(n), v]
        lower = np.maximum(lower, f - np.maximum(gap, 0))
        d = S[np.arange(n), :, v] - (res + g)
        den = (d ** 2).sum(1)
        gam = np.clip(np.where(den > 0, -(res * d).sum(1) / np.maximum(den, 1e-30), 0), 0, 1)
        w *= (1 - gam)[:, None]
        w[np.arange(n), v] += gam
        w[~seen] = 0
    hole = ((blend.reshape(-1, 3)[idx] - g) ** 2).sum(1)
    best = psnr_of(np.where(seen, f, hole), n)
    bound = psnr_of(np.where(seen, lower, hole), n)

    def p(img):
        return psnr_of(((img.reshape(-1, 3)[idx] - g) ** 2).sum(1), n)

    pb, pu, pn = p(blend), p(uniform), p(nearest)
    print(f"s{seed} {view}: blend {pb:.2f}, uniform {pu:.2f}, nearest ({s.image_names[j]}) "
          f"{pn:.2f}; oracle {best:.2f}, bound {bound:.2f} dB: at most {bound - pu:+.2f} dB over "
          f"the uniform average, {bound - pn:+.2f} dB over the nearest photograph")


if __name__ == "__main__":
    args = sys.argv[1:]
    for seed, view in zip(args[::2], args[1::2], strict=True):
        oracle(int(seed), view)
