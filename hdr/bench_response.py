"""Response and merge figures on the rendered bracket family, beside OpenCV,
for ``lumigraph bench hdr`` (issue 13's Debevec, Robertson and merge targets).

:func:`family_rows` fits our Debevec (automatic λ, noise estimated from the
bracket, bias-corrected) and OpenCV's CalibrateDebevec on every case of
:func:`capture.scenes.brackets.bracket_family` and merges each with its own
curve (ours :func:`hdr.merge.merge`, OpenCV MergeDebevec); OpenCV's
calibration and merge take 8-bit input only, so at 12 and 16 bits the
yardstick is our own 8-bit figure on the same kind and seed.
:func:`family_checks` turns the rows into the issue's targets, per scene kind
(median over seeds) and worst kind, on the held-out (``reported``) kinds and,
separately, on the ``tuned`` ones the defaults were chosen on.
:func:`memorial_speed` times Debevec and Robertson on the Memorial Church
bracket against OpenCV in the same process, single-threaded, interleaved,
minimum of repeats.

Errors: ln-response RMS over codes from ``10/255`` to 95 % of the range (so
codes 10–30 of an 8-bit curve count) after each channel's free offset;
merged radiance: relative RMS over the pixels well exposed in at least one
frame, after one global scale.

Examples
--------
>>> g = np.log(np.arange(1, 257, dtype=float))[None].repeat(3, 0)
>>> round(response_error(g + 1.0, g, 8), 12)
0.0
"""

from __future__ import annotations

import math
import time

import numpy as np

LOW_CODE = 10 / 255  # the error range starts at code 10 of 8 bits


def response_error(g: np.ndarray, g_true: np.ndarray, bit_depth: int) -> float:
    """ln-response RMS over codes ``LOW_CODE·z_max`` .. ``0.95·z_max``, each
    channel's mean difference removed."""
    zmax = 2 ** bit_depth - 1
    m = slice(int(math.ceil(LOW_CODE * zmax)), int(0.95 * zmax) + 1)
    d = np.asarray(g, np.float64)[:, m] - np.asarray(g_true, np.float64)[:, m]
    d = d - d.mean(axis=1, keepdims=True)
    return float(np.sqrt(np.mean(d ** 2)))


def merge_error(est: np.ndarray, truth: np.ndarray, z: np.ndarray, bit_depth: int) -> float:
    """Relative RMS radiance error over pixels well exposed (5–95 %) in some frame."""
    zmax = 2 ** bit_depth - 1
    mask = ((z > 0.05 * zmax) & (z < 0.95 * zmax)).any(axis=0)
    e = est[mask].astype(np.float64)
    t = truth[mask].astype(np.float64)
    ok = np.isfinite(e) & (t > 0)
    e, t = e[ok], t[ok]
    s = float(np.sum(e / t) / np.sum(e * e / t ** 2))
    return float(np.sqrt(np.mean(((s * e - t) / t) ** 2)))


def _cv_inputs(z, t):
    return [np.ascontiguousarray(im[..., ::-1]) for im in z], np.asarray(t, np.float32)


def family_rows(*, size=(160, 120), seeds=None, bit_depths=(8, 12, 16), merge=True) -> list[dict]:
    """One dict per family case: kind, seed, bits, split, ``ours``/``opencv``
    response errors, ``merge_ours``/``merge_opencv`` (8 bits)."""
    import cv2

    from lumigraph.capture.scenes.brackets import FAMILY_SEEDS, bracket_family
    from lumigraph.hdr.debevec1997 import response_debevec1997
    from lumigraph.hdr.merge import merge as merge_ours

    cv2.setNumThreads(1)
    rows = []
    for case in bracket_family(seeds=seeds or FAMILY_SEEDS, bit_depths=bit_depths):
        s = case.render(size)
        z = np.stack(s.images)
        t = np.asarray(s.stack["exposure_times_s"], np.float64)
        bd = case.bit_depth
        g_true = s.gt_arrays["g"]
        r = response_debevec1997(z, t, bit_depth=bd, rng=np.random.default_rng(case.seed))
        row = {"kind": case.kind, "seed": case.seed, "bits": bd, "split": case.split,
               "ours": response_error(r.g, g_true, bd), "warnings": len(r.warnings)}
        if bd == 8:
            bgr, tf = _cv_inputs(z, t)
            crv = cv2.createCalibrateDebevec().process(bgr, tf)
            g_cv = np.log(np.maximum(crv[:, 0, ::-1].T.astype(np.float64), 1e-12))
            row["opencv"] = response_error(g_cv, g_true, bd)
            if merge:
                truth = s.gt_arrays["radiance"].astype(np.float64) * s.gt["exposure_scale"]
                m = merge_ours(z, t, r)
                row["merge_ours"] = merge_error(m.radiance, truth, z, bd)
                mc = cv2.createMergeDebevec().process(bgr, tf, crv)[..., ::-1]
                row["merge_opencv"] = merge_error(mc, truth, z, bd)
        rows.append(row)
    return rows


