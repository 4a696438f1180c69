"""Bench stage ``calib``: detection + calibration, ours beside bare OpenCV.

Cases (``boards`` scene, 1280×960, 15 views of a 19×14-square board, i.e.
18×13 = 234 inner corners; 400×300, 6 views of the default 10×7 board in quick
mode): ``clean`` (normal lens), ``strong`` (k1 = −0.3), ``fronto`` (a
near-degenerate, nearly fronto-parallel pose set).

Why that capture: the principal point's standard deviation falls as
σ/√(corners) and with the spread of board orientations (Zhang 2000, §3.3).
With the scene's ``varied`` poses (boards filling 80–100 % of the width,
reaching toward the image corners, tilts 20–50° about axes in every
direction) and 0.2 px corner noise, the fit's covariance gives σ(cx) ≈ 0.21 px
and σ(cy) ≈ 0.16 px with 234 corners per view (≈ 0.9 and 0.65 px with the
earlier 54-corner board and narrower poses), so the 0.5 px target sits at
≈ 2.4σ per axis instead of ≈ 0.6σ. The checks report σ from the fit. On every synthetic case the
detected corners get the same injected isotropic Gaussian noise of 0.2 px RMS
(2-D; σ = 0.2/√2 per axis) before calibration, for every method. Plus the real
``calib-real`` photos (no ground truth: the error is the reprojection RMS) and
their stereo rig (error: RMS of the y difference of matched corners after
rectification).

Methods: ours with ``auto`` and with each fixed model (knob); the peer is the
bare OpenCV pipeline (``findChessboardCorners`` + ``cornerSubPix`` on the full
image, OpenCV's tutorial 11×11 window, 5×5 below 1000 px width where 11 would
reach the neighbouring corners, ``calibrateCamera`` with the same model's flags). Error: the larger
relative focal error in percent (``fx``, ``fy``); the principal-point error,
RMS and chosen model are extras.

Speed (``clean``, ``strong`` and the ChArUco sets of ``CHARUCO_SPEED``): ours
(detection + ``auto``) and the bare OpenCV calls (``findChessboardCorners`` +
``cornerSubPix``, or ``CharucoDetector.detectBoard``, then one
``calibrateCamera``) back to back in the same process on the same images,
OpenCV on one thread for both, order rotating per repeat; the ChArUco checks
take the min of the repeats of each.

Expected RMS from the noise: with N corners (2N coordinates) and p fitted
parameters (intrinsics + 6 per view) the residual sum of squares of iid noise
of variance σ² per coordinate is σ²(2N − p), so OpenCV's RMS (per corner,
both axes) is ``0.2 · sqrt(1 − p / 2N)`` px (plus the small detection error,
added in quadrature).
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.bench import Case, Check, Method, Results, Stage

NOISE_RMS_PX = 0.2
MODELS = ("none", "k1", "k1k2", "k1k2p1p2", "k1k2p1p2k3", "rational")


def _synthetic(size, views, board_opts, **opts):
    def load():
        from lumigraph.calib.detect import BoardSpec
        from lumigraph.capture.render import render

        s = render("boards", size=size, seed=11, views=views, supersample=2 if size[0] <= 640 else 1,
                   **board_opts, **opts)
        board = BoardSpec.parse(s.stack["board"])
        rng = np.random.default_rng(5)
        noise = rng.normal(0.0, NOISE_RMS_PX / np.sqrt(2), (views, board.n_corners, 2))
        return {"images": list(s.images), "board": board, "gt": s.gt, "noise": noise,
                "gt_corners": s.gt_arrays["corners"], "size": size}
    return load


# The board family (issue 14): checker and ChArUco boards, several image sizes,
# blurs and lenses, detected as captured (no injected noise). The ChArUco
# marker painting (calib/detect.py PAINT_GROW), the marker removal
# (REMOVE_MARKERS) and the X-junction model fit that replaced its last step
# (FIT_MODEL, calib/rohr1992.py; docs/decisions/charuco-marker-removal.md) were
# chosen on the sets marked "tuned"; the targets are reported on the others
# (seeds 30-34 at 320 and 30-32 at 640 blur 0.9 were added as held-out sets
# after the removal's choice).
FAMILY = (
    # name, board, size, blur, distortion, seed, role
    ("charuco 640 blur0.6", "charuco", (640, 480), 0.6, "normal", 3, "tuned"),
    ("charuco 640 blur1.2", "charuco", (640, 480), 1.2, "normal", 5, "tuned"),
    ("charuco 320 blur0.6", "charuco", (320, 240), 0.6, "normal", 4, "tuned"),
    ("charuco 640 blur0.9", "charuco", (640, 480), 0.9, "normal", 8, "reported"),
    ("charuco 640 strong blur0.8", "charuco", (640, 480), 0.8, "strong", 9, "reported"),
    ("charuco 960 blur1.0", "charuco", (960, 720), 1.0, "normal", 10, "reported"),
    ("charuco 640 blur0.6 s11", "charuco", (640, 480), 0.6, "normal", 11, "reported"),
    ("charuco 320 blur0.6 s13", "charuco", (320, 240), 0.6, "normal", 13, "reported"),
    ("charuco 320 blur0.6 s12", "charuco", (320, 240), 0.6, "normal", 12, "reported"),
    ("charuco 320 blur0.6 s20", "charuco", (320, 240), 0.6, "normal", 20, "tuned"),
    ("charuco 320 blur0.6 s21", "charuco", (320, 240), 0.6, "normal", 21, "tuned"),
    ("charuco 320 blur0.6 s22", "charuco", (320, 240), 0.6, "normal", 22, "tuned"),
    ("charuco 320 blur0.6 s23", "charuco", (320, 240), 0.6, "normal", 23, "tuned"),
    ("charuco 320 blur0.6 s24", "charuco", (320, 240), 0.6, "normal", 24, "tuned"),
    ("charuco 320 blur0.6 s30", "charuco", (320, 240), 0.6, "normal", 30, "reported"),
    ("charuco 320 blur0.6 s31", "charuco", (320, 240), 0.6, "normal", 31, "reported"),
    ("charuco 320 blur0.6 s32", "charuco", (320, 240), 0.6, "normal", 32, "reported"),
    ("charuco 320 blur0.6 s33", "charuco", (320, 240), 0.6, "normal", 33, "reported"),
    ("charuco 320 blur0.6 s34", "charuco", (320, 240), 0.6, "normal", 34, "reported"),
    ("charuco 640 blur0.9 s30", "charuco", (640, 480), 0.9, "normal", 30, "reported"),
    ("charuco 640 blur0.9 s31", "charuco", (640, 480), 0.9, "normal", 31, "reported"),
    ("charuco 640 blur0.9 s32", "charuco", (640, 480), 0.9, "normal", 32, "reported"),
    ("checker 640 blur0.9", "checker", (640, 480), 0.9, "normal", 8, "reported"),
    ("checker 640 strong blur0.8", "checker", (640, 480), 0.8, "strong", 9, "reported"),
    ("checker 320 blur0.6 s13", "checker", (320, 240), 0.6, "normal", 13, "reported"),
)


# the ChArUco speed rows (issue 14: the marker removal made ChArUco detection
# dearer): one family set per image size, all "reported" ones
CHARUCO_SPEED = ("charuco 320 blur0.6 s13", "charuco 640 blur0.9", "charuco 960 blur1.0")


def _family(board, size, blur, distortion, seed):
    def load():
        from lumigraph.calib.detect import BoardSpec
        from lumigraph.capture.render import render

        s = render("boards", size=size, seed=seed, views=15, board=board, blur=blur,
                   distortion=distortion)
        return {"images": list(s.images), "board": BoardSpec.parse(s.stack["board"]), "gt": s.gt,
                "noise": None, "gt_corners": s.gt_arrays["corners"], "size": size}
    return load


def _opencv_charuco(data, model):
    """The bare OpenCV ChArUco pipeline: ``CharucoDetector`` corners as
    returned, ``calibrateCamera`` with the model's flags."""
    import cv2

    from lumigraph.calib.detect import to_gray8
    from lumigraph.calib.zhang2000 import model_flags

    board = data["board"]
    det = cv2.aruco.CharucoDetector(board._charuco())
    obj, img = [], []
    for im in data["images"]:
        c, ids, _, _ = det.detectBoard(to_gray8(im))
        if ids is None or len(ids) < 6:
            continue
        obj.append(board.object_points[ids.ravel()].astype(np.float32))
        img.append(c.reshape(-1, 2).astype(np.float32))
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, img, data["size"], None, None, flags=model_flags(model))
    p = 4 + {"none": 0, "k1": 1, "k1k2": 2, "k1k2p1p2": 4, "k1k2p1p2k3": 5, "rational": 8}[model] + 6 * len(obj)
    return {"K": K, "rms": rms, "model": model, "p": p, "n": sum(len(i) for i in img), "warnings": [],
            "poor": []}


