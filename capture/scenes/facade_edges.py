"""Ground truth for Façade's photogrammetric modelling without images: the
model edges a set of cameras sees, as marked 2-D segments.

Given a block model (any object with ``edges(params)``, ``mesh(params)`` and
``named_values(params)``, i.e. :class:`lumigraph.stereo.debevec1996.BlockModel`;
this module sits on the ground floor and does not import it), the true
parameters and true cameras (``K``, ``R``, ``t``, ``image_size``; pose
``x_cam = R x_world + t``, pixels with the OpenCV convention), every model
edge is projected into every camera and kept where it is visible:

- sample points along the edge (``samples``, edge ends excluded) are tested
  for occlusion by the model's own triangles (a ray to the camera centre),
  in front of the camera and inside the frame; the marked segment is the
  projection of the stretch between the first and last visible sample (a
  user marks the part they see: any stretch of the line serves the solver);
- edges of no projected length worth marking (< ``min_length_px``) and
  repeats of an edge already marked (two blocks sharing a line) are left out.

Visibility is approximate (samples, not exact clipping); the renderer of
``lumigraph render facade`` can pass its own visibility test.

Examples
--------
>>> class Box:  # a 2 x 2 x 2 box standing on the ground, as a BlockModel would give it
...     V = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (0, 2)], float)
...     def edges(self, params=None):
...         return {"box/top-front": (self.V[1], self.V[5]), "box/front-left": (self.V[0], self.V[1])}
...     def mesh(self, params=None):
...         return None
...     def named_values(self, params=None):
...         return {"box/width": 2.0}
>>> R, t = look_at([0, -10, 1], [0, 0, 1])
>>> cams = {"a.png": {"K": [[100, 0, 50], [0, 100, 40], [0, 0, 1]], "R": R, "t": t,
...                   "image_size": [100, 80]}}
>>> marks = project_edges(Box(), cams)
>>> [(m["edge"], [round(v, 3) for v in m["segment"]]) for m in marks["a.png"]]
[('box/top-front', [40.0, 28.889, 60.0, 28.889]), ('box/front-left', [38.889, 50.0, 38.889, 30.0])]
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

EDGES_SCHEMA = "lumigraph.facade.edges"
GT_SCHEMA = "lumigraph.gt"


def look_at(centre, target, up=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """The pose ``(R, t)`` (``x_cam = R x + t``; camera ``z`` forward, ``y``
    down) of a camera at ``centre`` looking at ``target``, world ``up``."""
    c, g = np.asarray(centre, float), np.asarray(target, float)
    z = g - c
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ c


def ring_cameras(n: int, *, target, radius: float, height: float, focal_px: float,
                 image_size=(640, 480), arc_deg: tuple[float, float] = (-150.0, -30.0),
                 rng: np.random.Generator | None = None, jitter: float = 0.0) -> dict[str, dict]:
    """``n`` cameras on an arc around ``target`` (angles in degrees about
    ``z``, −90 = in front, on the −y side), each looking at it, named
    ``photo_00.png``…; ``jitter`` moves each centre by up to that fraction of
    ``radius`` and its aim point likewise (with ``rng``)."""
    rng = rng or np.random.default_rng(0)
    w, h = image_size
    K = np.array([[focal_px, 0, (w - 1) / 2], [0, focal_px, (h - 1) / 2], [0, 0, 1]])
    out = {}
    tg = np.asarray(target, float)
    for i, a in enumerate(np.radians(np.linspace(*arc_deg, n))):
        c = tg + np.array([radius * np.cos(a), radius * np.sin(a), height])
        c += jitter * radius * rng.uniform(-1, 1, 3)
        aim = tg + jitter * radius * rng.uniform(-1, 1, 3)
        R, t = look_at(c, aim)
        out[f"photo_{i:02d}.png"] = {"K": K.copy(), "R": R, "t": t, "image_size": [w, h]}
    return out


def _occluded(P: np.ndarray, centre: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Which points ``P`` (K, 3) have a model triangle (T, 3, 3) between them
    and ``centre`` (Möller–Trumbore; hits at the point itself, the faces the
    edge lies on, do not count)."""
    if tris is None or len(tris) == 0:
        return np.zeros(len(P), bool)
    return _hits(P, centre, tris).any(axis=1)


