"""``lumigraph bench facade``: Façade's photogrammetric modelling
(``stereo/debevec1996/``) against exact ground truth (issue 17).

Scenes: a family of block models (``house``: the fixture, a two-storey house
with a gable roof and a tower; ``tower``: a tall tower with a spire and a
roofed annex; ``ell``: an L-shaped pair of roofed wings; ``village``: ten
blocks; ``hall``: extrusions, an L-shaped footprint and a gable profile, in
the noise-free row only) seen by eight cameras on an arc (640x480, f = 700 px), their marks
projected exactly by :mod:`lumigraph.capture.scenes.facade_edges` (endpoint
noise added where a row says so). The defaults of the solver and of
automatic marking (robust scale, mis-mark limit, association gates, rounds)
were set while developing on ``house`` with camera seed 1 (TUNED); every
target is reported on the other models and seeds (REPORTED) and the tuning
case's figures are shown beside them, labelled.

No public library does stage 1 (issue 17), so there is no peer row; the
solve time is a library call, single thread (``OPENBLAS_NUM_THREADS=1`` is
the bench's setting), the minimum of three.

Rows and checks:

- noise-free marks: the largest relative parameter and camera-centre error
  and the largest rotation error (rad), from parameters 20 % off and no
  rough poses (vanishing-direction start) — target 1e-6;
- σ = 0.5 px endpoint noise, 50 draws per scene: per parameter, the RMS
  error over the draws divided by the mean reported σ — target [0.67, 1.5];
- 100 random starts per scene (parameters ±25 %, rough rotations 15° off
  about random axes; σ = 0.5 px marks): the fraction that reaches the
  minimum found from the truth (parameters within 1e-6 relative) — ≥ 95 %;
- automatic marking from four hand marks per photograph (two vertical, two
  horizontal, σ = 0.5 px) on painted photographs: the RMS relative parameter
  error over seeds against the fully (σ = 0.5 px) marked solve — ≤ 1.2×
  (its own split: tuned on house s1, tower s3, village s5, and looked at
  tower s8, village s9, village s7, shown as tuning cases; reported on
  house s2, ell s4, tower s6 and tower s12, village s13, house s14, named
  before any run; ``--quick``: tower s3 and s6); the detail also names what
  the full marks of 15 px or more (the detectable ones) leave unconstrained;
- the same on the rendered building (``lumigraph render facade``, Lambertian,
  640x480: bricks, tiles, windows; tuned on seeds 0, 4-19 and 28-59, reported
  on seeds 1-3, 20-27 and 60-69, worst, median and geometric mean; the RMS
  error over four noise draws of the marks per seed; two starts, a check
  each: one factor off (as tuned) and the renderer's own rough
  ``blocks.json``; a run whose marks do not fit the noise restarts from
  its own solve; ``--quick`` seed 1 at 320x240, one draw) —
  ≤ 1.2×: the painted photographs have flat faces, a photograph has
  texture;
- solve time, ``village`` (10 blocks) × 8 photographs × 150 segments each
  (each visible edge marked as several pieces) — ≤ 1 s;
- the real case (``stereo/bench_facade_temple.py``, skipped without the
  shared data): the Middlebury temple from 35 hand marks on 7 photographs,
  the given K fixed: recovered rotations (≤ 2 deg) and centres (≤ 2 % of the
  ring) against the given cameras after a similarity, and what limits them
  (the block model's misfit at the given cameras, the marks' layout).

``ROW_PROVIDERS`` lists the functions that add rows and checks (the VDTM
and model-stereo rows of ``stereo/bench_facade_vdtm.py`` among them): each
is ``provider(quick) -> (rows, checks)``.

The picture (``facade.png``): VDTM per new view, the blend and the blend
with the reflection layer, each over the uniform average and over the
nearest photograph, with the 2 dB target (``_plot``); the other targets are
single figures, in the report's table.
"""

from __future__ import annotations

import math
import time

import numpy as np

from lumigraph.capture.bench import Check, Row, Stage

TUNED = [("house", 1)]
REPORTED = [("house", 2), ("tower", 3), ("ell", 4), ("village", 5)]
# the extrusion kind came after the defaults were set: reported only, in the noise-free row
EXTRUSION_REPORTED = [("hall", 15)]
# automatic marking was reworked on tower s3 and village s5 (flush blocks, a
# hidden annex), so for it they are tuning cases too, and its target is
# reported on camera seeds no one looked at while tuning; tower s8 and
# village s9 were looked at after that (the final trust test came from
# village s9) and are shown as tuning cases, failures included
# round 2 named three more held-out camera seeds here before any run on
# them (tower s12, village s13, house s14); it then diagnosed a regression on
# village s7 (a bounded vote, removed), so village s7 is a tuning case now
AUTO_TUNED = [("house", 1), ("tower", 3), ("village", 5), ("tower", 8), ("village", 9),
              ("village", 7)]