def _real_folder():
    import os
    from pathlib import Path

    shared = Path(os.environ.get("LUMIGRAPH_SHARED", Path(__file__).resolve().parents[2] / "shared"))
    return shared / "data" / "calib-real"


def _real():
    from lumigraph.calib.detect import BoardSpec
    from lumigraph.capture.io import read_image

    folder = _real_folder()
    left = sorted(folder.glob("left*.jpg"))
    right = sorted(folder.glob("right*.jpg"))
    return {"images": [read_image(p) for p in left], "right": [read_image(p) for p in right],
            "board": BoardSpec.parse("checker:10x7:1"), "gt": None, "noise": None, "size": (640, 480)}


def _noisy(data, dets):
    from lumigraph.calib.detect import Detection

    if data["noise"] is None:
        return dets
    out = []
    for k, d in enumerate(dets):
        if len(d):
            d = Detection(d.ids, d.image_points + data["noise"][k][d.ids], d.object_points, d.image_size)
        out.append(d)
    return out


def _ours(model):
    def run(data, value):
        from lumigraph.calib.calibrate import calibrate
        from lumigraph.calib.detect import detect

        m = model or value
        dets = _noisy(data, [detect(im, data["board"]) for im in data["images"]])
        cam = calibrate(dets, model=m)
        return {"K": cam.K, "rms": cam.extra["rms_px"], "model": cam.model, "std": cam.extra["std"],
                "p": cam.extra["n_params"], "n": cam.extra["n_points"],
                "warnings": cam.extra["warnings"], "poor": cam.extra["poorly_determined"]}
    return run


