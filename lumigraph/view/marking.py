"""The marking session of ``lumigraph view --facade``: Façade's interactive
loop (Debevec, Taylor & Malik 1996, doi:10.1145/237170.237191; reference
ch. 5, §5.3.2: the user marks edges, solves, looks at the reprojected model,
corrects, solves again), held in memory for the web page.

A :class:`FacadeSession` holds the block model (``blocks.json``), the
photographs, their shared intrinsics (``camera.json``) and the marks being
edited. Every change is written at once to ``edges.json`` (the layout of
:mod:`lumigraph.stereo.debevec1996.edges`) through the project's atomic
writer (:func:`lumigraph.capture.artifact.write_artifact`: a temporary file
renamed over the old one), so the file on disk is always a complete, valid
``edges.json``, whether the browser or the server dies mid-edit. A segment
drawn but not yet tied to a model edge is kept under the file's extra key
``"unassigned"`` (``{photo: [[x0, y0, x1, y1], ...]}``), which the solver's
reader ignores.

Segments are pixels, OpenCV convention (``(0, 0)`` the centre of the
top-left pixel). A dragged segment is *snapped* to the nearest line segment
detected in the photograph (OpenCV contrib's fast line detector, the one
automatic marking uses, cached per photograph) when one lies within
:data:`SNAP_ANGLE_DEG` and :data:`SNAP_DISTANCE_PX`: the detection is refined
to sub-pixel precision and the dragged ends are moved onto its line (the edge
objective of eq. 5.3 measures the distance to the projected model line, so
the stretch a mark covers along the line matters little; its line matters).

``add`` answers how far the snap moved the drag (``jump_px``) and the drag
as drawn (``dragged``), so the page can show a snap that left the traced line
and undo it. ``solve`` runs
:func:`~lumigraph.stereo.debevec1996.solve.solve_facade` on the assigned
marks and returns, per photograph, every model edge reprojected, each mark's
RMS distance to its edge (px), and the weakly constrained parameters with
the unmarked edges that would hold each best (:func:`weak_spots`: the
user is told where the model is weak and what to mark there); when the
solver refuses because the marks do not constrain some unknowns, the refusal
carries, per unknown, the unmarked edges that would constrain it
(:func:`unconstrained_spots`), so the user is told what to mark, not only
what is free. ``propose`` runs
:func:`~lumigraph.stereo.debevec1996.automark.automark` from the marks so far
moves each proposal onto the intensity step it lies on (:func:`refine_on_edge`;
dropped when it lies on none: a texture line), and keeps the proposals
pending until each is accepted (then it is a mark,
``"proposed": true`` in the file) or rejected. ``resnap``, after a solve,
moves each mark onto the image step within its reprojected edge's
uncertainty band (the solve's covariance and residual scale), deleting the
solve's outliers: the user's "look, correct, solve again".

Examples
--------
>>> import numpy as np
>>> from lumigraph.view.marking import snap_segment
>>> det = np.array([[10.0, 20.0, 90.0, 20.0]])               # one detected horizontal line
>>> snap_segment(np.array([15.0, 23.0, 80.0, 22.0]), det, grey=None).tolist()
[15.0, 20.0, 80.0, 20.0]
>>> snap_segment(np.array([15.0, 60.0, 80.0, 60.0]), det, grey=None) is None   # too far
True
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np

from lumigraph.capture.errors import EstimationError, InputError
from lumigraph.stereo.debevec1996.automark import SUGGESTIONS, unconstrained_spots

SNAP_ANGLE_DEG = 5.0     # a drag by hand is rarely further off an edge's direction
SNAP_DISTANCE_PX = 3.0   # ... or further from its line; beyond, a parallel line (a window frame) is as likely
UNASSIGNED_KEY = "unassigned"
# snapping refines onto the intensity step (refine_on_edge) when True; False,
# the default: onto the strongest gradient, as automatic marking does -- the
# tuned seed's choice (docs/decisions/view-marking.md, "Onto the step")
SNAP_ON_STEP = False


# True: snapping refines the detected line over the stretch the user dragged
# and keeps the drag as drawn when the image does not show the line there;
# False, the default: refined over the detection's own extent and carried out
# to the dragged ends, as before. Tried in the fifth pass on the tuned seeds,
# not adopted (docs/decisions/view-marking.md, "Fresh seeds")
SNAP_OVER_DRAG = False
# True: refine_on_edge weights each profile's peak by its contrast squared
# (the inverse variance of a step's position) in its line fit; False, the
# default: equal weights. Tried in the fifth pass, not adopted (same section)
WEIGHTED_STEPS = False
# True: refine_on_edge fits its line to the steps most profiles agree on
# (:func:`_consensus`, within STEP_CONSENSUS_PX) and refuses the segment when
# those are fewer than EDGE_SUPPORT of its profiles; False, the default: a
# least-squares line through every profile's step (one 3-sigma trim). Tried
# in the ninth pass: fewer marks off their edge on the tuned seeds, no gain on
# fresh ones; not adopted (docs/decisions/view-marking.md, ninth pass)
STEP_CONSENSUS = False
STEP_CONSENSUS_PX = 0.5   # a step's position from a parabola on 1/4 px samples: ~0.2 px; 2-3 of that
EDGE_SUPPORT = 0.5       # a segment whose profiles mostly show no step there lies on texture, not on an edge
EDGE_HALF_WIDTH_PX = 2.5  # searched either side of the segment; less than the snap radius, more than a drag's error
# True: a mark the page put onto the image (a snapped drag, a re-snapped mark, a
# refined proposal) carries the scatter of the image's steps about it
# (:func:`step_spread`, ``spread_px`` in edges.json), and the solve counts its
# ends as noisy by the larger of that and its noise_px; a mark drawn with
# snapping off is the user's own and carries none
WEIGH_BY_SPREAD = True

# The endpoint noise a Solve from the page assumes, px (the page's "mark noise"
# field; the CLI's --noise-px default, 1.0, is for hand-typed files). The
# page's marks are snapped drags and proposals refined onto the image step
# (0.28-0.34 px RMS off their edge at the ends on the rendered scenes, off thin
# strips; docs/decisions/view-marking.md, fifteenth pass), and every choice of the
# marking flow was made with its Solves at 0.5 (docs/decisions/view-marking.md).
# It sets the mis-mark test's radius (5x), which marks count as weighed by
# their scatter, and the weak and check lists' scale.
SOLVE_NOISE_PX = 0.5


def _step_points(grey, seg, half_width, samples):
    """The profiles' steps of :func:`refine_on_edge` along ``seg`` ``(4,)``:
    ``(points (K, 2) px, their weights (K,))``, or None for a segment
    shorter than 4 px."""
    from lumigraph.stereo.debevec1996.automark import profiles_across

    reach = half_width + 2.5                            # the step test looks 2 px beyond a peak
    offs = np.arange(-reach, reach + 1e-9, 0.25)
    ts = np.linspace(0.06, 0.94, samples)
    across = profiles_across(grey, seg, ts, offs, min_length=4)
    if across is None:
        return None
    a, _, d, n, prof = across
    g = (prof[:, 4:] - prof[:, :-4])                    # 1 px central difference at offs[2:-2]
    go = offs[2:-2]
    inside = np.abs(go) <= half_width
    sign = 1.0 if np.sum(np.max(np.where(inside, g, 0), 1)) >= \
        np.sum(np.max(np.where(inside, -g, 0), 1)) else -1.0
    sg = np.where(inside, sign * g, -np.inf)
    pts, wts = [], []
    for k in range(len(ts)):
        i = int(np.argmax(sg[k]))
        peak = sg[k, i]
        if not (peak > 4.0 and 0 < i < len(go) - 1):
            continue
        y0, y1, y2 = sg[k, i - 1], sg[k, i], sg[k, i + 1]
        den = y0 - 2 * y1 + y2
        off = go[i] + (0.5 * 0.25 * (y0 - y2) / den if den < 0 and np.isfinite(den) else 0.0)
        j = i + 2                                       # go[i] is offs[i + 2]
        step = sign * (prof[k, min(j + 8, len(offs) - 1)] - prof[k, max(j - 8, 0)])
        if step < 0.5 * peak:
            continue
        pts.append(a + ts[k] * d + off * n)
        wts.append(peak ** 2)
    return np.array(pts).reshape(-1, 2), np.array(wts)


def refine_on_edge(grey: np.ndarray, seg: np.ndarray, *,
                   half_width: float = EDGE_HALF_WIDTH_PX, samples: int = 32,
                   min_support: float = EDGE_SUPPORT) -> np.ndarray | None:
    """``seg`` ``(4,)`` (px) moved onto the intensity *step* it lies on, or
    None when fewer than ``min_support`` of its profiles show one.

    Façade's edge term (Debevec, Taylor & Malik 1996, eq. 5.3 of the
    reference) measures a mark against the projected model edge, and a model
    edge is seen as a step between two faces (or a face and the sky), one
    side brighter all along it. Texture inside a face (a brick course, a
    mortar joint) is a thin line: two opposite steps close together, with
    the same brightness either side. So, on ``samples`` profiles across the
    segment (``grey`` 8-bit scaled, ±``half_width`` px, ¼ px steps): the
    signed derivative; one sign for the whole segment (the side that is
    brighter along most of it — the face order); per profile its peak of
    that sign, sub-pixel by a parabola, kept only when the grey level 2 px
    beyond the peak on either side still differs by half the peak's
    contrast in that sense (a step, not a line). A total-least-squares line
    through the kept peaks (one 3σ trim) gives the segment, its ends the
    orthogonal projections of the given ones; None when it moved an end by
    more than ``half_width``.

    >>> g = np.zeros((40, 60)); g[:, 30:] = 200.0; g[:, 27] = 120.0  # step at x=29.5, a line at 27
    >>> np.round(refine_on_edge(g, np.array([28.5, 5.0, 28.5, 35.0])), 1).tolist()
    [29.5, 5.0, 29.5, 35.0]
    """
    seg = np.asarray(seg, float)
    a, b = seg[:2], seg[2:]
    found = _step_points(grey, seg, half_width, samples)
    if found is None:
        return None
    pts, wts = found
    need = max(6, min_support * samples)
    if len(pts) < need:
        return None
    if STEP_CONSENSUS:
        # the line most of the profiles' steps lie on, not a least-squares line
        # through all of them: where the building has relief the block model
        # lacks (the pilasters' feet along a wall's bottom edge), part of the
        # profiles find the relief's step 2-3 px away, and a fit through both
        # is a tilted line that lies on neither
        keep = _consensus(pts, STEP_CONSENSUS_PX)
        if np.count_nonzero(keep) < need:
            return None
        pts, wts = pts[keep], wts[keep]
    from lumigraph.stereo.debevec1996.automark import fit_line
    # each peak weighted by its inverse variance: a step's position is known
    # to (noise or texture clutter) / contrast, so a stretch where the edge
    # barely shows (a silhouette against a face of the same brick, below the
    # part against the sky) must not tilt the line the clear stretch gives
    c, dd = fit_line(pts, weights=wts if WEIGHTED_STEPS else None)
    out = np.r_[c + ((a - c) @ dd) * dd, c + ((b - c) @ dd) * dd]
    if max(np.hypot(*(out[:2] - a)), np.hypot(*(out[2:] - b))) > half_width:
        return None
    return out


def _turn_deg(a, b) -> float:
    """The angle (degrees, 0–90) between two segments ``(4,)``' directions."""
    da = np.asarray(a[2:], float) - np.asarray(a[:2], float)
    db = np.asarray(b[2:], float) - np.asarray(b[:2], float)
    c = abs(da @ db) / max(np.hypot(*da) * np.hypot(*db), 1e-12)
    return float(np.degrees(np.arccos(min(c, 1.0))))