AUTO_REPORTED = [("house", 2), ("ell", 4), ("tower", 6), ("tower", 12), ("village", 13),
                 ("house", 14)]

MODELS = {
    "tower": {"blocks": [
        {"name": "tower", "kind": "box",
         "params": {"width": {"value": 4.0, "fixed": True}, "depth": 4.0, "height": 14.0}},
        {"name": "spire", "kind": "pyramid", "parent": "tower",
         "params": {"width": {"same_as": "tower/width"}, "depth": {"same_as": "tower/depth"},
                    "height": 4.0}},
        {"name": "annex", "kind": "box", "parent": "tower", "on": "base", "x": "offset",
         "y": "front", "params": {"width": 6.0, "depth": 3.0, "height": 4.0, "offset_x": 5.0}},
        {"name": "annex-roof", "kind": "wedge", "parent": "annex",
         "params": {"width": {"same_as": "annex/width"}, "depth": {"same_as": "annex/depth"},
                    "height": 1.5}}]},
    "ell": {"blocks": [
        {"name": "main", "kind": "box",
         "params": {"width": {"value": 12.0, "fixed": True}, "depth": 5.0, "height": 4.0}},
        {"name": "main-roof", "kind": "wedge", "parent": "main",
         "params": {"width": {"same_as": "main/width"}, "depth": {"same_as": "main/depth"},
                    "height": 2.0}},
        {"name": "wing", "kind": "box", "parent": "main", "on": "base", "x": "right", "y": "offset",
         "params": {"width": 5.0, "depth": 8.0, "height": {"same_as": "main/height"},
                    "offset_y": 6.5}},
        {"name": "wing-roof", "kind": "wedge", "parent": "wing",
         "params": {"width": {"same_as": "wing/width"}, "depth": {"same_as": "wing/depth"},
                    "height": 2.5}}]},
    # extrusions (issue 17, temple pass): an L-shaped hall (a footprint with a
    # notch, non-convex), a gable profile extruded along its depth, a box tower
    "hall": {"blocks": [
        {"name": "hall", "kind": "extrusion", "axis": "z",
         "polygon": [["-0.5*width", "-0.5*depth"], ["0.5*width", "-0.5*depth"],
                     ["0.5*width", "wing - 0.5*depth"], [1.0, "wing - 0.5*depth"],
                     [1.0, "0.5*depth"], ["-0.5*width", "0.5*depth"]],
         "params": {"width": {"value": 10.0, "fixed": True}, "depth": 8.0, "wing": 3.0,
                    "height": 5.0}},
        {"name": "roof", "kind": "extrusion", "parent": "hall", "axis": "y", "x": "offset",
         "y": "offset",
         "polygon": [["-0.5*span", 0], ["0.5*span", 0], ["0.5*span", "eave"],
                     [0, "eave + pitch"], ["-0.5*span", "eave"]],
         "params": {"span": 5.0, "depth": 5.0, "eave": 0.8, "pitch": 1.6, "offset_x": -2.0,
                    "offset_y": 1.5}},
        {"name": "tower", "kind": "box", "parent": "hall", "on": "base", "x": "right",
         "y": "front", "params": {"width": 2.0, "depth": {"same_as": "hall/wing"},
                                  "height": 7.0}}]},
    "village": {"blocks": [
        {"name": "house", "kind": "box",
         "params": {"width": {"value": 10.0, "fixed": True}, "depth": 6.0, "height": 6.0}},
        {"name": "roof", "kind": "wedge", "parent": "house",
         "params": {"width": {"same_as": "house/width"}, "depth": {"same_as": "house/depth"},
                    "height": 2.5}},
        {"name": "tower", "kind": "box", "parent": "house", "on": "base", "x": "offset", "y": "front",
         "params": {"width": 3.0, "depth": {"same_as": "tower/width"}, "height": 10.0,
                    "offset_x": 6.5}},
        {"name": "spire", "kind": "pyramid", "parent": "tower",
         "params": {"width": {"same_as": "tower/width"}, "depth": {"same_as": "tower/width"},
                    "height": 3.0}},
        {"name": "annex", "kind": "box", "parent": "house", "on": "base", "x": "offset",
         "y": "back", "params": {"width": 5.0, "depth": 4.0, "height": 3.5, "offset_x": -7.5}},
        {"name": "annex-roof", "kind": "wedge", "parent": "annex",
         "params": {"width": {"same_as": "annex/width"}, "depth": {"same_as": "annex/depth"},
                    "height": 1.5}},
        {"name": "shed", "kind": "box", "parent": "house", "on": "base", "x": "offset",
         "y": "offset", "params": {"width": 3.0, "depth": 3.0, "height": 2.5, "offset_x": -2.0,
                                   "offset_y": 6.0}},
        {"name": "shed-roof", "kind": "pyramid", "parent": "shed",
         "params": {"width": {"same_as": "shed/width"}, "depth": {"same_as": "shed/depth"},
                    "height": 1.2}},
        {"name": "porch", "kind": "box", "parent": "house", "on": "base", "x": "offset",
         "y": "offset", "params": {"width": 2.5, "depth": 1.5, "height": 2.6, "offset_x": -2.0,
                                   "offset_y": -3.75}},
        {"name": "porch-roof", "kind": "wedge", "parent": "porch",
         "params": {"width": {"same_as": "porch/width"}, "depth": {"same_as": "porch/depth"},
                    "height": 0.8}}]},
}