def _opencv(data, model):
    import cv2

    if data["board"].kind == "charuco":
        return _opencv_charuco(data, model)

    from lumigraph.calib.detect import to_gray8
    from lumigraph.calib.zhang2000 import model_flags

    board = data["board"]
    obj, img = [], []
    for k, im in enumerate(data["images"]):
        g = to_gray8(im)
        ok, c = cv2.findChessboardCorners(g, board.pattern_size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                          | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK)
        if not ok:
            continue
        c = cv2.cornerSubPix(g, c, _peer_window(g), (-1, -1), (3, 30, 1e-3)).reshape(-1, 2).astype(np.float64)
        if data["noise"] is not None:
            # OpenCV may return the board rotated by 180 deg: match the noise to the corner
            gt = data["gt_corners"][k]
            if np.abs(c - gt).max() > np.abs(c[::-1] - gt).max():
                c = c[::-1]
            c = c + data["noise"][k]
        obj.append(board.object_points.astype(np.float32))
        img.append(c.astype(np.float32))
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, img, data["size"], None, None, flags=model_flags(model))
    p = 4 + {"none": 0, "k1": 1, "k1k2": 2, "k1k2p1p2": 4, "k1k2p1p2k3": 5, "rational": 8}[model] + 6 * len(obj)
    return {"K": K, "rms": rms, "model": model, "p": p, "n": board.n_corners * len(obj), "warnings": [],
            "poor": []}


