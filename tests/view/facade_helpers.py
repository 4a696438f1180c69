"""Helpers shared by the view tests (not a test module): the rendered
Façade scene's true edge lines and the four hand marks a user starts with."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

EDGE_NOISE_PX = 0.5  # the scene's endpoint noise on its marks (render --edge-noise)


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


def four_hand_marks(model, marks):
    """Two vertical and two horizontal edges, the longest (as a user picks:
    ``lumigraph bench facade`` does the same)."""
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