def scene(name: str, seed: int, *, photos: int = 8):
    """(model, cameras) of a scene of the family, cameras drawn with ``seed``."""
    from lumigraph.capture.scenes.facade_edges import ring_cameras
    from lumigraph.stereo.debevec1996.model import BlockModel

    model = BlockModel.from_dict(_HOUSE if name == "house" else MODELS[name], where=name)
    V = model.vertices()
    lo, hi = V.min(0), V.max(0)
    centre = (lo + hi) / 2
    size = float(np.linalg.norm(hi - lo))
    cams = ring_cameras(photos, target=centre, radius=2.2 * size, height=0.3 * size,
                        focal_px=700, image_size=(640, 480), arc_deg=(-160.0, -20.0),
                        rng=np.random.default_rng(seed), jitter=0.05)
    return model, cams


_HOUSE = {"blocks": [  # fixtures/facade/blocks.json (the fixtures are not installed)
    {"name": "house", "kind": "box",
     "params": {"width": {"value": 10.0, "fixed": True}, "depth": 6.0, "height": 6.0}},
    {"name": "roof", "kind": "wedge", "parent": "house", "on": "top",
     "params": {"width": {"same_as": "house/width"}, "depth": {"same_as": "house/depth"},
                "height": 2.5}},
    {"name": "tower", "kind": "box", "parent": "house", "on": "base", "x": "offset", "y": "front",
     "params": {"width": 3.0, "depth": {"same_as": "tower/width"}, "height": 9.0,
                "offset_x": 6.5}},
    {"name": "spire", "kind": "pyramid", "parent": "tower", "on": "top",
     "params": {"width": {"same_as": "tower/width"}, "depth": {"same_as": "tower/width"},
                "height": 2.0}}]}


def _marks(model, cams, *, noise=0.0, rng=None):
    from lumigraph.capture.scenes.facade_edges import project_edges
    from lumigraph.stereo.debevec1996.edges import EdgeMarks

    raw = project_edges(model, cams, noise_px=noise, rng=rng)
    return raw, EdgeMarks.from_dict({"photographs": raw}, model=model, photographs=list(cams))


def _K(cams):
    return {p: c["K"] for p, c in cams.items()}


def _rot_err(A, B) -> float:
    """The angle (rad) of ``Aᵀ B`` (from its rotation vector: arccos of the
    trace loses half the digits near zero)."""
    from scipy.spatial.transform import Rotation

    return float(Rotation.from_matrix(A.T @ B).magnitude())


def _label(name, seed, tuned=TUNED):
    return f"{name} s{seed} ({'tuned' if (name, seed) in tuned else 'reported'})"


def _row(case, method, value, err, t=math.nan, **extra):
    return Row("facade", case, method, None, "", value, t, (t,) if not math.isnan(t) else (), err,
               "ok", extra)


# ------------------------------------------------------------------ protocols
def noise_free(quick: bool):
    from lumigraph.stereo.debevec1996.solve import solve_facade

    rows, worst = [], []
    for name, seed in TUNED + REPORTED + EXTRUSION_REPORTED:
        model, cams = scene(name, seed)
        _, marks = _marks(model, cams)
        start = model.with_values(model.values[~model.fixed] * 1.2)
        sol = solve_facade(start, marks, _K(cams))
        tv = model.named_values()
        pe = max(abs(sol.params[n] - v) / abs(v) for n, v in tv.items())
        size = float(np.ptp(np.array([-c["R"].T @ c["t"] for c in cams.values()]), axis=0).max())
        ce = max(float(np.linalg.norm(sol.centres[p] + c["R"].T @ c["t"])) / size
                 for p, c in cams.items())
        re = max(_rot_err(sol.poses[p][0], c["R"]) for p, c in cams.items())
        rows.append(_row(_label(name, seed), "solve, exact marks", None, max(pe, ce, re),
                         param_rel=pe, centre_rel=ce, rotation_rad=re))
        if (name, seed) not in TUNED:
            worst.append((pe, ce, re))
    w = np.max(worst, axis=0)
    checks = [Check("noise-free marks: parameters and camera centres to 1e-6 relative, rotations "
                    "to 1e-6 rad (reported scenes, worst)", float(w.max()), 1e-6, bool(w.max() <= 1e-6),
                    f"parameters {w[0]:.1e}, centres {w[1]:.1e} (of the camera spread), "
                    f"rotations {w[2]:.1e} rad; start 20 % off, no rough poses")]
    return rows, checks