def _speed(state, _value):
    """One interleaved repeat, OpenCV on one thread for all three: ours
    (detection + ``auto``), the bare OpenCV calls
    with the model ``auto`` chose, and ours with that model fixed, back to back
    (the order rotates per repeat) so machine load hits all three alike. The
    times of every repeat accumulate in ``state["times"]``."""
    import time

    from lumigraph.calib.zhang2000 import _one_opencv_thread

    data, times = state["data"], state["times"]
    model = state.get("model", "k1k2p1p2k3")
    k = len(times)
    runs = {"auto": lambda: _ours("auto")(data, None),
            "opencv": lambda: _opencv(data, state.get("model", "k1k2p1p2k3")),
            "fixed": lambda: _ours(state.get("model", "k1k2p1p2k3"))(data, None)}
    order = ["auto", "opencv", "fixed"]
    order = order[k % 3:] + order[:k % 3]
    t, out = {}, {}
    # single thread each (ours pins calibrateCamera to one thread for byte-stable
    # results; the peer gets the same), so the ratio compares the methods
    with _one_opencv_thread():
        for name in order:
            t0 = time.perf_counter()
            out[name] = runs[name]()
            t[name] = time.perf_counter() - t0
            if name == "auto":
                state["model"] = out["auto"]["model"]
    if out["auto"]["model"] != model:  # the first repeat learns the model: time it again
        return _speed(state, _value)
    times.append(t)
    return dict(out["auto"], times=list(times))


def _peer_window(gray):
    """OpenCV's tutorial window (11, 11) on large images; (5, 5) below 1000 px wide,
    where an 11-px half-window would reach the neighbouring corners."""
    return (11, 11) if gray.shape[1] >= 1000 else (5, 5)


def _rectified_y(rig_left_K, rig_left_d, rig_right_K, rig_right_d, R1, R2, P1, P2, pl, pr):
    import cv2

    yl = cv2.undistortPoints(pl.reshape(-1, 1, 2), rig_left_K, rig_left_d, R=R1, P=P1).reshape(-1, 2)[:, 1]
    yr = cv2.undistortPoints(pr.reshape(-1, 1, 2), rig_right_K, rig_right_d, R=R2, P=P2).reshape(-1, 2)[:, 1]
    return float(np.sqrt(np.mean((yl - yr) ** 2)))


def _ours_stereo(data, _value):
    from lumigraph.calib.calibrate import calibrate_stereo
    from lumigraph.calib.detect import detect
    from lumigraph.calib.rectify import rectify

    ld = [detect(im, data["board"]) for im in data["images"]]
    rd = [detect(im, data["board"]) for im in data["right"]]
    rig = calibrate_stereo(ld, rd)
    r = rectify(rig)
    pl = np.concatenate([a.image_points for a, b in zip(ld, rd, strict=True) if len(a) and len(b)])
    pr = np.concatenate([b.image_points for a, b in zip(ld, rd, strict=True) if len(a) and len(b)])
    return {"y_rms": _rectified_y(rig.left.K, rig.left.dist, rig.right.K, rig.right.dist,
                                  r.R1, r.R2, r.P1, r.P2, pl, pr), "rms": rig.extra["rms_px"]}


def _opencv_stereo(data, _value):
    import cv2

    board = data["board"]
    obj, il, ir = [], [], []
    for a, b in zip(data["images"], data["right"], strict=True):
        oka, ca = cv2.findChessboardCorners(a, board.pattern_size)
        okb, cb = cv2.findChessboardCorners(b, board.pattern_size)
        if oka and okb:
            il.append(cv2.cornerSubPix(a, ca, _peer_window(a), (-1, -1), (3, 30, 1e-3)))
            ir.append(cv2.cornerSubPix(b, cb, _peer_window(b), (-1, -1), (3, 30, 1e-3)))
            obj.append(board.object_points.astype(np.float32))
    _, K1, d1, _, _ = cv2.calibrateCamera(obj, il, data["size"], None, None)
    _, K2, d2, _, _ = cv2.calibrateCamera(obj, ir, data["size"], None, None)
    rms, K1, d1, K2, d2, R, T, _, _ = cv2.stereoCalibrate(obj, il, ir, K1, d1, K2, d2, data["size"],
                                                           flags=cv2.CALIB_FIX_INTRINSIC)
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K1, d1, K2, d2, data["size"], R, T, flags=cv2.CALIB_ZERO_DISPARITY,
                                           alpha=0)
    pl = np.concatenate([c.reshape(-1, 2) for c in il])
    pr = np.concatenate([c.reshape(-1, 2) for c in ir])
    return {"y_rms": _rectified_y(K1, d1, K2, d2, R1, R2, P1, P2, pl, pr), "rms": rms}


