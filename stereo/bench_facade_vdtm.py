"""Bench rows of ``lumigraph bench facade`` for Façade's stages 2 and 3:
view-dependent texture mapping on the glossy building, and model-based
stereo fed by the solved model (issue 17).

Scenes: ``lumigraph render facade`` (8 photographs on a 240° arc, 4 novel
views half-way between photographs). Seeds 0, 4 and 5 are the TUNED scenes
(the blend's weights ``DEFAULT_POWER``/``DEFAULT_NEIGHBOURS``, the view
map's choice of three and the scene's materials were set looking at their
views; the bench shows seed 0's rows, labelled); every check is on the
REPORTED seeds 1–3 (quick: seed 1) and holds at the WORST reported view
(the median is in the note).

- VDTM (glossy, 640x480; quick 160x120): PSNR (dB, 8-bit scale) against the
  noise-free novel view, over the pixels where the view sees the model's
  own surface, of the blend (Debevec, Taylor & Malik 1996), the view-map
  variant (Debevec, Yu & Borshukov 1998), the uniform average of the
  photographs that see each point (the blend with equal weights over all
  of them) and the nearest photograph's texture alone (the photograph whose
  centre is nearest the new one; what it does not see filled as VDTM fills
  holes). Targets (the issue's sentence read strictly): blend ≥ 2 dB above
  the uniform average AND ≥ 2 dB above the nearest photograph; view map
  within ±0.5 dB of the blend at ≥ 3× its speed. The speed is what a new
  view costs: the whole library call against the whole call (the shared
  z-buffer of the new view and hole filling included), one thread, calls
  interleaved, the minimum of five each in CPU time, with the photographs'
  depth maps and the view maps prepared once beforehand (both papers
  precompute visibility; the 1998 view maps, and here each photograph's
  visibility of each plane, are built once per model and photographs);
  the precompute, and the ratio with it spread over a model's views, are
  in the check's note; the texturing stage's ratio is in the row.
- Model-based stereo (Lambertian building, 640x480, quick 320x240; the
  glossy variant's highlights break SSD matching between two views): key
  ``photo_03``, offset ``photo_04``; marks with 0.5 px endpoint noise. The
  check feeds the solved model (its depth from the true key camera; the
  solved model is in the model's own frame, as the truth) with the true rig,
  against the true model; a further row uses the solved cameras too (the
  solved key camera's depth and the rig of the solved poses: the whole
  chain, pose error included). Error: the share of key pixels with a depth
  off the truth by more than 1 % (of the pixels the method answers), the
  truth taken along the rays of the key camera the depth map is in (the
  solved camera's rays are a little off the true one's: this measures the
  stereo, not the pose; the rig's error stays in). With a solved model the
  search follows the model's depth σ (``model_std``, from the solve's
  parameter covariance, :func:`~lumigraph.stereo.debevec1996.raster.model_depth_sigma`):
  pixels whose model can be off by more than the search are not answered,
  the range widens by 3 median σ.
  Target: with the solved model within 1.2× the error with the true one,
  at the worst reported seed.

No public library does VDTM or Façade's model-based stereo (issue 17): no peer row.
"""

from __future__ import annotations

import math
import time

import numpy as np

from lumigraph.capture.bench import Check, Row

TUNED_SEEDS = (0,)  # seeds 4 and 5 were tuned on too (not run here: bench time)
REPORTED_SEEDS = (1, 2, 3)
# the reflection layer (reflection.py) was built on seeds 0, 4 and 5; one view of seed 1
# (its left wall's windows) led to the layer's gate, and seed 9's worst view was looked at;
# seeds 12-14 were first rendered for the gated layer's report (docs/decisions/facade-vdtm.md)
LAYER_FRESH_SEEDS = (12, 13, 14)


def _label(seed, view=None):
    kind = "tuned" if seed in TUNED_SEEDS else "reported"
    return f"facade s{seed}{' ' + view if view else ''} ({kind})"


def _row(case, method, err, t=math.nan, **extra):
    return Row("facade", case, method, None, "", None, t, (t,) if not math.isnan(t) else (), err,
               "ok", extra)