def noise_calibration(quick: bool):
    from lumigraph.stereo.debevec1996.solve import solve_facade

    draws = 10 if quick else 50
    rows, ratios, worst_name = [], [], None
    for name, seed in (TUNED + REPORTED)[: 2 if quick else None]:
        model, cams = scene(name, seed)
        tv = model.named_values()
        names = model.parameter_names
        E, S = [], []
        for d in range(draws):
            rng = np.random.default_rng(1000 * seed + d)
            _, marks = _marks(model, cams, noise=0.5, rng=rng)
            sol = solve_facade(model, marks, _K(cams), noise_px=0.5)
            E.append([sol.params[n] - tv[n] for n in names])
            S.append([sol.std[n] for n in names])
        r = np.sqrt(np.mean(np.square(E), 0)) / np.mean(S, 0)
        rows.append(_row(_label(name, seed), "σ calibration, 0.5 px", None, float(np.max(np.abs(
            np.log(r)))), ratio_min=float(r.min()), ratio_max=float(r.max()),
            ratios={n: float(v) for n, v in zip(names, r, strict=True)}))
        if (name, seed) not in TUNED:
            ratios += list(r)
            if r.min() == min(ratios) or r.max() == max(ratios):
                worst_name = name
    lo, hi = float(min(ratios)), float(max(ratios))
    ok = 0.67 <= lo and hi <= 1.5
    return rows, [Check(f"σ = 0.5 px, {draws} draws: RMS error of each parameter within "
                        "[0.67, 1.5]x the reported σ (reported scenes)", hi if hi > 1.5 else lo,
                        1.5 if hi > 1.5 else 0.67, ok,
                        f"ratios {lo:.2f}..{hi:.2f} over {len(ratios)} parameters; median "
                        f"{np.median(ratios):.2f}; widest on {worst_name}")]


def _perturbed_rotation(R, rng, max_deg):
    from scipy.spatial.transform import Rotation

    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return Rotation.from_rotvec(axis * np.radians(max_deg)).as_matrix() @ R


def random_starts(quick: bool):
    from lumigraph.capture.errors import EstimationError
    from lumigraph.stereo.debevec1996.solve import solve_facade

    starts = 10 if quick else 100
    rows, fr = [], []
    for name, seed in (TUNED + REPORTED)[: 2 if quick else None]:
        model, cams = scene(name, seed)
        _, marks = _marks(model, cams, noise=0.5, rng=np.random.default_rng(seed))
        ref = solve_facade(model, marks, _K(cams), noise_px=0.5,
                           rough_rotations={p: c["R"] for p, c in cams.items()})
        rng = np.random.default_rng(77 + seed)
        hit = 0
        for _ in range(starts):
            f = rng.uniform(0.75, 1.25, int((~model.fixed).sum()))
            start = model.with_values(model.values[~model.fixed] * f)
            rough = {p: _perturbed_rotation(c["R"], rng, 15.0) for p, c in cams.items()}
            try:
                s = solve_facade(start, marks, _K(cams), noise_px=0.5, rough_rotations=rough)
            except EstimationError:
                continue
            if all(abs(s.params[n] - v) <= 1e-6 * abs(v) for n, v in ref.params.items()):
                hit += 1
        rows.append(_row(_label(name, seed), "random starts (±25 %, 15°)", None, 1 - hit / starts,
                         converged=hit, starts=starts))
        if (name, seed) not in TUNED:
            fr.append(hit / starts)
    worst = float(min(fr))
    return rows, [Check(f"from the linear initialisation, {starts} random starts (parameters "
                        "±25 %, rotations 15°) reach the minimum (reported scenes, worst)",
                        worst, 0.95, worst >= 0.95,
                        f"per scene {', '.join(f'{v:.0%}' for v in fr)}")]


def four_hand_marks(model, marks):
    """Two vertical and two horizontal edges of ``marks``, the longest, as a
    user picks them (the hand marks automatic marking starts from; the view's
    tests use the same pick)."""
    from lumigraph.stereo.debevec1996.solve import _known_axis

    ax = _known_axis(model, [m["edge"] for m in marks])
    L = [np.hypot(m["segment"][2] - m["segment"][0], m["segment"][3] - m["segment"][1])
         for m in marks]
    order = list(np.argsort(L)[::-1])
    out = [i for i in order if ax[i] == 2][:2]
    for a in (0, 1):
        pick = [i for i in order if ax[i] == a][:2]
        if len(pick) == 2:
            return [marks[i] for i in out + pick]
    return [marks[i] for i in order[:4]]