def _posed_photos(e) -> list[str]:
    """The photographs a solver refusal names only by their poses: every
    photograph of a :class:`~lumigraph.stereo.debevec1996.solve.CannotSeeMarks`,
    or of an :class:`~lumigraph.stereo.debevec1996.solve.Unconstrained` at
    the solution whose unknowns are all poses (``photo:rotation``,
    ``photo:position``); none otherwise (a free block parameter needs marks,
    not a start)."""
    if hasattr(e, "photos"):
        return list(e.photos)
    if getattr(e, "at_solution", False) and e.unknowns and all(":" in u for u in e.unknowns):
        return sorted({u.split(":")[0] for u in e.unknowns})
    return []


def step_spread(grey: np.ndarray, seg: np.ndarray, *, half_width: float = EDGE_HALF_WIDTH_PX,
                samples: int = 32) -> float | None:
    """The RMS distance (px) of the image's intensity steps from the line of
    ``seg`` ``(4,)`` along it: the profiles' steps of :func:`refine_on_edge`
    (within ±``half_width`` px), None when fewer than six profiles show one.

    A segment on a clean edge scatters by the steps' sub-pixel noise (a
    tenth to a few tenths of a pixel); one on an edge the image shows
    weakly, or broken by relief the model lacks (a pilaster's foot along a
    wall's bottom), by far more; and a segment off its step by that offset.
    The page stores it with the mark (``spread_px``) and the solve counts
    the mark's ends as noisy by the larger of it and its ``noise_px``
    (``stereo/debevec1996/solve.py``).

    >>> g = np.zeros((40, 60)); g[:, 30:] = 200.0
    >>> round(step_spread(g, np.array([29.5, 5.0, 29.5, 35.0])), 3)
    0.0
    >>> g[20:, 30:32] = 0.0; g[20:, 32:] = 200.0      # the lower half's step 2 px to the right
    >>> round(step_spread(g, np.array([30.5, 5.0, 30.5, 35.0])), 1)
    1.0
    """
    seg = np.asarray(seg, float)
    found = _step_points(grey, seg, half_width, samples)
    if found is None or len(found[0]) < 6:
        return None
    a, b = seg[:2], seg[2:]
    d = (b - a) / np.hypot(*(b - a))
    h = (found[0] - a) @ np.array([-d[1], d[0]])
    return float(np.sqrt(np.mean(h ** 2)))


def _consensus(pts: np.ndarray, tol: float) -> np.ndarray:
    """Which of the points ``pts`` ``(N, 2)`` (px) lie on the line that most
    of them agree on: over the lines through every two of them (at least
    1 px apart), the one with the least truncated squared distance
    ``Σ min(r², tol²)`` (MSAC, Torr & Zisserman 2000); its points within
    ``tol`` px. Deterministic (every pair is tried).

    >>> p = np.array([[x, 0.1 * (x % 2)] for x in range(10)] + [[x, 2.5] for x in range(4)], float)
    >>> _consensus(p, 0.5).astype(int).tolist()
    [1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0]
    """
    i, j = np.triu_indices(len(pts), 1)
    d = pts[j] - pts[i]
    L = np.hypot(d[:, 0], d[:, 1])
    ok = L >= 1.0
    i, d, L = i[ok], d[ok], L[ok]
    if i.size == 0:
        return np.ones(len(pts), bool)
    nrm = np.stack([-d[:, 1], d[:, 0]], 1) / L[:, None]
    r = np.abs(np.einsum("pnk,pk->pn", pts[None] - pts[i][:, None], nrm))   # (pairs, N)
    best = int(np.argmin(np.minimum(r, tol) ** 2 @ np.ones(len(pts))))
    return r[best] <= tol


