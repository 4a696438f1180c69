"""The block model of Façade's photogrammetric modelling (Debevec, Taylor &
Malik 1996, stage 1): parametrised polyhedral blocks in a hierarchy.

P. E. Debevec, C. J. Taylor and J. Malik, "Modeling and Rendering
Architecture from Photographs", SIGGRAPH 1996, doi:10.1145/237170.237191
(reference ch. 5, §5.3.2, "Stage 1. Photogrammetric modelling").

A model is a set of *blocks*, each of a *kind* with named dimensions, placed
relative to its parent block. World frame (metres, or whatever unit the
fixed parameter is in): ``z`` up, the ground at ``z = 0``; the root block
stands on the ground centred on the origin, its sides along ``x`` (width,
left = −x, right = +x) and ``y`` (depth, front = −y, back = +y). This fixes
the gauge of the reconstruction (the world frame is the model's); the scale
comes from the fixed parameter(s).

Kinds (local frame: origin at the centre of the block's base):

- ``box``: ``width`` (x) × ``depth`` (y) × ``height`` (z).
- ``wedge``: a gable roof: base ``width`` × ``depth``, ridge along ``x`` at
  ``y = 0`` and height ``height`` (the pitch is ``atan(2 height / depth)``).
- ``pyramid``: base ``width`` × ``depth``, apex at height ``height``.
- ``extrusion``: a planar polygon (``"polygon": [[u, v], …]``, at least three
  vertices, convex or simple non-convex) extruded along ``"axis"``: ``z``
  (the default; the polygon is a footprint in ``(x, y)``, extruded from
  ``z = 0`` up by ``height``), ``y`` (a profile in ``(x, z)`` seen from the
  front, extruded from ``y = −depth/2`` to ``+depth/2``) or ``x`` (a profile
  in ``(y, z)``, from ``x = −width/2`` to ``+width/2``). Each coordinate is a
  number (a constant) or a linear expression of the block's own parameters
  (``"0.5*width"``, ``"-half"``, ``"wall + 0.25"``;
  :mod:`~lumigraph.stereo.debevec1996.polygon`). Its parameters: the
  extrusion length (``height`` / ``depth`` / ``width``), every name the
  polygon uses, and optionally the others of ``width``/``depth``/``height``
  (children placed against it use them: ``on: top`` needs its ``height``,
  flush ``left``/``right`` its ``width``, ``front``/``back`` its ``depth``).
  Vertices ``bottom-<i>`` / ``top-<i>`` (the polygon's vertex ``i`` on the
  cap at the axis's low end — the ground, the front, the left — and at its
  high end); edges ``bottom-<i>`` and ``top-<i>`` (cap vertex ``i`` to
  ``i + 1``) and ``side-<i>`` (``bottom-<i>`` to ``top-<i>``). A polygon that
  crosses itself at the starting values is refused.

Placement (keys of a block with a ``parent``): ``on`` = ``top`` (its base on
the parent's top: ``z = parent height``; the default), ``base`` (on the
parent's base) or ``offset`` (parameter ``offset_z`` above the parent's
base); ``x`` = ``centre`` (default), ``left``/``right`` (its left/right side
flush with the parent's) or ``offset`` (parameter ``offset_x`` from the
parent's centre); ``y`` likewise with ``front``/``back`` and ``offset_y``.

Every quantity above is linear in the parameters, so every vertex in world
coordinates is ``C_v @ θ`` for a constant ``(3, S)`` matrix ``C_v`` over the
model's ``S`` parameter slots: the solver's derivatives with respect to the
block parameters are exact and constant (:meth:`BlockModel.edge_matrices`).

A parameter is written as a number (free, this is its starting value),
``{"value": v, "fixed": true}`` (held), or ``{"same_as": "block/param"}`` /
``{"same_as": "name"}`` (shares another block's parameter or a global one
from the top-level ``"parameters"``). Its stable name is ``block/param``
(a global one keeps its own name).

Examples
--------
>>> m = BlockModel.from_dict({"blocks": [
...     {"name": "house", "kind": "box",
...      "params": {"width": {"value": 10, "fixed": True}, "depth": 6, "height": 5}},
...     {"name": "roof", "kind": "wedge", "parent": "house",
...      "params": {"width": {"same_as": "house/width"}, "depth": {"same_as": "house/depth"},
...                 "height": 2}}]})
>>> m.parameter_names
('house/depth', 'house/height', 'roof/height')
>>> m.edges()["roof/ridge"]
(array([-5.,  0.,  7.]), array([5., 0., 7.]))
>>> mesh = m.mesh()
>>> mesh.vertices.shape, mesh.faces.shape
((14, 3), (20, 3))
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from dataclasses import replace as dc_replace
from functools import cached_property

import numpy as np

from lumigraph.capture.errors import EstimationError, InputError
from lumigraph.stereo.debevec1996.polygon import (
    crossing_edges,
    parse_coordinate,
    signed_area,
    triangulate,
)

BLOCKS_SCHEMA = "lumigraph.facade.blocks"

DIMENSIONS = ("width", "depth", "height")

# Vertices of each kind as multipliers of (width, depth, height) in the block's
# local frame; names say left/right (x), front/back (y), bottom/top (z).
_BOX_V = {f"{xn}-{yn}-{zn}": (ax, ay, az)
          for xn, ax in (("left", -0.5), ("right", 0.5))
          for yn, ay in (("front", -0.5), ("back", 0.5))
          for zn, az in (("bottom", 0.0), ("top", 1.0))}
_BASE_V = {k.removesuffix("-bottom"): v for k, v in _BOX_V.items() if k.endswith("bottom")}

_KINDS: dict[str, dict] = {
    "box": {
        "vertices": _BOX_V,
        "edges": {
            **{f"{z}-front": (f"left-front-{z}", f"right-front-{z}") for z in ("bottom", "top")},
            **{f"{z}-back": (f"left-back-{z}", f"right-back-{z}") for z in ("bottom", "top")},
            **{f"{z}-left": (f"left-front-{z}", f"left-back-{z}") for z in ("bottom", "top")},
            **{f"{z}-right": (f"right-front-{z}", f"right-back-{z}") for z in ("bottom", "top")},
            **{f"{y}-{x}": (f"{x}-{y}-bottom", f"{x}-{y}-top")
               for y in ("front", "back") for x in ("left", "right")},
        },
        "faces": [
            ("left-front-bottom", "right-front-bottom", "right-back-bottom", "left-back-bottom"),
            ("left-front-top", "right-front-top", "right-back-top", "left-back-top"),
            ("left-front-bottom", "right-front-bottom", "right-front-top", "left-front-top"),
            ("left-back-bottom", "right-back-bottom", "right-back-top", "left-back-top"),
            ("left-front-bottom", "left-back-bottom", "left-back-top", "left-front-top"),
            ("right-front-bottom", "right-back-bottom", "right-back-top", "right-front-top"),
        ],
    },
    "wedge": {
        "vertices": {**{f"{k}-bottom": v for k, v in _BASE_V.items()},
                     "ridge-left": (-0.5, 0.0, 1.0), "ridge-right": (0.5, 0.0, 1.0)},
        "edges": {
            "bottom-front": ("left-front-bottom", "right-front-bottom"),
            "bottom-back": ("left-back-bottom", "right-back-bottom"),
            "bottom-left": ("left-front-bottom", "left-back-bottom"),
            "bottom-right": ("right-front-bottom", "right-back-bottom"),
            "ridge": ("ridge-left", "ridge-right"),
            **{f"rake-{y}-{x}": (f"{x}-{y}-bottom", f"ridge-{x}")
               for y in ("front", "back") for x in ("left", "right")},
        },
        "faces": [
            ("left-front-bottom", "right-front-bottom", "right-back-bottom", "left-back-bottom"),
            ("left-front-bottom", "right-front-bottom", "ridge-right", "ridge-left"),
            ("left-back-bottom", "right-back-bottom", "ridge-right", "ridge-left"),
            ("left-front-bottom", "left-back-bottom", "ridge-left"),
            ("right-front-bottom", "right-back-bottom", "ridge-right"),
        ],
    },
    "pyramid": {
        "vertices": {**{f"{k}-bottom": v for k, v in _BASE_V.items()}, "apex": (0.0, 0.0, 1.0)},
        "edges": {
            "bottom-front": ("left-front-bottom", "right-front-bottom"),
            "bottom-back": ("left-back-bottom", "right-back-bottom"),
            "bottom-left": ("left-front-bottom", "left-back-bottom"),
            "bottom-right": ("right-front-bottom", "right-back-bottom"),
            **{f"hip-{y}-{x}": (f"{x}-{y}-bottom", "apex")
               for y in ("front", "back") for x in ("left", "right")},
        },
        "faces": [
            ("left-front-bottom", "right-front-bottom", "right-back-bottom", "left-back-bottom"),
            ("left-front-bottom", "right-front-bottom", "apex"),
            ("right-front-bottom", "right-back-bottom", "apex"),
            ("right-back-bottom", "left-back-bottom", "apex"),
            ("left-back-bottom", "left-front-bottom", "apex"),
        ],
    },
}

KINDS = (*_KINDS, "extrusion")
AXES = ("z", "y", "x")
# extrusion axis -> (world rows of the polygon's u, v; row of the axis; its length parameter)
_EXTRUDE = {"z": ((0, 1), 2, "height"), "y": ((0, 2), 1, "depth"), "x": ((1, 2), 0, "width")}
UNIT_SLOT = "1"  # a hidden fixed slot of value 1: the polygon's constant terms multiply it
PLACE_Z = ("top", "base", "offset")
PLACE_X = ("centre", "left", "right", "offset")
PLACE_Y = ("centre", "front", "back", "offset")


def _oriented_triangles(kind: str) -> list[tuple[str, str, str]]:
    """The kind's faces as triangles, counter-clockwise seen from outside
    (each block is convex: a normal pointing towards the centroid is flipped,
    so the table above need not get the winding right by hand)."""
    spec = _KINDS[kind]
    V = {k: np.array(v) for k, v in spec["vertices"].items()}
    centre = np.mean(list(V.values()), axis=0)
    tris = []
    for face in spec["faces"]:
        p = [V[n] for n in face]
        nrm = np.cross(p[1] - p[0], p[2] - p[0])
        if np.dot(nrm, np.mean(p, axis=0) - centre) < 0:
            face = face[::-1]
        tris += [(face[0], face[i], face[i + 1]) for i in range(1, len(face) - 1)]
    return tris


_TRIANGLES = {k: _oriented_triangles(k) for k in _KINDS}


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh of the model.

    vertices : (N, 3) float64, world coordinates; faces : (M, 3) int64 vertex
    indices, counter-clockwise seen from outside (outward normals);
    face_block : (M,) str, the block each face belongs to."""

    vertices: np.ndarray
    faces: np.ndarray
    face_block: np.ndarray


