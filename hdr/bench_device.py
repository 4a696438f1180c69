"""Device rows of ``lumigraph bench gpu`` for the HDR stage: merge and tone mapping.

Cases (synthetic, built here, nothing tuned on them; sizes are the issue's):

- ``merge``: a bracket of 9 exposures two stops apart (``4**-8`` .. 1 s) of
  a 12 MP RGB scene (4000x3000; quick: 640x480)
  whose radiance is log-normal (sigma 2.5 in log, centred in the bracket's
  range), 8-bit linear codes with 1 % noise. Truth: the radiance; error: RMS relative error over the pixels no
  exposure left unmeasured (flags 0).
  Rows: ``cpu`` (ours, numpy, variance weights), ``torch-cpu``, ``cuda`` (the
  issue's target: <= 0.1x our cpu time), and the CPU peer
  ``cv2.createMergeDebevec`` with the linear response (triangle weights: its
  difference from ours is the weights', not rounding).
- ``tonemap local`` / ``tonemap global``: Reinhard 2002 of the merge case's
  true radiance (12 MP; quick 0.3 MP), 8-bit codes. No truth (an operator,
  not an estimate): the error column is the max code difference from our cpu
  result. Rows: ``cpu``, ``torch-cpu``, ``cuda`` (local: target <= 0.1x),
  and the peer ``cv2.createTonemapReinhard`` (Reinhard-Devlin 2005, a
  different operator; its codes are shown for speed, not parity).

Full size, the torch-cpu rows are not run (minutes; ``--quick`` and
``tests/device`` check the port), a cpu or peer row is one call (seconds), a
cuda row the min of 5.
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.bench_device import DeviceRow, measure, skipped

TIMES = tuple(float(4.0 ** -k) for k in range(9))[::-1]


def _scene(quick: bool):
    rng = np.random.default_rng(20)
    h, w = (480, 640) if quick else (3000, 4000)
    # smooth log-normal radiance: a coarse field upsampled, plus texture
    coarse = rng.normal(0.0, 2.5, (h // 50 + 2, w // 50 + 2)).astype(np.float32)
    import cv2

    field = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    tex = rng.normal(0.0, 0.2, (h, w, 3)).astype(np.float32)
    # centred in what the bracket records: 5/255 per 1 s .. 255/255 per 4^-8 s
    # (log 0.02 .. log 65536, centre 3.6); the field's +-2.5 sigma stays inside
    x = np.exp(field[..., None] + tex + 3.6).astype(np.float32)
    return x


def _bracket(x):
    rng = np.random.default_rng(21)
    z = np.empty((len(TIMES),) + x.shape, np.uint8)
    for j, t in enumerate(TIMES):
        e = x * np.float32(t * 255)
        e *= 1 + np.float32(0.01) * rng.standard_normal(x.shape, dtype=np.float32)
        z[j] = np.clip(np.round(e), 0, 255)
    return z


def _skip_or(out_rows, stage, name, dev, devices, target, quick):
    if dev == "torch-cpu" and dev in devices and not quick:
        out_rows.append(skipped(stage, name, dev, "full size takes minutes on torch's CPU "
                                "device; --quick and tests/device check the port"))
        return True
    if dev in devices:
        return False
    why = "torch sees no CUDA GPU" if dev == "cuda" else "not asked (--device)"
    out_rows.append(skipped(stage, name, dev, why, target=target))
    return True


def rows(*, devices: tuple[str, ...], quick: bool) -> list[DeviceRow]:
    """The merge and tone-mapping rows (module docstring)."""
    import cv2

    from lumigraph.hdr.merge import merge
    from lumigraph.hdr.reinhard2002 import tonemap
    from lumigraph.hdr.response import ResponseCurve

    x = _scene(quick)
    z = _bracket(x)
    h, w = x.shape[:2]
    mp = f"{h * w / 1e6:.1f} MP"
    curve = ResponseCurve.linear(8, 3)
    # full size: a cpu call takes seconds (min of 1 is its time to a few %);
    # a cuda call milliseconds (min of 5)
    repeats = 3 if quick else 1
    rep = {"cpu": repeats, "torch-cpu": repeats, "cuda": 5}
    out_rows: list[DeviceRow] = []

    # ---- merge
    stage, name = "hdr merge", f"{len(TIMES)} x {mp} RGB 8-bit"
    truth_mask = {}

    def merge_truth(out):
        m = truth_mask.get("ok")
        rel = (out[m] - x[m]) / x[m]
        return float(np.sqrt(np.mean(rel ** 2)))

    ref = None
    for dev in ("cpu", "torch-cpu", "cuda"):
        target = 0.1 if dev == "cuda" else None
        if _skip_or(out_rows, stage, name, dev, devices, target, quick):
            continue
        if dev == "cpu":
            truth_mask["ok"] = merge(z, TIMES, curve).flags.max(axis=2) == 0
        row, out = measure(stage, name, dev,
                           lambda dev=dev: merge(z, TIMES, curve, device=dev).radiance,
                           reference=ref, truth=merge_truth, repeats=rep[dev], target=target)
        out_rows.append(row)
        if dev == "cpu":
            ref = out
    prev = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        # the linear response; code 0 at half a code (OpenCV takes its log)
        crf = (np.maximum(np.arange(256, dtype=np.float32), 0.5) / 255)[:, None, None]
        crf = np.ascontiguousarray(crf.repeat(3, axis=2))
        merger = cv2.createMergeDebevec()
        imgs = [np.ascontiguousarray(zi) for zi in z]
        tt = np.asarray(TIMES, np.float32)
        row, _ = measure(stage, name, "opencv", lambda: merger.process(imgs, tt, crf),
                         reference=ref, truth=merge_truth, repeats=repeats, peer="opencv",
                         note="cv2.createMergeDebevec, triangle weights")
        out_rows.append(row)

        # ---- tone mapping
        for method, stage, target_ratio in (("reinhard-local", "hdr tonemap local", 0.1),
                                            ("reinhard", "hdr tonemap global", None)):
            name = f"{mp} RGB -> 8-bit"
            ref = None
            for dev in ("cpu", "torch-cpu", "cuda"):
                target = target_ratio if dev == "cuda" else None
                if _skip_or(out_rows, stage, name, dev, devices, target, quick):
                    continue
                row, out = measure(stage, name, dev,
                                   lambda dev=dev, method=method: tonemap(x, method=method,
                                                                          device=dev),
                                   reference=ref, repeats=rep[dev], target=target)
                out_rows.append(row)
                if dev == "cpu":
                    ref = out
            tm = cv2.createTonemapReinhard()

            def peer(tm=tm):
                return np.clip(np.round(tm.process(x) * 255), 0, 255).astype(np.uint8)

            row, _ = measure(stage, name, "opencv", peer, reference=ref, repeats=repeats,
                             peer="opencv", note="cv2.createTonemapReinhard (Reinhard-Devlin "
                                                 "2005, another operator)")
            out_rows.append(row)
    finally:
        cv2.setNumThreads(prev)
    return out_rows
