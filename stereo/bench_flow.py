"""Bench stage ``flow``: optical flow and video matching against exact ground truth.

Cases: our capture sequences (``flow``, ``flow-large`` > 40 px,
``flow-textureless``, ``flow-brightness``, ``flow-video``), the Middlebury
training pairs in ``../shared/data/flow-real`` (frame10 -> frame11 with
flow10.flo; unknown GT > 1e9 left out), MPI-Sintel cave_2 and market_5 (clean
and final pass, ``../shared/data/flow-sintel``, frame_0002 -> frame_0003), and
a rendered ``flow`` scene at 320x240 and 1280x960 for the cost's scaling.
The rendered smooth-cloth pair (:func:`cloth_scene`, the kind of scene
Middlebury's Dimetrodon is) at seeds 0 (tuned on) and 2 (not).
Error: mean endpoint error (px) over pixels with known ground truth,
excluding occluded pixels on our synthetic cases (their flow is not
observable); on Sintel over all valid pixels (Sintel's "all"), with the
non-occluded EPE (``epe_noc``) in the extras.

**Tuned on / reported on.** The dense-inverse-search presets (the default
flow, :mod:`stereo.kroeger2016`) were chosen on our rendered scenes (the
cloth scene at seeds 0 and 1) and the Sintel pairs; the Middlebury pairs
are held out (never looked at while choosing), and their figures are the
report.

Ours, the default: dense inverse search (Kroeger et al. 2016) with OpenCV's
DIS as the inner solver at full size and median filtering; the accurate
preset adds the backward search, the fill of inconsistent pixels, full-size
variational refinement and the weighted median (knob: the preset,
fast/default/accurate). The older
pyramid flow (local Lucas-Kanade; knob: window), its fast setting (one
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
SINTEL = ("cave_2-clean", "market_5-clean", "cave_2-final", "market_5-final")
SCALING = ("flow 320x240", "flow 1280x960")
# The smooth-cloth scene (the Dimetrodon kind, rendered here): seed 0 tuned
# the accurate preset's refinement (with seed 1), seed 2 was not looked at.
CLOTH = ("flow-cloth s0", "flow-cloth s2")
LIGHTING = ("flow-brightness", "flow-video")
DIS_OURS = "dis (ours)"
DIS_SCALING = "dis default (ours), scaling"
PRESETS = ("fast", "default", "accurate")
OURS_FLOW = (DIS_OURS, "pyramid (ours)", "pyramid-fast (ours)", "pyramid-dense (ours)",
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


def _sintel(name: str, quick: bool):
    def load():
        import cv2

        from lumigraph.capture import io

        seq, pas = name.split("-")
        d = shared_data("data", "flow-sintel", "training")
        i0 = io.read_image(d / pas / seq / "frame_0002.png")
        i1 = io.read_image(d / pas / seq / "frame_0003.png")
        gt = io.read_flo(d / "flow" / seq / "frame_0002.flo")
        occ = io.read_image(d / "occlusions" / seq / "frame_0002.png") > 127
        invalid = io.read_image(d / "invalid" / seq / "frame_0002.png") > 127
        occ, invalid = (x if x.ndim == 2 else x[..., 0] for x in (occ, invalid))
        if quick:  # half size; the flow halves with it
            h, w = i0.shape[:2]
            i0 = cv2.resize(i0, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
            i1 = cv2.resize(i1, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
            gt = cv2.resize(gt, (w // 2, h // 2), interpolation=cv2.INTER_NEAREST) / 2
            occ, invalid = (cv2.resize(x.astype(np.uint8), (w // 2, h // 2),
                                       interpolation=cv2.INTER_NEAREST) > 0 for x in (occ, invalid))
        valid = ~invalid & np.isfinite(gt).all(axis=2)
        # Sintel's "all": every valid pixel, occluded ones included.
        return {"i0": i0, "i1": i1, "gt": gt, "valid": valid, "occluded": occ & valid,
                "noc": valid & ~occ}
    return load


def cloth_scene(seed: int, size=(388, 584)) -> dict:
    """A rendered pair of the kind Middlebury's Dimetrodon is (a cloth with
    smooth folds, faint fine weave, a few printed marks, a small rigid object
    in front; smooth non-rigid motion of a few px, sensor noise 2 codes):
    large low-texture regions where patch matches are noisy and only a
    well-converged smoothness term recovers the flow. ``size`` (H, W).

    Frame 0 samples the texture ``T`` (2x oversampled, bilinear) at ``x``,
    frame 1 at ``y - g(y)`` with ``g`` an affine field plus four Gaussian
    bumps, so the exact forward flow solves ``f(x) = g(x + f(x))`` (20
    fixed-point steps; ``g`` changes by < 0.05 px/px, a contraction). The
    object translates rigidly; background pixels it covers in frame 1, and
    pixels leaving the frame, are ``occluded``. uint8 RGB frames; keys as
    the other loaders (``i0``, ``i1``, ``gt``, ``valid``, ``occluded``).
    """
    import cv2

    rng = np.random.default_rng(seed)
    h, w = size
    s, pad = 2, 32
    H, W = h * s + 2 * pad, w * s + 2 * pad
    weave = cv2.GaussianBlur(rng.standard_normal((H, W)).astype(np.float32), (0, 0), 1.2 * s)
    weave /= weave.std()
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32) / s
    shade = np.zeros((H, W), np.float32)
    for _ in range(5):  # folds: low-frequency shading, periods of 150-600 px
        k, th, ph = rng.uniform(0.01, 0.04), rng.uniform(0, np.pi), rng.uniform(0, 6.3)
        shade += rng.uniform(0.03, 0.07) * np.sin(k * (np.cos(th) * xx + np.sin(th) * yy) + ph)
    prints = np.zeros((H, W), np.float32)
    for _ in range(12):
        cx, cy = rng.uniform(0, W), rng.uniform(0, H * 0.6)
        a, b = rng.uniform(4, 30) * s, rng.uniform(3, 10) * s
        cv2.ellipse(prints, (int(cx), int(cy)), (int(a), int(b)), rng.uniform(0, 180), 0, 360,
                    1.0, -1)
    prints = cv2.GaussianBlur(prints, (0, 0), 0.7 * s)
    base = 0.45 + shade
    # Red cloth: the weave is a 2.5 % modulation of red (about 3 codes).
    tex = np.dstack([base * (1 + 0.025 * weave) + 0.25 * prints,
                     0.15 * base * (1 + 0.08 * weave) + 0.55 * prints,
                     0.2 * base * (1 + 0.08 * weave) + 0.5 * prints]).astype(np.float32)
    gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
    A, t = rng.uniform(-0.006, 0.006, (2, 2)), rng.uniform(-3, 1.5, 2)
    g = np.dstack([t[c] + A[c, 0] * (gx - w / 2) + A[c, 1] * (gy - h / 2) for c in (0, 1)])
    for _ in range(4):
        cx, cy, r = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(60, 150)
        amp = rng.uniform(-1.5, 1.5, 2)
        g = g + np.exp(-((gx - cx) ** 2 + (gy - cy) ** 2) / (2 * r * r))[..., None] * amp
    g = g.astype(np.float32)

    def sample(u, v):
        return cv2.remap(tex, (u * s + pad).astype(np.float32), (v * s + pad).astype(np.float32),
                         cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)

    i0, i1 = sample(gx, gy), sample(gx - g[..., 0], gy - g[..., 1])
    f = g.copy()
    for _ in range(20):
        f = np.dstack([cv2.remap(np.ascontiguousarray(g[..., c]), gx + f[..., 0], gy + f[..., 1],
                                 cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                       for c in (0, 1)])
    ocx, ocy = rng.uniform(0.3, 0.7) * w, rng.uniform(0.65, 0.8) * h
    oa, ob = rng.uniform(60, 110), rng.uniform(20, 35)
    od = rng.uniform(-3, 3, 2)
    otex = cv2.GaussianBlur(rng.random((h, w)).astype(np.float32), (0, 0), 1.5)
    otex = 0.55 + 0.6 * (otex - otex.mean())
    m0 = ((gx - ocx) / oa) ** 2 + ((gy - ocy) / ob) ** 2 <= 1
    m1 = ((gx - ocx - od[0]) / oa) ** 2 + ((gy - ocy - od[1]) / ob) ** 2 <= 1
    ot0 = np.dstack([otex * 0.95, otex * 0.8, otex * 0.6])
    ot1 = cv2.warpAffine(ot0, np.float32([[1, 0, od[0]], [0, 1, od[1]]]), (w, h),
                         borderMode=cv2.BORDER_REFLECT)
    i0[m0], i1[m1] = ot0[m0], ot1[m1]
    f[m0] = od
    xt, yt = gx + f[..., 0], gy + f[..., 1]
    inside = (xt >= 0) & (xt <= w - 1) & (yt >= 0) & (yt <= h - 1)
    covered = cv2.remap(m1.astype(np.float32), xt, yt, cv2.INTER_NEAREST) > 0.5
    occ = (~m0 & covered) | ~inside
    noise = 2.0 / 255

    def to8(x):
        x = x + rng.normal(0, noise, x.shape)
        return np.clip(np.rint(x * 255), 0, 255).astype(np.uint8)

    i0, i1 = to8(i0), to8(i1)
    return {"i0": i0, "i1": i1, "gt": f.astype(np.float32), "valid": ~occ, "occluded": occ}


def _cloth(name: str):
    return lambda: cloth_scene(int(name.rsplit("s", 1)[1]))


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


def _dis_ours(d, preset):
    from lumigraph.stereo.kroeger2016 import dense_inverse_search

    return dense_inverse_search(d["i0"], d["i1"], preset=preset, consistency=False).flow


def _pcaflow(d, _v):
    import cv2

    return cv2.optflow.createOptFlow_PCAFlow().calc(d["g0"], d["g1"], None)


# --- video matching (the vmatch helper's rows and checks live below this line) ---

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
    noc = data.get("noc", data["valid"])
    return {"error": float(np.mean(e[data["valid"]])),
            "epe_noc": float(np.mean(e[noc])),
            "epe_occluded": float(np.mean(e[occ])) if occ.any() else None,
            "bad_3px": float(np.mean(e[data["valid"]] > 3.0))}


def _row(res, case, method, value=None):
    try:
        r = res.get(case, method, value) if value is not None else res.best(case, method)
    except KeyError:
        return None
    return r if r.status == "ok" else None


def _dis_checks(res: Results) -> list[Check]:
    """The default flow's targets (issue 15), each against the peer of the same run."""
    out = []
    cases = sorted({r.case for r in res.rows})
    # Default: EPE <= DIS-medium's on every Middlebury pair, time <= 3x its.
    for case in [c for c in REAL if c in cases]:
        ours, dis = _row(res, case, DIS_OURS, "default"), _row(res, case, "DIS medium")
        if ours is None or dis is None:
            continue
        out.append(Check(f"{case} (held out): default preset EPE <= DIS-medium's (ratio)",
                         ours.error / dis.error, 1.0, ours.error <= dis.error,
                         f"ours {ours.error:.3f} px, DIS-medium {dis.error:.3f} px"))
        t = ours.time_s / dis.time_s
        out.append(Check(f"{case}: default preset time <= 3x DIS-medium's (ratio)", t, 3.0, t <= 3.0,
                         f"ours {ours.time_s * 1e3:.1f} ms, DIS-medium {dis.time_s * 1e3:.1f} ms"))
    clean = [c for c in SINTEL if c.endswith("clean") and c in cases]
    pairs = [(_row(res, c, DIS_OURS, "default"), _row(res, c, "DIS medium")) for c in clean]
    pairs = [p for p in pairs if None not in p]
    if pairs:
        mo, md = (float(np.median([p[i].error for p in pairs])) for i in (0, 1))
        out.append(Check("Sintel clean (median of pairs): default preset EPE <= DIS-medium's (ratio)",
                         mo / md, 1.0, mo <= md, f"ours {mo:.3f} px, DIS-medium {md:.3f} px"))
        t = float(np.median([p[0].time_s / p[1].time_s for p in pairs]))
        out.append(Check("Sintel clean: default preset time <= 3x DIS-medium's (median ratio)",
                         t, 3.0, t <= 3.0, ", ".join(f"{p[0].case} {p[0].time_s * 1e3:.0f} vs "
                                                     f"{p[1].time_s * 1e3:.0f} ms" for p in pairs)))
    # Accurate: EPE <= 0.75x DIS-medium's on Middlebury and Sintel final, time <= DeepFlow's
    # (and on the rendered cloth scene, the kind of Middlebury's Dimetrodon).
    for case in [c for c in (*REAL, *SINTEL, *CLOTH) if c in cases and not c.endswith("clean")]:
        ours, dis = _row(res, case, DIS_OURS, "accurate"), _row(res, case, "DIS medium")
        if ours is None or dis is None:
            continue
        r = ours.error / dis.error
        out.append(Check(f"{case}: accurate preset EPE <= 0.75x DIS-medium's (ratio)", r, 0.75,
                         r <= 0.75, f"ours {ours.error:.3f} px, DIS-medium {dis.error:.3f} px"))
        deep = _row(res, case, "DeepFlow")
        if deep is not None:
            t = ours.time_s / deep.time_s
            out.append(Check(f"{case}: accurate preset time <= DeepFlow's (ratio)", t, 1.0, t <= 1.0,
                             f"ours {ours.time_s:.2f} s, DeepFlow {deep.time_s:.2f} s"))
    # Large motion: default <= DIS-medium's EPE.
    for case in [c for c in ("flow-large", "market_5-clean", "market_5-final") if c in cases]:
        ours, dis = _row(res, case, DIS_OURS, "default"), _row(res, case, "DIS medium")
        if ours is None or dis is None:
            continue
        out.append(Check(f"{case}: large motion, default preset EPE <= DIS-medium's (ratio)",
                         ours.error / dis.error, 1.0, ours.error <= dis.error,
                         f"ours {ours.error:.3f} px, DIS-medium {dis.error:.3f} px"))
    # Scaling: 320x240 -> 1280x960 costs <= 1.3x the pixel ratio (16).
    small, big = (_row(res, c, DIS_SCALING, "default") for c in SCALING)
    if small is not None and big is not None:
        r = big.time_s / small.time_s / 16.0
        out.append(Check("default preset: time(1280x960) / time(320x240) / 16 <= 1.3", r, 1.3,
                         r <= 1.3, f"{small.time_s * 1e3:.1f} ms -> {big.time_s * 1e3:.1f} ms"))
    return out