@dataclass(frozen=True)
class Block:
    """One block: ``params`` maps each parameter to its spec as written
    (a number, ``{"value", "fixed"}`` or ``{"same_as"}``)."""

    name: str
    kind: str
    params: dict
    parent: str | None = None
    on: str = "top"
    x: str = "centre"
    y: str = "centre"
    axis: str = "z"          # extrusion only: the axis it is extruded along
    polygon: tuple = ()      # extrusion only: ((u, v), …) as written (numbers / expressions)

    @cached_property
    def coordinates(self) -> tuple:
        """An extrusion's polygon parsed: ``((const, {param: coef}) × 2, …)``."""
        return tuple(tuple(parse_coordinate(c) for c in v) for v in self.polygon)

    @property
    def length_parameter(self) -> str:
        return _EXTRUDE[self.axis][2]


@dataclass(frozen=True)
class BlockModel:
    """A block model (see the module docstring). Build with
    :meth:`from_dict` / :func:`load_blocks`; ``values`` holds the current value
    of every parameter slot (the starting values as read, or the fitted ones
    after :meth:`with_values`)."""

    blocks: tuple[Block, ...]
    globals: dict = field(default_factory=dict)
    where: str = "blocks.json"

    # ------------------------------------------------------------- reading
    @classmethod
    def from_dict(cls, d: dict, *, where: str | os.PathLike = "blocks.json") -> BlockModel:
        """A model from its ``blocks.json`` layout; :class:`InputError`
        (``where``, one line naming the entry) on an unknown kind or parent, a
        cycle, a missing or unknown parameter, an unknown shared reference."""
        from lumigraph.capture.schema import check, fail, require, require_object, shown

        where = os.fspath(where)
        raw = require(d, "blocks", "list", path=where, min_length=1)
        blocks = []
        for i, b in enumerate(raw):
            key = f"blocks[{i}]"
            require_object(b, path=where, where=key, what="a block (name, kind, params)",
                           keys=("name", "kind", "params"))
            name = require(b, "name", "string", path=where, where=key)
            if "/" in name:
                raise fail(where, f"{key}.name", f"block name {name!r} may not contain '/'")
            kind = require(b, "kind", "string", path=where, where=key)
            if kind not in KINDS:
                raise fail(where, f"{key}.kind", f"block {name!r}: unknown kind {kind!r}; "
                                                  f"expected one of {', '.join(KINDS)}")
            params = check(b["params"], "object", path=where, key=f"{key}.params")
            parent = require(b, "parent", "string", path=where, where=key, default=None)
            on = require(b, "on", "string", path=where, where=key, default="top")
            px = require(b, "x", "string", path=where, where=key, default="centre")
            py = require(b, "y", "string", path=where, where=key, default="centre")
            for k, v, allowed in (("on", on, PLACE_Z), ("x", px, PLACE_X), ("y", py, PLACE_Y)):
                if v not in allowed:
                    raise fail(where, f"{key}.{k}", f"block {name!r}: unknown placement {v!r}; "
                                                    f"expected one of {', '.join(allowed)}")
            axis, poly = "z", ()
            if kind == "extrusion":
                axis = require(b, "axis", "string", path=where, where=key, default="z")
                if axis not in AXES:
                    raise fail(where, f"{key}.axis", f"block {name!r}: unknown axis {axis!r}; "
                                                     f"expected one of {', '.join(AXES)}")
                raw_poly = require(b, "polygon", "list", path=where, where=key)
                if len(raw_poly) < 3:
                    raise fail(where, f"{key}.polygon", f"block {name!r}: a polygon needs at "
                                                        f"least 3 vertices, got {len(raw_poly)}")
                for j, v in enumerate(raw_poly):
                    if not (isinstance(v, list) and len(v) == 2):
                        raise fail(where, f"{key}.polygon[{j}]", f"block {name!r}: expected a "
                                                                 f"vertex [u, v], got {shown(v)}")
                    for c in v:
                        try:
                            parse_coordinate(c)
                        except ValueError as err:
                            raise fail(where, f"{key}.polygon[{j}]",
                                       f"block {name!r}: {err}") from None
                poly = tuple(tuple(v) for v in raw_poly)
            else:
                for k in ("axis", "polygon"):
                    if k in b:
                        raise fail(where, f"{key}.{k}", f"block {name!r}: {k!r} belongs to an "
                                                        f"extrusion, not a {kind}")
            blocks.append(Block(name, kind, dict(params), parent, on, px, py, axis, poly))
        gl = d.get("parameters", {})
        check(gl, "object", path=where, key="parameters")
        for g, spec in gl.items():
            if "/" in g:
                raise fail(where, f"parameters.{g}", "a global parameter's name may not contain "
                                                     "'/' (that is a block parameter's name)")
            if isinstance(spec, dict) and "same_as" in spec:
                raise fail(where, f"parameters.{g}", "a global parameter holds a value, not "
                                                     "a 'same_as' reference")
        model = cls(tuple(blocks), dict(gl), where)
        model._check(fail, shown)
        return model

    def _check(self, fail, shown) -> None:
        names = [b.name for b in self.blocks]
        seen = set()
        for i, n in enumerate(names):
            if n in seen:
                raise fail(self.where, f"blocks[{i}].name", f"block name {n!r} used twice")
            seen.add(n)
        by = {b.name: b for b in self.blocks}
        roots = [b.name for b in self.blocks if b.parent is None]
        for i, b in enumerate(self.blocks):
            if b.parent is not None and b.parent not in by:
                raise fail(self.where, f"blocks[{i}].parent",
                           f"block {b.name!r}: unknown parent {b.parent!r}")
        for i, b in enumerate(self.blocks):
            chain, p = [b.name], b.parent
            while p is not None:
                if p in chain:
                    raise fail(self.where, f"blocks[{i}].parent",
                               f"block {b.name!r}: cycle in the hierarchy "
                               f"({' -> '.join([*chain, p])})")
                chain.append(p)
                p = by[p].parent
        if len(roots) != 1:
            raise fail(self.where, "blocks", f"expected exactly one root block (without a "
                                             f"parent), got {len(roots)}: {roots}")
        for i, b in enumerate(self.blocks):
            need, optional = set(DIMENSIONS), set()
            if b.kind == "extrusion":
                need = {b.length_parameter} | {n for v in b.coordinates for _, t in v for n in t}
                optional = set(DIMENSIONS) - need
            if b.parent is not None:
                need |= {f"offset_{a}" for a, v in (("x", b.x), ("y", b.y), ("z", b.on))
                         if v == "offset"}
            elif (b.on, b.x, b.y) != ("top", "centre", "centre"):
                raise fail(self.where, f"blocks[{i}]", f"root block {b.name!r} has no parent to "
                                                       "be placed against (it fixes the world frame)")
            for p in sorted(need - set(b.params)):
                raise fail(self.where, f"blocks[{i}].params",
                           f"block {b.name!r}: missing parameter {p!r}")
            for p in sorted(set(b.params) - need - optional):
                raise fail(self.where, f"blocks[{i}].params.{p}",
                           f"block {b.name!r}: unknown parameter {p!r} for "
                           f"{'an' if b.kind[0] in 'aeiou' else 'a'} {b.kind} placed "
                           f"this way; expected {', '.join(sorted(need))}")
            if b.parent is not None:
                # a placement against the parent uses its dimensions (an extrusion may lack them)
                uses = [(b.name, "width", b.x in ("left", "right")),
                        (b.parent, "width", b.x in ("left", "right")),
                        (b.name, "depth", b.y in ("front", "back")),
                        (b.parent, "depth", b.y in ("front", "back")),
                        (b.parent, "height", b.on == "top")]
                for owner, dim, used in uses:
                    if used and dim not in by[owner].params:
                        raise fail(self.where, f"blocks[{i}]",
                                   f"block {b.name!r}: its placement (on={b.on}, x={b.x}, y={b.y}) "
                                   f"needs a parameter {dim!r} of the extrusion {owner!r}: add one "
                                   "or place it with an offset")
            for p, spec in b.params.items():
                self._check_spec(spec, f"blocks[{i}].params.{p}", fail, shown)
        for g, spec in self.globals.items():
            self._check_spec(spec, f"parameters.{g}", fail, shown)
        _ = self._slots  # resolves every reference (unknown, cycles)
        for i, b in enumerate(self.blocks):
            if b.kind == "extrusion":
                bad = crossing_edges(self._polygon(b))
                if bad is not None:
                    what = (f"its edge {bad[0]} has zero length" if bad[0] == bad[1] else
                            f"its edges {bad[0]} and {bad[1]} touch or cross")
                    raise fail(self.where, f"blocks[{i}].polygon",
                               f"block {b.name!r}: the polygon is not simple at the starting "
                               f"values ({what}); list its vertices in order around it, without "
                               "crossings")

    def _polygon(self, b: Block, params=None) -> np.ndarray:
        """An extrusion's polygon ``(n, 2)`` at the values ``params``."""
        v = self.slot_vector(params)
        index = self._slots[3]
        return np.array([[c + sum(k * v[index[f"{b.name}/{n}"]] for n, k in t.items())
                          for c, t in vert] for vert in b.coordinates])

    def _check_spec(self, spec, key, fail, shown) -> None:
        ok = isinstance(spec, (int, float)) and not isinstance(spec, bool)
        if isinstance(spec, dict):
            if "same_as" in spec:
                ok = set(spec) == {"same_as"} and isinstance(spec["same_as"], str)
            else:
                ok = ("value" in spec and set(spec) <= {"value", "fixed"}
                      and isinstance(spec["value"], (int, float))
                      and not isinstance(spec["value"], bool)
                      and isinstance(spec.get("fixed", False), bool))
        if not ok:
            raise fail(self.where, key, f"expected a number, {{\"value\": v, \"fixed\": true}} "
                                        f"or {{\"same_as\": \"block/param\"}}, got {shown(spec)}")
        if not isinstance(spec, dict) or "same_as" not in spec:
            v = float(spec["value"] if isinstance(spec, dict) else spec)
            if not np.isfinite(v):
                raise fail(self.where, key, f"expected a finite number, got {v}")

    # ------------------------------------------------------------- slots
    @cached_property
    def _slots(self) -> tuple[list[str], np.ndarray, np.ndarray, dict[str, int]]:
        """(slot names, values, fixed mask, every parameter name -> slot)."""
        from lumigraph.capture.schema import fail

        specs: dict[str, tuple[object, str]] = {}
        for i, b in enumerate(self.blocks):
            for p, s in b.params.items():
                specs[f"{b.name}/{p}"] = (s, f"blocks[{i}].params.{p}")
        for g, s in self.globals.items():
            specs[g] = (s, f"parameters.{g}")
        names, values, fixed, index = [], [], [], {}

        def resolve(name, trail):
            if name in index:
                return index[name]
            spec, key = specs[name]
            if isinstance(spec, dict) and "same_as" in spec:
                target = spec["same_as"]
                if target not in specs:
                    raise fail(self.where, key, f"parameter {name!r}: unknown shared reference "
                                                f"{target!r}; expected a block/param or a "
                                                "global parameter's name")
                if target in trail:
                    raise fail(self.where, key, f"parameter {name!r}: circular 'same_as' "
                                                f"({' -> '.join([*trail, target])})")
                index[name] = resolve(target, [*trail, target])
                return index[name]
            v = float(spec["value"] if isinstance(spec, dict) else spec)
            index[name] = len(names)
            names.append(name)
            values.append(v)
            fixed.append(bool(spec.get("fixed", False)) if isinstance(spec, dict) else False)
            return index[name]

        for n in specs:
            resolve(n, [n])
        if any(c != 0 for b in self.blocks for v in b.coordinates for c, _ in v):
            # not in ``index``: no parameter name reaches it, it is never fitted or reported
            names.append(UNIT_SLOT)
            values.append(1.0)
            fixed.append(True)
        return names, np.array(values, float), np.array(fixed, bool), index

    @property
    def slot_names(self) -> tuple[str, ...]:
        """Every independent parameter (free and fixed), in slot order (with
        :data:`UNIT_SLOT`, fixed at 1, last when an extrusion's polygon has a
        constant term)."""
        return tuple(self._slots[0])

    @property
    def values(self) -> np.ndarray:
        """The current value of every slot, ``(S,)``."""
        return self._slots[1].copy()

    @property
    def fixed(self) -> np.ndarray:
        return self._slots[2].copy()

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The free parameters' names (the solver's unknowns), in slot order."""
        names, _, fixed, _ = self._slots
        return tuple(n for n, f in zip(names, fixed, strict=True) if not f)

    @property
    def all_parameter_names(self) -> tuple[str, ...]:
        """Every parameter's name, shared and fixed ones included."""
        return tuple(self._slots[3])

    def slot_of(self, name: str) -> int:
        """The slot a parameter name (possibly shared) resolves to."""
        return self._slots[3][name]

    def slot_vector(self, params=None) -> np.ndarray:
        """All slot values ``(S,)`` from ``params``: None (the current values),
        an array of the free parameters in :attr:`parameter_names` order, or a
        mapping of names (free ones; others keep their current values)."""
        v = self.values
        if params is None:
            return v
        free = ~self.fixed
        if isinstance(params, Mapping):
            for k, x in params.items():
                if k not in self._slots[3]:
                    raise InputError("params", f"unknown parameter {k!r}")
                v[self.slot_of(k)] = float(x)
            return v
        p = np.asarray(params, float).ravel()
        if p.size != int(free.sum()):
            raise InputError("params", f"expected {int(free.sum())} free parameter values "
                                       f"({', '.join(self.parameter_names)}), got {p.size}")
        v[free] = p
        return v

    def named_values(self, params=None) -> dict[str, float]:
        """Every parameter name (shared ones included) -> value."""
        v = self.slot_vector(params)
        return {n: float(v[s]) for n, s in self._slots[3].items()}

    def with_values(self, params) -> BlockModel:
        """The same model with the slot values of ``params`` as its values
        (shared references and fixed flags kept)."""
        v = self.slot_vector(params)
        names = self._slots[0]

        def upd(spec, name):
            if isinstance(spec, dict) and "same_as" in spec:
                return spec
            val = float(v[names.index(name)])
            return {"value": val, "fixed": True} if isinstance(spec, dict) and spec.get(
                "fixed") else val

        blocks = tuple(dc_replace(b, params={p: upd(s, f"{b.name}/{p}") for p, s in b.params.items()})
                       for b in self.blocks)
        gl = {g: upd(s, g) for g, s in self.globals.items()}
        return BlockModel(blocks, gl, self.where)

    def with_fixed(self, names) -> BlockModel:
        """The same model with the parameters ``names`` (slot names) held at
        their current values."""
        names = set(names)

        def upd(spec, name):
            if name not in names or (isinstance(spec, dict) and "same_as" in spec):
                return spec
            return {"value": float(spec["value"] if isinstance(spec, dict) else spec), "fixed": True}

        blocks = tuple(dc_replace(b, params={p: upd(s, f"{b.name}/{p}") for p, s in b.params.items()})
                       for b in self.blocks)
        return BlockModel(blocks, {g: upd(s, g) for g, s in self.globals.items()}, self.where)

    def to_dict(self) -> dict:
        """The ``blocks.json`` layout (:meth:`from_dict` reads it back)."""
        out = []
        for b in self.blocks:
            e = {"name": b.name, "kind": b.kind}
            if b.parent is not None:
                e.update(parent=b.parent, on=b.on, x=b.x, y=b.y)
            if b.kind == "extrusion":
                e.update(axis=b.axis, polygon=[list(v) for v in b.polygon])
            e["params"] = dict(b.params)
            out.append(e)
        d = {"schema": BLOCKS_SCHEMA, "schema_version": 1, "blocks": out}
        if self.globals:
            d["parameters"] = dict(self.globals)
        return d

    # ------------------------------------------------------------- geometry
    @cached_property
    def _linear(self) -> tuple[list[str], np.ndarray, dict[str, tuple[int, int]]]:
        """Vertex names ``block/vertex``, their ``(N, 3, S)`` coefficient
        matrices (world vertex = ``C @ slots``), and edge name -> vertex
        indices."""
        S = len(self._slots[0])
        by = {b.name: b for b in self.blocks}

        def e(name):
            row = np.zeros(S)
            row[self.slot_of(name)] = 1.0
            return row

        origin: dict[str, np.ndarray] = {}

        def base(b):  # (3, S): the block's base centre in world coordinates
            if b.name in origin:
                return origin[b.name]
            o = np.zeros((3, S))
            if b.parent is not None:
                p = by[b.parent]
                o = base(p).copy()
                # only the dimensions a placement uses (an extrusion may lack the others)
                if b.x in ("left", "right"):
                    half = (e(f"{p.name}/width") - e(f"{b.name}/width")) / 2
                    o[0] += half if b.x == "right" else -half
                elif b.x == "offset":
                    o[0] += e(f"{b.name}/offset_x")
                if b.y in ("front", "back"):
                    half = (e(f"{p.name}/depth") - e(f"{b.name}/depth")) / 2
                    o[1] += half if b.y == "back" else -half
                elif b.y == "offset":
                    o[1] += e(f"{b.name}/offset_y")
                if b.on == "top":
                    o[2] += e(f"{p.name}/height")
                elif b.on == "offset":
                    o[2] += e(f"{b.name}/offset_z")
            origin[b.name] = o
            return o

        def unit():
            row = np.zeros(S)
            row[self._slots[0].index(UNIT_SLOT)] = 1.0
            return row

        names, C, edges = [], [], {}
        for b in self.blocks:
            o = base(b)
            local = {}
            if b.kind == "extrusion":
                (ru, rv), ra, length = _EXTRUDE[b.axis]
                L = e(f"{b.name}/{length}")
                # the vertical extrusion stands on the base; a horizontal one is centred on it
                ends = (0 * L, L) if b.axis == "z" else (-L / 2, L / 2)
                n = len(b.polygon)
                for cap, end in zip(("bottom", "top"), ends, strict=True):
                    for j, vert in enumerate(b.coordinates):
                        row = o.copy()
                        for r, (c, t) in zip((ru, rv), vert, strict=True):
                            if c != 0:
                                row[r] += c * unit()
                            for pn, k in t.items():
                                row[r] += k * e(f"{b.name}/{pn}")
                        row[ra] += end
                        local[f"{cap}-{j}"] = len(names)
                        names.append(f"{b.name}/{cap}-{j}")
                        C.append(row)
                for j in range(n):
                    for cap in ("bottom", "top"):
                        edges[f"{b.name}/{cap}-{j}"] = (local[f"{cap}-{j}"],
                                                        local[f"{cap}-{(j + 1) % n}"])
                    edges[f"{b.name}/side-{j}"] = (local[f"bottom-{j}"], local[f"top-{j}"])
                continue
            dims = np.stack([e(f"{b.name}/{d}") for d in DIMENSIONS])
            spec = _KINDS[b.kind]
            for vn, a in spec["vertices"].items():
                local[vn] = len(names)
                names.append(f"{b.name}/{vn}")
                C.append(o + np.asarray(a)[:, None] * dims)
            for en, (v0, v1) in spec["edges"].items():
                edges[f"{b.name}/{en}"] = (local[v0], local[v1])
        return names, np.array(C), edges

    @property
    def edge_names(self) -> tuple[str, ...]:
        return tuple(self._linear[2])

    def vertices(self, params=None) -> np.ndarray:
        """World vertices ``(N, 3)`` (order of :meth:`mesh`)."""
        return self._linear[1] @ self.slot_vector(params)

    def edge_matrices(self, names=None) -> tuple[np.ndarray, np.ndarray]:
        """``(C0, C1)``, each ``(E, 3, S)``: the edges' endpoints are
        ``C0 @ slots`` and ``C1 @ slots`` (linear in the parameters; the
        derivative with respect to the free ones is ``C[..., ~fixed]``)."""
        _, C, edges = self._linear
        names = self.edge_names if names is None else names
        idx = np.array([edges[n] for n in names], int).reshape(-1, 2)
        return C[idx[:, 0]], C[idx[:, 1]]

    def edges(self, params=None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Every block edge's world endpoints ``name -> (p0 (3,), p1 (3,))``."""
        V = self.vertices(params)
        return {n: (V[i], V[j]) for n, (i, j) in self._linear[2].items()}

    def mesh(self, params=None) -> Mesh:
        """The model as one triangle mesh (blocks are not merged: a face hidden
        inside another block stays)."""
        names = self._linear[0]
        index = {n: i for i, n in enumerate(names)}
        V = self.vertices(params)
        faces, owner = [], []
        for b in self.blocks:
            tris = (self._extrusion_triangles(b, V, index, params) if b.kind == "extrusion" else
                    [[index[f"{b.name}/{v}"] for v in t] for t in _TRIANGLES[b.kind]])
            faces += tris
            owner += [b.name] * len(tris)
        return Mesh(V, np.array(faces, np.int64).reshape(-1, 3), np.array(owner))

    def _extrusion_triangles(self, b: Block, V, index, params) -> list[list[int]]:
        """An extrusion's faces at the given values: the caps by ear
        clipping (the polygon's shape may change with the values, so the
        triangulation is made for them), the sides as two triangles each;
        every triangle turned to face outwards."""
        P = self._polygon(b, params)
        try:
            cap = triangulate(P)
        except ValueError:
            raise EstimationError(self.where, f"block {b.name!r}: its polygon crosses itself at "
                                  "these parameter values (no mesh)") from None
        n = len(P)
        bot = [index[f"{b.name}/bottom-{j}"] for j in range(n)]
        top = [index[f"{b.name}/top-{j}"] for j in range(n)]
        axis = np.zeros(3)
        axis[_EXTRUDE[b.axis][1]] = 1.0
        (ru, rv), _, _ = _EXTRUDE[b.axis]
        ccw = 1.0 if signed_area(P) >= 0 else -1.0
        out = []

        def add(tri, outward):
            a, c, d = V[tri[0]], V[tri[1]], V[tri[2]]
            if np.dot(np.cross(c - a, d - a), outward) < 0:
                tri = [tri[0], tri[2], tri[1]]
            out.append(tri)

        for t in cap:
            add([bot[k] for k in t], -axis)
            add([top[k] for k in t], axis)
        for j in range(n):
            k = (j + 1) % n
            du, dv = P[k] - P[j]
            outward = np.zeros(3)
            outward[ru], outward[rv] = ccw * dv, -ccw * du
            add([bot[j], bot[k], top[k]], outward)
            add([bot[j], top[k], top[j]], outward)
        return out


def load_blocks(path: str | os.PathLike) -> BlockModel:
    """Read ``blocks.json`` (see the module docstring for its layout)."""
    from lumigraph.capture.artifact import load_json_artifact

    body = load_json_artifact(path, "block model", schemas=(BLOCKS_SCHEMA,))
    return BlockModel.from_dict(body, where=path)


def save_blocks(path: str | os.PathLike, model: BlockModel) -> None:
    from lumigraph.capture.artifact import save_json_artifact

    save_json_artifact(path, model.to_dict())