def _psnr(a, b, m):
    return float(10 * np.log10(255.0 ** 2 / np.mean((a[m] - b[m]) ** 2)))


def _photos(s):
    from lumigraph.capture.scenes.facade import Building
    from lumigraph.stereo.debevec1996.vdtm import Photograph, prepare_photographs, prepare_view_maps

    b = Building(s.gt["parameters"]).mesh()
    mesh = (b.vertices, b.faces)
    photos = prepare_photographs(mesh, [
        Photograph(im.astype(np.float32), np.array(c["K"]), np.array(c["R"]), np.array(c["t"]))
        for im, c in zip(s.images, s.gt["cameras"].values(), strict=True)])
    # the view maps' precompute (once per model and photographs: the polygons' maps,
    # the planes and each photograph's visibility of each plane), timed apart
    t0 = time.process_time()
    maps = prepare_view_maps(mesh, photos)
    return mesh, photos, maps, time.process_time() - t0


def _interleaved(fns, repeats=5):
    """``(outputs, best seconds)`` of each of ``fns``, called in turn
    ``repeats`` times (interleaved, so a load change hits all alike); the
    seconds are CPU time of this process (``time.process_time``: on a
    shared machine steadier than the wall clock; one thread, so the same),
    the output that of the fastest call (its stage timings beside it)."""
    best, out = [math.inf] * len(fns), [None] * len(fns)
    for _ in range(repeats):
        for i, fn in enumerate(fns):
            t0 = time.process_time()
            o = fn()
            dt = time.process_time() - t0
            if dt < best[i]:
                best[i], out[i] = dt, o
    return out, best