def automatic_marking(quick: bool):
    from lumigraph.capture.scenes.facade_edges import paint_facade
    from lumigraph.stereo.debevec1996.automark import automark
    from lumigraph.stereo.debevec1996.edges import EdgeMarks
    from lumigraph.stereo.debevec1996.solve import solve_facade

    seeds = 2 if quick else 4
    rows, ratios, held_by, tuned, blinds = [], [], {}, [], []
    # quick: one tuning and one reported case, flush blocks both
    cases = [("tower", 3), ("tower", 6)] if quick else AUTO_TUNED + AUTO_REPORTED
    for name, seed in cases:
        model, cams = scene(name, seed)
        tv = model.named_values()
        free = list(model.parameter_names)
        ea, ef, props, held, blind = [], [], [], set(), set()
        # the tuning cases are shown for reference: two noise seeds suffice
        n_seeds = min(seeds, 2) if (name, seed) in AUTO_TUNED else seeds
        for k in range(n_seeds):
            rng = np.random.default_rng(500 + 10 * seed + k)
            raw, full = _marks(model, cams, noise=0.5, rng=rng)
            hand = EdgeMarks.from_dict({"photographs": {p: four_hand_marks(model, v)
                                                        for p, v in raw.items()}},
                                       model=model, photographs=list(cams))
            images = {p: paint_facade(model, c, rng=rng) for p, c in cams.items()}
            start = model.with_values(model.values[~model.fixed] * rng.uniform(0.9, 1.1))
            sf = solve_facade(start, full, _K(cams), noise_px=0.5)
            # like with like: the full marks automatic marking could detect at
            # all (at least its 15 px minimum length); what they leave
            # unconstrained (held, or fitted 100 % off) is information the
            # photographs' detectable lines do not hold, counted, not excused
            seen = {p: [m for m in v if math.hypot(m["segment"][2] - m["segment"][0],
                                                   m["segment"][3] - m["segment"][1]) >= 15.0]
                    for p, v in raw.items()}
            sv = solve_facade(start, EdgeMarks.from_dict({"photographs": seen}, model=model,
                                                         photographs=list(cams)),
                              _K(cams), noise_px=0.5, hold_unconstrained=True)
            blind |= set(sv.held) | {n for n in free if abs(sv.params[n] - tv[n]) > abs(tv[n])}
            res = automark(start, hand, images, _K(cams), noise_px=0.5)
            # what the proposals leave unconstrained keeps its rough value and
            # counts with that error (a user would have to mark it)
            sa = solve_facade(start, res.marks, _K(cams), noise_px=0.5, hold_unconstrained=True)
            held |= set(sa.held)
            props.append(res.proposed)
            ea.append([(sa.params[n] - tv[n]) / tv[n] for n in free])
            ef.append([(sf.params[n] - tv[n]) / tv[n] for n in free])
        ra = float(np.sqrt(np.mean(np.square(ea))))
        rf = float(np.sqrt(np.mean(np.square(ef))))
        rows.append(_row(_label(name, seed, AUTO_TUNED), "automatic marking (4 hand marks)", None,
                         ra / rf, auto_rms_rel=ra, full_rms_rel=rf,
                         proposed_mean=float(np.mean(props)), seeds=n_seeds, held=sorted(held),
                         unconstrained_by_detectable_full_marks=sorted(blind)))
        if blind:
            blinds.append(f"{name} s{seed}: {', '.join(sorted(blind))}")
        if (name, seed) in AUTO_TUNED:
            tuned.append(f"{name} s{seed} {ra / rf:.2f}")
        else:
            ratios.append(ra / rf)
            if held:
                held_by[name] = sorted(held)
    worst = float(max(ratios))
    why = "; ".join(f"{n}: never proposed, so held at the rough value: {', '.join(h)}"
                    for n, h in held_by.items())
    return rows, [Check("automatic marking from 4 hand marks per photograph: RMS parameter error "
                        "within 1.2x the fully marked solve (reported scenes, worst)", worst, 1.2,
                        worst <= 1.2, "per reported scene " + ", ".join(
                            f"{n} s{sd} {v:.2f}" for (n, sd), v in zip(
                                [c for c in cases if c not in AUTO_TUNED], ratios, strict=True))
                        + f"; tuning cases (outside the target) {', '.join(tuned)}"
                        + f"; {seeds} noise seeds per reported scene (2 per tuning one), "
                          "σ = 0.5 px hand and full marks" + (f"; {why}" if why else "")
                        + ("; the full marks of 15 px or more (what the detector can see) leave "
                           "unconstrained " + "; ".join(blinds) if blinds else ""))]


