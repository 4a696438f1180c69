"""Writes fixtures/facade-temple/edges.json and rough.json: the hand marks
of the Middlebury temple case (issue 17, docs/decisions/facade.md, "The
temple"). Reproduce: ``.venv/bin/python docs/decisions/facade_temple_marks.py``.

How the marks were made: on each photograph OpenCV contrib's fast line
detector ran (``automark.detect_segments``, 15-20 px minimum) and its
segments were drawn numbered on an upright copy of the photograph (the
temple lies on its side in every view); the segments below were picked *by
eye* as the model edge named beside them (the given cameras were not used to
pick or place any mark; they were used to diagnose an earlier set, which is
why the stylobate lines are not here: docs/decisions/facade.md). Each is then moved onto the intensity step it lies
on (``lumigraph.view.marking.refine_on_edge``, the marking mode's snap); a
refinement that moves an end more than 1.5 px jumped to a neighbouring edge
and the detection is kept instead.

Rough rotations (``rough.json``, the CLI's ``--rough-poses`` layout): each
photograph's heading around the temple rounded to 45 degrees by eye (0 =
seen from +x, -90 = from the front, -y), the camera 0.57 m from the centre
and 0.15 m above the ground looking at (0, 0, 0.08), and the image roll the
photographs show: world up points right in templeSR0001-0011 and left in
0012-0016.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from lumigraph.capture.bench import shared_data
from lumigraph.capture.scenes.facade_edges import look_at
from lumigraph.stereo.debevec1996.automark import _grey
from lumigraph.view.marking import refine_on_edge

OUT = Path(__file__).resolve().parents[2] / "fixtures" / "facade-temple"
HEADING = {1: -90, 6: 135, 7: 180, 9: -135, 12: 90, 13: 45, 15: 135}

# view -> (model edge, approximate segment x0, y0, x1, y1 in that photograph's pixels)
PICK = {
 1: [("entablature/bottom-front", [411.6, 205.0, 411.7, 238.0]),
     ("entablature/bottom-front", [412.6, 291.0, 414.8, 329.1]),
     ("entablature/top-front", [484.3, 214.0, 485.0, 236.0]),
     ("entablature/top-front", [482.1, 258.0, 481.0, 230.0]),
     ("roof/ridge", [547.7, 275.1, 551.8, 218.0]),
     ("base/bottom-front", [131.4, 123.0, 133.0, 238.0]),
     ("entablature/front-left", [457.0, 153.0, 427.0, 152.6])],
 7: [("base/bottom-left", [120.0, 117.0, 119.5, 301.0]),
     ("entablature/bottom-left", [403.9, 231.0, 402.8, 257.0]),
     ("entablature/top-left", [487.9, 174.0, 487.8, 271.0]),
     ("entablature/back-left", [481.0, 172.8, 450.0, 173.1]),
     ("entablature/front-left", [440.0, 295.2, 468.0, 297.7])],
 12: [("base/bottom-back", [509.5, 341.0, 502.8, 94.0]),
      ("entablature/bottom-back", [226.8, 231.0, 227.8, 282.0]),
      ("entablature/bottom-back", [228.4, 320.0, 224.6, 277.9]),
      ("entablature/top-back", [124.9, 174.0, 123.7, 116.0]),
      ("roof/ridge", [76.6, 204.0, 80.7, 273.1]),
      ("entablature/back-left", [200.0, 146.3, 158.0, 143.5])],
 9: [("base/bottom-front", [117.7, 209.8, 139.3, 291.4]),
     ("base/bottom-left", [149.4, 71.5, 115.9, 191.4]),
     ("entablature/top-left", [489.3, 127.0, 488.2, 191.0])],
 6: [("base/bottom-left", [110.5, 170.1, 128.8, 339.3]),
     ("base/bottom-back", [165.8, 91.9, 133.1, 138.7]),
     ("entablature/bottom-left", [403.7, 259.0, 404.8, 285.1]),
     ("entablature/top-left", [487.8, 204.0, 487.7, 314.0]),
     ("entablature/bottom-back", [412.0, 146.0, 410.6, 177.0])],
 13: [("base/bottom-back", [518.5, 281.9, 487.5, 71.9]),
      ("entablature/bottom-back", [226.9, 210.0, 227.6, 237.0]),
      ("entablature/bottom-back", [224.1, 238.0, 222.7, 179.0]),
      ("entablature/back-left", [218.9, 144.6, 186.0, 141.1])],
 15: [("base/bottom-back", [475.6, 389.8, 521.3, 228.1]),
      ("base/bottom-left", [486.8, 153.0, 506.6, 232.6]),
      ("entablature/bottom-back", [227.7, 255.9, 218.7, 342.0]),
      ("entablature/bottom-back", [219.3, 300.9, 224.9, 249.0]),
      ("entablature/top-back", [126.8, 327.0, 126.4, 247.0])],
}


def rough_rotation(view: int) -> np.ndarray:
    a = np.radians(HEADING[view])
    R, _ = look_at([0.57 * np.cos(a), 0.57 * np.sin(a), 0.15], [0.0, 0.0, 0.08])
    # look_at's image is upright; the temple photographs are turned by 90 degrees
    return np.stack([-R[1], R[0], R[2]]) if view < 12 else np.stack([R[1], -R[0], R[2]])


def main() -> None:
    folder = shared_data("data", "multiview-temple-sparsering")
    photos, moved = {}, []
    for view, picks in PICK.items():
        name = f"templeSR{view:04d}.png"
        grey = _grey(cv2.imread(str(folder / name))[..., ::-1])
        marks = []
        for edge, seg in picks:
            seg = np.array(seg, float)
            r = refine_on_edge(grey, seg)
            if r is not None and np.abs(r - seg).max() > 1.5:
                r = None
            moved.append(np.nan if r is None else float(np.abs(r - seg).max()))
            marks.append({"edge": edge, "segment": [round(float(v), 2) for v in (seg if r is None else r)]})
        photos[name] = marks
    (OUT / "edges.json").write_text(json.dumps(
        {"schema": "lumigraph.facade.edges", "schema_version": 1, "photographs": photos}, indent=1) + "\n")
    rough = {f"templeSR{v:04d}.png": {"R": rough_rotation(v).round(6).tolist()} for v in PICK}
    (OUT / "rough.json").write_text(json.dumps({"cameras": rough}, indent=1) + "\n")
    m = np.array(moved)
    print(f"{len(m)} marks, {np.isnan(m).sum()} kept as detected, refinement moved the others "
          f"by median {np.nanmedian(m):.2f} px, max {np.nanmax(m):.2f} px")


if __name__ == "__main__":
    main()