def family_checks(rows: list[dict]):
    """The issue's targets from :func:`family_rows`, as ``capture.bench.Check``
    (one per split and target; worst kind of the median over seeds)."""
    from lumigraph.capture.bench import Check

    out = []
    for split in ("reported", "tuned"):
        sub = [r for r in rows if r["split"] == split]
        kinds = sorted({r["kind"] for r in sub})
        if not kinds:
            continue

        def med(kind, key, bits=8, sub=sub):
            v = [r[key] for r in sub if r["kind"] == kind and r["bits"] == bits and key in r]
            return float(np.median(v)) if v else math.nan

        ratio = {k: med(k, "ours") / med(k, "opencv") for k in kinds}
        worst = max(ratio, key=ratio.get)
        out.append(Check(f"Debevec ln-response RMS / OpenCV CalibrateDebevec <= 0.5 on every kind, "
                         f"8-bit, codes 10-95 % ({split} kinds {', '.join(kinds)})",
                         ratio[worst], 0.5, ratio[worst] <= 0.5,
                         f"worst {worst}; per kind " +
                         ", ".join(f"{k} {med(k, 'ours'):.4f}/{med(k, 'opencv'):.4f}"
                                   for k in kinds)))
        for bits in sorted({r["bits"] for r in sub} - {8}):
            deep = {k: med(k, "ours", bits) / med(k, "ours") for k in kinds}
            w = max(deep, key=deep.get)
            out.append(Check(f"Debevec {bits}-bit RMS / our 8-bit RMS <= 1 on every kind "
                             f"({split})", deep[w], 1.0, deep[w] <= 1.0,
                             f"worst {w}; per kind " + ", ".join(
                                 f"{k} {med(k, 'ours', bits):.4f}" for k in kinds)))
        if any("merge_ours" in r for r in sub):
            mr = {k: med(k, "merge_ours") / med(k, "merge_opencv") for k in kinds}
            w = max(mr, key=mr.get)
            out.append(Check(f"merged radiance rel. RMS / OpenCV MergeDebevec <= 0.8 on every "
                             f"kind ({split})", mr[w], 0.8, mr[w] <= 0.8,
                             f"worst {w}; per kind " + ", ".join(
                                 f"{k} {med(k, 'merge_ours'):.4f}/{med(k, 'merge_opencv'):.4f}"
                                 for k in kinds)))
    return out


def _min_time(fn, repeats):
    best, out = math.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def memorial_speed(folder, *, repeats=5, robertson=True) -> dict:
    """Wall time of our Debevec (automatic λ) and Robertson against OpenCV's
    CalibrateDebevec (default 70 samples, and ours' 600) and CalibrateRobertson
    on the Memorial bracket (16 × 512×768), interleaved, minimum of ``repeats``.
    Call with OPENBLAS_NUM_THREADS=1 in the environment (numpy reads it at
    import); OpenCV is pinned here."""
    from fractions import Fraction
    from pathlib import Path

    import cv2

    from lumigraph.hdr.debevec1997 import response_debevec1997
    from lumigraph.hdr.robertson2003 import response_robertson2003

    cv2.setNumThreads(1)
    folder = Path(folder)
    files = sorted(folder.glob("memorial*.png"))
    times = [float(Fraction(x)) for x in (folder / "shutter_times.txt").read_text().split()]
    bgr = [cv2.imread(str(f)) for f in files]
    z = np.stack([im[..., ::-1] for im in bgr])
    t = np.asarray(times, np.float64)
    tf = t.astype(np.float32)
    res = {"ours_debevec": math.inf, "cv_debevec": math.inf, "cv_debevec_600": math.inf}
    for _ in range(repeats):
        res["cv_debevec"] = min(res["cv_debevec"], _min_time(
            lambda: cv2.createCalibrateDebevec().process(bgr, tf), 1)[0])
        dt, r = _min_time(lambda: response_debevec1997(z, t), 1)
        res["ours_debevec"] = min(res["ours_debevec"], dt)
    res["cv_debevec_600"] = _min_time(
        lambda: cv2.createCalibrateDebevec(samples=600).process(bgr, tf), 1)[0]
    res["debevec_warnings"] = list(r.warnings)
    if robertson:
        res["cv_robertson"], _ = _min_time(
            lambda: cv2.createCalibrateRobertson().process(bgr, tf), 1)
        res["ours_robertson"], rr = _min_time(lambda: response_robertson2003(z, t), 1)
        res["robertson_iterations"] = [c["iterations"] for c in rr.fit["convergence"]]
    return res