def snap_segment(segment: np.ndarray, detected: np.ndarray, *, grey: np.ndarray | None,
                 max_angle_deg: float = SNAP_ANGLE_DEG,
                 max_distance_px: float = SNAP_DISTANCE_PX) -> np.ndarray | None:
    """The dragged ``segment`` ``(4,)`` (x0, y0, x1, y1, px) moved onto the
    line of the nearest ``detected`` segment ``(N, 4)``, or None when no
    detection is within ``max_angle_deg`` and (both dragged ends)
    ``max_distance_px`` of its line and overlaps the drag. With ``grey`` (an
    8-bit-scaled grey image) the detection is first refined to sub-pixel
    precision (:func:`~lumigraph.stereo.debevec1996.automark.refine_segment`).
    The ends keep their place along the line (their orthogonal projections)."""
    seg = np.asarray(segment, float)
    a, b = seg[:2], seg[2:]
    if len(detected) == 0 or np.hypot(*(b - a)) < 1.0:
        return None
    p, q = detected[:, :2], detected[:, 2:]
    L = np.maximum(np.hypot(*(q - p).T), 1e-9)
    d = (q - p) / L[:, None]
    n = np.stack([-d[:, 1], d[:, 0]], 1)
    u = (b - a) / np.hypot(*(b - a))
    cos = np.abs(d @ u)
    ha, hb = ((a - p) * n).sum(1), ((b - p) * n).sum(1)
    ta, tb = ((a - p) * d).sum(1), ((b - p) * d).sum(1)
    overlap = np.minimum(np.maximum(ta, tb), L) - np.maximum(np.minimum(ta, tb), 0.0)
    ok = (cos >= np.cos(np.radians(max_angle_deg))) & (np.maximum(np.abs(ha), np.abs(hb))
                                                       <= max_distance_px) & (overlap > 0)
    if not ok.any():
        return None
    score = np.where(ok, np.abs(ha) + np.abs(hb), np.inf)
    best = detected[int(np.argmin(score))]
    if grey is not None:
        from lumigraph.stereo.debevec1996.automark import refine_segment

        refine = refine_on_edge if SNAP_ON_STEP else refine_segment
        if SNAP_OVER_DRAG:
            # refined over the stretch the user dragged (carried onto the
            # detection's line), not over the detection alone: a detection
            # may cover a fifth of a long edge (the part against the sky),
            # and its line carried out to the far end is an extrapolation
            # (0.7 degrees off is 2 px at the far end of a 160 px edge)
            p0, q0 = best[:2], best[2:]
            d0 = (q0 - p0) / max(np.hypot(*(q0 - p0)), 1e-9)
            refined = refine(grey, np.r_[p0 + ((a - p0) @ d0) * d0, p0 + ((b - p0) @ d0) * d0])
            if refined is None:
                return None     # the image does not show the line along the drag: no snap
        else:
            refined = refine(grey, best)
            if refined is None and SNAP_ON_STEP:        # no step there: texture, not an edge
                return None
        if refined is not None:
            best = refined
    p, q = best[:2], best[2:]
    d = (q - p) / max(np.hypot(*(q - p)), 1e-9)
    out = np.r_[p + ((a - p) @ d) * d, p + ((b - p) @ d) * d]
    # the refined line, carried out to the dragged ends, must still be near
    # them: a short detection a few degrees off would swing a long drag's ends
    if max(np.hypot(*(out[:2] - a)), np.hypot(*(out[2:] - b))) > max_distance_px:
        return None
    return out


# hand marks listed after a Solve for a second look (docs/decisions/view-marking.md,
# ninth pass: set before any run, not tuned)
CHECK_MARKS = 3
# what orders them: "deleted" (the default), each mark's distance from where
# the *other* marks put its edge, in σ (automark.deleted_residuals), listed
# from CHECK_MIN_SCORE up; "residual" (before the eleventh pass), each mark's
# RMS distance to its solved edge. Chosen on seeds 2-80 (eleventh pass)
CHECK_BY = "deleted"
CHECK_MIN_SCORE = 2.0   # P(√(χ²₂/2) > 2) = e⁻⁴ ≈ 0.02 per mark on noise alone
# True: a mark's deleted residual is measured against its own noise (its
# spread_px where that is above the solve's noise); False: against the solve's
CHECK_OWN_NOISE = False


def marks_to_check(marks: dict, residual_by_id: dict, *, count: int | None = None,
                   score_by_id: dict | None = None,
                   min_score: float | None = None) -> list[dict]:
    """The hand-drawn marks (not accepted proposals) to look at again after
    a Solve: ``count`` of them (default :data:`CHECK_MARKS`), each ``{id,
    photo, edge, rms_px}`` and, with ``score_by_id``, ``score``.

    With ``score_by_id`` (each mark's deleted residual,
    :func:`~lumigraph.stereo.debevec1996.automark.deleted_residuals`: its
    distance from where the other marks put its edge, in σ), the marks
    scoring ``min_score`` (default :data:`CHECK_MIN_SCORE`) or more,
    highest first; a mark that alone holds some unknown (score ``inf``)
    cannot be checked by the others and is not listed (the weak list says
    where the model rests on few marks). Without it, the marks farthest from
    their reprojected edge, farthest first.

    Why the deleted residual: an off mark pulls the solve towards itself, so
    its residual is smaller than its error, and most so where few other
    marks hold the same unknowns; a residual ranking then lists the marks it
    pulled off, not itself. On the rendered Façade scene (seeds 2-80) the
    marks that spoiled a from-scratch solve were hand marks that snapping
    put 1-3.5 px off an edge the image barely shows (a wall corner against
    a wall of the same brick); ranked by their residual they were missed
    (docs/decisions/view-marking.md, eleventh pass). Why hand marks: a
    proposal was accepted because it lies on its edge.

    >>> marks = {1: {"photo": "a.png", "edge": "house/top-front", "proposed": False},
    ...          2: {"photo": "a.png", "edge": "house/front-left", "proposed": True},
    ...          3: {"photo": "b.png", "edge": "tower/top-left", "proposed": False},
    ...          4: {"photo": "b.png", "edge": "tower/top-front", "proposed": False}}
    >>> res = {1: 0.4, 2: 2.0, 3: 1.1, 4: 0.2}
    >>> [m["id"] for m in marks_to_check(marks, res, score_by_id=None)]
    [3, 1, 4]
    >>> [m["id"] for m in marks_to_check(marks, res, score_by_id={1: 0.9, 2: 5.0, 3: 2.5,
    ...                                                          4: 3.1})]
    [4, 3]
    """
    count = CHECK_MARKS if count is None else count
    hand = [k for k, m in marks.items() if not m.get("proposed") and k in residual_by_id]
    if score_by_id is None:
        hand.sort(key=lambda k: -residual_by_id[k])
    else:
        lo = CHECK_MIN_SCORE if min_score is None else min_score
        score = {k: float(score_by_id.get(k, np.nan)) for k in hand}
        hand = [k for k in hand if np.isfinite(score[k]) and score[k] >= lo]
        hand.sort(key=lambda k: -score[k])
    return [{"id": k, "photo": marks[k]["photo"], "edge": marks[k]["edge"],
             "rms_px": float(residual_by_id[k]),
             **({"score": score[k]} if score_by_id is not None else {})}
            for k in hand[:count]]