def _error(data, out):
    if "times" in out:
        import statistics

        base = _error(data, {k: v for k, v in out.items() if k != "times"})
        med = {k: statistics.median(t[k] for t in out["times"]) for k in ("auto", "opencv", "fixed")}
        low = {k: min(t[k] for t in out["times"]) for k in ("auto", "opencv", "fixed")}
        return dict(base, repeats=len(out["times"]), ours_auto_s=med["auto"], opencv_s=med["opencv"],
                    ours_fixed_s=med["fixed"],
                    auto_ratio=statistics.median(t["auto"] / t["opencv"] for t in out["times"]),
                    fixed_ratio=statistics.median(t["fixed"] / t["opencv"] for t in out["times"]),
                    # the least-disturbed run of each (the house rule for speed: min of repeats)
                    ours_auto_min_s=low["auto"], opencv_min_s=low["opencv"], ours_fixed_min_s=low["fixed"],
                    auto_ratio_min=low["auto"] / low["opencv"], fixed_ratio_min=low["fixed"] / low["opencv"])
    if "y_rms" in out:
        return {"error": out["y_rms"], "stereo_rms_px": out["rms"]}
    if data["gt"] is None:
        return {"error": out["rms"], "rms_px": out["rms"], "model": out["model"]}
    Kt = np.array(data["gt"]["camera"]["K"])
    K = out["K"]
    f_err = float(100 * max(abs(K[0, 0] / Kt[0, 0] - 1), abs(K[1, 1] / Kt[1, 1] - 1)))
    pp = float(np.hypot(K[0, 2] - Kt[0, 2], K[1, 2] - Kt[1, 2]))
    expected = NOISE_RMS_PX * np.sqrt(1 - out["p"] / (2 * out["n"]))
    std = out.get("std") or {}
    return {"error": f_err, "pp_px": pp, "fx_sigma_pct": float(100 * std.get("fx", np.nan) / Kt[0, 0]),
            "cx_err_px": float(abs(K[0, 2] - Kt[0, 2])), "cy_err_px": float(abs(K[1, 2] - Kt[1, 2])), "pp_sigma_px": float(np.hypot(std.get("cx", np.nan), std.get("cy", np.nan))),
            "cx_sigma_px": std.get("cx", np.nan), "cy_sigma_px": std.get("cy", np.nan),
            "rms_px": out["rms"], "expected_rms_px": float(expected),
            "model": out["model"], "warnings": len(out["warnings"]), "poor": ",".join(out["poor"])}


