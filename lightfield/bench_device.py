"""Device rows of ``lumigraph bench gpu`` for the light-field stage: refocusing.

One case: a rendered camera array (9x9 views of 512x512 RGB; quick: 5x5 of
96x96) refocused at 100 slopes (quick: 6) spread over the scene's
disparities, two of which (0.35 and 0.7 px/view) the renderer also gives as
exact synthetic-aperture images (the truth: RMS over those two).

Rows, per method (shift-and-add with its default Lanczos-3 kernel; Fourier
slice): ``cpu`` (ours, numpy), ``torch-cpu``, ``cuda`` (the issue's target:
<= 0.05x our cpu time on the full case), and for shift-and-add the CPU peer:
bilinear shifts by ``cv2.remap`` of each view, summed (OpenCV, single
thread). ``max_abs_vs_cpu`` of the peer is the kernels' difference, not
rounding. Full size, torch-cpu is not run (minutes; the port is checked by
``--quick`` and ``tests/device``). Nothing here was tuned: the slopes and sizes
are the issue's.
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.bench_device import DeviceRow, measure, skipped

TRUTH_SLOPES = (0.35, 0.7)


def _case(quick: bool):
    from lumigraph.capture.render import render
    from lumigraph.lightfield.field import LightField

    size, grid, n = ((96, 96), "5x5", 6) if quick else ((512, 512), "9x9", 100)
    s = render("lightfield-array", size=size, grid=grid, thin_lens=False, focus=TRUTH_SLOPES)
    lf = LightField(s.gt_arrays["views"].astype(np.float32))
    slopes = sorted({*np.round(np.linspace(-1.0, 1.2, n - 2), 6).tolist(), *TRUTH_SLOPES})
    while len(slopes) < n:            # a linspace value fell on a truth slope
        slopes.append(1.2 + 0.01 * len(slopes))
    at = [slopes.index(x) for x in TRUTH_SLOPES]
    truth = s.gt_arrays["synthetic_aperture"].astype(np.float64)
    name = f"{grid}x{size[0]}x{size[1]} RGB, {len(slopes)} depths"
    return lf, slopes[:n], at, truth, name


def _opencv_shift_add(lf, slopes):
    """The peer: each view shifted by ``cv2.remap`` (bilinear, reflected
    border as our symmetric one), summed; the same geometry as ours."""
    import cv2

    u, v = lf.grid
    uc, vc = lf.center
    _, _, h, w, c = lf.data.shape
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    out = np.empty((len(slopes), h, w, c), np.float32)
    for k, s in enumerate(slopes):
        acc = np.zeros((h, w, c), np.float32)
        for i in range(u):
            for j in range(v):
                dx, dy = -s * (j - vc), -s * (i - uc)
                img = cv2.remap(lf.data[i, j], xs + np.float32(dx), ys + np.float32(dy),
                                cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
                acc += img.reshape(h, w, c)
        out[k] = acc / np.float32(u * v)
    return out


def rows(*, devices: tuple[str, ...], quick: bool) -> list[DeviceRow]:
    """The refocusing rows (module docstring)."""
    import cv2

    from lumigraph.lightfield.refocus import focal_stack

    lf, slopes, at, truth, name = _case(quick)
    repeats = 3 if quick else 1          # a full cpu stack takes ~half a minute

    def truth_rms(out):
        return float(np.sqrt(np.mean((out[at] - truth) ** 2)))

    out_rows: list[DeviceRow] = []
    for method, stage in (("shift-add", "lightfield refocus shift-add"),
                          ("fourier", "lightfield refocus fourier")):
        ref = None
        for dev in ("cpu", "torch-cpu", "cuda"):
            target = 0.05 if dev == "cuda" and method == "shift-add" else None
            if dev not in devices:
                why = "torch sees no CUDA GPU" if dev == "cuda" else "not asked (--device)"
                out_rows.append(skipped(stage, name, dev, why, target=target))
                continue
            if dev == "torch-cpu" and not quick:
                out_rows.append(skipped(stage, name, dev, "full size takes minutes on torch's "
                                        "CPU device; --quick and tests/device check the port"))
                continue
            row, out = measure(stage, name, dev,
                               lambda dev=dev, method=method: focal_stack(
                                   lf, slopes, method=method, device=dev),
                               reference=ref, truth=truth_rms,
                               repeats=3 if dev == "cuda" else repeats, target=target)
            out_rows.append(row)
            if dev == "cpu":
                ref = out
        if method == "shift-add":
            prev = cv2.getNumThreads()
            cv2.setNumThreads(1)
            try:
                row, _ = measure(stage, name, "opencv", lambda: _opencv_shift_add(lf, slopes),
                                 reference=ref, truth=truth_rms, repeats=repeats, peer="opencv",
                                 note="bilinear cv2.remap per view (not Lanczos-3)")
            finally:
                cv2.setNumThreads(prev)
            out_rows.append(row)
    return out_rows