def vdtm(quick: bool):
    """The VDTM rows and checks (module docstring)."""
    import cv2

    from lumigraph.capture.render import render
    from lumigraph.stereo.debevec1996.vdtm import render_vdtm

    cv2.setNumThreads(1)
    from lumigraph.stereo.debevec1996.reflection import fit_reflection_layer

    size = (160, 120) if quick else (640, 480)
    seeds = TUNED_SEEDS + (REPORTED_SEEDS[:1] if quick else REPORTED_SEEDS + LAYER_FRESH_SEEDS)
    rows, gains_u, gains_n, vm_diff, speed, speed_all = [], [], [], [], [], []
    layer_u, layer_n, layer_b, layer_fit = [], [], [], []  # the reflection layer's, per view
    # per view: its label and the share of its model pixels one photograph alone sees
    # (where no method can follow the view), for the blend's views and the layer's
    seen_b, seen_l = [], []
    prep, amortised = [], []  # view maps' precompute (s) per reported seed; ratios with it
    for seed in seeds:
        s = render("facade", size=size, seed=seed)
        mesh, photos, maps, t_maps = _photos(s)
        t0 = time.process_time()
        layer = fit_reflection_layer(mesh, photos)
        t_layer = time.process_time() - t0
        if seed not in TUNED_SEEDS:
            layer_fit.append(t_layer)
        if seed in REPORTED_SEEDS:
            prep.append(t_maps)
            n_views = sum(1 for k in range(len(s.gt["novel_cameras"]))
                          if s.gt_arrays[f"novel_model_{k}"].sum() >= 100)
        for k, (name, cam) in enumerate(s.gt["novel_cameras"].items()):
            K, R, t = (np.array(cam[x]) for x in ("K", "R", "t"))
            gt, m = s.gt_arrays[f"novel_{k}"], s.gt_arrays[f"novel_model_{k}"]
            if m.sum() < 100:
                continue
            case = _label(seed, name)
            def call(method, K=K, R=R, t=t, mesh=mesh, photos=photos, maps=maps):
                return render_vdtm(mesh, photos, K, R, t, size, method=method, maps=maps)

            layered = render_vdtm(mesh, photos, K, R, t, size, reflection=layer)
            if seed not in REPORTED_SEEDS + TUNED_SEEDS:  # the layer's fresh seeds: its rows only
                p_l = _psnr(layered.image, gt, m)
                p_u, p_n, j = _references(mesh, photos, K, R, t, size, gt, m)
                p_b = _psnr(render_vdtm(mesh, photos, K, R, t, size).image, gt, m)
                rows += [_row(case, "VDTM blend + reflection layer: PSNR dB", p_l,
                              layer_fit_s=t_layer, used=_used(layer)),
                         _row(case, "VDTM blend: PSNR dB", p_b),
                         _row(case, "uniform average: PSNR dB", p_u),
                         _row(case, "nearest photograph: PSNR dB", p_n, photograph=s.image_names[j])]
                layer_u.append(p_l - p_u)
                layer_n.append(p_l - p_n)
                layer_b.append(p_l - p_b)
                seen_l.append((case, layered.info["seen_by_one_fraction"]))
                continue
            (blend, vmap), (tb, tv) = _interleaved([lambda: call("blend"), lambda: call("view-map")])
            p_u, p_n, j = _references(mesh, photos, K, R, t, size, gt, m)
            p_b, p_v = _psnr(blend.image, gt, m), _psnr(vmap.image, gt, m)
            tex_b = blend.info["timings_s"]["texture"]
            tex_v = vmap.info["timings_s"]["texture"]
            p_l = _psnr(layered.image, gt, m)
            rows += [_row(case, "VDTM blend + reflection layer: PSNR dB", p_l,
                          layer_fit_s=t_layer, used=_used(layer)),
                     _row(case, "VDTM blend: PSNR dB", p_b, tb, texture_s=tex_b,
                          holes=blend.info["hole_fraction"]),
                     _row(case, "VDTM view map: PSNR dB", p_v, tv, texture_s=tex_v,
                          speedup=tb / tv, texture_speedup=tex_b / tex_v),
                     _row(case, "uniform average: PSNR dB", p_u),
                     _row(case, "nearest photograph: PSNR dB", p_n, photograph=s.image_names[j])]
            if seed in REPORTED_SEEDS:
                layer_u.append(p_l - p_u)
                layer_n.append(p_l - p_n)
                layer_b.append(p_l - p_b)
                seen_l.append((case, layered.info["seen_by_one_fraction"]))
                seen_b.append((case, blend.info["seen_by_one_fraction"]))
                gains_u.append(p_b - p_u)
                gains_n.append(p_b - p_n)
                vm_diff.append(p_v - p_b)
                speed.append(tex_b / tex_v)
                speed_all.append(tb / tv)
                # the precompute spread over this model's views
                amortised.append(tb / (tv + t_maps / max(n_views, 1)))
    med, worst = float(np.median(gains_u)), float(np.min(gains_u))
    medn, worstn = float(np.median(gains_n)), float(np.min(gains_n))
    medv, worstv = float(np.median(vm_diff)), float(np.max(np.abs(vm_diff)))
    meds, worsts = float(np.median(speed_all)), float(np.min(speed_all))
    n = len(gains_u)

    def worst_at(gains, seen):  # the worst view and its share seen by one photograph
        i = int(np.argmin(gains))
        return (f"; worst view {seen[i][0]}, {100 * seen[i][1]:.0f}% of its model pixels seen by "
                "one photograph only" + (" (there every method gives that photograph's colour)"
                                         if seen[i][1] > 0 else ""))

    checks = [
        Check(f"VDTM blend >= 2 dB above the uniform average of the visible photographs "
              f"(worst of {n} reported views)", worst, 2.0, worst >= 2.0,
              f"median {med:+.2f} dB; no peer (no public VDTM){worst_at(gains_u, seen_b)}"),
        Check(f"VDTM blend >= 2 dB above the nearest photograph's texture (worst of {n} reported "
              "views)", worstn, 2.0, worstn >= 2.0, f"median {medn:+.2f} dB{worst_at(gains_n, seen_b)}"),
        Check(f"view map within 0.5 dB of the blend (worst |PSNR view map - blend| of {n} "
              "reported views)", worstv, 0.5, worstv <= 0.5, f"median {medv:+.2f} dB"),
        Check(f"view map at >= 3x the blend's speed (whole call, worst of {n} reported views; "
              "interleaved, min of 5 calls, CPU time, one thread)", worsts, 3.0, worsts >= 3.0,
              f"median {meds:.2f}x; timed: what a new view costs, render_vdtm(method='blend') "
              "against render_vdtm(method='view-map', maps=...), each with its own z-buffer of "
              "the new view, texturing and hole filling; not timed: the photographs' depth maps "
              "(both) and the view maps' precompute (once per model and photographs: the "
              "planes' visibility in every photograph; median "
              f"{1e3 * float(np.median(prep)):.0f} ms; spread over the {n_views} views of a "
              f"model, ratio median {float(np.median(amortised)):.2f}x, worst "
              f"{float(np.min(amortised)):.2f}x); texturing stage alone median "
              f"{float(np.median(speed)):.2f}x, worst {float(np.min(speed)):.2f}x"),
    ]
    nl = len(layer_u)
    which = (f"reported seeds {', '.join(map(str, REPORTED_SEEDS[:1] if quick else REPORTED_SEEDS))}"
             + ("" if quick else f" and fresh seeds {', '.join(map(str, LAYER_FRESH_SEEDS))}"))
    fit_note = (f"the layer's fit (once per model and photographs, CPU) median "
                f"{float(np.median(layer_fit)):.1f} s")
    checks += [
        Check(f"VDTM blend + reflection layer >= 2 dB above the uniform average (worst of {nl} "
              f"views: {which})", float(np.min(layer_u)), 2.0, float(np.min(layer_u)) >= 2.0,
              f"median {float(np.median(layer_u)):+.2f} dB; against the plain blend median "
              f"{float(np.median(layer_b)):+.2f}, worst {float(np.min(layer_b)):+.2f} dB; {fit_note}"
              f"{worst_at(layer_u, seen_l)}"),
        Check(f"VDTM blend + reflection layer >= 2 dB above the nearest photograph's texture (worst "
              f"of {nl} views: {which})", float(np.min(layer_n)), 2.0, float(np.min(layer_n)) >= 2.0,
              f"median {float(np.median(layer_n)):+.2f} dB; views within: "
              f"{int(np.sum(np.array(layer_n) >= 2.0))} of {nl}{worst_at(layer_n, seen_l)}"),
    ]
    return rows, checks