def _checks(res: Results, _ctx) -> list[Check]:
    out = []

    def row(case, method, value=None):
        try:
            return res.get(case, method, value)
        except KeyError:
            return None

    def ok(r):
        return r is not None and r.status == "ok"

    cv5 = row("clean", "OpenCV calibrateCamera", "k1k2p1p2k3")
    a = row("clean", "ours auto")
    if ok(a):
        ref = cv5.error if ok(cv5) else None
        out.append(Check("clean: focal error < 0.1 % (auto)", a.error, ref, a.error < 0.1,
                         f"model {a.extra['model']}; reference: OpenCV k1k2p1p2k3"))
        out.append(Check("clean: principal point error < 0.5 px (auto)", a.extra["pp_px"],
                         cv5.extra["pp_px"] if ok(cv5) else None, a.extra["pp_px"] < 0.5,
                         f"fit's sigma(cx, cy) = ({a.extra['cx_sigma_px']:.3f}, {a.extra['cy_sigma_px']:.3f}) px; "
                         "reference: OpenCV k1k2p1p2k3"))
        rel = a.extra["rms_px"] / a.extra["expected_rms_px"] - 1
        out.append(Check("clean: RMS within 10 % of the noise's expected RMS 0.2*sqrt(1-p/2N)",
                         a.extra["rms_px"], a.extra["expected_rms_px"], abs(rel) < 0.10,
                         f"relative difference {rel:+.1%}"))
    s = row("strong", "ours auto")
    if ok(s):
        out.append(Check("strong distortion: auto focal error < 0.1 %", s.error, None, s.error < 0.1,
                         f"model {s.extra['model']}"))
        cs = row("strong", "OpenCV calibrateCamera", s.extra["model"])
        out.append(Check("strong distortion: auto principal point < 0.5 px", s.extra["pp_px"],
                         cs.extra["pp_px"] if ok(cs) else None, s.extra["pp_px"] < 0.5,
                         f"fit's sigma(cx, cy) = ({s.extra['cx_sigma_px']:.3f}, {s.extra['cy_sigma_px']:.3f}) px; "
                         f"reference: OpenCV {s.extra['model']}"))
        simple = row("strong", "OpenCV calibrateCamera", "k1")
        if ok(simple):
            fails = simple.error >= 0.1 or simple.extra["pp_px"] >= 0.5
            out.append(Check("strong distortion: too-simple model (OpenCV, k1 only) fails the targets",
                             simple.error, s.error, fails,
                             f"focal {simple.error:.3f} %, pp {simple.extra['pp_px']:.2f} px"))
    f = row("fronto", "ours auto")
    if ok(f):
        named = {"fx", "fy"} & set(f.extra["poor"].split(","))
        out.append(Check("near-degenerate: warning names the poorly determined parameters",
                         float(f.extra["warnings"]), None, bool(named),
                         f"named: {f.extra['poor'] or 'none'}; focal error {f.error:.2f} %"))
    for m in ("k1k2p1p2k3", "k1k2p1p2"):
        o, c = row("real left", "ours fixed", m), row("real left", "OpenCV calibrateCamera", m)
        if ok(o) and ok(c):
            out.append(Check(f"real: RMS no worse than OpenCV's ({m})", o.error, c.error,
                             o.error <= c.error * 1.0 + 1e-9))
    st, sc = row("real stereo", "ours stereo+rectify"), row("real stereo", "OpenCV stereo+rectify")
    if ok(st):
        out.append(Check("real: rectified matched corners differ in y by < 0.5 px RMS", st.error,
                         sc.error if ok(sc) else None, st.error < 0.5))
    for name, board, *_rest, role in FAMILY:
        a, o = row(name, "ours auto"), row(name, "OpenCV calibrateCamera (family)", "k1k2p1p2k3")
        if not ok(a):
            continue
        e = a.extra
        zf = a.error / e["fx_sigma_pct"]
        zc = max(e["cx_err_px"] / e["cx_sigma_px"], e["cy_err_px"] / e["cy_sigma_px"])
        out.append(Check(f"family {name} ({role}): focal and principal-point errors within 3 sigma",
                         max(zf, zc), 3.0, max(zf, zc) <= 3.0,
                         f"model {e['model']}; focal {a.error:.3f} % = {zf:.1f} sigma, principal point "
                         f"{e['cx_err_px']:.2f}/{e['cy_err_px']:.2f} px = {zc:.1f} sigma"))
        if board == "charuco":
            out.append(Check(f"family {name} ({role}): ChArUco focal < 0.1 %, principal point < 0.5 px",
                             a.error, o.error if ok(o) else None, a.error < 0.1 and e["pp_px"] < 0.5,
                             f"principal point {e['pp_px']:.2f} px (OpenCV k1k2p1p2k3: "
                             f"{o.extra['pp_px']:.2f} px)" if ok(o) else f"principal point {e['pp_px']:.2f} px"))
        if ok(o):
            out.append(Check(f"family {name} ({role}): focal error no worse than OpenCV k1k2p1p2k3's + sigma",
                             a.error, o.error, a.error <= o.error + e["fx_sigma_pct"],
                             f"sigma {e['fx_sigma_pct']:.3f} %; principal point ours {e['pp_px']:.2f} px, "
                             f"OpenCV {o.extra['pp_px']:.2f} px"))
    for case in ("clean", "strong"):
        sp = row(case, "speed: ours vs bare OpenCV (interleaved)")
        if not ok(sp):
            continue
        e = sp.extra
        out.append(Check(f"speed ({case}): detection + calibration with auto / bare OpenCV "
                         f"(find + cornerSubPix + calibrateCamera {e['model']}) <= 1.5",
                         e["auto_ratio"], 1.5, e["auto_ratio"] <= 1.5,
                         f"medians of {e['repeats']} interleaved repeats: ours {e['ours_auto_s']:.3f} s, "
                         f"OpenCV {e['opencv_s']:.3f} s"))
        out.append(Check(f"speed ({case}): detection + calibration with the model fixed ({e['model']}) "
                         "/ bare OpenCV <= 1.5", e["fixed_ratio"], 1.5, e["fixed_ratio"] <= 1.5,
                         f"ours {e['ours_fixed_s']:.3f} s, OpenCV {e['opencv_s']:.3f} s (same repeats)"))
    for case in CHARUCO_SPEED:
        sp = row(case, "speed: ours vs bare OpenCV (interleaved)")
        if not ok(sp):
            continue
        e = sp.extra
        out.append(Check(f"speed ({case}, reported): ChArUco detection + calibration with auto / bare OpenCV "
                         f"(CharucoDetector + calibrateCamera {e['model']}) <= 1.5",
                         e["auto_ratio_min"], 1.5, e["auto_ratio_min"] <= 1.5,
                         f"min of {e['repeats']} interleaved repeats, one thread each: ours "
                         f"{e['ours_auto_min_s']:.3f} s, OpenCV {e['opencv_min_s']:.3f} s (medians "
                         f"{e['ours_auto_s']:.3f} / {e['opencv_s']:.3f} s, median ratio {e['auto_ratio']:.2f}); "
                         f"model fixed: {e['fixed_ratio_min']:.2f}"))
    return out


