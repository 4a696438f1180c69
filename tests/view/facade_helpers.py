"""Helpers shared by the view tests (not a test module): the rendered
Façade scene's true edge lines and the four hand marks a user starts with."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lumigraph.stereo.bench_facade import four_hand_marks  # noqa: F401 - the bench's pick, re-exported

EDGE_NOISE_PX = 0.5  # the scene's endpoint noise on its marks (render --edge-noise)


def onto_line(segment, line) -> np.ndarray:
    """``segment`` ``(4,)`` with its ends moved onto the infinite ``line``
    (two points): their orthogonal projections."""
    a, b = np.asarray(line[0], float), np.asarray(line[1], float)
    d = (b - a) / np.hypot(*(b - a))
    s = np.asarray(segment, float)
    return np.r_[a + ((s[:2] - a) @ d) * d, a + ((s[2:] - a) @ d) * d]


def noisy_full_marks(full: dict, truth: dict, photos, rng) -> dict:
    """An ``edges.json`` body: every mark of the scene's ``full`` marks put
    back on its true line (its ends' orthogonal projections), then a fresh
    draw of the scene's σ = :data:`EDGE_NOISE_PX` endpoint noise from ``rng``
    (the fully marked solve's noise, drawn again)."""
    body = {"photographs": {}}
    for p in photos:
        out = []
        for m in full[p]:
            exact = onto_line(m["segment"], truth[p][m["edge"]])
            out.append({"edge": m["edge"], "segment": (exact + rng.normal(0, EDGE_NOISE_PX, 4)).tolist()})
        body["photographs"][p] = out
    return body


def truth_lines(folder: Path) -> dict:
    """photo -> edge -> the true model edge projected by the true camera."""
    from lumigraph.stereo.debevec1996.model import load_blocks
    from lumigraph.stereo.debevec1996.solve import project_model_edges

    gt = json.loads((folder / "gt.json").read_text())
    model = load_blocks(folder / "blocks.json")
    model = model.with_values({n: gt["parameters"][n] for n in model.parameter_names})
    return {p: project_model_edges(model, c["K"], c["R"], c["t"]) for p, c in gt["cameras"].items()}


def distance(seg, line) -> float:
    """Largest distance (px) of a segment's ends from an infinite line."""
    a, b = np.asarray(line[0]), np.asarray(line[1])
    d = (b - a) / np.hypot(*(b - a))
    n = np.array([-d[1], d[0]])
    s = np.asarray(seg, float)
    return float(max(abs((s[:2] - a) @ n), abs((s[2:] - a) @ n)))


def refusal_marks(unconstrained, full, have, *, most=4):
    """The simulated user's answer to a refusal: the page lists, per
    unconstrained unknown, the unmarked edges that would constrain it
    (``unconstrained`` of the Solve's 422 answer); the user marks by hand
    up to ``most`` of them (as many hand marks a round as before the
    list), taking each unknown's list in turn, best first, and skipping an
    edge the photograph does not show (not among the scene's marks
    ``full``) or already marked (``have``). Returns ``[(photo, mark)]``."""
    byedge = {p: {m["edge"]: m for m in ms} for p, ms in full.items()}
    queues = [[q for q in u["suggest"] if q["edge"] in byedge.get(q["photo"], {})]
              for u in unconstrained]
    out, taken = [], set(have)
    while len(out) < most and any(queues):
        for qs in queues:
            while qs and (qs[0]["photo"], qs[0]["edge"]) in taken:
                qs.pop(0)
            if qs and len(out) < most:
                q = qs.pop(0)
                taken.add((q["photo"], q["edge"]))
                out.append((q["photo"], byedge[q["photo"]][q["edge"]]))
    return out
