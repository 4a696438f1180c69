"""Bench stage ``flow``: optical flow and video matching against exact ground truth.

Cases: our capture sequences (``flow``, ``flow-large`` > 40 px,
``flow-textureless``, ``flow-brightness``, ``flow-video``) and the Middlebury
training pairs in ``../shared/data/flow-real`` (frame10 -> frame11 with
flow10.flo). Error: mean endpoint error (px) over pixels with known ground
truth, excluding occluded pixels on the synthetic cases (their flow is not
observable); extras report EPE on occluded pixels.

Ours: pyramid flow (local Lucas-Kanade; knob: window), its fast setting (one
warp per level; knob: the level refinement stops at), dense pyramid flow
(knob: warps per level), pyramid flow with the colour-guided weighted median
(knob: its radius), Sand-Teller video matching (knob: regression kernel
width) on the lighting-change cases. All run forward only (no
forward-backward check), as the peers do. Peers in the same run: OpenCV
Farneback, DIS at its ultrafast/fast/medium presets, DeepFlow and DualTVL1
(``cv2.optflow``; TV-L1 with 3 warps and 60 inner iterations to stay in the
time budget).
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.bench import Case, Check, Method, Results, Stage, missing_shared, shared_data
from lumigraph.stereo.bench_vmatch import with_video_matching

SYNTHETIC = ("flow", "flow-large", "flow-textureless", "flow-brightness", "flow-video")
REAL = ("RubberWhale", "Venus", "Dimetrodon", "Hydrangea")
LIGHTING = ("flow-brightness", "flow-video")
OURS_FLOW = ("pyramid (ours)", "pyramid-fast (ours)", "pyramid-dense (ours)",
             "pyramid + weighted median (ours)")


def _synthetic(name: str, size):
    def load():
        from lumigraph.capture.render import render

        s = render(name, size=size, seed=0)
        g = s.gt_arrays
        valid = ~g["occluded"] & np.isfinite(g["flow"]).all(axis=2)
        return {"i0": s.images[0], "i1": s.images[1], "gt": g["flow"], "valid": valid,
                "occluded": g["occluded"] & np.isfinite(g["flow"]).all(axis=2)}
    return load


def _real(name: str, quick: bool):
    def load():
        import cv2

        from lumigraph.capture import io

        d = shared_data("data", "flow-real", name)
        i0, i1 = io.read_image(d / "frame10.png"), io.read_image(d / "frame11.png")
        gt = io.read_flo(d / "flow10.flo")
        if quick:  # half size for the smoke test; the flow halves with it
            h, w = i0.shape[:2]
            i0 = cv2.resize(i0, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
            i1 = cv2.resize(i1, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
            gt = cv2.resize(gt, (w // 2, h // 2), interpolation=cv2.INTER_NEAREST) / 2
        return {"i0": i0, "i1": i1, "gt": gt, "valid": np.isfinite(gt).all(axis=2),
                "occluded": np.zeros(gt.shape[:2], bool)}
    return load


def _gray8(img):
    from lumigraph.stereo.luma import luma_normalised

    return np.clip(np.rint(luma_normalised(img) * 255), 0, 255).astype(np.uint8)


def _prep_gray(data):
    return {**data, "g0": _gray8(data["i0"]), "g1": _gray8(data["i1"])}


def _ours(method: str, knob: str, **fixed):
    def run(d, value):
        from lumigraph.stereo.pyramid_flow import pyramid_flow

        kw = {**fixed, knob: value}
        return pyramid_flow(d["i0"], d["i1"], method=method, consistency=False, **kw).flow
    return run


def _video(d, sigma):
    from lumigraph.stereo.sand2004 import video_matching

    return video_matching(d["i0"], d["i1"], regression_sigma=sigma).flow


def _farneback(d, _v):
    import cv2

    # OpenCV's documented typical parameters; 5 levels so it can reach 40 px.
    return cv2.calcOpticalFlowFarneback(d["g0"], d["g1"], None, 0.5, 5, 15, 3, 5, 1.2, 0)


def _dis(preset: int):
    def run(d, _v):
        import cv2

        return cv2.DISOpticalFlow_create(preset).calc(d["g0"], d["g1"], None)
    return run


def _deepflow(d, _v):
    import cv2

    return cv2.optflow.createOptFlow_DeepFlow().calc(d["g0"], d["g1"], None)


def _tvl1(d, _v):
    import cv2

    tv = cv2.optflow.DualTVL1OpticalFlow_create(warps=3, innnerIterations=20, outerIterations=3,
                                                 scaleStep=0.5, nscales=5)
    return tv.calc(d["g0"], d["g1"], None)


def _optflow_missing():
    import cv2

    return None if hasattr(cv2, "optflow") else "opencv-contrib (cv2.optflow) not installed"


def _error(data, out) -> dict:
    flow = np.asarray(out, np.float32)
    e = np.hypot(flow[..., 0] - data["gt"][..., 0], flow[..., 1] - data["gt"][..., 1])
    occ = data["occluded"]
    return {"error": float(np.mean(e[data["valid"]])),
            "epe_occluded": float(np.mean(e[occ])) if occ.any() else None,
            "bad_3px": float(np.mean(e[data["valid"]] > 3.0))}


def _checks(res: Results, _ctx) -> list[Check]:
    out = []
    cases = sorted({r.case for r in res.rows})
    ours_flow = OURS_FLOW
    for case in [c for c in ("flow", "RubberWhale", "Venus") if c in cases]:
        try:
            fb = res.best(case, "Farneback")
        except KeyError:
            continue
        rows = [r for m in ours_flow for r in res.of(case, m) if r.time_s <= fb.time_s]
        best = min(rows, key=lambda r: r.error) if rows else None
        meas = best.error / fb.error if best else float("inf")
        out.append(Check(f"{case}: EPE <= Farneback's at <= its wall time (ratio)", meas, 1.0,
                         meas <= 1.0, f"ours {best.method} {best.knob}={best.value}: "
                                      f"{best.error:.3f} px in {best.time_s * 1e3:.1f} ms; "
                                      f"Farneback {fb.error:.3f} px in {fb.time_s * 1e3:.1f} ms"
                         if best else f"no setting of ours ran within {fb.time_s * 1e3:.1f} ms"))
    for case, target in (("flow", "some knob setting: EPE <= DIS-medium's (ratio)"),
                         ("RubberWhale", "some knob setting: EPE <= DIS-medium's (ratio)"),
                         ("flow-large", "large displacement (> 40 px): EPE <= DIS-medium's "
                                        "(ratio)")):
        if case not in cases:
            continue
        rows = [r for m in ours_flow for r in res.of(case, m)]
        try:
            dis = res.best(case, "DIS medium")
        except KeyError:
            continue
        if not rows:
            continue
        best = min(rows, key=lambda r: r.error)
        out.append(Check(f"{case}: {target}", best.error / dis.error, 1.0,
                         best.error <= dis.error,
                         f"ours {best.method} {best.knob}={best.value}: {best.error:.3f} px; "
                         f"DIS-medium {dis.error:.3f} px"))
    for case in [c for c in LIGHTING if c in cases]:
        try:
            vm = res.get(case, "video matching (ours)", 9.0)
            pf = res.get(case, "pyramid (ours)", 9)
            dis = res.best(case, "DIS medium")
        except KeyError:
            continue
        ok = vm.status == "ok" and vm.error <= 0.5 * pf.error and vm.error <= dis.error
        out.append(Check(f"{case}: video matching EPE <= 0.5x plain pyramid flow's and <= "
                         "DIS-medium's (ratio to the larger bound)",
                         vm.error / min(0.5 * pf.error, dis.error), 1.0, ok,
                         f"video matching {vm.error:.3f} px; pyramid {pf.error:.3f} px; "
                         f"DIS-medium {dis.error:.3f} px"))
    return out


@with_video_matching  # the lighting-change family of video matching (issue 15)
def stage(*, quick: bool = False) -> Stage:
    size = (160, 120) if quick else (320, 240)
    synth = ("flow", "flow-large", "flow-brightness") if quick else SYNTHETIC
    real = ("RubberWhale",) if quick else REAL
    cases = [Case(n, _synthetic(n, size), f"capture scene {n!r} at {size[0]}x{size[1]}, seed 0")
             for n in synth]
    cases += [Case(n, _real(n, quick), f"Middlebury {n} frame10 -> frame11"
                   + (" (half size)" if quick else ""),
                   unavailable=missing_shared("data", "flow-real", n)) for n in real]
    windows = (7, 9) if quick else (5, 7, 9, 13)
    warps = (2, 3) if quick else (1, 2, 3, 5)
    slow = tuple(c.name for c in cases if c.name in ("flow", "flow-brightness", "RubberWhale"))
    methods = (
        Method("pyramid (ours)", _ours("local", "window"), "window", windows, prepare=_prep_gray),
        # The speed end: one warp per level, refinement stopping at full or
        # half size (DIS's "finest scale").
        Method("pyramid-fast (ours)", _ours("local", "finest_level", iterations=1), "finest_level",
               (0, 1), prepare=_prep_gray),
        Method("pyramid-dense (ours)", _ours("dense", "iterations"), "iterations", warps,
               prepare=_prep_gray),
        # The accuracy end: colour-guided weighted median after each level.
        Method("pyramid + weighted median (ours)", _ours("local", "median_radius"),
               "median_radius", (10,) if quick else (5, 10), prepare=_prep_gray,
               cases=("flow",) if quick else None),
        Method("video matching (ours)", _video, "regression_sigma", (9.0,) if quick else (6.0, 9.0),
               cases=LIGHTING),
        Method("Farneback", _farneback, peer="opencv", prepare=_prep_gray),
        Method("DIS ultrafast", _dis(0), peer="opencv", prepare=_prep_gray),
        Method("DIS fast", _dis(1), peer="opencv", prepare=_prep_gray),
        Method("DIS medium", _dis(2), peer="opencv", prepare=_prep_gray),
        Method("DeepFlow", _deepflow, peer="opencv", prepare=_prep_gray,
               unavailable=_optflow_missing, cases=None if not quick else ("flow",)),
        Method("DualTVL1", _tvl1, peer="opencv", prepare=_prep_gray, unavailable=_optflow_missing,
               cases=slow if not quick else ("flow",)),
    )
    return Stage("flow", tuple(cases), methods, _error, "mean endpoint error (px)",
                 checks=_checks,
                 description="Forward flow only for every method (our forward-backward check "
                             "is off here). Error over known, non-occluded pixels. Times are "
                             "medians of 3 runs on a shared 2-core machine.")
