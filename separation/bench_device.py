"""Device rows of ``lumigraph bench gpu`` for separation: the checker estimator.

Case (synthetic, built here; nothing was tuned on it): a shifted-checkerboard
set, 2 × 2 shifts and their complements (8 captures), square 8 px, α = ½, black
level b = 0.05, of a scene with known direct and global images (uniform
random per pixel; RGB), with Gaussian noise σ = 0.01; 1024x768 (quick:
320x240). Error vs truth: RMS of the direct image against the true one (the
same figure on every row). Rows: ``cpu`` (ours, numpy, the noise-robust
``pairs`` estimator given the noise σ), ``torch-cpu``, ``cuda``, and the
textbook max/min estimator (Fig. 8.43) on numpy as the reference point: no
other library implements the separation, so there is no external peer.
Every CPU row runs single-threaded (cv2, OpenBLAS and torch at one thread).
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.bench_device import DeviceRow, measure


def _case(quick: bool):
    from lumigraph.capture.patterns import checker_set

    w, h = (320, 240) if quick else (1024, 768)
    rng = np.random.default_rng(30)
    d = rng.uniform(0.1, 0.8, (h, w, 3)).astype(np.float32)
    g = rng.uniform(0.05, 0.4, (h, w, 3)).astype(np.float32)
    b = 0.05
    ps = checker_set((w, h), square=8, shifts=2)
    ims = np.empty((len(ps.images), h, w, 3), np.float32)
    for k, p in enumerate(ps.images):
        lit = (b + (1 - b) * p.astype(np.float32))[..., None]
        ims[k] = d * lit + np.float32(b + (1 - b) * 0.5) * g
        ims[k] += rng.normal(0, 0.01, (h, w, 3)).astype(np.float32)
    return ims, list(ps.complement_of), d, b


def rows(*, devices: tuple[str, ...], quick: bool) -> list[DeviceRow]:
    """The checker rows (module docstring)."""
    from lumigraph.capture.bench_device import device_rows, repeats_for, single_thread
    from lumigraph.separation import nayar2006

    ims, comp, d_true, b = _case(quick)
    n, h, w, _ = ims.shape
    stage, name = "separate", f"checker {n} x {w}x{h} RGB float32"
    sigma = np.float32(0.01)

    def truth(out):
        return float(np.sqrt(np.mean((out[0] - d_true) ** 2)))

    def call(dev):
        if dev == "cpu":
            r = nayar2006.checker(ims, complement_of=comp, b=b, sigma=sigma)
        else:
            from lumigraph.separation import nayar2006_torch

            r = nayar2006_torch.checker(ims, complement_of=comp, b=b, sigma=sigma, device=dev)
        return np.stack([r[0], r[1]])

    out_rows: list[DeviceRow] = []
    with single_thread():
        ref = device_rows(out_rows, stage, name, devices, call, truth=truth, quick=quick)

        def maxmin():
            r = nayar2006.checker(ims, complement_of=comp, b=b, estimator="maxmin")
            return np.stack([r[0], r[1]])

        row, _ = measure(stage, name, "numpy max/min", maxmin, reference=ref, truth=truth,
                         repeats=repeats_for("cpu", quick), peer="numpy",
                         note="textbook max/min (Fig. 8.43): no library peer exists")
        out_rows.append(row)
    return out_rows