def ray_triangles(O: np.ndarray, d: np.ndarray, tris: np.ndarray):
    """Möller–Trumbore for every ray against every triangle: rays from
    ``O`` ``(K, 3)`` (or one ``(3,)`` origin for all) along ``d`` ``(K,
    3)``, triangles ``tris`` ``(T, 3, 3)``. Returns ``(ok, u, v, tt)``, each
    ``(K, T)``: ``ok`` false where ray and triangle are parallel, ``u, v``
    the barycentric coordinates of the hit, ``tt`` its parameter along
    ``d`` (in units of ``d``'s length)."""
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    # the cross and dot products by components on (K, T) arrays: np.cross
    # and einsum on (K, T, 3) cost twice as much, and this test runs on
    # every sample of every edge in automatic marking's crease scans
    d = np.asarray(d, float)
    dx, dy, dz = d[:, 0, None], d[:, 1, None], d[:, 2, None]
    ex, ey, ez = e2[:, 0], e2[:, 1], e2[:, 2]
    px, py, pz = dy * ez - dz * ey, dz * ex - dx * ez, dx * ey - dy * ex      # d × e2
    det = px * e1[:, 0] + py * e1[:, 1] + pz * e1[:, 2]
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    O = np.asarray(O, float).reshape(-1, 3)
    sx, sy, sz = (O[:, j, None] - v0[:, j] for j in range(3))                 # origin − v0
    u = (sx * px + sy * py + sz * pz) * inv
    ax, ay, az = e1[:, 0], e1[:, 1], e1[:, 2]
    qx, qy, qz = sy * az - sz * ay, sz * ax - sx * az, sx * ay - sy * ax      # s × e1
    v = (dx * qx + dy * qy + dz * qz) * inv
    tt = (qx * ex + qy * ey + qz * ez) * inv
    return ok, u, v, tt


