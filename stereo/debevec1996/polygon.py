"""Planar polygons of the Façade ``extrusion`` block: the coordinate
expressions of ``blocks.json``, the simplicity test and the cap
triangulation.

A polygon vertex coordinate is a number (a constant, in the model's unit) or
a linear expression of the block's own parameters, e.g. ``"0.5*width"``,
``"-half"``, ``"wall + 0.25"``: a sum of terms, each a number, a parameter
name, or ``number*name``. Linear expressions keep every model vertex linear
in the parameters (the solver's derivatives stay constant matrices, eq. 5.5
stays linear).

The cap is triangulated by ear clipping (O(n²) per ear search; polygons of a
building are a handful of vertices), which works for convex and simple
non-convex polygons; a self-intersecting polygon has no consistent inside
and is refused by :func:`crossing_edges` before that.

Examples
--------
>>> parse_coordinate("0.5*width - 2")
(-2.0, {'width': 0.5})
>>> L = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float)   # an L
>>> signed_area(L), crossing_edges(L)
(3.0, None)
>>> tris = triangulate(L)
>>> len(tris), sum(signed_area(L[list(t)]) for t in tris)
(4, 3.0)
>>> crossing_edges(np.array([[0, 0], [1, 1], [1, 0], [0, 1]], float))   # a bow tie
(0, 2)
"""

from __future__ import annotations

import re

import numpy as np

_NUMBER = r"(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_NAME = r"[A-Za-z_][A-Za-z0-9_]*"
_TERM = re.compile(rf"\s*([+-])?\s*(?:({_NUMBER})\s*(\*)?\s*)?({_NAME})?\s*")


def parse_coordinate(spec) -> tuple[float, dict[str, float]]:
    """``(constant, {parameter: coefficient})`` of one coordinate: a number,
    or a linear expression string (module docstring). :class:`ValueError`
    with a message saying what is wrong otherwise."""
    if isinstance(spec, bool) or not isinstance(spec, (int, float, str)):
        raise ValueError("expected a number or an expression such as \"0.5*width\"")
    if not isinstance(spec, str):
        if not np.isfinite(spec):
            raise ValueError(f"expected a finite number, got {spec}")
        return float(spec), {}
    const, terms, pos, first = 0.0, {}, 0, True
    while pos < len(spec):
        m = _TERM.match(spec, pos)
        sign, num, star, name = m.groups()
        if m.end() == pos or (num is None and name is None) or (star and name is None) \
                or (num is not None and name is not None and not star) \
                or (sign is None and not first):
            raise ValueError(f"cannot read the expression {spec!r}: expected terms like "
                             "\"0.5*width\", \"-depth\" or \"0.25\" joined by + or -")
        k = (-1.0 if sign == "-" else 1.0) * (float(num) if num is not None else 1.0)
        if name is None:
            const += k
        else:
            terms[name] = terms.get(name, 0.0) + k
        pos, first = m.end(), False
    if first:
        raise ValueError("empty expression")
    return const, terms


def signed_area(P: np.ndarray) -> float:
    """Shoelace area of the polygon ``P`` (n, 2): positive when its vertices
    run counter-clockwise (u to the right, v up)."""
    P = np.asarray(P, float)
    x, y = P[:, 0], P[:, 1]
    return float(0.5 * (x @ np.roll(y, -1) - y @ np.roll(x, -1)))


def _cross(o, a, b) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


def _segments_meet(p, q, r, s, eps) -> bool:
    """Whether closed segments pq and rs share a point (collinear overlaps
    included)."""
    d1, d2 = _cross(r, s, p), _cross(r, s, q)
    d3, d4 = _cross(p, q, r), _cross(p, q, s)
    if ((d1 > eps and d2 < -eps) or (d1 < -eps and d2 > eps)) and \
            ((d3 > eps and d4 < -eps) or (d3 < -eps and d4 > eps)):
        return True

    def on(a, b, c, d):  # c on segment ab, given collinear
        return abs(d) <= eps and min(a[0], b[0]) - eps <= c[0] <= max(a[0], b[0]) + eps \
            and min(a[1], b[1]) - eps <= c[1] <= max(a[1], b[1]) + eps

    return on(r, s, p, d1) or on(r, s, q, d2) or on(p, q, r, d3) or on(p, q, s, d4)


def crossing_edges(P: np.ndarray) -> tuple[int, int] | None:
    """The first pair of polygon edges ``(i, j)`` (edge ``i`` joins vertices
    ``i`` and ``i + 1``) that touch or cross although they are not
    neighbours, or ``(i, i)`` for an edge of zero length; None for a simple
    polygon. Tolerance: 1e-12 of the polygon's squared extent."""
    P = np.asarray(P, float)
    n = len(P)
    ext = float(np.ptp(P, axis=0).max()) if n else 0.0
    eps = 1e-12 * max(ext, 1e-300) ** 2
    for i in range(n):
        if np.sum((P[(i + 1) % n] - P[i]) ** 2) <= eps:
            return (i, i)
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue  # neighbours through the closing vertex
            if _segments_meet(P[i], P[(i + 1) % n], P[j], P[(j + 1) % n], eps):
                return (i, j)
    return None


def triangulate(P: np.ndarray) -> list[tuple[int, int, int]]:
    """Ear-clipping triangulation of a simple polygon ``P`` (n, 2), either
    orientation: ``n − 2`` vertex-index triangles, each with the polygon's
    own orientation (their signed areas add up to the polygon's).
    :class:`ValueError` when no ear is found (a self-intersecting or
    degenerate polygon)."""
    P = np.asarray(P, float)
    sgn = 1.0 if signed_area(P) >= 0 else -1.0
    idx = list(range(len(P)))
    out = []
    ext = float(np.ptp(P, axis=0).max()) if len(P) else 0.0
    eps = 1e-12 * max(ext, 1e-300) ** 2
    while len(idx) > 3:
        for k in range(len(idx)):
            a, b, c = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            if sgn * _cross(P[a], P[b], P[c]) <= eps:
                continue  # reflex or flat corner: not an ear
            inside = False
            for o in idx:
                if o in (a, b, c):
                    continue
                if (sgn * _cross(P[a], P[b], P[o]) >= -eps and sgn * _cross(P[b], P[c], P[o]) >= -eps
                        and sgn * _cross(P[c], P[a], P[o]) >= -eps):
                    inside = True
                    break
            if not inside:
                out.append((a, b, c))
                del idx[k]
                break
        else:
            raise ValueError("no ear found: the polygon is not simple")
    out.append(tuple(idx))
    return out