def _references(mesh, photos, K, R, t, size, gt, m):
    """PSNR of the issue's two references, the uniform average of the
    photographs that see each point and the nearest photograph's texture
    alone, and the nearest photograph's index."""
    from lumigraph.stereo.debevec1996.vdtm import render_vdtm

    uniform = render_vdtm(mesh, photos, K, R, t, size, power=1e-9, neighbours=0)
    C = -R.T @ t
    j = int(np.argmin([np.linalg.norm(p.centre - C) for p in photos]))
    nearest = render_vdtm(mesh, [photos[j]], K, R, t, size)
    return _psnr(uniform.image, gt, m), _psnr(nearest.image, gt, m), j


def _used(layer):
    """The orientations whose layer the held-out test chose, as normals."""
    return [[round(float(x), 3) for x in g.normal] for g in layer.groups if g.used]


def _model_case(seed, size):
    """Model-based stereo on the Lambertian building: with the true model and
    cameras, and with the solved ones (marks with 0.5 px endpoint noise)."""
    from lumigraph.capture.camera import Camera
    from lumigraph.capture.render import render
    from lumigraph.capture.scenes.facade import scene_depth
    from lumigraph.stereo.debevec1996.edges import EdgeMarks
    from lumigraph.stereo.debevec1996.model import BlockModel
    from lumigraph.stereo.debevec1996.model_stereo import model_stereo
    from lumigraph.stereo.debevec1996.raster import model_depth, model_depth_sigma
    from lumigraph.stereo.debevec1996.solve import solve_facade
    from lumigraph.stereo.debevec1996.vdtm import rig_between

    s = render("facade", size=size, seed=seed, lambertian=True, novel=0, edge_noise=0.5)
    model = BlockModel.from_dict(s.files["blocks.json"])
    marks = EdgeMarks.from_dict(s.files["edges.json"], model=model, photographs=list(s.image_names))
    Ks = {p: np.array(c["K"]) for p, c in s.gt["cameras"].items()}
    sol = solve_facade(model, marks, Ks, noise_px=0.5)
    key, off = "photo_03.png", "photo_04.png"
    cam = Camera(Ks[key], [], size)
    out = {}
    true_poses = {p: (np.array(c["R"]), np.array(c["t"])) for p, c in s.gt["cameras"].items()}
    true_mesh = model.with_values({n: v for n, v in s.gt["parameters"].items()
                                   if n in model.parameter_names}).mesh()
    # the solved model lives in the model's own frame (root block centred on the
    # origin, the fixed width's scale): the true cameras see it where they see the truth
    # the solved parameters' covariance (the first columns of the solve's unknowns)
    names = sol.model.parameter_names
    assert tuple(sol.unknowns[:len(names)]) == tuple(names)
    cov = sol.covariance[:len(names), :len(names)]
    for label, poses, mesh in (("true model", true_poses, true_mesh),
                               ("solved model", true_poses, sol.model.mesh()),
                               ("solved model and cameras", sol.poses, sol.model.mesh())):
        (Rk, tk), (Ro, to) = poses[key], poses[off]
        zm = model_depth(mesh, Ks[key], Rk, tk, size)
        rig = rig_between((cam, Rk, tk), (Camera(Ks[off], [], size), Ro, to))
        # the solved model's depth σ (its parameters' covariance) sets the search
        std = None if label == "true model" else model_depth_sigma(
            sol.model, {n: sol.params[n] for n in names}, cov, Ks[key], Rk, tk, size)
        t0 = time.perf_counter()
        res = model_stereo(s.images[3], s.images[4], zm, rig, max_offset=0.5, model_std=std)
        dt = time.perf_counter() - t0
        z = np.where(res.valid, res.depth, np.nan)
        # the truth along the rays of the camera the depth map is in (the solved
        # key camera's are a little off the true one's): the stereo's error, not the pose's
        truth = scene_depth(s.gt["parameters"], Ks[key], Rk, tk, size)
        ok = np.isfinite(z) & np.isfinite(truth)
        bad = float(np.mean(np.abs(z[ok] - truth[ok]) > 0.01 * truth[ok])) if ok.any() else 1.0
        out[label] = (bad, float(ok.mean()), dt)
    return out