def rendered_case(seed: int, size=(640, 480)) -> dict:
    """Automatic marking's case on the rendered building (``lumigraph render
    facade``, Lambertian: brick walls, tiled roofs, windows, a tower built
    against the house's end wall): the true model, the scene's marks with
    σ = 0.5 px (``edge_noise``) as the full marks and four of them per
    photograph as the hand marks, the start 10 % off the truth (one factor,
    as the painted scenes'), the rough rotations (the true ones), the
    photographs and the intrinsics."""
    from lumigraph.capture.render import render
    from lumigraph.stereo.debevec1996.edges import EdgeMarks
    from lumigraph.stereo.debevec1996.model import BlockModel

    s = render("facade", size=size, seed=seed, lambertian=True, novel=0, edge_noise=0.5)
    rough = BlockModel.from_dict(s.files["blocks.json"])
    tv = {n: s.gt["parameters"][n] for n in rough.parameter_names}
    model = rough.with_values(tv)
    photos = list(s.image_names)
    full = EdgeMarks.from_dict(s.files["edges.json"], model=model, photographs=photos)
    hand = EdgeMarks.from_dict({"photographs": {
        p: four_hand_marks(model, v) for p, v in s.files["edges.json"]["photographs"].items()}},
        model=model, photographs=photos)
    rng = np.random.default_rng(700 + seed)
    start = model.with_values(model.values[~model.fixed] * rng.uniform(0.9, 1.1))
    return dict(model=model, truth=tv, full=full, hand=hand, start=start,
                K={p: np.array(c["K"]) for p, c in s.gt["cameras"].items()},
                rotations={p: np.array(c["R"]) for p, c in s.gt["cameras"].items()},
                cameras=s.gt["cameras"], images=dict(zip(photos, s.images, strict=True)))


class _Draws(list):
    """:func:`rendered_draws`' list, with ``rough``: the render's own rough
    model (its ``blocks.json`` depends on the renderer's draws, so it is
    this exact-mark render's, not :func:`rendered_case`'s)."""

    rough = None


def rendered_draws(seed: int, size=(640, 480), *, draws: int = 4) -> list:
    """``draws`` noise draws of :func:`rendered_case`'s marks: ``[(full,
    hand), …]``, σ = 0.5 px on every endpoint coordinate of the scene's exact
    marks (``edge_noise`` 0; the photographs are the same: the renderer draws
    the image noise first), the hand marks the same four picks of each
    draw's full marks. One draw's error is a noisy figure (on seed 7 the
    fully marked solve's RMS error ranged 0.21-0.30 % over four draws and
    the ratio 0.63-3.12), so the row compares RMS errors over draws, as the
    painted row does."""
    from lumigraph.capture.render import render
    from lumigraph.stereo.debevec1996.edges import EdgeMarks
    from lumigraph.stereo.debevec1996.model import BlockModel

    s = render("facade", size=size, seed=seed, lambertian=True, novel=0, edge_noise=0.0)
    rough = BlockModel.from_dict(s.files["blocks.json"])
    model = rough.with_values({n: s.gt["parameters"][n] for n in rough.parameter_names})
    photos = list(s.image_names)
    exact = s.files["edges.json"]["photographs"]
    out = _Draws()
    out.rough = rough       # this render's rough blocks.json (the row's second start)
    for k in range(draws):
        rng = np.random.default_rng(9000 + 100 * seed + k)
        noisy = {p: [{"edge": m["edge"], "segment": list(np.asarray(m["segment"], float)
                                                         + rng.normal(0.0, 0.5, 4))}
                     for m in v] for p, v in exact.items()}
        full = EdgeMarks.from_dict({"photographs": noisy}, model=model, photographs=photos)
        hand = EdgeMarks.from_dict({"photographs": {p: four_hand_marks(model, v)
                                                    for p, v in noisy.items()}},
                                   model=model, photographs=photos)
        out.append((full, hand))
    return out


# the rendered building's layouts automatic marking was tuned on (and its
# tests use); the bench reports the others
RENDERED_TUNED = (0, *range(4, 20), *range(28, 60))     # the row's text names them
# 1-3 and 20-27 named in session 28, 60-69 in session 30, each before its first run
RENDERED_REPORTED = (1, 2, 3, *range(20, 28), *range(60, 70))
RENDERED_DRAWS = 4      # noise draws of the marks per seed (:func:`rendered_draws`)


# automatic marking's warnings that say its result may be wrong (not the
# informational ones): the rendered row counts the failing draws they cover
DOUBTS = ("proposals on edges the solved model hides", "no hand mark or proposal constrains",
          "the solve with the proposals leaves out", "the proposals took",
          "the image lines of the edges that", "proposals that alone place what they move",
          "the image lines past the corners that")