# a free parameter is "weakly constrained" when its relative σ is more than
# this many times the median relative σ of the free parameters: the marks
# hold it clearly less well than the rest (chosen on the tuned seeds 2, 7, 8,
# docs/decisions/view-marking.md, "Told where the model is weak")
WEAK_FACTOR = 2.0
WEAK_SUGGESTIONS = SUGGESTIONS   # unmarked edges suggested per weak parameter (and per refused unknown)


def weak_spots(sol, marked, sizes: dict, *, factor: float | None = None,
               suggestions: int | None = None) -> list[dict]:
    """Where the solved model is weak, and which marks would hold it.

    ``sol`` a :class:`~lumigraph.stereo.debevec1996.solve.FacadeSolution`,
    ``marked`` the set of ``(photo, edge)`` already marked, ``sizes``
    photo -> (width, height) px; ``factor`` and ``suggestions`` default to
    :data:`WEAK_FACTOR` and :data:`WEAK_SUGGESTIONS`. Each free parameter's relative first-order
    σ (its σ over its value, or for an offset near zero over a tenth of the
    model's median size); the parameters whose relative σ is over
    ``factor`` times the median of them all are weak. For each, the
    unmarked model edges in front of each camera and in frame (hidden by
    the solved model's faces or not: ``hidden_in_solve`` says which, since
    a weak model's occlusion is not to be trusted), listed in turn: each
    the one that gives the parameter the least σ with a mark on the edge's
    stretch in frame added *to those above it*
    (:func:`~lumigraph.stereo.debevec1996.automark.std_with_marks_in_turn`:
    what the mark adds to the marks already there and to the suggestions
    above it, poses and shared parameters included; a suggestion the
    solved model hides is listed but not assumed marked, since the
    photograph may not show it), while one lowers it; ``std_after`` is
    that σ; ``suggestions`` of them. So a user who marks from the top does
    not pile the marks into one photograph where another view would hold
    the parameter better. Returns ``[{parameter, value, std, rel_std,
    median_rel_std, suggest: [{photo, edge, std_after, hidden_in_solve}]}]``,
    weakest first.

    The test scene's tower with its right side marked in one photograph
    only (its left side in all): its width is weak, the edges to mark are
    on its right side, and the second is in another photograph than the
    first.

    >>> from lumigraph.capture.scenes.facade_edges import ring_cameras, project_edges
    >>> from lumigraph.stereo.debevec1996.edges import EdgeMarks
    >>> from lumigraph.stereo.debevec1996.model import BlockModel
    >>> from lumigraph.stereo.debevec1996.solve import FIXTURE, solve_facade
    >>> m = BlockModel.from_dict(FIXTURE)
    >>> cams = ring_cameras(6, target=[1.5, 0, 4], radius=30, height=4, focal_px=700)
    >>> seen, first = project_edges(m, cams), True
    >>> for p in seen:
    ...     right = [e for e in seen[p] if e["edge"] in ("tower/front-right", "tower/back-right",
    ...                                                  "tower/top-right", "tower/bottom-right")]
    ...     keep, first = (right[:1] if first and right else []), first and not right
    ...     seen[p] = [e for e in seen[p] if e not in right or e in keep]
    >>> marks = [k for k in EdgeMarks.from_dict({"photographs": seen}, model=m,
    ...                                         photographs=list(cams)).marks]
    >>> marks = [type(k)(k.photo, k.edge, k.segment + 0.5 * np.cos(np.arange(4) + i))
    ...          for i, k in enumerate(marks)]                  # ±0.5 px, deterministic
    >>> sol = solve_facade(m, EdgeMarks(tuple(marks), tuple(cams)),
    ...                    {p: c["K"] for p, c in cams.items()})
    >>> weak = weak_spots(sol, {(k.photo, k.edge) for k in marks},
    ...                   {p: c["image_size"] for p, c in cams.items()})
    >>> top = weak[0]["suggest"][:2]
    >>> [w["parameter"] for w in weak], [q["edge"] for q in top], top[0]["photo"] != top[1]["photo"]
    (['tower/width'], ['tower/back-right', 'tower/back-right'], True)
    """
    from lumigraph.capture.scenes.facade_edges import project_edges
    from lumigraph.stereo.debevec1996.automark import _scale, std_with_marks_in_turn
    from lumigraph.stereo.debevec1996.edges import Mark

    factor = WEAK_FACTOR if factor is None else factor
    suggestions = WEAK_SUGGESTIONS if suggestions is None else suggestions
    names = list(sol.model.parameter_names)
    if len(names) < 2:
        return []
    scale = _scale(sol.model, names)
    rel = {n: sol.std[n] / scale[n] for n in names if scale[n] > 0 and np.isfinite(sol.std[n])}
    if not rel:
        return []
    med = float(np.median(list(rel.values())))
    weak = sorted((n for n, r in rel.items() if r > factor * med), key=lambda n: -rel[n])
    out = []
    # candidates: in front and in frame, hidden or not by the solved model's
    # faces -- where the model is weak its occlusion is too (seed 3's over-wide
    # wing hides its own right side in the house); the solved model's verdict
    # is passed on ("hidden_in_solve") for the user's eye
    cands, shown = [], set()
    for p, (R, t) in sol.poses.items():
        cam = {p: {"K": sol.K[p], "R": R, "t": t, "image_size": sizes[p]}}
        shown |= {(p, m["edge"]) for m in project_edges(sol.model, cam)[p]}
        cands += [Mark(p, m["edge"], np.asarray(m["segment"], float))
                  for m in project_edges(sol.model, cam, occlusion=False)[p]
                  if (p, m["edge"]) not in marked]
    for n in weak:
        # each suggestion the best given those above it marked: a list of
        # marks that share one photograph's pose is not a list of best marks
        # (one the solved model hides is listed, not assumed marked: the
        # photograph may not show it)
        order = std_with_marks_in_turn(sol, cands, n, count=suggestions,
                                       markable=[(m.photo, m.edge) in shown for m in cands]) \
            if cands else []
        out.append({"parameter": n, "value": float(sol.params[n]), "std": float(sol.std[n]),
                    "rel_std": float(rel[n]), "median_rel_std": med,
                    "suggest": [{"photo": cands[i].photo, "edge": cands[i].edge,
                                 "std_after": sd,
                                 "hidden_in_solve": (cands[i].photo, cands[i].edge) not in shown}
                                for i, sd in order]})
    return out