def _video_checks(res: Results) -> list[Check]:
    """Video matching's targets (the vmatch helper's section)."""
    out = []
    cases = sorted({r.case for r in res.rows})
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


def _checks(res: Results, _ctx) -> list[Check]:
    out = []
    cases = sorted({r.case for r in res.rows})
    for case in [c for c in ("flow", "RubberWhale", "Venus") if c in cases]:
        try:
            fb = res.best(case, "Farneback")
        except KeyError:
            continue
        rows = [r for m in OURS_FLOW for r in res.of(case, m) if r.time_s <= fb.time_s]
        best = min(rows, key=lambda r: r.error) if rows else None
        meas = best.error / fb.error if best else float("inf")
        out.append(Check(f"{case}: EPE <= Farneback's at <= its wall time (ratio)", meas, 1.0,
                         meas <= 1.0, f"ours {best.method} {best.knob}={best.value}: "
                                      f"{best.error:.3f} px in {best.time_s * 1e3:.1f} ms; "
                                      f"Farneback {fb.error:.3f} px in {fb.time_s * 1e3:.1f} ms"
                         if best else f"no setting of ours ran within {fb.time_s * 1e3:.1f} ms"))
    return out + _dis_checks(res) + _video_checks(res)


def _video_methods(quick: bool) -> tuple:
    """Video matching's rows (the vmatch helper's section)."""
    # One setting: the default (dense) search does not use the regression
    # kernel (stereo/sand2004.py), so a second width would repeat the row.
    return (Method("video matching (ours)", _video, "regression_sigma", (9.0,), cases=LIGHTING),)