def automatic_marking_rendered(quick: bool):
    """Automatic marking on the rendered building (:func:`rendered_case`),
    the scene the VDTM and model-stereo rows use; the painted scenes above
    have flat faces. Tuned on the seeds of ``RENDERED_TUNED``, reported on
    ``RENDERED_REPORTED``'s. Two starts, a check each: every parameter off
    the truth by one factor (10 % at most, as the painted scenes'; what
    automatic marking was tuned with), and the rough model the renderer
    writes (``blocks.json``: each parameter off by its own amount, up to
    15 %; what ``lumigraph render facade`` gives a user; tuned on, on the
    same tuning seeds, since session 33)."""
    from lumigraph.stereo.debevec1996.automark import automark
    from lumigraph.stereo.debevec1996.solve import solve_facade

    size = (320, 240) if quick else (640, 480)
    rows, checks = [], []
    seeds = (1,) if quick else RENDERED_REPORTED
    draws = 1 if quick else RENDERED_DRAWS
    cases = {seed: rendered_case(seed, size) for seed in seeds}
    marks = {seed: rendered_draws(seed, size, draws=draws) for seed in seeds}
    for kind in ("one factor", "blocks.json"):
        ratios, flagged = [], []
        for seed in seeds:
            c = cases[seed]
            tv, free = c["truth"], list(c["truth"])
            start = c["start"] if kind == "one factor" else marks[seed].rough
            ea, ef, props, held, each, doubt, took = [], [], [], set(), [], [], []
            for full, hand in marks[seed]:
                sf = solve_facade(start, full, c["K"], noise_px=0.5)
                t0 = time.perf_counter()
                res = automark(start, hand, c["images"], c["K"], noise_px=0.5,
                               rough_rotations=c["rotations"])
                took.append(time.perf_counter() - t0)
                sa = solve_facade(start, res.marks, c["K"], noise_px=0.5,
                                  hold_unconstrained=True)
                ea.append([(sa.params[n] - tv[n]) / tv[n] for n in free])
                ef.append([(sf.params[n] - tv[n]) / tv[n] for n in free])
                each.append(float(np.sqrt(np.mean(np.square(ea[-1]))
                                          / np.mean(np.square(ef[-1])))))
                props.append(res.proposed)
                held |= set(sa.held)
                doubt.append(any(w.startswith(DOUBTS) for w in res.warnings))
            ra = float(np.sqrt(np.mean(np.square(ea))))
            rf = float(np.sqrt(np.mean(np.square(ef))))
            ratios.append(ra / rf)
            rows.append(_row(f"rendered facade s{seed} (reported), start {kind}",
                             "automatic marking (4 hand marks)", None, ra / rf,
                             float(np.median(took)), auto_rms_rel=ra, full_rms_rel=rf,
                             proposed_mean=float(np.mean(props)), draws=draws,
                             ratio_per_draw=each, warned_per_draw=doubt, held=sorted(held),
                             seconds_per_draw=took))
            flagged += list(zip(each, doubt, strict=True))
        worst = float(max(ratios))
        start_said = ("the start every parameter off by one factor (≤ 10 %)" if kind == "one factor"
                      else "the start the renderer's rough blocks.json (each parameter off by "
                           "its own amount, ≤ 15 %; tuned on the same seeds since 2026-12-05)")
        checks.append(Check(
            f"automatic marking on the rendered building (bricks, windows), start {kind}: RMS "
            "parameter error within 1.2x the fully marked solve (reported seeds, worst)",
            worst, 1.2, worst <= 1.2,
            f"median {float(np.median(ratios)):.2f}, geometric mean "
            f"{float(np.exp(np.mean(np.log(ratios)))):.2f}, "
            f"{sum(r <= 1.2 for r in ratios)} of {len(ratios)} within 1.2x, over seeds "
            + ", ".join(f"s{sd} {r:.2f}" for sd, r in zip(seeds, ratios, strict=True))
            + f"; RMS over {draws} noise draws of the marks per seed (σ = 0.5 px); {start_said}"
            + f"; draws beyond 3x: {sum(r > 3 for r, _ in flagged)}, of them warned "
              f"{sum(r > 3 and w for r, w in flagged)}; draws within 1.2x warned "
              f"{sum(r <= 1.2 and w for r, w in flagged)} of {sum(r <= 1.2 for r, _ in flagged)} "
              "(the warning on proposals the solved model hides was designed on seeds 21, 23, "
              "26, 65, 66, and replacing them by a crease on those and 70-81: s21 is not "
              "held out; judged on 82-87, docs/decisions/facade.md, session 37; a seam's "
              "step held to 80 % of its stretch: designed on s82, where it fixes one draw and "
              "breaks another, so s82 is not held out; judged on 90-98, session 38; a texture's "
              "lines refused (a parallel step of the line's sign two thirds as strong within "
              "twice the gate on each side): designed on seeds 0, 4-11 and the failures of 82, "
              "90, 95, 96, 98; judged on 99-109, session 39; a line the crease scan moves "
              "under 5 px left out of it: designed on s118 and s99; it changed no other "
              "crease search on 0, 4-11 or 114-127, session 40; a run whose marks do not "
              "fit the noise restarted from its own solve, the ends then ranked with the fit to "
              "the noise before the proposals: designed on s124, judged on 128-139 (session 41); "
              "redesigned on 140-151, judged on 152-163, session 42; a loosely fixed block's "
              "crease accepted at half a held block's summed |z|: designed on s148 and s141, "
              "judged on 164-175, session 42)"
            + "; tuned on seeds 0, 4-19, 28-59; the causes followed so far: window "
              "columns and brick courses beside a block's edge taken for it, the "
              "rough model's occlusions (docs/decisions/facade.md, 2026-12-05)"))
    return rows, checks