class FacadeSession:
    """One photogrammetric-modelling session (module docstring).

    Open with :meth:`open`. Methods that change the marks take the session's
    lock (the web server answers from several threads), save ``edges.json``
    and return the changed mark as a dict ``{id, photo, edge (None while
    unassigned), segment [4], proposed}``. Bad requests raise
    :class:`InputError` naming the argument; a fit the marks cannot support
    raises :class:`EstimationError` (the solver's reason)."""

    def __init__(self, *, model, blocks_path: Path, photos: list[str], paths: dict,
                 images: dict, camera, camera_path: Path, edges_path: Path,
                 producer: str = "lumigraph view"):
        self.model = model
        self.blocks_path = blocks_path
        self.photos = photos
        self.paths = paths
        self.images = images
        self.camera = camera
        self.camera_path = camera_path
        self.edges_path = edges_path
        self.producer = producer
        self.marks: dict[int, dict] = {}
        self.proposals: dict[int, dict] = {}
        self.solution: dict | None = None
        self.refusal: dict | None = None     # the last Solve's refusal, with what to mark
        self.proposal_warnings: list[str] = []
        self._next = 1
        self._lock = threading.RLock()
        self._detected: dict[str, np.ndarray] = {}
        self._grey: dict[str, np.ndarray] = {}
        self._png: dict[str, bytes] = {}
        self._inputs = None

    # ------------------------------------------------------------- opening
    @classmethod
    def open(cls, blocks: str | os.PathLike, images=(), *, edges: str | os.PathLike,
             camera: str | os.PathLike | None = None,
             producer: str = "lumigraph view") -> FacadeSession:
        """Load ``blocks`` (a ``blocks.json``, or a folder with ``stack.json``,
        ``blocks.json`` and ``camera.json``, as ``stereo facade solve``
        reads), the photographs ``images`` (files; default: the folder's
        ``stack.json``), the intrinsics ``camera`` (default ``camera.json``
        beside the model) and ``edges`` (the file marks are saved to; read
        when it exists, else the session starts with no marks)."""
        from lumigraph.capture.camera import Camera
        from lumigraph.capture.io import read_image, read_stack_json
        from lumigraph.stereo.debevec1996.model import load_blocks

        blocks = Path(blocks)
        folder = blocks if blocks.is_dir() else blocks.parent
        if blocks.is_dir():
            blocks = folder / "blocks.json"
        if not blocks.is_file():
            raise InputError(blocks, "no block model here; give a blocks.json (see 'lumigraph "
                                     "stereo facade solve --help' for its layout) or a folder "
                                     "that holds one")
        paths: dict[str, Path] = {}
        if images:
            for p in map(Path, images):
                if p.is_dir():
                    raise InputError(p, "is a folder; give the photographs as files (or give "
                                        "the folder alone, with its stack.json, as the model)")
                if p.name in paths:
                    raise InputError(p, f"two photographs are named {p.name}; edges.json keys "
                                        "marks by file name")
                paths[p.name] = p
        else:
            sj = folder / "stack.json"
            if not sj.is_file():
                raise InputError(folder, "no photographs given and no stack.json here naming "
                                         "them; give the photographs after blocks.json")
            for i, name in enumerate(read_stack_json(sj)["images"]):
                if not (folder / name).is_file():
                    raise InputError(sj, f"key 'images[{i}]': {name} is not a file in {folder}")
                paths[name] = folder / name
        model = load_blocks(blocks)
        cam_path = Path(camera) if camera else folder / "camera.json"
        if not cam_path.is_file():
            raise InputError(cam_path, "no camera.json (the photographs' intrinsics); give one "
                                       "with --camera")
        cam = Camera.load(cam_path)
        loaded = {}
        for name, p in paths.items():
            img = read_image(p)
            if tuple(img.shape[1::-1]) != tuple(cam.image_size):
                raise InputError(p, f"is {img.shape[1]}x{img.shape[0]}, the camera ({cam_path}) "
                                    f"is {cam.image_size[0]}x{cam.image_size[1]}")
            loaded[name] = img
        s = cls(model=model, blocks_path=blocks, photos=list(paths), paths=paths, images=loaded,
                camera=cam, camera_path=cam_path, edges_path=Path(edges), producer=producer)
        from lumigraph.capture.artifact import remove_stale_temps

        # the temporaries of a session killed mid-save (its file is whole: old or new)
        remove_stale_temps(edges)
        if Path(edges).exists():
            s._load_edges()
        return s

    def _load_edges(self) -> None:
        from lumigraph.capture.artifact import load_json_artifact
        from lumigraph.capture.schema import check, fail
        from lumigraph.stereo.debevec1996.edges import EDGES_SCHEMA, EdgeMarks

        path = self.edges_path
        body = load_json_artifact(path, "marked edges", schemas=(EDGES_SCHEMA,))
        marks = EdgeMarks.from_dict(body, model=self.model, photographs=self.photos,
                                    image_sizes=self.sizes, where=path)
        for m in marks.marks:
            self._store(m.photo, m.edge, m.segment, m.proposed, spread=m.spread_px)
        extra = body.get(UNASSIGNED_KEY, {})
        check(extra, "object", path=str(path), key=UNASSIGNED_KEY)
        for photo, segs in extra.items():
            if photo not in self.photos:
                raise fail(str(path), f"{UNASSIGNED_KEY}.{photo}", f"unknown photograph {photo!r}")
            check(segs, "list", path=str(path), key=f"{UNASSIGNED_KEY}.{photo}")
            for i, s in enumerate(segs):
                try:
                    seg = self._segment(s, f"{UNASSIGNED_KEY}.{photo}[{i}]", photo)
                except InputError as e:
                    raise InputError(path, e.problem) from None
                self._store(photo, None, seg, False)

    # ------------------------------------------------------------- helpers
    @property
    def sizes(self) -> dict:
        return {p: tuple(img.shape[1::-1]) for p, img in self.images.items()}

    def _store(self, photo, edge, seg, proposed, *, into=None, spread=None) -> dict:
        m = {"id": self._next, "photo": photo, "edge": edge,
             "segment": [float(v) for v in seg], "proposed": bool(proposed)}
        if spread is not None:
            m["spread_px"] = float(spread)
        (self.marks if into is None else into)[self._next] = m
        self._next += 1
        return m

    def _spread(self, photo, seg) -> float | None:
        """The image's step scatter about a segment the page put on the
        image (:func:`step_spread`), when :data:`WEIGH_BY_SPREAD`."""
        return step_spread(self.grey(photo), np.asarray(seg, float)) if WEIGH_BY_SPREAD else None

    def _photo(self, photo) -> str:
        if isinstance(photo, int) and not isinstance(photo, bool) and 0 <= photo < len(self.photos):
            return self.photos[photo]
        if photo not in self.photos:
            raise InputError("photo", f"unknown photograph {photo!r}; the session's photographs "
                                      f"are {', '.join(self.photos)}")
        return photo

    def _edge(self, edge) -> str | None:
        if edge is None:
            return None
        if not isinstance(edge, str) or edge not in self.model.edge_names:
            raise InputError("edge", f"unknown model edge {edge!r}; the model's edges are named "
                                     f"like {self.model.edge_names[0]!r} (see the edge list)")
        return edge

    def _segment(self, seg, where: str, photo: str) -> np.ndarray:
        try:
            s = np.asarray(seg, float)
        except (TypeError, ValueError):
            s = None
        if s is None or s.shape != (4,) or not np.all(np.isfinite(s)):
            raise InputError(where, f"expected a segment [x0, y0, x1, y1] of 4 finite numbers "
                                    f"(px), got {seg!r}")
        if np.hypot(s[2] - s[0], s[3] - s[1]) < 1.0:
            raise InputError(where, "segment is shorter than 1 pixel; drag from one end of the "
                                    "edge to the other")
        w, h = self.sizes[photo]
        if min(s[0], s[2]) < -0.5 or min(s[1], s[3]) < -0.5 or max(s[0], s[2]) > w - 0.5 \
                or max(s[1], s[3]) > h - 0.5:
            raise InputError(where, f"segment {s.tolist()} lies outside photograph {photo!r} "
                                    f"({w}x{h})")
        return s

    def find(self, mark_id, table=None) -> dict:
        table = self.marks if table is None else table
        try:
            return table[int(mark_id)]
        except (KeyError, TypeError, ValueError):
            what = "mark" if table is self.marks else "proposal"
            raise InputError("id", f"no {what} with id {mark_id!r}") from None

    def grey(self, photo: str) -> np.ndarray:
        from lumigraph.stereo.debevec1996.automark import _grey

        if photo not in self._grey:
            self._grey[photo] = _grey(self.images[photo])
        return self._grey[photo]

    def detected(self, photo) -> np.ndarray:
        """Line segments ``(N, 4)`` detected in a photograph (cached)."""
        from lumigraph.stereo.debevec1996.automark import detect_segments

        photo = self._photo(photo)
        with self._lock:
            if photo not in self._detected:
                self._detected[photo] = detect_segments(self.grey(photo), min_length_px=10.0)
            return self._detected[photo]

    def png(self, photo) -> bytes:
        """The photograph as 8-bit PNG bytes (cached), for the page."""
        import cv2

        photo = self._photo(photo)
        if photo not in self._png:
            img = np.asarray(self.images[photo])
            if img.dtype == np.uint16:
                img = (img / 257.0).round().astype(np.uint8)
            elif img.dtype != np.uint8:
                img = np.clip(np.asarray(img, float) ** (1 / 2.2) * 255.0, 0, 255).astype(np.uint8)
            if img.ndim == 3:
                img = np.ascontiguousarray(img[..., 2::-1] if img.shape[2] >= 3 else img[..., 0])
            ok, buf = cv2.imencode(".png", img)
            if not ok:  # pragma: no cover - encoding an 8-bit array does not fail
                raise InputError(self.paths[photo], "could not encode the photograph as PNG")
            self._png[photo] = buf.tobytes()
        return self._png[photo]

    # ------------------------------------------------------------- the state
    def state(self) -> dict:
        """Everything the page shows: photographs (name, size), the model's
        edge names, the marks, the pending proposals, the last solve (and
        the last Solve's refusal, with what to mark)."""
        with self._lock:
            return {"photos": [{"index": i, "name": p, "width": self.sizes[p][0],
                                "height": self.sizes[p][1]} for i, p in enumerate(self.photos)],
                    "edges": list(self.model.edge_names),
                    "marks": list(self.marks.values()),
                    "proposals": list(self.proposals.values()),
                    "solution": self.solution,
                    "refusal": self.refusal,
                    "edges_path": str(self.edges_path)}

    def edge_marks(self):
        """The assigned marks as :class:`~lumigraph.stereo.debevec1996.edges.EdgeMarks`
        (checked as the solver's reader checks a file)."""
        from lumigraph.stereo.debevec1996.edges import EdgeMarks

        with self._lock:
            body = {"photographs": {p: [] for p in self.photos}}
            for m in self.marks.values():
                if m["edge"] is not None:
                    e = {"edge": m["edge"], "segment": m["segment"]}
                    if m["proposed"]:
                        e["proposed"] = True
                    if m.get("spread_px") is not None:
                        e["spread_px"] = m["spread_px"]
                    body["photographs"][m["photo"]].append(e)
            return EdgeMarks.from_dict(body, model=self.model, photographs=self.photos,
                                       image_sizes=self.sizes, where=self.edges_path)

    def document(self) -> dict:
        """``edges.json``'s body: the assigned marks, then the unassigned segments."""
        body = self.edge_marks().to_dict()
        un: dict[str, list] = {}
        for m in self.marks.values():
            if m["edge"] is None:
                un.setdefault(m["photo"], []).append(m["segment"])
        body[UNASSIGNED_KEY] = un
        return body

    def save(self) -> Path:
        """Write ``edges.json`` atomically (a complete file replaces the old
        one by a rename; its ``.meta.json`` sidecar first)."""
        from lumigraph.capture.artifact import dumps_json, make_meta, write_artifact

        with self._lock:
            body = self.document()
            if self._inputs is None:  # the inputs' hashes, once per session
                self._inputs = make_meta("x", inputs=[self.blocks_path, self.camera_path,
                                                      *self.paths.values()])["inputs"]
            n = sum(m["edge"] is not None for m in self.marks.values())
            meta = make_meta("lumigraph.facade.edges", quality={"marks": n},
                             extra={"inputs": self._inputs, "producer": self.producer})
            text = dumps_json(body)
            return write_artifact(self.edges_path, lambda tmp: tmp.write_text(text), meta=meta)

    # ------------------------------------------------------------- edits
    def add(self, photo, segment, *, edge=None, snap: bool = True) -> dict:
        """Add a segment to a photograph (snapped to a detected line when one
        is near and ``snap``), optionally assigned to ``edge``; saved."""
        photo = self._photo(photo)
        seg = self._segment(segment, "segment", photo)
        edge = self._edge(edge)
        dragged, snapped = seg.copy(), False
        if snap:
            s = snap_segment(seg, self.detected(photo), grey=self.grey(photo),
                             max_distance_px=SNAP_DISTANCE_PX)
            if s is not None:
                w, h = self.sizes[photo]
                s[[0, 2]] = np.clip(s[[0, 2]], -0.5, w - 0.5)
                s[[1, 3]] = np.clip(s[[1, 3]], -0.5, h - 0.5)
                if np.hypot(s[2] - s[0], s[3] - s[1]) >= 1.0:
                    seg, snapped = s, True
        with self._lock:
            if edge is not None:
                self._drop_same(photo, edge)
            m = self._store(photo, edge, seg, False,
                            spread=self._spread(photo, seg) if snapped else None)
            self.save()
            # how far snapping moved the drag (px, the farther end): the page
            # shows it, so a user sees a snap that left the line they traced
            # and can keep the drag as drawn (``dragged``, with ``move``)
            jump = float(max(np.hypot(*(seg[:2] - dragged[:2])), np.hypot(*(seg[2:] - dragged[2:]))))
            return dict(m, snapped=snapped, jump_px=jump, dragged=[float(v) for v in dragged])

    def _drop_same(self, photo, edge, keep=None) -> None:
        # one mark per model edge and photograph: a new one replaces the old
        for k, m in list(self.marks.items()):
            if m["photo"] == photo and m["edge"] == edge and k != keep:
                del self.marks[k]

    def assign(self, mark_id, edge) -> dict:
        """Tie a mark to a model edge (None: untie it); saved."""
        edge = self._edge(edge)
        with self._lock:
            m = self.find(mark_id)
            if edge is not None:
                self._drop_same(m["photo"], edge, keep=m["id"])
            m["edge"] = edge
            m["proposed"] = False
            self.save()
            return m

    def move(self, mark_id, segment) -> dict:
        """Replace a mark's segment (no snapping: the user's own, with no
        step scatter); saved."""
        with self._lock:
            m = self.find(mark_id)
            m["segment"] = [float(v) for v in self._segment(segment, "segment", m["photo"])]
            m.pop("spread_px", None)
            self.save()
            return m

    def delete(self, mark_id) -> dict:
        with self._lock:
            m = self.find(mark_id)
            del self.marks[m["id"]]
            self.save()
            return m

    # ------------------------------------------------------------- solve
    def _K(self) -> dict:
        return {p: self.camera.K for p in self.photos}

    def _undistorted(self, marks):
        from dataclasses import replace

        if not np.any(self.camera.dist):
            return marks
        out = []
        for m in marks.marks:
            ray = self.camera.unproject(m.segment.reshape(2, 2))
            uv = ray @ self.camera.K.T
            out.append(replace(m, segment=(uv[:, :2] / uv[:, 2:]).ravel()))
        return replace(marks, marks=tuple(out))

    def solve(self, *, noise_px: float = SOLVE_NOISE_PX) -> dict:
        """Fit the model and the cameras to the assigned marks. Returns
        ``{parameters: {name: {value, std}}, rms_px, sigma_px, warnings,
        outliers: [{photo, edge, rms_px}], dropped, projected: {photo:
        {edge: [x0, y0, x1, y1]}}, residuals: {photo: {edge: rms px}},
        residual_by_id: {mark id: rms px}, weak: [...] (:func:`weak_spots`),
        check: [...] (:func:`marks_to_check`)}``;
        kept as the session's solution (the proposals' starting point).
        A refusal because the marks do not constrain some unknowns raises
        :class:`~lumigraph.stereo.debevec1996.solve.Unconstrained` with
        ``unconstrained`` set to :func:`unconstrained_spots`' answer (the
        unmarked edges that would constrain each), also kept as the
        session's ``refusal`` ``{error, unconstrained}`` until the next
        Solve."""
        from dataclasses import replace

        from lumigraph.stereo.debevec1996.solve import (
            CannotSeeMarks,
            NoRotationStart,
            Unconstrained,
            _without,
            project_model_edges,
            solve_facade,
        )

        with self._lock:
            marks = self.edge_marks()
            if not marks.marks:
                raise EstimationError(self.edges_path, "no marks tied to model edges yet: draw "
                                                       "segments and assign each to an edge")
            # each photograph's pose in the last solve that had it (a photograph
            # left out of the last solve keeps its pose from the one before)
            known = dict(getattr(self, "_known_poses", {}))
            rough, started, restarted, left_out = {}, [], [], []
            try:
                while True:
                    try:
                        sol = solve_facade(self.model, _without(self._undistorted(marks), left_out),
                                           self._K(), noise_px=noise_px, where=str(self.edges_path),
                                           rough_rotations=rough or None)
                        break
                    except NoRotationStart as e:
                        # a photograph whose marks no longer start its rotation
                        # (a re-snap deleted the solver's outliers among them, or
                        # the user did) starts from its pose in the last solve
                        if e.photo not in known or e.photo in rough:
                            raise
                        rough[e.photo] = known[e.photo][0]
                        started.append(e.photo)
                    except (Unconstrained, CannotSeeMarks) as e:
                        # a pose the solve from the marks' vanishing directions
                        # ended on, that the marks do not fix there or from
                        # which the camera cannot see them (a wrong pose that
                        # fits them): the last solve's pose of that photograph is
                        # a start the page has, once (marking eval, fresh seeds
                        # 261 and 274: no model without it)
                        named = _posed_photos(e)
                        if not named or set(named) & set(left_out):
                            raise
                        again = [p for p in named if p in known and p not in rough]
                        if len(again) == len(named):
                            for p in again:
                                rough[p] = known[p][0]
                            restarted += again
                            continue
                        # no start left to try: the model from the other
                        # photographs, those left out and said so (marking eval,
                        # fresh seed 274: three marks left on a photograph by a
                        # re-snap, a pose they fit in two ways)
                        left_out += named
            except Unconstrained as e:
                # the page lists, per refused unknown, the unmarked edges
                # that would constrain it (what to mark next, not just names)
                e.unconstrained = unconstrained_spots(
                    self.model, self._undistorted(marks), self._K(), self.sizes, e.unknowns,
                    noise_px=noise_px, where=str(self.edges_path), suggestions=WEAK_SUGGESTIONS,
                    marked={(m["photo"], m["edge"]) for m in self.marks.values()})
                self.refusal = {"error": str(e), "unconstrained": e.unconstrained}
                raise
            self.refusal = None
            if left_out:
                sol = replace(sol, dropped=list(sol.dropped) + left_out)
                marks = _without(marks, left_out)
            self._sol = sol
            self._known_poses = {**known, **sol.poses}
            self.solution = solution_dict(sol, self.photos, self.marks, project_model_edges)
            self.solution["warnings"] = [
                f"photograph {p!r}: its marks alone cannot start its rotation (two edges along "
                "each of two of the model's axes); started from its pose in the last solve"
                for p in started] + [
                f"photograph {p!r}: the solve from its marks' directions ended on a pose they "
                "do not fix, or that cannot see them; solved again from its pose in the last "
                "solve (mark edges in other directions on it)" for p in restarted] + [
                f"photograph {p!r} left out of this solve: its marks fit a wrong pose (they do not "
                "fix it, or the camera could not see them from it) from every start the page has; "
                "mark edges in other directions on it" for p in left_out] \
                + list(self.solution["warnings"])
            # the page's "weakly constrained" list: what to mark next
            self.solution["weak"] = weak_spots(
                sol, {(m["photo"], m["edge"]) for m in self.marks.values()}, self.sizes)
            self.solution["check"] = marks_to_check(
                self.marks, self.solution["residual_by_id"],
                score_by_id=self._deleted_scores(sol, marks) if CHECK_BY == "deleted" else None)
            return self.solution

    def _deleted_scores(self, sol, marks) -> dict | None:
        """Each solved mark's deleted residual (:func:`deleted_residuals`: its
        distance from where the other marks put its edge, in σ), by mark id."""
        from dataclasses import replace

        from lumigraph.stereo.debevec1996.automark import deleted_residuals

        out = {(p, e) for p, e, _ in sol.outliers}
        und = self._undistorted(marks)
        kept = [m for m in und.marks if (m.photo, m.edge) not in out]
        try:
            t = deleted_residuals(sol, replace(und, marks=tuple(kept)).marks,
                                  own_noise=CHECK_OWN_NOISE)
        except np.linalg.LinAlgError:
            # (a Jacobian with non-finite entries) the list falls back to the residuals
            return None
        score = dict(zip(((m.photo, m.edge) for m in kept), t, strict=True))
        return {k: float(score[(m["photo"], m["edge"])]) for k, m in self.marks.items()
                if (m["photo"], m["edge"]) in score}

    # ------------------------------------------------------------- re-snap
    def resnap(self, *, every: bool = True) -> dict:
        """The user's second look, done for every mark at once: after a
        Solve, each mark (``every``; else only a mark with an end farther
        from its reprojected edge than the solve explains) is moved onto
        the intensity step that lies within the edge's uncertainty band, or
        flagged when the band shows none; the solver's outliers are
        deleted. Saved. Returns ``{moved: [ids], flagged: [ids], deleted:
        [ids], band_px: {id: px}}``.

        The band of a mark is ``3 sqrt(σ_e² + σ²)``: σ_e the first-order
        standard deviation of where the solve puts the edge at the mark's
        ends (:func:`~lumigraph.stereo.debevec1996.automark.edge_offset_std`,
        from the solve's covariance), σ the solve's estimated endpoint noise
        (its residual scale); a correct mark lies within it of the
        reprojected edge (3σ). A mark farther off sits on another image line
        (snapping took a stronger step nearby: a pilaster's relief, a brick
        course, the next face's shading). Within the band around the
        reprojected edge, :func:`refine_on_edge` looks for a step (one sign
        along the edge, a step not a line); the mark moves onto it when one
        is found and turns it by at most ``SNAP_ANGLE_DEG``, else it is
        flagged for the user. Not circular: a mark only
        ever moves to where the *image* shows a step; the model line only
        bounds the search, and a band with no step moves nothing. A mark
        whose band is wider than its photograph (the solve does not know
        where the edge is: a parameter it barely holds) is left as it is."""
        from lumigraph.stereo.debevec1996.automark import edge_offset_std
        from lumigraph.stereo.debevec1996.edges import Mark
        from lumigraph.stereo.debevec1996.solve import project_model_edges

        if np.any(self.camera.dist):
            raise InputError(self.camera_path, "re-snapping needs undistorted photographs "
                                               "('lumigraph calib undistort' them first)")
        with self._lock:
            sol = getattr(self, "_sol", None)
            if sol is None:
                raise EstimationError(self.edges_path, "no solve yet: Solve first, then "
                                                       "re-snap to the solved model")
            out = {(p, e) for p, e, _ in sol.outliers}
            deleted = [k for k, m in self.marks.items() if (m["photo"], m["edge"]) in out]
            for k in deleted:
                del self.marks[k]
            kept = {(p, e) for p, e, _ in sol.mark_rms_px}
            ids = [k for k, m in self.marks.items()
                   if m["edge"] is not None and m["photo"] in sol.poses
                   and (m["photo"], m["edge"]) in kept]
            ms = [Mark(self.marks[k]["photo"], self.marks[k]["edge"],
                       np.asarray(self.marks[k]["segment"], float)) for k in ids]
            sd = edge_offset_std(sol, ms)
            moved, flagged, band = [], [], {}
            lines = {p: project_model_edges(sol.model, sol.K[p], *sol.poses[p])
                     for p in sol.poses}
            for k, m, s in zip(ids, ms, sd, strict=True):
                w = 3.0 * float(np.sqrt(np.max(s) ** 2 + sol.sigma_px ** 2))
                band[k] = w
                if not np.all(np.isfinite(s)) or w > max(self.sizes[m.photo]):
                    # the solve does not know where this edge is (a band wider
                    # than the photograph): nothing to search, the mark stays
                    continue
                a, b = (np.asarray(v, float) for v in lines[m.photo][m.edge])
                d = (b - a) / max(np.hypot(*(b - a)), 1e-9)
                nrm = np.array([-d[1], d[0]])
                off = max(abs((m.segment[:2] - a) @ nrm), abs((m.segment[2:] - a) @ nrm))
                if not every and off <= w:
                    continue        # both ends within the band: what the solve explains
                # the mark's stretch carried onto the reprojected edge: the search's centre
                seg = np.r_[a + ((m.segment[:2] - a) @ d) * d, a + ((m.segment[2:] - a) @ d) * d]
                new = refine_on_edge(self.grey(m.photo), seg, half_width=w)
                if new is None or _turn_deg(new, m.segment) > SNAP_ANGLE_DEG:
                    # no step in the band, or one that would turn the mark
                    # further than a drag is off its edge's direction: a wide
                    # band (a pose the solve barely holds) can take steps of
                    # two lines at its two ends (marking eval, fresh seed 261:
                    # a hand mark turned 19° and 38 px off at one end)
                    flagged.append(k)
                    continue
                self.marks[k]["segment"] = [float(v) for v in new]
                sp = self._spread(m.photo, new)
                if sp is None:
                    self.marks[k].pop("spread_px", None)
                else:
                    self.marks[k]["spread_px"] = sp
                moved.append(k)
            self.save()
            return {"moved": moved, "flagged": flagged, "deleted": deleted, "band_px": band}

    # ------------------------------------------------------------- propose
    def propose(self, *, noise_px: float = 1.0, refine: bool = True) -> list[dict]:
        """Automatic marking from the marks so far: the proposals (pending,
        not saved until accepted), replacing any earlier pending ones. With
        ``refine`` each proposal is moved onto the intensity step it lies on
        (:func:`refine_on_edge`) and dropped when it lies on none."""
        from lumigraph.stereo.debevec1996.automark import automark

        if np.any(self.camera.dist):
            raise InputError(self.camera_path, "automatic marking needs undistorted photographs "
                                               "('lumigraph calib undistort' them first)")
        with self._lock:
            marks = self.edge_marks()
            if not marks.marks:
                raise EstimationError(self.edges_path, "mark a few edges first (four per "
                                                       "photograph work well), then Propose")
            res = automark(self.model, marks, self.images, self._K(), noise_px=noise_px,
                           where=str(self.edges_path))
            self.proposals = {}
            have = {(m["photo"], m["edge"]) for m in self.marks.values()}
            for m in res.marks.marks:
                if m.proposed and (m.photo, m.edge) not in have:
                    seg = m.segment
                    if refine:
                        # automatic marking's match may sit on a texture line
                        # near the edge: onto the step, or not proposed at all
                        seg = refine_on_edge(self.grey(m.photo), np.asarray(seg, float))
                        if seg is None:
                            continue
                    self._store(m.photo, m.edge, seg, True, into=self.proposals,
                                spread=self._spread(m.photo, seg) if refine else None)
            self.proposal_warnings = list(res.warnings)
            return list(self.proposals.values())

    def accept(self, proposal_id) -> dict:
        """A pending proposal becomes a mark (``"proposed": true``); saved."""
        with self._lock:
            p = self.find(proposal_id, self.proposals)
            del self.proposals[p["id"]]
            self._drop_same(p["photo"], p["edge"])
            self.marks[p["id"]] = p
            self.save()
            return p

    def accept_all(self) -> list[dict]:
        with self._lock:
            got = list(self.proposals.values())
            for p in got:
                self._drop_same(p["photo"], p["edge"])
                self.marks[p["id"]] = p
            self.proposals = {}
            self.save()
            return got

    def reject(self, proposal_id) -> dict:
        with self._lock:
            p = self.find(proposal_id, self.proposals)
            del self.proposals[p["id"]]
            return p