def _hits(P: np.ndarray, centre: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(K, T) bool: triangle t lies between point k and ``centre``
    (:func:`_occluded`'s test, per triangle)."""
    ok, u, v, tt = ray_triangles(P, centre[None, :] - P, tris)   # towards the camera
    eps = 1e-9
    return ok & (u > eps) & (v > eps) & (u + v < 1 - eps) & (tt > 1e-6) & (tt < 1 - 1e-9)


def project_edges(model, cameras: dict[str, dict], *, params=None, noise_px: float = 0.0,
                  rng: np.random.Generator | None = None, min_length_px: float = 8.0,
                  samples: int = 21, occlusion: bool = True, visible=None) -> dict[str, list]:
    """Every visible model edge in every camera, as ``edges.json``'s
    ``photographs`` entry: ``{photo: [{"edge": name, "segment": [x0, y0, x1,
    y1]}, …]}`` (pixels). ``noise_px``: Gaussian noise of that standard
    deviation added to each endpoint coordinate (with ``rng``). ``visible``:
    an optional ``visible(photo, points (K, 3)) -> (K,) bool`` that replaces
    the built-in occlusion test."""
    rng = rng or np.random.default_rng(0)
    edges = model.edges(params)
    tris = None
    if occlusion and visible is None:
        mesh = model.mesh(params)
        if mesh is not None:
            tris = mesh.vertices[mesh.faces]
    s = np.linspace(0.0, 1.0, samples)[1:-1] if samples > 2 else np.array([0.5])
    out: dict[str, list] = {}
    for photo, cam in cameras.items():
        K, R, t = (np.asarray(cam[k], float) for k in ("K", "R", "t"))
        t = t.ravel()
        w, h = cam["image_size"]
        centre = -R.T @ t
        marks, seen = [], set()
        for name, (p0, p1) in edges.items():
            key = tuple(sorted((tuple(np.round(p0, 9)), tuple(np.round(p1, 9)))))
            if key in seen:
                continue
            P = p0[None] + s[:, None] * (p1 - p0)[None]
            Y = P @ R.T + t
            ok = Y[:, 2] > 1e-6
            uv = np.full((len(P), 2), np.nan)
            uv[ok] = (Y[ok] @ K.T)[:, :2] / (Y[ok] @ K.T)[:, 2:]
            ok &= (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
            if visible is not None:
                ok &= np.asarray(visible(photo, P), bool)
            elif tris is not None:
                ok &= ~_occluded(P, centre, tris)
            if ok.sum() < 2:
                continue
            i, j = np.flatnonzero(ok)[[0, -1]]
            a, b = uv[i].copy(), uv[j].copy()
            if np.hypot(*(b - a)) < min_length_px:
                continue
            if noise_px > 0:
                a += rng.normal(0, noise_px, 2)
                b += rng.normal(0, noise_px, 2)
            seen.add(key)
            marks.append({"edge": name, "segment": [float(a[0]), float(a[1]),
                                                    float(b[0]), float(b[1])]})
        out[photo] = marks
    return out


def facade_gt(model, cameras: dict[str, dict], *, params=None) -> dict:
    """``gt.json``'s body: ``"parameters": {name: value}`` (every block
    parameter, shared ones included) and ``"cameras": {photo: {K, R, t,
    image_size}}``."""
    cams = {p: {"K": np.asarray(c["K"], float).tolist(), "R": np.asarray(c["R"], float).tolist(),
                "t": np.asarray(c["t"], float).ravel().tolist(),
                "image_size": [int(v) for v in c["image_size"]]} for p, c in cameras.items()}
    return {"schema": GT_SCHEMA, "schema_version": 1, "scene": "facade",
            "parameters": dict(model.named_values(params)), "cameras": cams}


def write_facade_edges(folder: str | os.PathLike, model, cameras: dict[str, dict], *,
                       params=None, noise_px: float = 0.0, rng: np.random.Generator | None = None,
                       **options) -> tuple[Path, Path]:
    """Write ``edges.json`` (the marks, :func:`project_edges` with
    ``options``) and ``gt.json`` (:func:`facade_gt`) into ``folder``."""
    from lumigraph.capture.artifact import save_json_artifact

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    marks = project_edges(model, cameras, params=params, noise_px=noise_px, rng=rng, **options)
    e = save_json_artifact(folder / "edges.json", {"schema": EDGES_SCHEMA, "schema_version": 1,
                                                   "noise_px": noise_px, "photographs": marks})
    g = save_json_artifact(folder / "gt.json", facade_gt(model, cameras, params=params))
    return e, g


def paint_facade(model, cam: dict, *, params=None, noise: float = 1.0, supersample: int = 8,
                 rng: np.random.Generator | None = None) -> np.ndarray:
    """A crude grey photograph of the model for tests of automatic marking:
    flat-shaded faces (a fixed sun, a grey level per block) drawn far to near
    (painter's algorithm: exact for these convex blocks seen from outside,
    approximate where blocks interpenetrate) at ``supersample``² samples per
    pixel and box-filtered (area coverage), over a sky gradient, 8-bit with
    Gaussian noise of ``noise`` codes. Not a renderer: ``lumigraph render
    facade`` draws the real scene.

    A sample is inside a face's triangle when its centre is
    (:func:`_fill_triangle`), so an edge sits where the projection puts it:
    OpenCV's fills, anti-aliased or not, also take samples the boundary only
    touches and grew every face by 0.06–0.12 px at 8 samples a pixel, which
    moved every automatically proposed mark outwards
    (``docs/decisions/facade.md``)."""
    rng = rng or np.random.default_rng(0)
    K, R, t = (np.asarray(cam[k], float) for k in ("K", "R", "t"))
    t = t.ravel()
    w, h = (int(v) for v in cam["image_size"])
    ss = int(supersample)
    img = np.tile(np.linspace(200, 150, h * ss)[:, None], (1, w * ss)).astype(np.float32)
    mesh = model.mesh(params)
    V = mesh.vertices
    Y = V @ R.T + t
    sun = np.array([0.4, -0.7, 0.6])
    sun /= np.linalg.norm(sun)
    blocks = list(dict.fromkeys(mesh.face_block.tolist()))
    depth = Y[mesh.faces][:, :, 2].mean(1)
    for f in np.argsort(-depth):
        tri = mesh.faces[f]
        if np.any(Y[tri, 2] <= 1e-6):
            continue
        n = np.cross(V[tri[1]] - V[tri[0]], V[tri[2]] - V[tri[0]])
        n /= np.linalg.norm(n)
        if np.dot(n, -R.T @ t - V[tri[0]]) <= 0:
            continue                                      # back face
        albedo = 0.55 + 0.35 * (blocks.index(mesh.face_block[f]) % 3) / 2
        level = 25 + 190 * albedo * (0.35 + 0.65 * max(np.dot(n, sun), 0.0))
        uv = Y[tri] @ K.T
        uv = uv[:, :2] / uv[:, 2:]
        _paint_triangle(img, uv, ss, float(level))
    img = img.reshape(h, ss, w, ss).mean(axis=(1, 3), dtype=np.float64)
    out = img + rng.normal(0, noise, img.shape) if noise > 0 else img
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


def _paint_triangle(fine: np.ndarray, uv: np.ndarray, ss: int, level: float) -> None:
    """Paint the triangle ``uv`` ``(3, 2)`` (pixels, centres at integers)
    on the ``ss``-times finer grid ``fine``, whose sample ``(i, j)`` sits at
    ``((j + 0.5) / ss − 0.5, (i + 0.5) / ss − 0.5)`` pixels."""
    _fill_triangle(fine, (np.asarray(uv, float) + 0.5) * ss - 0.5, level)


def _fill_triangle(img: np.ndarray, tri: np.ndarray, level: float) -> None:
    """Set the samples of ``img`` whose centres (integer coordinates, x
    along a row) lie in the triangle ``tri`` ``(3, 2)`` (x, y; a centre on
    its boundary counts) to ``level``: one span per row, from the edges'
    crossings of the row.

    >>> img = np.zeros((4, 6))      # the hypotenuse passes through the centre (3, 1)
    >>> _fill_triangle(img, np.array([[0.5, -0.5], [4.5, -0.5], [0.5, 3.5]]), 1.0)
    >>> img.astype(int).tolist()
    [[0, 1, 1, 1, 1, 0], [0, 1, 1, 1, 0, 0], [0, 1, 1, 0, 0, 0], [0, 1, 0, 0, 0, 0]]
    """
    h, w = img.shape
    y0 = max(int(np.ceil(tri[:, 1].min())), 0)
    y1 = min(int(np.floor(tri[:, 1].max())), h - 1)
    if y1 < y0:
        return
    ys = np.arange(y0, y1 + 1, dtype=float)
    lo = np.full(ys.size, -np.inf)
    hi = np.full(ys.size, np.inf)
    for k in range(3):
        (ax, ay), (bx, by) = tri[k], tri[(k + 1) % 3]
        if ay == by:
            continue
        # x where the edge's line crosses each row; which side is inside
        # follows from the third vertex
        x = ax + (ys - ay) * (bx - ax) / (by - ay)
        cx, cy = tri[(k + 2) % 3]
        xc = ax + (cy - ay) * (bx - ax) / (by - ay)
        if cx >= xc:
            lo = np.maximum(lo, x)
        else:
            hi = np.minimum(hi, x)
    a = np.clip(np.ceil(lo), 0, w).astype(int)
    b = np.clip(np.floor(hi) + 1, 0, w).astype(int)
    for r, (i, j) in enumerate(zip(a.tolist(), b.tolist(), strict=True)):
        if j > i:
            img[y0 + r, i:j] = level


def write_facade_folder(folder: str | os.PathLike, model, cameras: dict[str, dict], *,
                        start=None, params=None, noise_px: float = 0.0, image_noise: float = 1.0,
                        rng: np.random.Generator | None = None) -> Path:
    """A complete input folder for ``lumigraph stereo facade solve``: the
    painted photographs (:func:`paint_facade`), ``stack.json``, the shared
    ``camera.json``, ``blocks.json`` (``start``: a model with the starting
    values, default ``model``), ``edges.json`` and ``gt.json``
    (:func:`write_facade_edges`)."""
    from lumigraph.capture.artifact import save_json_artifact
    from lumigraph.capture.io import write_image

    rng = rng or np.random.default_rng(0)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for photo, cam in cameras.items():
        write_image(folder / photo, paint_facade(model, cam, params=params, noise=image_noise,
                                                 rng=rng))
    first = next(iter(cameras.values()))
    save_json_artifact(folder / "stack.json", {"schema": "lumigraph.stack", "schema_version": 1,
                                               "scene": "facade", "images": list(cameras)})
    save_json_artifact(folder / "camera.json", {
        "schema": "lumigraph.camera", "schema_version": 1,
        "image_size": [int(v) for v in first["image_size"]],
        "K": np.asarray(first["K"], float).tolist(), "dist": [], "model": "none"})
    save_json_artifact(folder / "blocks.json", (start or model).to_dict())
    write_facade_edges(folder, model, cameras, params=params, noise_px=noise_px, rng=rng)
    return folder