def model_stereo_solved(quick: bool):
    """Model-based stereo fed by the solved model against the true model."""
    size = (320, 240) if quick else (640, 480)
    seeds = TUNED_SEEDS + (REPORTED_SEEDS[:1] if quick else REPORTED_SEEDS)
    rows, ratios, chain = [], [], []
    for seed in seeds:
        r = _model_case(seed, size)
        case = _label(seed)
        for label in ("true model", "solved model", "solved model and cameras"):
            bad, frac, dt = r[label]
            rows.append(_row(case, f"model-based stereo, {label}: share off > 1 %", bad, dt,
                             valid_fraction=frac))
        if seed in REPORTED_SEEDS:
            ratios.append(r["solved model"][0] / max(r["true model"][0], 1e-9))
            chain.append(r["solved model and cameras"][0] / max(r["true model"][0], 1e-9))
    med, worst = float(np.median(ratios)), float(np.max(ratios))
    return rows, [Check(f"model-based stereo fed by the solved model (0.5 px marks; the true rig; "
                        f"the search following the model's σ) within 1.2x its error with the true "
                        f"model (worst of {len(ratios)} reported seeds)", worst, 1.2, worst <= 1.2,
                        f"median {med:.2f}x; with the solved cameras too (the whole chain) "
                        f"median {float(np.median(chain)):.2f}x; key photo_03, offset photo_04, "
                        "Lambertian building")]


ROW_PROVIDERS = [vdtm, model_stereo_solved]
