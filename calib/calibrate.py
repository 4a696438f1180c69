"""Camera calibration you can trust: automatic distortion-model choice by
held-out error, parameter uncertainties, outlier views, degeneracy warnings,
and stereo rigs.

Model choice (``model="auto"``, DESIGN §9)
    Every candidate of :data:`calib.zhang2000.MODELS` (simple to rich) is fitted
    to all views, and scored by **leave-views-out** cross-validation: the views
    are split into ``min(4, V)`` folds (view k in fold k mod 4); for each fold the candidate is refitted
    on the other views and each held-out view's pose alone is fitted
    (``solvePnP``) with those intrinsics; the held-out error of a view is its
    mean squared corner residual. The rule: with ``best`` the candidate of
    lowest mean held-out error, choose the simplest candidate that is **not
    significantly worse** than ``best`` by a one-sided paired t-test over the
    held-out views at the 5 % level: ``mean(d) <= t(0.95, V-1) · sd(d)/sqrt(V)``
    with ``d_v = e_candidate(v) - e_best(v)``. (We compare with the best rather
    than blindly with the richest so an over-fitted rich model, whose held-out
    error is inflated, cannot make a too-simple one look acceptable; normally
    the best is the richest or ties with it.) A simpler candidate chosen so
    must also agree with the best: none of fx, fy, cx, cy more than
    ``SHIFT_Z`` (1) of its own sigma from the best's, else the next richer
    one is taken (noisy corners hide small terms from the t-test, and the
    simple model's sigma knows nothing of the terms it dropped). Every candidate's training RMS,
    held-out RMS, mean difference, its standard error and the verdict go to
    ``camera.json["candidates"]``. To stay within 1.5x of one bare OpenCV
    calibration, the work is pruned (see :func:`select_model`): candidates are
    refined from the anchor ``k1k2p1p2k3`` fit and fold refits from the
    all-view solution, both by Levenberg–Marquardt on the intrinsics' Schur
    complement (:func:`calib.zhang2000.refine`), simple candidates whose training error is
    already significantly worse than the best held-out error are rejected
    without refits (with the candidates nested in them), and richer candidates
    are tried only while each step up improves significantly.

Outlier views
    A view whose RMS under the k1k2p1p2k3 fit (the fixed model's own fit when
    ``model`` is given) exceeds 3× the median view RMS
    (per-view RMS of iid corner noise over ~50 corners varies by ~10 %, so 3×
    is never chance) is dropped, named in ``views`` with ``used: false``, and
    the fit repeated (twice at most; at least 3 views always remain).

Degeneracy checks (warnings in ``camera.json["warnings"]`` and on stderr; with
``strict=True`` they refuse with EstimationError)
    * fewer than 6 views;
    * corners covering less than half of an 8 × 6 grid of image cells (the
      distortion is then extrapolated toward the edges);
    * all boards within 10° of fronto-parallel, or all board normals within 5°
      of each other: Zhang's constraints degenerate for parallel planes and the
      focal length and principal point become poorly determined (Zhang 2000,
      §3.3 "degenerate configurations");
    * a parameter whose one-standard-deviation change moves the farthest image
      corner by more than 1 px (``fx``: σ·|x_n|max, ``cx``: σ, ``k_i``:
      f σ r^(2i+1), ``p_i``: 3 f σ r², rational terms like the radial ones),
      or a focal length with relative σ above 0.5 %. Each such parameter is
      named.

Units: translations are in the board's square unit (``--board …:SQUARE``).

Examples
--------
>>> from lumigraph.capture.render import render
>>> from lumigraph.calib.detect import BoardSpec, detect
>>> s = render("boards", size=(320, 240), seed=2, views=6)
>>> board = BoardSpec.parse(s.stack["board"])
>>> cam = calibrate([detect(im, board) for im in s.images], model="k1k2")
>>> bool(abs(cam.K[0, 0] / s.gt["camera"]["K"][0][0] - 1) < 0.01)
True
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from lumigraph.calib.detect import Detection
from lumigraph.calib.zhang2000 import (
    FREE,
    MODELS,
    ZhangFit,
    _free_columns,
    _normal,
    _one_opencv_thread,
    calibrate_fixed,
    n_intrinsics,
    refine,
)
from lumigraph.capture.camera import Camera
from lumigraph.capture.errors import EstimationError, InputError

MIN_VIEWS = 3
OUTLIER_FACTOR = 3.0
SIGNIFICANCE = 0.05
FOLDS = 4
# A candidate the held-out test cannot tell from the best may still move the
# focal length or principal point: too-noisy corners hide small tangential
# terms from the t-test, and the simpler model's estimate is then biased
# beyond its own sigma, which knows nothing of the terms it left out (ChArUco
# with 0.15 px corner noise: k1 chosen, principal point 3-5 of its sigma
# off). So a simpler candidate is kept only if none of fx, fy, cx, cy moves
# from the best candidate's by more than SHIFT_Z of its own sigma: the sigma
# it reports then also covers the choice of model (Hausman's idea, with the
# simple model's sigma as the yardstick: docs/decisions/calibration-model-choice.md).
SHIFT_Z = 1.0
_SHIFT_PARAMS = ("fx", "fy", "cx", "cy")
# a baseline below this fraction of the board's extent is no rig: the same
# views on both sides (a real rig's baseline is a sizeable part of its field)
ZERO_BASELINE = 1e-6


def _split(detections: Sequence[Detection], names):
    names = list(names) if names is not None else [f"view {k}" for k in range(len(detections))]
    if len(names) != len(detections):
        raise ValueError(f"names: expected {len(detections)} names, got {len(names)}")
    used = [(n, d) for n, d in zip(names, detections, strict=True) if len(d) >= 6]
    skipped = [n for n, d in zip(names, detections, strict=True) if len(d) < 6]
    sizes = {d.image_size for _, d in used}
    if len(sizes) > 1:
        raise InputError("images", f"mixed image sizes {sorted(sizes)}; calibrate one camera "
                                   "(one image size) at a time")
    return used, skipped


# A held-out refit starts at the all-view solution, a few views away from its own
# optimum, and is refined by Levenberg-Marquardt on the intrinsics' Schur complement
# (zhang2000.refine) until a step lowers the squared error by less than 1e-6 of it:
# the held-out errors then lie within ~1e-5 relative of fully converged refits (bench
# sets clean, strong, fronto, checked against 100-step refits), far below the
# few-percent differences the t-test resolves. (Three steps of OpenCV's own solver, the
# earlier rule, left up to 4 % on the nearly fronto-parallel set, at 3-8x the cost.)
# A candidate started from the anchor model's solution is refined the same way to
# 1e-8. The chosen model is then refined to full convergence by OpenCV (60 steps,
# 1e-9), with its uncertainties.
_CV_RTOL, _WARM_RTOL = 1e-6, 1e-8
# OpenCV's solver, where ours fails (a singular system: no views left to fix a term)
_CV_ITER, _CV_EPS = 3, 1e-7
_WARM_ITER, _WARM_EPS = 12, 1e-7


def view_mse(fit: ZhangFit, obj, img) -> np.ndarray:
    """Mean squared corner residual per view (px²) of a fit on these views."""
    import cv2

    out = np.empty(len(obj))
    for v in range(len(obj)):
        proj, _ = cv2.projectPoints(np.asarray(obj[v], np.float64), fit.rvecs[v], fit.tvecs[v],
                                    fit.K, fit.dist)
        out[v] = float(np.mean(np.sum((proj.reshape(-1, 2) - img[v]) ** 2, axis=1)))
    return out


def _heldout(fits_full: ZhangFit, obj, img, size, folds) -> np.ndarray:
    """Mean squared held-out residual per view (px²) for one candidate model; each
    fold's refit starts from the all-view solution (intrinsics and poses)."""
    import cv2

    V = len(obj)
    obj = [np.asarray(o, np.float64) for o in obj]
    img = [np.asarray(p, np.float64) for p in img]
    f0 = fits_full
    cols = _free_columns(f0.model)
    at_start = _normal(obj, img, np.arange(V), f0.K, f0.dist, f0.rvecs, f0.tvecs, cols)
    err = np.full(V, np.inf)
    for f in range(folds):
        test = [v for v in range(V) if v % folds == f]
        train = [v for v in range(V) if v % folds != f]
        if len(train) < 2:
            continue
        try:
            K, dist = refine(obj, img, model=f0.model, K=f0.K, dist=f0.dist, rvecs=f0.rvecs,
                             tvecs=f0.tvecs, views=train, rtol=_CV_RTOL,
                             start=at_start.take(train))[:2]
        except EstimationError:
            try:
                fit = calibrate_fixed([obj[v] for v in train], [img[v] for v in train], size,
                                      model=f0.model, K0=f0.K, dist0=f0.dist,
                                      rvecs0=f0.rvecs[train], tvecs0=f0.tvecs[train],
                                      uncertainties=False, max_iter=_CV_ITER, eps=_CV_EPS)
            except EstimationError:
                continue
            K, dist = fit.K, fit.dist
        for v in test:
            # the all-view pose is a good start; the held-out pose is refined for these intrinsics
            rv, tv = f0.rvecs[v].copy(), f0.tvecs[v].copy()
            ok, rv, tv = cv2.solvePnP(obj[v], img[v], K, dist, rv, tv,
                                      useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
            if not ok:
                continue
            proj, _ = cv2.projectPoints(obj[v], rv, tv, K, dist)
            err[v] = float(np.mean(np.sum((proj.reshape(-1, 2) - img[v]) ** 2, axis=1)))
    return err


def select_model(fits, obj, img, size) -> tuple[str, list[dict]]:
    """The simplest candidate not significantly worse than the best on held-out
    views (rule in the module docstring); returns the choice and every score.

    ``fits`` maps candidate names, simple to rich, to their all-view fits (a
    dict, or a callable ``name -> ZhangFit`` with ``fits.candidates`` giving
    the order, so fits are made only when needed). Work saved, all recorded
    in the rows:

    * the anchor (``k1k2p1p2k3``, else the richest) is cross-validated first;
    * simpler candidates, rich to simple: one whose *training* error is
      already significantly worse than the best held-out error is rejected
      without cross-validation (a view's held-out error exceeds its training
      error in expectation, so the held-out test could only confirm it), and
      so are the candidates nested in it (their training error is larger);
    * richer candidates are evaluated only while each step up improved the
      held-out error significantly (early stop).
    """
    from scipy.special import stdtrit  # scipy.stats costs a second to import

    if isinstance(fits, dict):
        order, get = list(fits), fits.__getitem__
    else:
        order, get = list(fits.candidates), fits
    V = len(obj)
    folds = min(FOLDS, V)
    tcrit = float(stdtrit(V - 1, 1 - SIGNIFICANCE))

    def compare(a, b):
        d = a - b
        se = float(d.std(ddof=1) / np.sqrt(V)) if V > 1 else 0.0
        return bool(d.mean() > tcrit * se and d.mean() > 0), float(d.mean()), se

    done, errs, notes, best = {}, {}, {}, None

    def fitted(m):
        if m not in done:
            try:
                done[m] = get(m)
            except (EstimationError, KeyError):
                done[m] = None
                notes[m] = "fit failed"
        return done[m]

    def cross_validate(m):
        nonlocal best
        e = _heldout(done[m], obj, img, size, folds)
        if not np.all(np.isfinite(e)):
            notes[m] = "cross-validation fit failed"
            return
        errs[m] = e
        best = min(errs, key=lambda k: errs[k].mean())

    ai = order.index("k1k2p1p2k3") if "k1k2p1p2k3" in order else len(order) - 1
    if fitted(order[ai]) is not None:
        cross_validate(order[ai])
    screened_below = None
    for m in reversed(order[:ai]):
        if screened_below is not None:
            notes[m] = f"nested in {screened_below}, rejected by its training error: not evaluated"
            continue
        if fitted(m) is None:
            continue
        if best is not None:
            worse, md, se = compare(view_mse(done[m], obj, img), errs[best])
            if worse:
                notes[m] = (f"training error significantly worse than {best}'s held-out error: "
                            "not cross-validated")
                errs_screen = {"mean_diff_px2": md, "se_px2": se}
                done[m] = (done[m], errs_screen)
                screened_below = m
                continue
        cross_validate(m)
    prev = order[ai]
    for k, m in enumerate(order[ai + 1:], start=ai + 1):
        simpler = order[k - 2] if k >= 2 else None
        below = done.get(simpler)
        improved = simpler is None or isinstance(below, tuple) or (
            prev in errs and simpler in errs and compare(errs[simpler], errs[prev])[0])
        if not improved:
            for r in order[k:]:
                notes[r] = f"not evaluated: {prev} did not improve significantly on {simpler}"
            break
        if fitted(m) is not None:
            cross_validate(m)
        prev = m
    if best is None:
        raise EstimationError("calibration", "no distortion model could be cross-validated; "
                                             "add views with the whole board visible")
    rows, chosen = [], None
    for m in order:
        f = done.get(m)
        screen = None
        if isinstance(f, tuple):
            f, screen = f
        row = {"model": m, "n_params": n_intrinsics(m) + 6 * V,
               "rms_px": f.rms_px if f is not None else None}
        if m in errs:
            worse, md, se = compare(errs[m], errs[best])
            row.update(heldout_rms_px=float(np.sqrt(errs[m].mean())), mean_diff_px2=md, se_px2=se,
                       significantly_worse=worse)
            if chosen is None and not worse:
                chosen = m
        else:
            # screened or nested in a screened candidate: rejected; richer ones never
            # evaluated (early stop) or failed: no verdict
            nested = notes.get(m, "").startswith("nested")
            row.update(heldout_rms_px=None,
                       significantly_worse=True if (screen is not None or nested) else None,
                       **(screen or {}))
        if m in notes:
            row["note"] = notes[m]
        rows.append(row)
    for r in rows:
        r["chosen"] = r["model"] == chosen
        r["best_heldout"] = r["model"] == best
    return chosen, rows


def _agree_with_best(fits, rows, chosen, obj, img, size):
    """The chosen model, moved up toward the best held-out one while its focal
    length or principal point sits more than ``SHIFT_Z`` of its own sigma
    from the best's (see ``SHIFT_Z``); returns it and its full fit with
    uncertainties. Each row tested gets ``shift_sigma``."""
    order = [r["model"] for r in rows]
    best = next(r["model"] for r in rows if r["best_heldout"])

    def full(m):  # the uncertainties (and per-view RMS) from the model's optimum
        c = fits(m)
        return calibrate_fixed(obj, img, size, model=m, K0=c.K, dist0=c.dist, rvecs0=c.rvecs,
                               tvecs0=c.tvecs)

    if order.index(best) <= order.index(chosen):
        return chosen, full(chosen)
    # the best's all-view fit (no uncertainties needed: the yardstick is the
    # simple model's own sigma) gives the reference values
    ref = fits(best).K[[0, 1, 0, 1], [0, 1, 2, 2]]
    pick, fit = best, None
    for r in rows[order.index(chosen):order.index(best)]:
        if r.get("significantly_worse") is not False:
            continue
        f = full(r["model"])
        sig = np.array([f.std[p] for p in ("fx", "fy", "cx", "cy")])
        z = float(np.max(np.abs(f.K[[0, 1, 0, 1], [0, 1, 2, 2]] - ref) / sig))
        r["shift_sigma"] = z
        if z <= SHIFT_Z:
            pick, fit = r["model"], f
            break
        r["note"] = (r.get("note", "") + "; " if r.get("note") else "") + \
            f"fx, fy, cx or cy {z:.1f} of its sigma from {best}'s: biased, not chosen"
    for r in rows:
        r["chosen"] = r["model"] == pick
    return pick, (fit if fit is not None else full(pick))


def _tilts(fit: ZhangFit) -> tuple[np.ndarray, float]:
    import cv2

    normals = np.array([cv2.Rodrigues(r)[0][:, 2] for r in fit.rvecs])
    tilt = np.degrees(np.arccos(np.clip(np.abs(normals[:, 2]), 0, 1)))
    cosines = np.clip(np.abs(normals @ normals.T), 0, 1)
    spread = float(np.degrees(np.arccos(cosines.min())))
    return tilt, spread


def _sensitivity(fit: ZhangFit, size) -> dict[str, float]:
    """Pixel displacement of the farthest image corner for a one-sigma change of each parameter."""
    w, h = size
    K = fit.K
    xn = max(abs(0 - K[0, 2]), abs(w - 1 - K[0, 2])) / K[0, 0]
    yn = max(abs(0 - K[1, 2]), abs(h - 1 - K[1, 2])) / K[1, 1]
    r = float(np.hypot(xn, yn))
    f = float(max(K[0, 0], K[1, 1]))
    power = {"k1": 3, "k2": 5, "k3": 7, "k4": 3, "k5": 5, "k6": 7}
    out = {}
    for name, s in fit.std.items():
        if name == "fx":
            out[name] = s * xn
        elif name == "fy":
            out[name] = s * yn
        elif name in ("cx", "cy"):
            out[name] = s
        elif name in power:
            out[name] = f * s * r ** power[name]
        else:  # p1, p2
            out[name] = 3 * f * s * r * r
    return out


def degeneracy_warnings(fit: ZhangFit, img, size) -> tuple[list[str], list[str]]:
    """Warnings about the view set and the poorly determined parameters (names)."""
    warnings, poor = [], []
    V = len(img)
    if V < 6:
        warnings.append(f"only {V} usable views (6 or more with varied tilts are recommended)")
    w, h = size
    occ = np.zeros((6, 8), bool)
    for p in img:
        gx = np.clip((p[:, 0] / w * 8).astype(int), 0, 7)
        gy = np.clip((p[:, 1] / h * 6).astype(int), 0, 5)
        occ[gy, gx] = True
    cover = float(occ.mean())
    if cover < 0.5:
        warnings.append(f"poor image coverage: corners fall in {cover:.0%} of an 8x6 grid of image "
                        "cells; distortion is extrapolated toward the uncovered edges")
    tilt, spread = _tilts(fit)
    if tilt.max() < 10.0:
        warnings.append(f"all views nearly fronto-parallel (largest tilt {tilt.max():.1f} deg < 10): "
                        "focal length and principal point are poorly determined; tilt the board "
                        "20-45 deg in several directions")
    elif spread < 5.0:
        warnings.append(f"all board normals within {spread:.1f} deg of each other (parallel planes): "
                        "focal length and principal point are poorly determined")
    sens = _sensitivity(fit, size)
    for name, px in sens.items():
        rel = fit.std[name] / fit.K[0, 0] if name == "fx" else (
            fit.std[name] / fit.K[1, 1] if name == "fy" else 0.0)
        if px > 1.0 or rel > 0.005:
            poor.append(name)
    if poor:
        warnings.append("poorly determined parameters: " + ", ".join(
            f"{n} (1 sigma moves the image corner {sens[n]:.2f} px)" for n in poor))
    return warnings, poor


def _reject_outliers(obj, img, names, size, first: ZhangFit):
    """Drop outlier views in place (screened with ``first``'s model); returns their report rows."""
    rejected = []
    for it in range(2):
        fit = first if it == 0 else calibrate_fixed(obj, img, size, model=first.model)
        med = float(np.median(fit.view_rms_px))
        bad = [v for v in range(len(obj)) if fit.view_rms_px[v] > OUTLIER_FACTOR * med]
        if not bad or len(obj) - len(bad) < MIN_VIEWS:
            break
        for v in sorted(bad, reverse=True):
            rejected.append({"name": names[v], "used": False, "rms_px": float(fit.view_rms_px[v]),
                             "reason": f"outlier: view RMS {fit.view_rms_px[v]:.3f} px > "
                                       f"{OUTLIER_FACTOR:g} x median {med:.3f} px"})
            del obj[v], img[v], names[v]
    return rejected


def calibrate(detections: Sequence[Detection], *, model: str = "auto",
              names: Sequence[str] | None = None, candidates: Sequence[str] = MODELS,
              reject_outliers: bool = True, strict: bool = False) -> Camera:
    """Calibrate one camera from board detections (Zhang 2000, see module docstring).

    Parameters
    ----------
    detections : sequence of Detection
        One per image; empty ones (no board) are skipped and named in
        ``extra["skipped"]``.
    model : str, keyword-only
        ``"auto"`` (default) or one of :data:`calib.zhang2000.MODELS`.
    names : sequence of str, optional
        Image names for the report.
    candidates : sequence of str
        Candidate models for ``auto``, simple to rich.
    reject_outliers : bool
        Drop views whose RMS is over 3× the median.
    strict : bool
        Refuse (EstimationError) instead of warning on a degenerate set.

    Returns
    -------
    Camera
        With ``extra``: ``rms_px``, ``std``, ``views`` (name, used, RMS,
        ``cam_from_world``), ``candidates``, ``model_selection``, ``warnings``,
        ``poorly_determined``, ``skipped``, ``n_points``, ``corner_fit_fallbacks``.

    Raises
    ------
    InputError
        No board found, fewer than 3 usable views, mixed image sizes.
    EstimationError
        The optimiser failed, or ``strict`` and the set is degenerate.
    """
    import cv2

    if model != "auto" and model not in MODELS:
        raise ValueError(f"model: expected 'auto' or one of {', '.join(MODELS)}, got {model!r}")
    used, skipped = _split(detections, names)
    if not used:
        raise InputError("images", "no calibration board found in any image; check the board "
                                   "(COLSxROWS counts squares) and the photos")
    if len(used) < MIN_VIEWS:
        raise InputError("images", f"only {len(used)} usable view(s) with the board found; at least "
                                   f"{MIN_VIEWS} are needed (skipped: {', '.join(skipped) or 'none'})")
    size = used[0][1].image_size
    vnames = [n for n, _ in used]
    obj = [d.object_points for _, d in used]
    img = [d.image_points for _, d in used]

    def fitter(models):
        """Candidate fits on demand: one cold fit (Zhang's closed-form start) of the
        anchor model; every other candidate is refined from its intrinsics and poses
        (``refine``: a few steps instead of a full solve; the rational model alone
        costs 5-20x more from scratch)."""
        anchor = "k1k2p1p2k3" if "k1k2p1p2k3" in models else models[-1]
        cache = {}
        obj64 = [np.asarray(o, np.float64) for o in obj]
        img64 = [np.asarray(p, np.float64) for p in img]

        def get(m):
            if m not in cache:
                if m == anchor:
                    cache[m] = calibrate_fixed(obj, img, size, model=m, uncertainties=False)
                else:
                    try:
                        a = get(anchor)
                    except EstimationError:
                        a = None
                    cache[m] = _warm(m, a)
            return cache[m]

        def _warm(m, a):
            if a is not None:
                try:
                    K, dist, rv, tv, sq, _ = refine(obj64, img64, model=m, K=a.K, dist=a.dist,
                                                    rvecs=a.rvecs, tvecs=a.tvecs, rtol=_WARM_RTOL)
                    n = sum(len(o) for o in obj64)
                    return ZhangFit(m, K, dist, rv, tv, float(np.sqrt(sq / n)), {},
                                    np.full(len(obj64), np.nan), n)
                except EstimationError:
                    pass
            warm = {"K0": a.K, "dist0": a.dist, "rvecs0": a.rvecs, "tvecs0": a.tvecs} if a else {}
            return calibrate_fixed(obj, img, size, model=m, uncertainties=False,
                                   max_iter=_WARM_ITER, eps=_WARM_EPS, **warm)

        get.candidates = tuple(models)
        get.anchor = anchor
        return get

    rejected = []
    if model == "auto":
        candidates = tuple(candidates)
        fits = fitter(candidates)
        if reject_outliers:  # the anchor candidate doubles as the outlier screen
            try:
                screen = fits(fits.anchor)
            except EstimationError:
                screen = None
            if screen is not None:
                screen = replace(screen, view_rms_px=np.sqrt(view_mse(screen, obj, img)))
                rejected = _reject_outliers(obj, img, vnames, size, screen)
            if rejected:
                fits = fitter(candidates)
        with _one_opencv_thread():  # once for the dozen solves below (see zhang2000)
            chosen, rows = select_model(fits, obj, img, size)
            chosen, fit = _agree_with_best(fits, rows, chosen, obj, img, size)
        selection = {"rule": "simplest candidate whose held-out (leave-views-out, "
                             f"{min(FOLDS, len(obj))}-fold) error is not significantly worse than the "
                             f"best candidate's: one-sided paired t-test over views at {SIGNIFICANCE:g}, "
                             f"and whose fx, fy, cx, cy lie within {SHIFT_Z:g} sigma of the best's",
                     "chosen": chosen, "best_heldout": next(r["model"] for r in rows if r["best_heldout"])}
    else:
        fit = calibrate_fixed(obj, img, size, model=model)
        if reject_outliers:
            rejected = _reject_outliers(obj, img, vnames, size, fit)
            if rejected:
                fit = calibrate_fixed(obj, img, size, model=model)
        rows = [{"model": model, "n_params": fit.n_params, "rms_px": fit.rms_px, "chosen": True}]
        selection = {"rule": "fixed by the caller", "chosen": model}
    warnings, poor = degeneracy_warnings(fit, img, size)
    if strict and warnings:
        raise EstimationError("calibration", "refused (strict): " + "; ".join(warnings))
    views = []
    for v, n in enumerate(vnames):
        R = cv2.Rodrigues(fit.rvecs[v])[0]
        views.append({"name": n, "used": True, "rms_px": float(fit.view_rms_px[v]),
                      "n_corners": int(len(img[v])),
                      "cam_from_world": {"R": R.tolist(), "t": fit.tvecs[v].tolist()}})
    extra = {"rms_px": fit.rms_px, "std": fit.std, "views": views + rejected,
             "candidates": rows, "model_selection": selection, "warnings": warnings,
             "poorly_determined": poor, "skipped": list(skipped), "n_points": fit.n_points,
             "n_params": fit.n_params,
             # corners whose X-junction fit failed and kept cornerSubPix's position (detect.py)
             "corner_fit_fallbacks": int(sum(getattr(d, "fallbacks", 0) for d in detections))}
    return Camera(fit.K, fit.dist, size, fit.model, extra)


def view_points(detections: Sequence[Detection]):
    """``(object_points, image_points)`` lists of the non-empty detections."""
    return ([d.object_points for d in detections if len(d)],
            [d.image_points for d in detections if len(d)])


def _same_file(a, b) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_stereo_pairs(left: Sequence, right: Sequence) -> None:
    """Check that :func:`calibrate_stereo` gets its views in pairs: as many
    ``right`` as ``left`` (detections, or the image files before they are
    read); :class:`InputError` naming ``right`` otherwise.

    >>> check_stereo_pairs(["l0.png", "l1.png"], ["r0.png"])
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: right: expected as many right images as left (2), got 1
    >>> check_stereo_pairs(["l0.png"], ["l0.png"])
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: right: l0.png is also the left image of pair 0; a rig's two cameras see the board from two places: give the right camera's images
    """
    if len(left) != len(right):
        raise InputError("right", f"expected as many right images as left ({len(left)}), got {len(right)}")
    for k, (a, b) in enumerate(zip(left, right, strict=True)):
        # the same image on both sides calibrates a rig of zero baseline
        if isinstance(a, str | os.PathLike) and isinstance(b, str | os.PathLike) and (
                os.fspath(a) == os.fspath(b) or _same_file(a, b)):
            raise InputError("right", f"{os.fspath(b)} is also the left image of pair {k}; a rig's "
                                      "two cameras see the board from two places: give the right "
                                      "camera's images")


def calibrate_stereo(left: Sequence[Detection], right: Sequence[Detection], *, model: str = "auto",
                     names: Sequence[str] | None = None, left_camera: Camera | None = None,
                     right_camera: Camera | None = None, strict: bool = False):
    """Calibrate a stereo rig: each camera alone (:func:`calibrate`), then the
    right-from-left pose by OpenCV ``stereoCalibrate`` with the intrinsics fixed,
    on the pairs where both images show the board (common corners).

    Parameters
    ----------
    left, right : sequence of Detection
        Simultaneous views, pairwise.
    left_camera, right_camera : Camera, optional
        Known intrinsics (skip the single-camera calibrations).

    Returns
    -------
    Rig
        ``x_right = R x_left + T`` (T in board units); ``extra`` holds
        ``rms_px``, per-pair RMS, the pair names and both cameras' warnings.
    """
    import cv2

    from lumigraph.capture.rig import Rig

    check_stereo_pairs(left, right)
    names = list(names) if names is not None else [f"pair {k}" for k in range(len(left))]
    lcam = left_camera or calibrate(left, model=model, names=[f"{n} (left)" for n in names], strict=strict)
    rcam = right_camera or calibrate(right, model=model, names=[f"{n} (right)" for n in names],
                                     strict=strict)
    obj, il, ir, pairs = [], [], [], []
    for n, a, b in zip(names, left, right, strict=True):
        common, ia, ib = np.intersect1d(a.ids, b.ids, return_indices=True)
        if len(common) >= 6:
            obj.append(a.object_points[ia].astype(np.float32).reshape(-1, 1, 3))
            il.append(a.image_points[ia].astype(np.float32).reshape(-1, 1, 2))
            ir.append(b.image_points[ib].astype(np.float32).reshape(-1, 1, 2))
            pairs.append(n)
    if len(pairs) < MIN_VIEWS:
        raise InputError("images", f"only {len(pairs)} pair(s) show the board in both cameras; "
                                   f"at least {MIN_VIEWS} are needed")
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    try:
        out = cv2.stereoCalibrateExtended(
            obj, il, ir, lcam.K, lcam.dist, rcam.K, rcam.dist, lcam.image_size, None, None,
            flags=cv2.CALIB_FIX_INTRINSIC, criteria=criteria)
    except cv2.error as e:
        raise EstimationError("stereo", f"OpenCV stereoCalibrate failed ({str(e).strip().splitlines()[-1]})") from None
    rms, R, T, per_view = out[0], out[5], out[6], out[-1]
    per_view = np.asarray(per_view, np.float64).reshape(len(pairs), -1)
    warnings = [f"left: {w}" for w in lcam.extra.get("warnings", [])] + \
               [f"right: {w}" for w in rcam.extra.get("warnings", [])]
    T = np.asarray(T, np.float64).ravel()
    # identical left and right views fit T ~ 1e-9: no rig, whatever the RMS says
    extent = max(float(np.ptp(np.concatenate([o.reshape(-1, 3) for o in obj]), axis=0).max()), 1e-300)
    if not np.linalg.norm(T) > ZERO_BASELINE * extent:
        raise EstimationError("right", f"the right camera sits where the left one does (baseline "
                                       f"{np.linalg.norm(T):.3g} for a board {extent:.3g} across): "
                                       "are the same images given as left and right?")
    return Rig.from_pose(lcam, rcam, np.asarray(R, np.float64), T, rms_px=float(rms),
                         pairs=[{"name": n, "rms_px_left": float(e[0]), "rms_px_right": float(e[1])}
                                for n, e in zip(pairs, per_view, strict=True)],
                         warnings=warnings, n_pairs=len(pairs))


__all__ = ["calibrate", "calibrate_stereo", "select_model", "degeneracy_warnings", "FREE", "MODELS"]