def stage(*, quick: bool = False) -> Stage:
    size, views = ((400, 300), 6) if quick else ((1280, 960), 15)
    board = {} if quick else {"cols": 19, "rows": 14}
    cases = [Case("clean", _synthetic(size, views, board), f"{size[0]}x{size[1]}, {views} views, normal lens, "
                                                          f"{board or 'default'} board"),
             Case("strong", _synthetic(size, views, board, distortion="strong"), "k1 = -0.3"),
             Case("fronto", _synthetic(size, views, board, poses="fronto"),
                  "all boards within 3 deg of fronto-parallel")]
    if quick:
        cases = cases[:1]
    else:
        cases += [Case(name, _family(board, sz, blur, dist, seed),
                       f"{board} {sz[0]}x{sz[1]}, 15 views, blur {blur} px, {dist} lens, seed {seed}, "
                       f"as detected (no injected noise); {role}")
                  for name, board, sz, blur, dist, seed, role in FAMILY]
    if _real_folder().is_dir():  # the real photos are optional (../shared)
        cases += [Case("real left", _real, "OpenCV's left01..14 (no GT: error = RMS px)")]
        if not quick:
            cases += [Case("real stereo", _real, "left/right pairs (error = rectified y RMS px)")]
    models = ("k1k2p1p2k3",) if quick else MODELS
    family = tuple(f[0] for f in FAMILY)
    synth = tuple(c.name for c in cases if not c.name.startswith("real") and c.name not in family)
    mono = synth + ("real left",)
    methods = (
        Method("ours auto", _ours("auto"), cases=mono + family),
        Method("ours fixed", _ours(None), "model", models, cases=mono),
        Method("OpenCV calibrateCamera", _opencv, "model", models, peer="opencv", cases=mono),
        Method("OpenCV calibrateCamera (family)", _opencv, "model", ("k1k2p1p2k3",), peer="opencv",
               cases=family),
        Method("speed: ours vs bare OpenCV (interleaved)", _speed, cases=synth[:2] + CHARUCO_SPEED,
               prepare=lambda d: {"data": d, "times": []}),
        Method("ours stereo+rectify", _ours_stereo, cases=("real stereo",)),
        Method("OpenCV stereo+rectify", _opencv_stereo, peer="opencv", cases=("real stereo",)),
    )
    return Stage("calib", tuple(cases), methods, _error, "focal error % (real: RMS px / rectified y RMS px)",
                 checks=_checks, repeats=3,
                 description="Detection + calibration on rendered boards with 0.2 px corner noise "
                             "and on OpenCV's real stereo photos, ours beside bare OpenCV.")