def solution_dict(sol, photos, marks: dict, project) -> dict:
    """The JSON answer of :meth:`FacadeSession.solve` from a
    :class:`~lumigraph.stereo.debevec1996.solve.FacadeSolution`."""
    projected, residuals = {}, {}
    for p in photos:
        if p not in sol.poses:
            continue
        R, t = sol.poses[p]
        proj = project(sol.model, sol.K[p], R, t)
        projected[p] = {e: [float(v) for v in np.r_[a, b]] for e, (a, b) in proj.items()
                        if np.all(np.isfinite(a)) and np.all(np.isfinite(b))}
    for p, e, r in sol.mark_rms_px:
        residuals.setdefault(p, {})[e] = float(r)
    out = {(p, e): float(r) for p, e, r in sol.outliers}
    by_id = {}
    for m in marks.values():
        key = (m["photo"], m["edge"])
        r = residuals.get(m["photo"], {}).get(m["edge"], out.get(key))
        if r is not None:
            by_id[m["id"]] = r
    return {"parameters": {n: {"value": float(v), "std": float(sol.std[n])}
                           for n, v in sol.params.items()},
            "rms_px": float(sol.rms_px), "sigma_px": float(sol.sigma_px),
            "noise_px": float(sol.noise_px),
            "warnings": list(sol.warnings),
            "outliers": [{"photo": p, "edge": e, "rms_px": float(r)} for p, e, r in sol.outliers],
            "dropped": list(sol.dropped), "projected": projected, "residuals": residuals,
            "residual_by_id": by_id}