def solve_time(quick: bool):
    from lumigraph.stereo.debevec1996.edges import EdgeMarks
    from lumigraph.stereo.debevec1996.solve import solve_facade

    model, cams = scene("village", 5)
    raw, _ = _marks(model, cams, noise=0.5, rng=np.random.default_rng(3))
    per = {}
    rng = np.random.default_rng(4)
    for p, v in raw.items():
        pieces = []
        k = int(math.ceil(150 / max(len(v), 1)))
        for m in v:
            a, b = np.array(m["segment"][:2]), np.array(m["segment"][2:])
            cuts = np.linspace(0, 1, k + 1)
            for i in range(k):
                s0 = a + (b - a) * cuts[i]
                s1 = a + (b - a) * cuts[i + 1]
                if np.hypot(*(s1 - s0)) >= 2:
                    pieces.append({"edge": m["edge"], "segment": [*(s0 + rng.normal(0, 0.1, 2)),
                                                                  *(s1 + rng.normal(0, 0.1, 2))]})
        per[p] = pieces[:150]
    marks = EdgeMarks.from_dict({"photographs": per}, model=model, photographs=list(cams))
    nseg = len(marks.marks)
    start = model.with_values(model.values[~model.fixed] * 1.1)
    times = []
    for _ in range(2 if quick else 5):
        t0 = time.perf_counter()
        solve_facade(start, marks, _K(cams), noise_px=0.5)
        times.append(time.perf_counter() - t0)
    t = min(times)
    row = _row("village s5 (reported)", "solve time", None, t, t, segments=nseg,
               blocks=len(model.blocks), photographs=len(cams))
    return [row], [Check(f"solve time, {len(model.blocks)} blocks x {len(cams)} photographs x "
                         f"{nseg // len(cams)} segments (min of {len(times)}, one thread)", t, 1.0,
                         t <= 1.0, "no public library does this (no peer); start 10 % off, no "
                                   "rough poses")]


def _stages_2_3():
    # VDTM and model-based stereo fed by the solved model (stereo/bench_facade_vdtm.py)
    from lumigraph.stereo.bench_facade_vdtm import ROW_PROVIDERS as more

    return more


def _temple():
    # the real case: the Middlebury temple, hand marks (stereo/bench_facade_temple.py)
    from lumigraph.stereo.bench_facade_temple import temple_rows

    return [temple_rows]


ROW_PROVIDERS = [noise_free, noise_calibration, random_starts, automatic_marking,
                 automatic_marking_rendered, solve_time,
                 *_stages_2_3(), *_temple()]


def _extra(quick):
    def run():
        rows, checks = [], []
        for provider in ROW_PROVIDERS:
            r, c = provider(quick)
            rows += r
            checks += c
        return rows, checks
    return run


VDTM_TARGET_DB = 2.0


def _plot(path, stage, rows) -> None:
    """The stage's picture: VDTM per new view, the blend and the blend with
    the reflection layer over the issue's two references (the uniform
    average, the nearest photograph's texture), the 2 dB target drawn; the
    tuning seed's views hollow. The other rows are single figures, in the
    report's table."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lumigraph.capture.artifact import atomic_path

    psnr = {}
    for r in rows:
        if r.status == "ok" and r.method.endswith(": PSNR dB"):
            psnr.setdefault(r.case, {})[r.method[: -len(": PSNR dB")]] = r.error
    refs = ("uniform average", "nearest photograph")
    ours = (("VDTM blend", "#999999", "s"), ("VDTM blend + reflection layer", "#1f77b4", "o"))
    cases = [c for c in psnr if all(k in psnr[c] for k in refs)]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, ref in zip(axes, refs, strict=True):
        for name, colour, marker in ours:
            at = [i for i, c in enumerate(cases) if name in psnr[c]]
            d = [psnr[cases[i]][name] - psnr[cases[i]][ref] for i in at]
            tuned = ["tuned" in cases[i] for i in at]
            ax.scatter([at[j] for j in range(len(at)) if not tuned[j]],
                       [d[j] for j in range(len(at)) if not tuned[j]], c=colour, marker=marker,
                       s=22, label=name)
            if any(tuned):
                ax.scatter([at[j] for j in range(len(at)) if tuned[j]],
                           [d[j] for j in range(len(at)) if tuned[j]], facecolors="none",
                           edgecolors=colour, marker=marker, s=22, label=f"{name} (tuning seed)")
        ax.axhline(VDTM_TARGET_DB, color="#d62728", ls="--", lw=1, label="target +2 dB")
        ax.axhline(0, color="black", lw=0.5)
        ax.set_xticks(range(len(cases)), [c.split(" (")[0].replace("facade ", "") for c in cases],
                      rotation=90, fontsize=6)
        ax.set_title(f"PSNR over the {ref} (dB), per new view", fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="best", framealpha=0.8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def stage(*, quick: bool = False) -> Stage:
    return Stage("facade", (), (), error=lambda data, out: math.nan,
                 error_name="per row: see the method (relative error, ratio, fraction or s)",
                 description=__doc__.split("\n\n")[0], extra=_extra(quick), plot=_plot)