@with_video_matching  # the lighting-change family of video matching (issue 15)
def stage(*, quick: bool = False) -> Stage:
    import cv2

    cv2.setNumThreads(1)  # single thread for every method, ours and the peers
    size = (160, 120) if quick else (320, 240)
    synth = ("flow", "flow-large", "flow-brightness") if quick else SYNTHETIC
    real = ("RubberWhale",) if quick else REAL
    sintel = ("market_5-clean",) if quick else SINTEL
    cases = [Case(n, _synthetic(n, size), f"capture scene {n!r} at {size[0]}x{size[1]}, seed 0 "
                  "(tuned on)") for n in synth]
    cases += [Case(n, _real(n, quick), f"Middlebury {n} frame10 -> frame11 (held out)"
                   + (" (half size)" if quick else ""),
                   unavailable=missing_shared("data", "flow-real", n)) for n in real]
    cases += [Case(n, _sintel(n, quick), f"MPI-Sintel {n} frame_0002 -> 0003, all pixels; epe_noc: "
                   "non-occluded (tuned on)" + (" (half size)" if quick else ""),
                   unavailable=missing_shared("data", "flow-sintel", "training")) for n in sintel]
    if not quick:
        cases += [Case(n, _cloth(n), "rendered smooth cloth (the Dimetrodon kind), 584x388, "
                       + ("seed 0 (tuned on)" if n.endswith("s0") else "seed 2 (not tuned on)"))
                  for n in CLOTH]
        cases += [Case(n, _synthetic("flow", tuple(map(int, n.split()[1].split("x")))),
                       f"capture scene 'flow' at {n.split()[1]}, seed 0: the cost's scaling")
                  for n in SCALING]
    windows = (7, 9) if quick else (5, 9, 13)
    warps = (2, 3) if quick else (1, 3)
    flowcases = tuple(c.name for c in cases if c.name not in SCALING)
    legacy = tuple(c.name for c in cases
                   if c.name not in SCALING and c.name not in SINTEL and c.name not in CLOTH)
    slow = tuple(c.name for c in cases if c.name in ("flow", "flow-brightness", "RubberWhale",
                                                     "cave_2-final"))
    methods = (
        Method(DIS_OURS, _dis_ours, "preset", PRESETS, prepare=_prep_gray, cases=flowcases),
        Method(DIS_SCALING, _dis_ours, "preset", ("default",), prepare=_prep_gray,
               cases=SCALING),
        Method("pyramid (ours)", _ours("local", "window"), "window", windows, prepare=_prep_gray,
               cases=legacy),
        # The older pyramid flow's speed end: one warp per level, refinement
        # stopping at full or half size (DIS's "finest scale").
        Method("pyramid-fast (ours)", _ours("local", "finest_level", iterations=1), "finest_level",
               (0, 1), prepare=_prep_gray, cases=legacy),
        Method("pyramid-dense (ours)", _ours("dense", "iterations"), "iterations", warps,
               prepare=_prep_gray, cases=legacy),
        Method("pyramid + weighted median (ours)", _ours("local", "median_radius"),
               "median_radius", (10,), prepare=_prep_gray,
               cases=("flow",) if quick else ("flow", *REAL)),
        *_video_methods(quick),
        Method("Farneback", _farneback, peer="opencv", prepare=_prep_gray, cases=flowcases),
        Method("DIS ultrafast", _dis(0), peer="opencv", prepare=_prep_gray, cases=flowcases),
        Method("DIS fast", _dis(1), peer="opencv", prepare=_prep_gray, cases=flowcases),
        Method("DIS medium", _dis(2), peer="opencv", prepare=_prep_gray),
        Method("DeepFlow", _deepflow, peer="opencv", prepare=_prep_gray,
               unavailable=_optflow_missing, cases=flowcases if not quick else ("flow",)),
        Method("DualTVL1", _tvl1, peer="opencv", prepare=_prep_gray, unavailable=_optflow_missing,
               cases=slow if not quick else ("flow",)),
        Method("PCAFlow", _pcaflow, peer="opencv", prepare=_prep_gray, unavailable=_optflow_missing,
               cases=flowcases if not quick else ("flow",)),
    )
    return Stage("flow", tuple(cases), methods, _error, "mean endpoint error (px)",
                 checks=_checks,
                 description="Forward flow only for every method (our forward-backward check "
                             "is off here). Error over known, non-occluded pixels (Sintel: all "
                             "valid pixels; epe_noc non-occluded). Every method single-threaded "
                             "(cv2.setNumThreads(1)); times are medians of 3 runs on a shared "
                             "2-core machine. 'dis (ours)' is dense inverse search built on "
                             "OpenCV's DIS as inner solver (stereo/kroeger2016.py). Presets "
                             "tuned on the rendered scenes and Sintel; Middlebury held out.")
