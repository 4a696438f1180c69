"""A building of blocks photographed from around it: ground truth for Façade
(Debevec, Taylor & Malik 1996, doi:10.1145/237170.237191; reference ch. 5,
§5.3.2: photogrammetric modelling, view-dependent texture mapping,
model-based stereo).

``facade``
    A house (box) with a gable roof (wedge), a tower (box) flush with its
    front and a pyramid spire, and a lower wing at the back left, standing on
    a ground plane (not part of the model) under a sky; three pilasters stand
    0.3 m proud of the house front (relief the block model lacks, for
    model-based stereo). Walls are bricks with
    framed glass windows (procedural, in each wall's own coordinates), roofs
    glazed tiles, flat tops gravel. Materials are glossy: Blinn–Phong
    specular under a directional sun plus a Fresnel-weighted reflection of
    the sky (so the windows' appearance depends strongly on the view),
    shaded per pixel from the rasterised position and normal and
    anti-aliased by ``supersample²`` samples per pixel. ``--lambertian``
    drops both view-dependent terms (a diffuse scene).

Files: ``photo_NN.png`` (8-bit, linear codes with read noise), ``stack.json``
(naming the photographs, ``blocks.json`` and ``edges.json``: the folder is an
input of ``lumigraph stereo facade solve`` as it stands), ``camera.json`` (the
photographs' shared intrinsics), ``blocks.json`` (the
model with rough starting values: free parameters off by up to ±15 %, the
house width fixed at its true value, the scale), ``edges.json`` (every
visible model edge's 2-D segment per photograph, from the true model and
cameras; ``--edge-noise`` adds Gaussian endpoint noise), ``cameras/*.json``
(one ``camera.json`` with its ``cam_from_world`` per photograph) and
``novel/view_N.json`` (the novel views' cameras).

Ground truth: ``gt.json`` ``parameters`` (every block parameter, by its
stable name, shared ones too), ``cameras`` (``{photo: {K, R, t,
image_size}}``, ``x_cam = R x_world + t``, world ``z`` up, metres),
``novel_cameras`` (likewise, ``view_N``); arrays ``depth_NN`` (camera ``z`` of
the visible surface, relief and ground included; NaN on the sky),
``model_depth_NN`` (camera ``z`` of the block model alone, NaN off it: the
rough model of model-based stereo), and per novel view ``novel_N`` (noise-free float code values,
clipped as the sensor clips) with ``novel_model_N`` (where it sees the block
model's own surface: on the model, not behind relief).

The building's geometry is the block model's (``blocks.json`` read by
:class:`lumigraph.stereo.debevec1996.BlockModel`, which this ground-floor
module cannot import; ``tests/stereo/test_facade_scene.py`` checks that the
mesh and edge names here equal the BlockModel's).

Examples
--------
>>> s = render_facade(size=(64, 48), seed=0, rng=np.random.default_rng(0), photos=6, novel=1,
...                   supersample=1)
>>> len(s.images), s.stack["blocks"], sorted(s.gt["parameters"])[:3]
(6, 'blocks.json', ['house/depth', 'house/height', 'house/width'])
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.capture.render import Option, RenderedScene, SceneSpec

# The true model: (name, kind, parent, placement {on, x, y}, parameters).
# A parameter given as a string shares that parameter.
BLOCKS = (
    ("house", "box", None, {}, {"width": 10.0, "depth": 6.0, "height": 6.0}),
    ("roof", "wedge", "house", {"on": "top"},
     {"width": "house/width", "depth": "house/depth", "height": 2.5}),
    ("tower", "box", "house", {"on": "base", "x": "offset", "y": "front"},
     {"width": 3.0, "depth": "tower/width", "height": 9.0, "offset_x": 6.5}),
    ("spire", "pyramid", "tower", {"on": "top"},
     {"width": "tower/width", "depth": "tower/width", "height": 2.0}),
    ("wing", "box", "house", {"on": "base", "x": "offset", "y": "back"},
     {"width": 4.0, "depth": 4.0, "height": 4.0, "offset_x": -7.0}),
)
FIXED = ("house/width",)  # the scale
PILASTER_M = 0.3  # relief the model lacks: pilasters this far proud of the house front
GROUND_HALF_M = 80.0
SUN = np.array([-0.45, -0.6, 0.66]) / np.linalg.norm([-0.45, -0.6, 0.66])  # towards the sun

_BOX_V = {f"{xn}-{yn}-{zn}": (ax, ay, az)
          for xn, ax in (("left", -0.5), ("right", 0.5))
          for yn, ay in (("front", -0.5), ("back", 0.5))
          for zn, az in (("bottom", 0.0), ("top", 1.0))}
_BASE_V = {k.removesuffix("-bottom"): v for k, v in _BOX_V.items() if k.endswith("bottom")}
_BOTTOM_E = {f"bottom-{s}": e for s, e in (("front", ("left-front-bottom", "right-front-bottom")),
                                          ("back", ("left-back-bottom", "right-back-bottom")),
                                          ("left", ("left-front-bottom", "left-back-bottom")),
                                          ("right", ("right-front-bottom", "right-back-bottom")))}
_KINDS = {
    "box": (_BOX_V,
            {**{f"{z}-{s}": (a.replace("bottom", z), b.replace("bottom", z))
                for z in ("bottom", "top") for s, (a, b) in
                (("front", _BOTTOM_E["bottom-front"]), ("back", _BOTTOM_E["bottom-back"]),
                 ("left", _BOTTOM_E["bottom-left"]), ("right", _BOTTOM_E["bottom-right"]))},
             **{f"{y}-{x}": (f"{x}-{y}-bottom", f"{x}-{y}-top")
                for y in ("front", "back") for x in ("left", "right")}},
            [("left-front-bottom", "right-front-bottom", "right-back-bottom", "left-back-bottom"),
             ("left-front-top", "right-front-top", "right-back-top", "left-back-top"),
             ("left-front-bottom", "right-front-bottom", "right-front-top", "left-front-top"),
             ("left-back-bottom", "right-back-bottom", "right-back-top", "left-back-top"),
             ("left-front-bottom", "left-back-bottom", "left-back-top", "left-front-top"),
             ("right-front-bottom", "right-back-bottom", "right-back-top", "right-front-top")]),
    "wedge": ({**{f"{k}-bottom": v for k, v in _BASE_V.items()},
               "ridge-left": (-0.5, 0.0, 1.0), "ridge-right": (0.5, 0.0, 1.0)},
              {**_BOTTOM_E, "ridge": ("ridge-left", "ridge-right"),
               **{f"rake-{y}-{x}": (f"{x}-{y}-bottom", f"ridge-{x}")
                  for y in ("front", "back") for x in ("left", "right")}},
              [("left-front-bottom", "right-front-bottom", "right-back-bottom", "left-back-bottom"),
               ("left-front-bottom", "right-front-bottom", "ridge-right", "ridge-left"),
               ("left-back-bottom", "right-back-bottom", "ridge-right", "ridge-left"),
               ("left-front-bottom", "left-back-bottom", "ridge-left"),
               ("right-front-bottom", "right-back-bottom", "ridge-right")]),
    "pyramid": ({**{f"{k}-bottom": v for k, v in _BASE_V.items()}, "apex": (0.0, 0.0, 1.0)},
                {**_BOTTOM_E, **{f"hip-{y}-{x}": (f"{x}-{y}-bottom", "apex")
                                 for y in ("front", "back") for x in ("left", "right")}},
                [("left-front-bottom", "right-front-bottom", "right-back-bottom", "left-back-bottom"),
                 ("left-front-bottom", "right-front-bottom", "apex"),
                 ("right-front-bottom", "right-back-bottom", "apex"),
                 ("right-back-bottom", "left-back-bottom", "apex"),
                 ("left-back-bottom", "left-front-bottom", "apex")]),
}


class _Mesh:
    def __init__(self, vertices, faces, face_block):
        self.vertices, self.faces, self.face_block = vertices, faces, face_block


class Building:
    """The scene's block model with given parameter values: the duck type of
    :class:`lumigraph.stereo.debevec1996.BlockModel` that
    :func:`lumigraph.capture.scenes.facade_edges.project_edges` takes
    (``edges``, ``mesh``, ``named_values``; ``params`` is ignored: the values
    are this object's)."""

    def __init__(self, values: dict[str, float]):
        self.values = dict(values)
        V, names, faces, owner = [], {}, [], []
        base = {}
        self._edges = {}
        for name, kind, parent, place, params in BLOCKS:
            def val(p, name=name, params=params):
                v = params[p]
                return self.values[v if isinstance(v, str) else f"{name}/{p}"]
            dims = np.array([val("width"), val("depth"), val("height")])
            if parent is None:
                o = np.zeros(3)
            else:
                po, pd = base[parent]
                o = po.copy()
                on = place.get("on", "top")
                o[2] = po[2] + (pd[2] if on == "top" else val("offset_z") if on == "offset" else 0.0)
                for ax, key, lo, hi in ((0, "x", "left", "right"), (1, "y", "front", "back")):
                    how = place.get(key, "centre")
                    if how == lo:
                        o[ax] = po[ax] - pd[ax] / 2 + dims[ax] / 2
                    elif how == hi:
                        o[ax] = po[ax] + pd[ax] / 2 - dims[ax] / 2
                    elif how == "offset":
                        o[ax] = po[ax] + val(f"offset_{key}")
            base[name] = (o, dims)
            verts, edges, polys = _KINDS[kind]
            idx = {}
            for vn, m in verts.items():
                idx[vn] = len(V)
                V.append(o + np.array(m) * dims)
            for en, (a, b) in edges.items():
                self._edges[f"{name}/{en}"] = (V[idx[a]], V[idx[b]])
            cen = np.mean([V[i] for i in idx.values()], axis=0)
            for poly in polys:
                p = [V[idx[n]] for n in poly]
                if np.dot(np.cross(p[1] - p[0], p[2] - p[0]), np.mean(p, axis=0) - cen) < 0:
                    poly = poly[::-1]
                faces += [(idx[poly[0]], idx[poly[i]], idx[poly[i + 1]]) for i in range(1, len(poly) - 1)]
                owner += [name] * (len(poly) - 2)
            names[name] = kind
        self._mesh = _Mesh(np.array(V), np.array(faces, np.int64), np.array(owner))
        self.kinds = names

    def edges(self, params=None):
        return dict(self._edges)

    def mesh(self, params=None):
        return self._mesh

    def named_values(self, params=None):
        return dict(self.values)


def true_values() -> dict[str, float]:
    """Every block parameter by its stable name (shared ones take the value
    of the parameter they share)."""
    own = {f"{n}/{p}": v for n, _, _, _, ps in BLOCKS for p, v in ps.items() if not isinstance(v, str)}
    shared = {f"{n}/{p}": own[v] for n, _, _, _, ps in BLOCKS for p, v in ps.items() if isinstance(v, str)}
    return {**own, **shared}


def blocks_document(values: dict[str, float]) -> dict:
    """``blocks.json`` with ``values`` as the starting values (the fixed
    parameters hold theirs)."""
    blocks = []
    for name, kind, parent, place, params in BLOCKS:
        ps = {}
        for p, v in params.items():
            key = f"{name}/{p}"
            ps[p] = ({"same_as": v} if isinstance(v, str) else
                     {"value": values[key], "fixed": True} if key in FIXED else values[key])
        b = {"name": name, "kind": kind}
        if parent:
            b["parent"] = parent
        b.update(place)
        b["params"] = ps
        blocks.append(b)
    return {"schema": "lumigraph.facade.blocks", "schema_version": 1, "blocks": blocks}


# ------------------------------------------------------------------ shading
def _hash(i, j, k=0):
    return np.modf(np.abs(np.sin(i * 12.9898 + j * 78.233 + k * 37.719) * 43758.5453))[0]


def _sky(d):
    """Sky radiance (…, 3) in direction ``d`` (…, 3) unit, as the camera sees
    it: :func:`_environment` plus streaks of cloud (the background only:
    reflections use the smooth environment)."""
    el = d[..., 2]
    az = np.arctan2(d[..., 1], d[..., 0])
    cloud = np.clip(np.sin(3 * az + 5 * el) * np.sin(7 * az - 2 * el + 1.3) + 0.2, 0, 1)
    return _environment(d) + 0.3 * (cloud * np.clip(el * 4, 0, 1))[..., None]


def _environment(d):
    """The light reflected by the glossy surfaces from direction ``d``: a
    smooth sky, pale at the horizon, deeper blue at the zenith, warm and
    bright towards the sun, darker away from it, fading to a grey ground
    below the horizon (smooth everywhere, so a reflection changes smoothly
    with the view)."""
    el = np.clip(d[..., 2], -1, 1)
    a = (np.tanh(3 * el) + 1) / 2  # 0 below, 1 above, smooth across the horizon
    hor = np.array([0.85, 0.88, 0.92])
    zen = np.array([0.25, 0.42, 0.85])
    up = np.clip(el, 0, 1)[..., None]
    sky = hor * (1 - up) + zen * up
    sunward = d @ SUN
    sky = sky * (0.75 + 0.25 * sunward)[..., None] + np.array([1.0, 0.85, 0.6]) * (
        0.9 * np.clip(sunward, 0, 1) ** 4)[..., None]
    ground = np.array([0.3, 0.3, 0.27])
    return sky * a[..., None] + ground * (1 - a[..., None])


def _face_frames(V, F):
    """Per triangle: unit normal, in-plane axes ``u`` (horizontal) and ``w``
    (up the face), and the face group's extents along them (a block's
    coplanar triangles form one group: its polygon)."""
    tri = V[F]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    ref = np.where(np.abs(n[:, 2:3]) < 0.9, np.array([[0, 0, 1.0]]), np.array([[0, 1.0, 0]]))
    u = np.cross(ref, n)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(n, u)
    s = np.einsum("mkj,mj->mk", tri, u)
    q = np.einsum("mkj,mj->mk", tri, w)
    ext = np.stack([s.min(1), s.max(1), q.min(1), q.max(1)], 1)
    key = np.round(np.concatenate([n, np.einsum("mj,mj->m", tri[:, 0], n)[:, None]], 1), 6)
    for k in np.unique(key, axis=0):
        g = (key == k).all(1)
        ext[g] = [ext[g, 0].min(), ext[g, 1].max(), ext[g, 2].min(), ext[g, 3].max()]
    return n, u, w, ext


def _materials(X, m, kind, n, u, w, ext, lambertian):
    """Albedo, specular weight, shininess and mirror weight per sample."""
    P = len(X)
    albedo = np.zeros((P, 3))
    ks = np.zeros(P)
    shin = np.full(P, 20.0)
    kr = np.zeros(P)
    k_ = kind[m]
    wall = np.flatnonzero(k_ == 0)
    if len(wall):
        mw, Xw = m[wall], X[wall]
        s = np.einsum("pj,pj->p", Xw, u[mw])
        q = np.einsum("pj,pj->p", Xw, w[mw])
        # bricks 0.6 x 0.3 m, every other row offset, each its own shade
        row = np.floor(q / 0.3)
        off = 0.5 * (row % 2)
        col = np.floor(s / 0.6 + off)
        mortar = (q / 0.3 - row < 0.15) | (s / 0.6 + off - col < 0.075)
        shade = (0.8 + 0.2 * _hash(row, col)) * (0.95 + 0.05 * _hash(np.floor(s * 12), np.floor(q * 10), 3))
        a = np.array([0.62, 0.34, 0.24]) * shade[:, None]
        a[mortar] = [0.58, 0.42, 0.34]
        kw = np.full(len(wall), 0.35)
        sw = np.full(len(wall), 8.0)
        rw = np.full(len(wall), 0.25)
        # windows: 1.0 x 1.3 m, 2.2 m apart, one per 3 m storey, 0.7 m from the corners
        e = ext[mw]
        s0, s1 = e[:, 0] + 0.7, e[:, 1] - 0.7
        ncol = np.maximum(np.floor((s1 - s0 - 1.0) / 2.2) + 1, 0)
        first = (s0 + s1) / 2 - ((ncol - 1) * 2.2 + 1.0) / 2
        k = np.floor((s - first) / 2.2)
        ds = s - first - 2.2 * k
        storey = np.floor((q - e[:, 2]) / 3.0)
        dq = q - e[:, 2] - 3.0 * storey
        inwin = ((k >= 0) & (k < ncol) & (ds >= 0) & (ds <= 1.0) & (dq >= 0.9) & (dq <= 2.2)
                 & (e[:, 2] + 3.0 * storey + 2.2 <= e[:, 3] - 0.3))
        frame = inwin & ((ds < 0.08) | (ds > 0.92) | (dq < 0.98) | (dq > 2.12)
                         | (np.abs(ds - 0.5) < 0.03))
        glass = inwin & ~frame
        a[frame] = [0.6, 0.55, 0.5]
        kw[frame], sw[frame], rw[frame] = 0.2, 30.0, 0.05
        a[glass] = np.array([0.2, 0.22, 0.25]) * (0.8 + 0.4 * _hash(k[glass], storey[glass], 5))[:, None]
        kw[glass], sw[glass], rw[glass] = 0.9, 120.0, 1.0
        albedo[wall], ks[wall], shin[wall], kr[wall] = a, kw, sw, rw
    roof = np.flatnonzero(k_ == 1)
    if len(roof):
        mr, Xr = m[roof], X[roof]
        s = np.einsum("pj,pj->p", Xr, u[mr])
        q = np.einsum("pj,pj->p", Xr, w[mr])
        # glazed tiles 0.3 m wide, rows 0.25 m up the slope
        trow = np.floor(q / 0.25)
        tcol = np.floor(s / 0.3 + 0.5 * (trow % 2))
        tshade = np.where(q / 0.25 - trow < 0.1, 0.75, 0.8 + 0.2 * _hash(trow, tcol, 7))
        albedo[roof] = np.array([0.55, 0.2, 0.12]) * tshade[:, None]
        ks[roof], shin[roof], kr[roof] = 0.4, 10.0, 0.3
    top = np.flatnonzero(k_ == 2)
    if len(top):  # flat tops: gravel
        Xt = X[top]
        grav = 0.45 + 0.25 * _hash(np.floor(Xt[:, 0] * 11), np.floor(Xt[:, 1] * 11), 2)
        albedo[top] = np.array([0.8, 0.8, 0.78]) * grav[:, None]
    ground = np.flatnonzero(k_ == 3)
    if len(ground):  # the ground: paving, Lambertian
        Xg = X[ground]
        pav = 0.5 + 0.2 * _hash(np.floor(Xg[:, 0] / 0.8), np.floor(Xg[:, 1] / 0.8), 4)
        pav = pav * (0.85 + 0.15 * _hash(np.floor(Xg[:, 0] * 9), np.floor(Xg[:, 1] * 9), 6))
        albedo[ground] = np.array([0.55, 0.56, 0.5]) * pav[:, None]
    if lambertian:
        ks[:] = 0.0
        kr[:] = 0.0
    return albedo, ks, shin, kr


def _box_triangles(lo, hi, base):
    """An axis-aligned box's 8 corners and 12 outward triangles (indices from ``base``)."""
    V = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    F = []
    c = V.mean(0)
    for q in quads:
        p = V[list(q)]
        if np.dot(np.cross(p[1] - p[0], p[2] - p[0]), p.mean(0) - c) < 0:
            q = q[::-1]
        F += [(q[0], q[1], q[2]), (q[0], q[2], q[3])]
    return V, np.array(F) + base


def _relief(values):
    """Detail the block model lacks (what model-based stereo recovers): three
    pilasters 0.8 m wide, ``PILASTER_M`` proud of the house's front wall, between its
    window columns, as tall as the house."""
    y0 = -values["house/depth"] / 2
    return [((x - 0.4, y0 - PILASTER_M, 0.0), (x + 0.4, y0, values["house/height"]))
            for x in (-2.2, 0.0, 2.2)]


def _scene_mesh(building):
    """The model's triangles (``[0, n_model)``), the relief's (``[n_model,
    n_solid)``) and the ground's two (``n_solid``, ``n_solid + 1``): the
    ground is not rasterised (it reaches behind every camera, so its
    bounding box would be the frame) but intersected per ray
    (:func:`_scene_raster`); its triangles give it a normal and a kind."""
    mesh = building.mesh()
    V, F = [mesh.vertices], [mesh.faces]
    n = len(mesh.vertices)
    for lo, hi in _relief(building.values):
        v, f = _box_triangles(lo, hi, n)
        V.append(v)
        F.append(f)
        n += len(v)
    g = GROUND_HALF_M
    V.append(np.array([[-g, -g, 0.0], [g, -g, 0], [g, g, 0], [-g, g, 0]]))
    F.append(np.array([[0, 1, 2], [0, 2, 3]]) + n)
    F = np.concatenate(F)
    return np.concatenate(V), F, len(mesh.faces), len(F) - 2


def _scene_raster(V, F, n_solid, K, R, t, size, rays=None):
    """Depth and face per pixel of the building (model and relief, the first
    ``n_solid`` triangles) and the ground plane z = 0 (within
    ``GROUND_HALF_M``, face ``n_solid``): the building by the z-buffer, the
    ground by its ray–plane intersection, the nearer wins."""
    from lumigraph.capture.raster import pixel_rays, rasterize

    if rays is None:
        rays = pixel_rays(K, size)
    r = rasterize(V, F[:n_solid], K, R, t, size, rays=rays)
    C = -R.T @ t
    d = rays @ R  # world direction per unit camera z
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = -C[2] / d[..., 2]
    P = C + lam[..., None] * d
    ground = (lam > 0) & (np.abs(P[..., 0]) <= GROUND_HALF_M) & (np.abs(P[..., 1]) <= GROUND_HALF_M)
    ground &= lam < r.depth
    depth = np.where(ground, lam, r.depth)
    face = np.where(ground, n_solid, r.face)
    return depth, face, rays


def _shade_view(V, F, n_solid, kinds, frames, K, R, t, size, ss, lambertian):
    """Noise-free float radiance (H, W, 3) of one view, ``ss²`` samples a pixel."""
    w, h = size
    S = np.array([[ss, 0, (ss - 1) / 2], [0, ss, (ss - 1) / 2], [0, 0, 1.0]])
    Ks = S @ K
    depth, face, rays = _scene_raster(V, F, n_solid, Ks, R, t, (w * ss, h * ss))
    d_world = rays.reshape(-1, 3) @ R  # R^T ray, per unit camera z
    dn = d_world / np.linalg.norm(d_world, axis=1, keepdims=True)
    hit = face.ravel() >= 0
    out = np.empty((len(dn), 3))
    out[~hit] = _sky(dn[~hit])
    m = face.ravel()[hit]
    C = -R.T @ t
    X = C + d_world[hit] * depth.ravel()[hit, None]
    n, u, w_, ext = frames
    albedo, ks, shin, kr = _materials(X, m, kinds, n, u, w_, ext, lambertian)
    nn = n[m]
    v = -dn[hit]
    ndl = np.clip(nn @ SUN, 0, None)
    hv = v + SUN
    hv /= np.linalg.norm(hv, axis=1, keepdims=True)
    ndh = np.clip(np.einsum("pj,pj->p", nn, hv), 0, None)
    ndv = np.clip(np.einsum("pj,pj->p", nn, v), 0, 1)
    col = albedo * (0.35 + 0.75 * ndl)[:, None]
    col += (ks * ndh ** shin * (ndl > 0) * 1.2)[:, None]
    # the mirror term, Fresnel-weighted (Schlick) on a floor of 30 %: glazed
    # bricks and tiles reflect the sky at every angle, more at grazing ones
    fres = 0.3 + 0.7 * (1 - ndv) ** 5
    refl = 2 * ndv[:, None] * nn - v
    glossy = np.flatnonzero(kr > 0)
    col[glossy] += (kr[glossy] * fres[glossy])[:, None] * _environment(refl[glossy])
    out[hit] = col
    img = out.reshape(h, ss, w, ss, 3).mean(axis=(1, 3))
    return img


def _view_camera(centre, target, K, size):
    from lumigraph.capture.scenes.facade_edges import look_at

    R, t = look_at(centre, target)
    return {"K": np.asarray(K, float), "R": R, "t": t, "image_size": list(size)}


def _camera_doc(cam):
    return {"schema": "lumigraph.camera", "schema_version": 1, "image_size": list(cam["image_size"]),
            "K": np.asarray(cam["K"]).tolist(), "dist": [0.0] * 5,
            "dist_names": ["k1", "k2", "p1", "p2", "k3"], "model": "none",
            "cam_from_world": {"R": np.asarray(cam["R"]).tolist(),
                               "t": np.asarray(cam["t"]).ravel().tolist()}}


def _gt_cam(cam):
    return {"K": np.asarray(cam["K"]).tolist(), "R": np.asarray(cam["R"]).tolist(),
            "t": np.asarray(cam["t"]).ravel().tolist(), "image_size": list(cam["image_size"])}


def _edge_visibility(V, F, n_solid, normals, cam, size):
    """``visible(points)`` for one photograph: in front of the z-buffer of the
    whole scene (within 0.2 %) and on a crease or silhouette (the surface on
    the two sides of the projected edge differs in normal or depth), so an
    edge lying inside a coplanar join of two blocks is not a visible edge."""
    K, R, t = cam["K"], cam["R"], cam["t"]
    w, h = size
    zbuf, face, _ = _scene_raster(V, F, n_solid, K, R, t, size)

    def visible(P, direction):
        # P (k, 3): samples along one edge, direction its 3-D direction
        pc = P @ R.T + t
        q = pc @ K.T
        px = q[:, :2] / q[:, 2:3]
        xi = np.clip(np.rint(px[:, 0]).astype(int), 0, w - 1)
        yi = np.clip(np.rint(px[:, 1]).astype(int), 0, h - 1)
        # the edge point is seen when no surface in its 3x3 neighbourhood is
        # all nearer: the nearest pixel may lie on either face of the edge
        zmax = np.full(len(P), -np.inf)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                zmax = np.maximum(zmax, zbuf[np.clip(yi + dy, 0, h - 1), np.clip(xi + dx, 0, w - 1)])
        ok = pc[:, 2] <= zmax * (1 + 2e-3)
        # a crease: sample 1.5 px to each side, across the projected edge
        e = direction @ R.T
        e2 = (pc + e[None] * 1e-3) @ K.T
        dpx = e2[:, :2] / e2[:, 2:3] - px
        nrm = np.stack([-dpx[:, 1], dpx[:, 0]], 1)
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
        sides = []
        for sgn in (-1.5, 1.5):
            a = px + sgn * nrm
            ax = np.clip(np.rint(a[:, 0]).astype(int), 0, w - 1)
            ay = np.clip(np.rint(a[:, 1]).astype(int), 0, h - 1)
            f = face[ay, ax]
            sides.append((np.where(f[:, None] >= 0, normals[np.maximum(f, 0)], 0.0), zbuf[ay, ax]))
        same_n = np.einsum("pj,pj->p", sides[0][0], sides[1][0]) > 0.999
        z0, z1 = sides[0][1], sides[1][1]
        with np.errstate(invalid="ignore"):
            same_z = np.isfinite(z0) & np.isfinite(z1) & (np.abs(z0 - z1) < 0.05 * np.minimum(z0, z1))
        return ok & ~(same_n & same_z)

    return visible


def render_facade(*, size, seed, rng, photos=8, novel=4, noise=1.0, supersample=2,
                  edge_noise=0.0, lambertian=False, layout="arc"):
    """Photographs, marks and ground truth of the building (module docstring).

    Cameras: ``photos`` with azimuths evenly spread (up to ±4° of jitter),
    24–30 m from the centre, 2–9 m high, each aimed near the building's
    centre. ``layout="arc"``: over 240° in front of the building (−y), the
    arc's ends included, so the back wall is seen only at grazing angles
    from the ends; ``"ring"``: over 360°, the building photographed all
    round. ``novel`` views half-way in azimuth between consecutive
    photographs (3–8 m high), spread over the layout. Focal
    ``1.05 W`` px, principal point at the image centre. Photographs: float
    radiance × 200 as code values, Gaussian read noise ``noise`` codes,
    rounded and clipped to 8 bits.
    """
    w, h = size
    truth = true_values()
    building = Building(truth)
    V, F, n_model, n_solid = _scene_mesh(building)
    mesh_kind = np.full(len(F), 3)  # 0 wall, 1 roof, 2 flat top, 3 ground
    frames = _face_frames(V, F)
    nz = frames[0][:, 2]
    owner = building.mesh().face_block
    for i in range(n_solid):
        kind = building.kinds[owner[i]] if i < n_model else "box"
        mesh_kind[i] = 0 if abs(nz[i]) < 1e-9 else 2 if nz[i] > 0.999 else 1 if kind != "box" else 2
    K = np.array([[1.05 * w, 0, (w - 1) / 2], [0, 1.05 * w, (h - 1) / 2], [0, 0, 1.0]])
    centre = np.array([-0.5, 0.0, 4.0])

    if layout not in ("arc", "ring"):
        raise InputError("layout", f"expected 'arc' or 'ring', got {layout!r}")
    gaps = photos - 1 if layout == "arc" else photos  # spaces between consecutive photographs

    def ring(i, n, offset, heights):
        # arc: 240° in front of the building (−y), ends included; ring: 360°, from the front
        if layout == "arc":
            a = np.radians(-210 + 240 * (i + offset) / (n - 1) + rng.uniform(-4, 4))
        else:
            a = np.radians(-90 + 360 * (i + offset) / n + rng.uniform(-4, 4))
        rad = rng.uniform(24, 30)
        c = centre + [rad * np.cos(a), rad * np.sin(a), rng.uniform(*heights) - centre[2]]
        aim = centre + rng.uniform(-1, 1, 3) * [1.0, 1.0, 0.5]
        return _view_camera(c, aim, K, size)

    cams = {f"photo_{i:02d}.png": ring(i, photos, 0.0, (2.0, 9.0)) for i in range(photos)}
    # novel views half-way between photographs, spread over the layout
    novels = {f"view_{k}": ring(round((k + 0.5) * gaps / max(novel, 1) - 0.5), photos, 0.5,
                                (3.0, 8.0))
              for k in range(novel)}
    ss = int(supersample)
    images, arrays = [], {}
    for i, cam in enumerate(cams.values()):
        img = _shade_view(V, F, n_solid, mesh_kind, frames, cam["K"], cam["R"], cam["t"], size, ss,
                             lambertian)
        codes = img * 200.0
        if noise > 0:
            codes = codes + rng.normal(0.0, noise, codes.shape)
        images.append(np.clip(np.round(codes), 0, 255).astype(np.uint8))
        arrays.update(_depths(V, F, n_model, n_solid, cam, size, f"{i:02d}"))
    for name, cam in novels.items():
        img = _shade_view(V, F, n_solid, mesh_kind, frames, cam["K"], cam["R"], cam["t"], size, ss,
                             lambertian)
        arrays[name.replace("view", "novel")] = np.clip(img * 200.0, 0, 255).astype(np.float32)
        d = _depths(V, F, n_model, n_solid, cam, size, "")
        # the model's own surface in view (not hidden by relief the model lacks)
        with np.errstate(invalid="ignore"):
            arrays[name.replace("view", "novel_model")] = (np.abs(d["depth_"] - d["model_depth_"])
                                                           <= 1e-5 * d["model_depth_"])
    # the marks: every visible model edge, clipped by each photograph's z-buffer
    from lumigraph.capture.scenes.facade_edges import project_edges

    vis = {p: _edge_visibility(V, F, n_solid, frames[0], c, size) for p, c in cams.items()}
    marks = project_edges(building, cams, noise_px=edge_noise, rng=rng, samples=41,
                          min_length_px=12.0, visible=lambda p, P: vis[p](P, P[-1] - P[0]))
    # rough starting values for the solver: ±15 % off the truth
    start = {}
    for name, _, _, _, ps in BLOCKS:
        for prm, v in ps.items():
            key = f"{name}/{prm}"
            if isinstance(v, str):
                continue
            start[key] = v if key in FIXED else round(float(v * (1 + rng.uniform(-0.15, 0.15))), 3)
    files = {"blocks.json": blocks_document(start),
             "edges.json": {"schema": "lumigraph.facade.edges", "schema_version": 1,
                            "noise_px": float(edge_noise), "photographs": marks}}
    # the photographs' shared intrinsics (what 'stereo facade solve' reads), then each pose
    shared = _camera_doc(next(iter(cams.values())))
    del shared["cam_from_world"]
    files["camera.json"] = shared
    for p, cam in cams.items():
        files[f"cameras/{p.rsplit('.', 1)[0]}.json"] = _camera_doc(cam)
    for p, cam in novels.items():
        files[f"novel/{p}.json"] = _camera_doc(cam)
    gt = {"parameters": truth, "cameras": {p: _gt_cam(c) for p, c in cams.items()},
          "novel_cameras": {p: _gt_cam(c) for p, c in novels.items()},
          "noise_sigma_codes": float(noise), "edge_noise_px": float(edge_noise),
          "lambertian": bool(lambertian), "world": "z up, ground z = 0, metres",
          "code_scale": "code = 200 x radiance (linear sensor, clipped at 255)"}
    return RenderedScene("facade", {}, tuple(images), tuple(cams), gt=gt, gt_arrays=arrays,
                         stack={"blocks": "blocks.json", "edges": "edges.json", "bit_depth": 8,
                                "linear": True},
                         files=files)


def scene_depth(values: dict[str, float], K, R, t, size) -> np.ndarray:
    """Camera ``z`` (H, W) float32 of the scene's surface (building, relief
    and ground; NaN on the sky) seen by any camera ``K, R, t`` (``x_cam = R
    x_world + t``), for the block parameters ``values``: the truth of a depth
    map made from a solved, slightly wrong camera, along its own rays."""
    V, F, _, n_solid = _scene_mesh(Building(values))
    depth, face, _ = _scene_raster(V, F, n_solid, np.asarray(K, float), np.asarray(R, float),
                                   np.asarray(t, float).ravel(), size)
    return np.where(face >= 0, depth, np.nan).astype(np.float32)


def _depths(V, F, n_model, n_solid, cam, size, tag):
    from lumigraph.capture.raster import rasterize

    depth, face, _ = _scene_raster(V, F, n_solid, cam["K"], cam["R"], cam["t"], size)
    z = np.where(face >= 0, depth, np.nan).astype(np.float32)
    # the model alone, without its relief (the ground, z = 0, hides none of it)
    r = rasterize(V, F[:n_model], cam["K"], cam["R"], cam["t"], size)
    zm = np.where(r.hit, r.depth, np.nan).astype(np.float32)
    return {f"depth_{tag}": z, f"model_depth_{tag}": zm}


SPECS = {"facade": SceneSpec("facade", (160, 120), (
    Option("photos", int, 8, "number of photographs around the building", low=6, high=10),
    Option("novel", int, 4, "novel views (cameras and noise-free images) for VDTM", low=0, high=10),
    Option("noise", float, 1.0, "read noise (8-bit code values)", low=0),
    Option("supersample", int, 2, "samples per pixel side (anti-aliasing)", low=1, high=4),
    Option("edge_noise", float, 0.0, "Gaussian noise (px) on each marked endpoint coordinate",
           low=0),
    Option("lambertian", bool, False, "no specular or mirror terms (a diffuse building)"),
    Option("layout", str, "arc", "cameras on a 240° arc in front (arc) or all round (ring)",
           choices=("arc", "ring")),
), version=5, min_size=(48, 36))}
