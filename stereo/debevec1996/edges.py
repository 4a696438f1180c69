"""The marked image edges of Façade's photogrammetric modelling
(``edges.json``; Debevec, Taylor & Malik 1996, reference ch. 5 §5.3.2).

Layout::

    {"schema": "lumigraph.facade.edges", "schema_version": 1,
     "photographs": {"photo_00.png": [
         {"edge": "house/top-front", "segment": [x0, y0, x1, y1]}, ...], ...}}

Each photograph (a file named by the folder's ``stack.json``) lists the 2-D
segments marked on it (pixels, OpenCV convention: ``(0, 0)`` the centre of
the top-left pixel), each tied to a model edge by its stable name
(``block/edge``, :attr:`BlockModel.edge_names`). A segment need not span the
whole edge: any stretch of the line serves. An entry may carry
``"proposed": true`` (written by automatic marking) and is then used like
any other. An entry may also carry ``"spread_px"``: the scatter (px, RMS)
of the image's intensity step about the segment's line along it, measured
when the page snapped it onto the image; the solver then treats that mark's
ends as noisy by the larger of it and its ``noise_px`` (an edge the image
shows weakly, or broken by relief the model lacks, counts for less).

Examples
--------
>>> from lumigraph.stereo.debevec1996.model import BlockModel
>>> m = BlockModel.from_dict({"blocks": [{"name": "b", "kind": "box",
...     "params": {"width": {"value": 2, "fixed": True}, "depth": 1, "height": 3}}]})
>>> marks = EdgeMarks.from_dict({"photographs": {"a.png": [
...     {"edge": "b/top-front", "segment": [1, 2, 30, 2]}]}}, model=m, photographs=["a.png"])
>>> marks.count("a.png"), marks.marks[0].edge
(1, 'b/top-front')
>>> EdgeMarks.from_dict({"photographs": {"a.png": [{"edge": "b/top", "segment": [1, 2, 3, 4]}]}},
...                     model=m, photographs=["a.png"], where="edges.json")
Traceback (most recent call last):
...
lumigraph.capture.errors.InputError: edges.json: key 'photographs.a.png[0].edge': unknown model edge 'b/top'; the model's edges are named like 'b/bottom-front' (see blocks.json)
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

EDGES_SCHEMA = "lumigraph.facade.edges"


@dataclass(frozen=True)
class Mark:
    """One marked segment: ``photo`` (file name), ``edge`` (model edge name),
    ``segment`` ``(4,)`` float64 ``x0, y0, x1, y1`` in pixels, ``proposed``
    (found by automatic marking rather than by hand), ``spread_px`` the
    scatter of the image's step about the segment's line (px; None: not
    measured, the mark is as noisy as the solve's ``noise_px``)."""

    photo: str
    edge: str
    segment: np.ndarray
    proposed: bool = False
    spread_px: float | None = None


@dataclass(frozen=True)
class EdgeMarks:
    """All marks of an ``edges.json``, in file order."""

    marks: tuple[Mark, ...]
    photographs: tuple[str, ...]
    where: str = "edges.json"

    def count(self, photo: str) -> int:
        return sum(m.photo == photo for m in self.marks)

    def of(self, photo: str) -> list[Mark]:
        return [m for m in self.marks if m.photo == photo]

    @classmethod
    def from_dict(cls, d: dict, *, model, photographs, image_sizes: dict | None = None,
                  where: str | os.PathLike = "edges.json") -> EdgeMarks:
        """Marks from the ``edges.json`` layout, checked against ``model``
        (unknown edge name), ``photographs`` (unknown photograph) and, when
        given, ``image_sizes`` ``{photo: (w, h)}`` (a segment outside its
        photograph: marked on another image?). :class:`InputError` naming
        ``where`` and the entry."""
        from lumigraph.capture.schema import check, fail, require, require_object

        where = os.fspath(where)
        body = require(d, "photographs", "object", path=where)
        known = set(model.edge_names)
        example = model.edge_names[0] if model.edge_names else "block/edge"
        marks = []
        for photo, entries in body.items():
            if photo not in photographs:
                raise fail(where, f"photographs.{photo}",
                           f"unknown photograph {photo!r}: not in the stack "
                           f"({', '.join(photographs) or 'no photographs'})")
            check(entries, "list", path=where, key=f"photographs.{photo}")
            for i, e in enumerate(entries):
                key = f"photographs.{photo}[{i}]"
                require_object(e, path=where, where=key, what="a marked edge (edge, segment)",
                               keys=("edge", "segment"))
                name = require(e, "edge", "string", path=where, where=key)
                if name not in known:
                    raise fail(where, f"{key}.edge", f"unknown model edge {name!r}; the model's "
                                                     f"edges are named like {example!r} "
                                                     "(see blocks.json)")
                seg = require(e, "segment", "matrix", shape=(4,), path=where, where=key)
                proposed = require(e, "proposed", "boolean", path=where, where=key, default=False)
                if np.hypot(seg[2] - seg[0], seg[3] - seg[1]) < 1.0:
                    raise fail(where, f"{key}.segment", f"segment of edge {name!r} is shorter "
                                                        "than 1 pixel; mark both ends of the edge")
                if image_sizes is not None and photo in image_sizes:
                    w, h = image_sizes[photo]
                    xs, ys = seg[[0, 2]], seg[[1, 3]]
                    if xs.min() < -0.5 or ys.min() < -0.5 or xs.max() > w - 0.5 or ys.max() > h - 0.5:
                        raise fail(where, f"{key}.segment",
                                   f"segment of edge {name!r} lies outside photograph {photo!r} "
                                   f"({w}x{h}): marked on another image?")
                spread = require(e, "spread_px", "number", path=where, where=key, default=None,
                                 low=0)
                marks.append(Mark(photo, name, seg, proposed,
                                  None if spread is None else float(spread)))
        return cls(tuple(marks), tuple(photographs), where)

    def to_dict(self) -> dict:
        out: dict[str, list] = {p: [] for p in self.photographs}
        for m in self.marks:
            e = {"edge": m.edge, "segment": [float(v) for v in m.segment]}
            if m.proposed:
                e["proposed"] = True
            if m.spread_px is not None:
                e["spread_px"] = float(m.spread_px)
            out.setdefault(m.photo, []).append(e)
        return {"schema": EDGES_SCHEMA, "schema_version": 1, "photographs": out}


def load_edges(path: str | os.PathLike, *, model, photographs, image_sizes=None) -> EdgeMarks:
    """Read ``edges.json`` (see :meth:`EdgeMarks.from_dict`)."""
    from lumigraph.capture.artifact import load_json_artifact

    body = load_json_artifact(path, "marked edges", schemas=(EDGES_SCHEMA,))
    return EdgeMarks.from_dict(body, model=model, photographs=photographs,
                               image_sizes=image_sizes, where=path)
