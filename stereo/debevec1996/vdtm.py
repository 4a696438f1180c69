"""View-dependent texture mapping (VDTM): a model rendered from a new
viewpoint, each surface point textured from the photographs that see it.

P. E. Debevec, C. J. Taylor and J. Malik, "Modeling and Rendering
Architecture from Photographs: A hybrid geometry- and image-based approach",
SIGGRAPH 1996, doi:10.1145/237170.237191 (reference ch. 5, §5.3.2 "Stage 2",
Fig. 5.11); P. E. Debevec, Y. Yu and G. Borshukov, "Efficient
View-Dependent Image-Based Rendering with Projective Texture-Mapping",
Eurographics Rendering Workshop 1998, doi:10.1007/978-3-7091-6453-2_10
(the per-polygon *view map*).

``method="blend"`` (1996). The new camera's z-buffer of the model gives the
surface point ``X`` of each pixel. Photograph ``i`` (centre ``C_i``) sees
``X`` when ``X`` projects inside its frame and the bilinear taps (of
non-zero weight) of its depth map lie on ``X``'s surface: they lie on one
continuous surface (their depths within ``2 · tolerance`` relative of each
other: a slanted surface's depth changes across a pixel) and ``z_i(X)`` is
within ``tolerance · z_i(X)`` of their range. So a sample never mixes an
occluder's or the background's colour in. The
colour is the weighted mean of the visible photographs' bilinear samples,

    c(X) = Σ_i w_i c_i(X) / Σ_i w_i,
    w_i = (θ_i + ε)^(−power) · max(0, 1 − θ_i / θ_(k+1))  for the k nearest

with ``θ_i`` the angle at ``X`` between the new viewing ray ``X − C`` and
photograph ``i``'s ray ``X − C_i`` (Fig. 5.11's ``b_1, b_2``; the paper's
weights are "inversely proportional to the angles", ``power = 1``;
``ε = 10⁻⁹`` rad keeps the new view equal to a photograph a copy of it).
Only the ``k = neighbours`` nearest visible photographs take part, each
tapered to 0 at the next nearest angle ``θ_(k+1)`` (C. Buehler et al.,
"Unstructured Lumigraph Rendering", SIGGRAPH 2001,
doi:10.1145/383259.383309), so no seam appears where the nearest change;
``neighbours = 0`` blends every photograph that sees ``X``.

``method="view-map"`` (1998). Each plane of the model (its coplanar
polygons) is textured from at most three photographs, chosen once per
plane and view: the three the blend gives the most weight over points
spread on its polygons, weighted by their area (:meth:`ViewMaps.choose_planes`).
Rendering does what the paper's projective texture mapping does: one
plane-induced homography per photograph warps the photograph onto the
plane's pixels (``cv2.warpPerspective``), and visibility is precomputed
once per model and photographs (:func:`prepare_view_maps`: per plane, the
photograph's pixels whose surface lies on that plane), so a new view needs
no per-pixel depth test, world point or angle. The blend's weights among
the three come from angles computed on a coarse grid over the plane and
interpolated (the paper interpolates per-vertex weights). Where fewer of
the three see a pixel than the blend would take (the plane partly hidden
from them) and other photographs see the plane, and on planes showing a
few pixels, the pixel is blended from every photograph that sees the plane.
The per-polygon Delaunay map of the photographs' directions
(:meth:`ViewMaps.lookup`) is kept for its barycentric weights.

Pixels of the model no photograph sees are *holes*, filled from their
neighbours (push–pull: a pyramid of weighted means, Gortler et al. 1996).
Values are blended as given: linear radiance stays linear.

Examples
--------
A plane seen by two photographs; the new view equals the first: a copy.

>>> K = np.array([[20.0, 0, 7.5], [0, 20.0, 5.5], [0, 0, 1]])
>>> quad = (np.array([[-2.0, -2, 4], [2, -2, 4], [2, 2, 4], [-2, 2, 4]]), np.array([[0, 1, 2], [0, 2, 3]]))
>>> rng = np.random.default_rng(0)
>>> p0 = Photograph(rng.random((12, 16, 3)), K, np.eye(3), np.zeros(3))
>>> p1 = Photograph(rng.random((12, 16, 3)), K, np.eye(3), np.array([0.3, 0, 0]))
>>> photos = prepare_photographs(quad, [p0, p1])
>>> out = render_vdtm(quad, photos, K, np.eye(3), np.zeros(3), (16, 12))
>>> bool(np.abs(out.image - p0.image).max() < 1e-6)
True
>>> vm = render_vdtm(quad, photos, K, np.eye(3), np.zeros(3), (16, 12), method="view-map")
>>> bool(np.abs(vm.image - p0.image).max() < 1e-6)
True
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.capture.raster import check_mesh, pixel_rays, rasterize

METHODS = ("blend", "view-map")
EPS_RAD = 1e-9
# weights θ^-power: 1 is the paper's "inversely proportional"
DEFAULT_POWER = 1.0
# only the nearest NEIGHBOURS by angle blend, tapered to 0 at the next one (Buehler et
# al. 2001); 2 was chosen on the glossy facade scene's tuning seeds
# (docs/decisions/facade-vdtm.md); 0 = every photograph that sees the point
DEFAULT_NEIGHBOURS = 2
# a view-map triangle with a smaller angle is a sliver: the nearest three are used instead
SLIVER_DEG = 15.0


@dataclass(frozen=True)
class Photograph:
    """One photograph of the model: its image and its camera.

    ``image`` (H, W) or (H, W, C) float (code values or linear radiance, as
    they are to be blended); ``K`` (3, 3), ``R, t`` cam_from_world
    (``x_cam = R x_world + t``); ``depth`` (H, W) its z-buffer of the model
    (``inf`` off the model), ``face_pixels`` (M,) how many of its pixels
    see each triangle and ``whole`` (M,) which triangles it sees whole (every
    pixel centre their projection covers shows them) and ``cells`` (H, W)
    which bilinear cells (pixels ``[y, y+1] × [x, x+1]``) lie on one
    continuous surface, ``face`` (H, W) its z-buffer's triangle ids (-1 off
    the model), filled by :func:`prepare_photographs`.
    """

    image: np.ndarray
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    depth: np.ndarray | None = field(default=None, repr=False)
    face_pixels: np.ndarray | None = field(default=None, repr=False)
    whole: np.ndarray | None = field(default=None, repr=False)
    cells: np.ndarray | None = field(default=None, repr=False)
    face: np.ndarray | None = field(default=None, repr=False)

    @property
    def centre(self) -> np.ndarray:
        """Camera centre in the world, ``−Rᵀ t``."""
        return -np.asarray(self.R, np.float64).T @ np.asarray(self.t, np.float64)


@dataclass(frozen=True)
class VDTMImage:
    """A VDTM rendering.

    Attributes
    ----------
    image : ndarray, (H, W, C) float32
        The rendered view; ``background`` off the model.
    model : ndarray, (H, W) bool
        Pixels on the model.
    filled : ndarray, (H, W) bool
        Model pixels no photograph saw, filled from their neighbours.
    info : dict
        ``method``, ``photographs_per_pixel`` (mean number blended),
        ``hole_fraction``, ``seen_by_one_fraction`` (the share of the model's
        pixels that one photograph alone sees, where the colour cannot follow
        the view; ``None`` for the view map with ``neighbours`` 0 or 1 where
        a pixel one of its three photographs sees is not tested against the
        others), ``timings_s``.
    """

    image: np.ndarray
    model: np.ndarray
    filled: np.ndarray
    info: dict


def _mesh(mesh):
    if hasattr(mesh, "vertices"):
        return check_mesh(mesh.vertices, mesh.faces, where="mesh")
    vertices, faces = mesh
    return check_mesh(vertices, faces, where="mesh")


def _cells(depth, tolerance):
    """(H, W) bool: the four depths of the bilinear cell at each pixel (the
    last row and column repeat theirs) are finite and agree within
    ``tolerance`` relative: the cell lies on one continuous surface."""
    d = np.pad(depth, ((0, 1), (0, 1)), mode="edge")
    taps = np.stack([d[:-1, :-1], d[:-1, 1:], d[1:, :-1], d[1:, 1:]])
    with np.errstate(invalid="ignore"):
        return np.isfinite(taps).all(0) & (taps.max(0) - taps.min(0) <= tolerance * taps.min(0))


def prepare_photographs(mesh, photographs, *, tolerance: float = 0.01) -> tuple[Photograph, ...]:
    """The photographs with their depth maps of ``mesh`` (the visibility
    every rendering reuses; ``tolerance`` as :func:`render_vdtm`'s, for the
    view map's per-cell test). ``InputError`` naming ``photographs`` when
    there are none or an image is not 2-D/3-D."""
    v, f = _mesh(mesh)
    photographs = list(photographs)
    if not photographs:
        raise InputError("photographs", "no photographs: VDTM needs at least one")
    out = []
    for i, p in enumerate(photographs):
        img = np.asarray(p.image)
        if img.ndim not in (2, 3):
            raise InputError("photographs", f"photograph {i}: expected an (H, W[, C]) image, "
                                            f"got shape {img.shape}")
        h, w = img.shape[:2]
        r = rasterize(v, f, p.K, p.R, p.t, (w, h))
        counts = np.bincount(r.face[r.hit].ravel(), minlength=len(f))
        out.append(replace(p, depth=r.depth, face_pixels=counts,
                           whole=(counts > 0) & (counts == r.covered),
                           # one continuous surface: as _sample's tap test
                           cells=_cells(r.depth, 2 * tolerance), face=r.face))
    return tuple(out)


def _sample(photo, X, tolerance, whole=None):
    """Bilinear samples ``(N, C)`` float32 of ``photo`` at the world points
    ``X (N, 3)`` and whether each is seen cleanly: the bilinear taps of
    non-zero weight lie on one continuous surface and the point on it (the
    module docstring); where ``whole (N,)`` is true the caller knows the
    point's polygon is seen whole, and only the cell's continuity is looked
    up."""
    import cv2

    img = photo.image
    if img.dtype != np.float32:
        img = np.asarray(img, np.float32)
    if img.ndim == 2:
        img = img[..., None]
    h, w = img.shape[:2]
    # one product: K (R X + t), whose third row is the camera z (K's is [0, 0, 1])
    KR = np.asarray(photo.K, np.float64) @ np.asarray(photo.R, np.float64)
    q = X @ KR.T
    q += np.asarray(photo.K, np.float64) @ np.asarray(photo.t, np.float64)
    z = q[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        px = q[:, :2] / z[:, None]
    # inside the frame: pixel footprints reach half a pixel past the centres
    # (taps clipped to the border there, as remap's BORDER_REPLICATE)
    ok = ((z > 0) & (px[:, 0] >= -0.5) & (px[:, 0] <= w - 0.5)
          & (px[:, 1] >= -0.5) & (px[:, 1] <= h - 0.5))
    pxs = np.where(ok[:, None], px, 0.0)
    # a point a rounding error off a pixel centre is on it (its own photograph's view)
    near = np.rint(pxs)
    pxs = np.where(np.abs(pxs - near) < 1e-6, near, pxs)
    # floor (the coordinates are >= -0.5), the taps clipped to the frame
    x0 = np.floor(pxs[:, 0]).astype(np.intp)
    y0 = np.floor(pxs[:, 1]).astype(np.intp)
    np.clip(x0, 0, w - 1, out=x0)
    np.clip(y0, 0, h - 1, out=y0)
    depth = photo.depth.ravel()
    # a tap with no weight (the point on a pixel centre's row or column) is not
    # looked at: a photograph seeing its own pixel centres needs no neighbour
    full = np.arange(len(X)) if whole is None else np.flatnonzero(~whole)
    if whole is not None and whole.any():  # polygons seen whole: the cell must lie on one surface
        cw = np.flatnonzero(whole)
        at = y0[cw] * w + x0[cw]
        cell = photo.cells.ravel()[at]
        # (a point on a pixel centre has one tap: that pixel's depth must agree)
        centre = np.flatnonzero(~cell & (pxs[cw, 0] == x0[cw]) & (pxs[cw, 1] == y0[cw]))
        cc = cw[centre]
        cell[centre] = np.abs(depth[at[centre]] - z[cc]) <= tolerance * np.abs(z[cc])
        ok[cw] &= cell
    if len(full):
        fx0, fy0, zf = x0[full], y0[full], z[full]
        dx = (pxs[full, 0] - fx0 > 1e-9) & (fx0 < w - 1)  # the right tap has weight
        dy = (pxs[full, 1] - fy0 > 1e-9) & (fy0 < h - 1)
        at = fy0 * w + fx0
        taps = (depth[at], depth[at + dx], depth[at + w * dy], depth[at + dx + w * dy])
        lo = np.minimum(np.minimum(taps[0], taps[1]), np.minimum(taps[2], taps[3]))
        hi = np.maximum(np.maximum(taps[0], taps[1]), np.maximum(taps[2], taps[3]))
        tol = tolerance * np.abs(zf)
        # the taps lie on one continuous surface (as _cells: a slanted one's depth
        # changes across the cell, by more than tolerance at a coarse resolution)
        # and the point on it: within tolerance of the taps' depth range
        with np.errstate(invalid="ignore"):
            good = (ok[full] & (hi - lo <= 2 * tolerance * lo)
                    & (zf >= lo - tol) & (zf <= hi + tol))
        ok[full] = good
    # the sample positions as a map of rows of 1024 (remap wants fewer than 2^15 rows)
    n = len(X)
    rows = max(-(-n // 1024), 1)
    m = np.zeros((rows * 1024, 2), np.float32)
    m[:n] = pxs
    mx, my = m[:, 0].reshape(rows, 1024), m[:, 1].reshape(rows, 1024)
    if img.shape[2] <= 4:
        s = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        s = s.reshape(rows * 1024, -1)[:n]
    else:  # at most 4 channels a call
        s = np.concatenate([cv2.remap(np.ascontiguousarray(img[..., c:c + 4]), mx, my,
                                      cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
                                      ).reshape(rows * 1024, -1)[:n]
                            for c in range(0, img.shape[2], 4)], 1)
    return s, ok


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)


def _angle_to(ray_unit, X, centre):
    """Angles (rad) at the points ``X (N, 3)`` between the unit new viewing
    rays ``ray_unit`` and the rays from ``centre``; accurate near 0 (the
    chord: θ = 2 asin(|a − b| / 2) for unit a, b)."""
    d = X - centre
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d -= ray_unit
    chord = np.sqrt(np.einsum("ij,ij->i", d, d))
    return 2 * np.arcsin(np.minimum(chord / 2, 1.0))


def _weights(theta, power, neighbours):
    """Blend weights ``(P, N)`` from the angles ``theta (P, N)`` (``inf``
    where the photograph does not see the point): ``(θ + ε)^−power``, and
    with ``neighbours = k`` only the ``k`` nearest take part, each weight
    times ``1 − θ / θ_(k+1)`` (``θ_(k+1)`` the next nearest angle; Buehler
    et al. 2001), so a photograph's weight falls to 0 where it stops being
    one of the ``k`` nearest: no seam where the choice changes."""
    seen = np.isfinite(theta)
    with np.errstate(over="ignore"):
        w = np.where(seen, (np.where(seen, theta, 1.0) + EPS_RAD) ** -power, 0.0)
    if neighbours and len(theta) > neighbours:
        if len(theta) == neighbours + 1:
            nxt = theta.max(0)
        else:
            nxt = np.partition(theta.T, neighbours, axis=1)[:, neighbours]
        with np.errstate(invalid="ignore", divide="ignore"):
            taper = np.where(np.isfinite(nxt), np.clip(1 - theta / nxt, 0, None), 1.0)
        tapered = w * np.where(seen, taper, 0.0)
        # ties at the threshold (equal angles) would leave no weight: untapered there
        w = np.where((tapered.sum(0) > 0) | ~seen.any(0), tapered, w)
    return w


def _blend(X, C, photos, tolerance, power, neighbours, channels, reflection=None, faces=None):
    ray = _unit(X - C)
    theta = np.full((len(photos), len(X)), np.inf)
    samples = []
    for j, p in enumerate(photos):
        s, ok = _sample(p, X, tolerance)
        samples.append(s)
        theta[j, ok] = _angle_to(ray[ok], X[ok], p.centre)
    W = _weights(theta, power, neighbours)
    acc = np.zeros((len(X), channels))
    for j, s in enumerate(samples):
        acc += W[j][:, None] * s
    if reflection is not None:  # each sample moved to the new view by the layer
        from lumigraph.stereo.debevec1996.reflection import corrections

        for j, c in enumerate(corrections(reflection, X, faces, C, photos, which=W > 0)):
            if c is not None:
                acc += W[j][:, None] * c
    return acc, W.sum(0), (W > 0).sum(0), np.isfinite(theta).sum(0)


@dataclass(frozen=True)
class ViewMaps:
    """Every polygon's view map (Debevec, Yu & Borshukov 1998), built once
    for a mesh and its photographs by :func:`prepare_view_maps`: the
    photographs that see the polygon, their directions from its centroid
    projected onto its plane, and their Delaunay triangulation; the
    polygons' planes and each photograph's visibility of each plane (what
    rendering a new view reuses, :func:`_plane_masks`)."""

    centroids: np.ndarray
    axes: np.ndarray  # (M, 2, 3): the plane's u, w
    photos: tuple  # per polygon: ids of the photographs that see it
    points: tuple  # per polygon: (k, 2) projected directions
    triangulations: tuple  # per polygon: scipy Delaunay or None
    centres: np.ndarray  # (N, 3) the photographs' centres
    good: tuple = ()  # per polygon: which of its triangles are not slivers
    grid: np.ndarray | None = None  # (M, G, 3) points spread over each polygon
    grid_seen: np.ndarray | None = None  # (N, M, G) which photograph sees which point
    # the polygons' planes and each photograph's per-plane visibility (see _plane_masks)
    face_plane: np.ndarray | None = None  # (M,) plane of each polygon
    planes: np.ndarray | None = None  # (P, 4): unit normal n and offset d, n . X = d
    face_area: np.ndarray | None = None  # (M,)
    masks: tuple = ()  # per photograph, per plane: (x0, y0, uint8 crop) or None
    vertices: np.ndarray | None = None  # (V, 3) the mesh's
    plane_vertices: tuple = ()  # per plane: the indices of its polygons' corners

    def scores(self, C, *, power: float = DEFAULT_POWER, neighbours: int = DEFAULT_NEIGHBOURS,
               faces=None):
        """``(M, N)``: the weight the blend (:func:`_weights`, the same
        ``power`` and ``neighbours``) gives each photograph over each
        polygon's grid points for the view from ``C``, each point's weights
        summing to 1, then a millionth of the share of the points it sees
        (ties go to the photograph that sees more of the polygon). With
        ``faces`` (indices), those polygons' rows only (``(len(faces), N)``)."""
        grid, grid_seen = self.grid, self.grid_seen
        if faces is not None:
            grid, grid_seen = grid[faces], grid_seen[:, faces]
        M, G = grid.shape[:2]
        ray = _unit((grid - C).reshape(-1, 3))
        X = grid.reshape(-1, 3)
        theta = np.stack([np.where(grid_seen[i].ravel(), _angle_to(ray, X, c), np.inf)
                          for i, c in enumerate(self.centres)])
        W = _weights(theta, power, neighbours)
        W /= np.maximum(W.sum(0), 1e-300)
        score = W.reshape(len(self.centres), M, G).sum(2).T  # (M, N)
        score += 1e-6 * grid_seen.mean(2).T
        return score

    def choose(self, C, *, power: float = DEFAULT_POWER, neighbours: int = DEFAULT_NEIGHBOURS):
        """The three photographs of each polygon for the view from ``C``
        (``ids (M, 3)``, -1 = none): those the blend gives the most weight
        over the polygon's grid points (:meth:`scores`)."""
        return _top3(self.scores(C, power=power, neighbours=neighbours))

    def choose_planes(self, C, *, power: float = DEFAULT_POWER,
                      neighbours: int = DEFAULT_NEIGHBOURS, planes=None):
        """The three photographs of each plane (``ids (P, 3)``, -1 = none):
        the polygons' :meth:`scores` weighted by their area, summed over the
        plane's polygons. With ``planes`` (indices), for those only (the
        others' rows -1: a view asks for the planes it shows)."""
        faces = None if planes is None else np.flatnonzero(np.isin(self.face_plane, planes))
        score = self.scores(C, power=power, neighbours=neighbours, faces=faces)
        fp = self.face_plane if faces is None else self.face_plane[faces]
        score *= self.face_area[:, None] if faces is None else self.face_area[faces, None]
        plane = np.zeros((len(self.planes), score.shape[1]))
        np.add.at(plane, fp, score)
        return _top3(plane)

    def lookup(self, C, *, power: float = DEFAULT_POWER):
        """The at most three photographs and weights of each polygon for the
        view from ``C``: ``(ids (M, 3) int, -1 = none; weights (M, 3))``.
        Inside the map's hull, the containing triangle's corners with their
        barycentric weights; outside it, in a sliver triangle (smallest angle
        below :data:`SLIVER_DEG`) or with fewer than three, the three nearest
        by angle, weighted ``θ^−power``. (:func:`render_vdtm` takes its
        three from :meth:`choose`.)"""
        M = len(self.centroids)
        ids = np.full((M, 3), -1)
        wts = np.zeros((M, 3))
        dv = C - self.centroids
        dv /= np.linalg.norm(dv, axis=1, keepdims=True)
        q = np.einsum("mkj,mj->mk", self.axes, dv)
        for m in range(M):
            js = self.photos[m]
            if not len(js):
                continue
            d = self.triangulations[m]
            if d is not None:
                s = int(d.find_simplex(q[m]))
                if s >= 0 and self.good[m][s]:
                    T = d.transform[s]
                    b = T[:2] @ (q[m] - T[2])
                    bc = np.append(b, 1 - b.sum())
                    bc = np.where(bc > 1e-9, bc, 0.0)  # on a corner: that photograph alone
                    ids[m] = js[d.simplices[s]]
                    wts[m] = bc / bc.sum()
                    continue
            dirs = self.centres[js] - self.centroids[m]
            dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
            ang = np.arccos(np.clip(dirs @ dv[m], -1, 1))
            order = np.argsort(ang)[:3]
            wk = (ang[order] + EPS_RAD) ** -power
            ids[m, :len(order)] = js[order]
            wts[m, :len(order)] = wk / wk.sum()
        return ids, wts


def _top3(score, k=3):
    order = np.argsort(-score, axis=1, kind="stable")[:, :k]
    return np.where(np.take_along_axis(score, order, 1) > 0, order, -1)


def prepare_view_maps(mesh, photos, *, tolerance: float = 0.01) -> ViewMaps:
    """The view map of every polygon (triangle) of ``mesh``: a photograph
    enters a polygon's map when it sees the polygon in at least one pixel
    (its z-buffer's face ids, :func:`prepare_photographs`) or sees one of
    28 points spread over it (depth ``tolerance`` as :func:`render_vdtm`'s);
    with the polygons grouped by plane and each photograph's visibility of
    each plane (:func:`_plane_masks`). Built once per model and
    photographs, for any number of new views."""
    from scipy.spatial import Delaunay

    v, f = _mesh(mesh)
    photos = list(photos)
    tri = v[f]
    cen = tri.mean(1)
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    ref = np.where(np.abs(nrm[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    u = np.cross(nrm, ref)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(nrm, u)
    # a photograph sees a polygon when its z-buffer shows it, or when it sees one
    # of a grid of points on it: coplanar neighbours (the tower's front flush with
    # the house's) tie in depth and the z-buffer keeps one face id of the two
    g = np.array([(i, j) for i in range(7) for j in range(7 - i)], np.float64) / 6
    bc = np.stack([g[:, 0], g[:, 1], 1 - g.sum(1)], 1)
    grid = np.einsum("gk,mkc->mgc", bc, tri)
    grid = cen[:, None] + 0.98 * (grid - cen[:, None])  # off the outline
    # seen: the nearest pixel's depth agrees (looser than the bilinear taps: a
    # point near the polygon's outline at a coarse resolution still counts)
    grid_seen = np.stack([_seen_nearest(p, grid.reshape(-1, 3), tolerance).reshape(len(f), -1)
                          for p in photos])  # (N, M, G)
    sees = np.stack([p.face_pixels > 0 for p in photos], 1) | grid_seen.any(2).T  # (M, N)
    # the centroid joins the grid, counted as seen by every photograph that sees
    # the polygon (a small polygon's pixels can fall between the grid's points)
    grid = np.concatenate([grid, cen[:, None]], 1)
    grid_seen = np.concatenate([grid_seen, sees.T[..., None]], 2)
    centres = np.array([p.centre for p in photos])
    ids, pts, dels, good = [], [], [], []
    for m in range(len(f)):
        js = np.flatnonzero(sees[m])
        dirs = centres[js] - cen[m]
        dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-300)
        pm = np.stack([dirs @ u[m], dirs @ w[m]], 1)
        d = None
        if len(js) >= 3:
            try:
                d = Delaunay(pm)
            except Exception:  # collinear directions (QhullError): no triangle to locate in
                d = None
        ids.append(js)
        pts.append(pm)
        dels.append(d)
    # every polygon's triangles tested at once (the same values, one call)
    tris = [pm[d.simplices] if d is not None else np.zeros((0, 3, 2))
            for pm, d in zip(pts, dels, strict=True)]
    ok = _not_sliver(np.concatenate(tris)) if tris else np.zeros(0, bool)
    good = np.split(ok, np.cumsum([len(x) for x in tris])[:-1]) if tris else []
    fp, planes = _face_planes(v, f)
    corners = tuple(np.unique(f[fp == P]) for P in range(len(planes)))
    masks = tuple(_plane_masks(v, f, fp, planes, p, tolerance, corners) for p in photos)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return ViewMaps(cen, np.stack([u, w], 1), tuple(ids), tuple(pts), tuple(dels), centres,
                    tuple(good), grid, grid_seen, fp, planes, area, masks, v, corners)


def _seen_nearest(photo, X, tolerance):
    """(N,) bool: ``photo`` sees the points ``X`` at their nearest pixel (its
    depth within ``tolerance`` relative of theirs)."""
    q = X @ (np.asarray(photo.K, np.float64) @ np.asarray(photo.R, np.float64)).T
    q += np.asarray(photo.K, np.float64) @ np.asarray(photo.t, np.float64)
    h, w = photo.depth.shape
    z = q[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        px = np.rint(q[:, :2] / z[:, None])
    ok = (z > 0) & (px[:, 0] >= 0) & (px[:, 0] <= w - 1) & (px[:, 1] >= 0) & (px[:, 1] <= h - 1)
    xi = np.where(ok, px[:, 0], 0).astype(np.intp)
    yi = np.where(ok, px[:, 1], 0).astype(np.intp)
    return ok & (np.abs(photo.depth[yi, xi] - z) <= tolerance * np.abs(z))


def _not_sliver(tri, min_deg=SLIVER_DEG):
    """(T,) bool: the triangles ``tri`` (T, 3, 2) whose smallest angle is at
    least ``min_deg``: barycentric weights in a sliver blend photographs far
    apart (the photographs of a ring seen from a wall project to a line)."""
    angles = []
    for k in range(3):
        a = tri[:, (k + 1) % 3] - tri[:, k]
        b = tri[:, (k + 2) % 3] - tri[:, k]
        cos = np.einsum("ij,ij->i", a, b) / np.maximum(
            np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
        angles.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    return np.min(angles, axis=0) >= min_deg


def view_maps(mesh, photos, C, *, power=DEFAULT_POWER):
    """Per polygon (triangle), the at most three photographs and weights the
    view map gives the view from ``C`` (:meth:`ViewMaps.lookup` of
    :func:`prepare_view_maps`). Returns ``(ids (M, 3), weights (M, 3))``."""
    return prepare_view_maps(mesh, photos).lookup(C, power=power)


def _face_planes(v, f):
    """``(face_plane (M,), planes (P, 4))``: the polygons grouped by their
    plane (unit normal ``n`` and offset ``d``, ``n · X = d``; equal within
    1e-9, the offset relative to the model's extent). Coplanar polygons of
    different blocks (the tower's front flush with the house's) share one."""
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    d = np.einsum("ij,ij->i", n, tri[:, 0])
    scale = max(float(np.abs(v).max()) if len(v) else 1.0, 1e-300)
    fp = np.full(len(f), -1, np.int64)
    planes: list = []
    for m in range(len(f)):
        for k, (nk, dk) in enumerate(planes):
            if nk @ n[m] > 1 - 1e-9 and abs(dk - d[m]) <= 1e-9 * scale:
                fp[m] = k
                break
        else:
            fp[m] = len(planes)
            planes.append((n[m], d[m]))
    return fp, np.array([np.append(nk, dk) for nk, dk in planes]).reshape(-1, 4)


def _plane_masks(v, f, fp, planes, photo, tolerance, corners=None):
    """Per plane, where ``photo`` sees it (the 1998 paper's visibility,
    computed once per model and photograph): ``(x0, y0, crop)``, ``crop``
    uint8 over the plane's bounding box in the photograph, 255 at the pixels
    whose surface lies on the plane: the z-buffer shows one of the plane's
    polygons there or beside it (3x3: a bilinear cell across a crease, as
    the blend's continuity test) and the depth along the pixel's ray is the
    plane's within ``tolerance`` relative; else 0. ``None`` where the
    photograph sees none of it; 128 where the plane is seen so obliquely
    that its depth changes by more than ``2 · tolerance`` relative to the
    next pixel (the blend's cells, :func:`_cells`, reject such a cell). A
    bilinear sample of the crop is 255 only when every tap of non-zero
    weight sees the plane, as the blend's per-pixel test (:func:`_sample`);
    at the photograph's own pixel centres (one tap) 128 is seen too.
    ``corners``: per plane, the indices of its polygons' corners (found
    here when not given)."""
    import cv2

    h, w = photo.depth.shape
    K = np.asarray(photo.K, np.float64)
    R, t = np.asarray(photo.R, np.float64), np.asarray(photo.t, np.float64)
    Kinv = np.linalg.inv(K)
    face = photo.face
    if face is None:
        face = rasterize(v, f, K, R, t, (w, h), bary=False).face
    if corners is None:
        corners = tuple(np.unique(f[fp == P]) for P in range(len(planes)))
    # each pixel's plane (-1 off the model; int16 when it holds them: half the bytes
    # of the gather's output), and the planes the photograph shows at all (the others
    # have no pixel in any box)
    lut = np.append(fp, -1).astype(np.int16 if len(planes) < 2 ** 15 else np.int64)
    pid = np.take(lut, face)
    counts = photo.face_pixels
    if counts is None or photo.face is None:
        counts = np.bincount(face[face >= 0], minlength=len(f))
    shown = np.zeros(len(planes), bool)
    shown[fp[counts > 0]] = True
    out = []
    for P in range(len(planes)):
        if not shown[P]:
            out.append(None)
            continue
        vc = v[corners[P]] @ R.T + t
        if (vc[:, 2] <= 1e-12).any():  # reaches behind the camera: the whole frame
            x0, y0, x1, y1 = 0, 0, w - 1, h - 1
        else:
            px = vc @ K.T
            px = px[:, :2] / px[:, 2:]
            lo, hi = np.floor(px.min(0)) - 1, np.ceil(px.max(0)) + 1
            if (hi < 0).any() or lo[0] > w - 1 or lo[1] > h - 1:
                out.append(None)
                continue
            x0, y0 = min(max(int(lo[0]), 0), w - 1), min(max(int(lo[1]), 0), h - 1)
            x1, y1 = min(max(int(hi[0]), 0), w - 1), min(max(int(hi[1]), 0), h - 1)
        mine = (pid[y0:y1 + 1, x0:x1 + 1] == P).astype(np.uint8)
        if not mine.any():
            out.append(None)
            continue
        near = cv2.dilate(mine, np.ones((3, 3), np.uint8)) > 0
        rows, cols = np.flatnonzero(near.any(1)), np.flatnonzero(near.any(0))
        near = near[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
        y0, x0 = int(y0) + int(rows[0]), int(x0) + int(cols[0])
        h_, w_ = near.shape
        # the plane's inverse depth along each pixel's (unit z) ray is affine in the
        # pixel: u = n_c . K^-1 (x, y, 1) / d_c = A x + B y + c
        nc = R @ planes[P, :3]
        dc = planes[P, 3] + nc @ t
        A, B, c = (nc @ Kinv) / dc
        u = (A * np.arange(x0, x0 + w_))[None, :] + (B * np.arange(y0, y0 + h_) + c)[:, None]
        z = photo.depth[y0:y0 + h_, x0:x0 + w_]
        with np.errstate(divide="ignore", invalid="ignore"):
            zp = 1 / u
            on = near & np.isfinite(z) & (np.abs(z - zp) <= tolerance * z)
            # the plane seen this obliquely (its depth changing by more than twice the
            # tolerance to the next pixel: |1/(u + A) - 1/u| = |A / (u + A)| / u) is not
            # seen between pixel centres: the blend's cells (taps within 2 tolerance of
            # each other) reject it alike
            steep = ((np.abs(A) > 2 * tolerance * np.abs(u + A))
                     | (np.abs(B) > 2 * tolerance * np.abs(u + B)))
        # 255: seen; 128: seen, too obliquely for a sample between pixel centres
        out.append((x0, y0, np.where(on, np.where(steep, 128, 255), 0).astype(np.uint8)))
    return tuple(out)


def _same_camera(K, R, t, photo):
    """The new camera is ``photo``'s (within 1e-12 relative): its pixel
    centres fall on the photograph's, so a sample has one tap."""
    def near(a, b):
        a, b = np.asarray(a, np.float64), np.asarray(b, np.float64).reshape(np.shape(a))
        return bool(np.abs(a - b).max() <= 1e-12 * max(np.abs(a).max(), 1.0))

    return near(K, photo.K) and near(R, photo.R) and near(t, photo.t)


# the angles are computed on a grid of this many pixels per step over each plane and
# interpolated (they vary smoothly over a plane; 1998: per-vertex angles interpolated)
ANGLE_STEP_PX = 16


def _weights3(th, power, neighbours):
    """:func:`_weights` for at most three photographs, on float32 images
    ``th (k, H, W)`` (``inf`` = not seen; k <= 3): the same values, without
    the general partial sort (the caller silences inf/inf); and their sum
    over the photographs ``(H, W)``."""
    w = th + np.float32(EPS_RAD)
    if power == 1:
        np.reciprocal(w, out=w)  # inf -> 0: not seen
    else:
        np.power(w, np.float32(-power), out=w)
    if neighbours and len(th) > neighbours:
        a, b = th[0], th[1]
        c = th[2] if len(th) > 2 else np.float32(np.inf)
        if neighbours == 1:  # the middle one
            nxt = np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))
        else:
            nxt = np.maximum(np.maximum(a, b), c)
        # 1 - θ/θ_next, 0 at the next and beyond; 1 where no next is seen (θ/inf);
        # NaN (inf/inf, a photograph not seen) to 0
        q = th / nxt
        np.subtract(np.float32(1), q, out=q)
        np.fmax(q, np.float32(0), out=q)
        q *= w
        qs = q.sum(0)
        # equal angles at the threshold (every tapered weight 0 where one is seen): untapered
        tie = qs == 0
        if tie.any():
            tie &= w.sum(0) > 0
            if tie.any():
                q[:, tie] = w[:, tie]
                qs = q.sum(0)
        return q, qs
    return w, w.sum(0)


def _view_map_planes(plane, covered, K, R, t, C, ids, maps, photos, power, neighbours, channels,
                     background):
    """The view map's texturing (Debevec, Yu & Borshukov 1998): each plane of
    the model that the new view's z-buffer shows (``plane (H, W)``: the
    plane of the polygon seen at each pixel, -1 off the model; ``covered
    (M,)`` its polygons' pixels) is textured from its three photographs
    ``ids (P, 3)`` by projective texture mapping (one plane-induced
    homography per photograph: ``cv2.warpPerspective`` of the photograph and
    of its precomputed visibility of the plane), with the blend's weights
    among the three (:func:`_weights3`) from angles on a grid interpolated
    over the plane: no per-pixel depth test, world point or angle. Where
    fewer of the three see a point than the blend would take and other
    photographs see the plane, :func:`_plane_pixels`. Returns ``(image (H,
    W, C) float32, known (H, W) bool, count, one)``, ``count`` the number of
    photographs blended summed over the model's pixels, ``one`` the number
    of pixels that one photograph alone sees (``None`` where that is not
    known: with ``neighbours`` 0 or 1 a pixel one of the three sees is not
    tested against the others)."""
    import cv2

    h, w = plane.shape
    # zeros: each plane's weighted samples are added into its box in place (the
    # weights are 0 off the plane's pixels), no per-plane image and copy
    image = np.zeros((h, w, channels), np.float32)
    known = np.zeros((h, w), bool)
    count = 0
    one = 0  # pixels seen by one photograph alone; None once one such pixel is unsure
    K = np.asarray(K, np.float64)
    Kinv = np.linalg.inv(K)
    R = np.asarray(R, np.float64)
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    need = min(neighbours or 1, 3)
    # the photographs' cameras stacked (homographies per plane at once), and which
    # one the new view is (its pixel centres on the photograph's: one tap a sample)
    Ks = np.stack([np.asarray(p.K, np.float64) for p in photos])
    Rs = np.stack([np.asarray(p.R, np.float64) for p in photos])
    ts = np.stack([np.asarray(p.t, np.float64).reshape(3) for p in photos])
    centres = np.einsum("nji,nj->ni", Rs, -ts)
    own = [_same_camera(K, R, t, p) for p in photos]
    Rr = Rs @ R.T  # new camera frame to each photograph's
    tr = ts - Rr @ t
    cams = (Ks, Rr, tr, centres, own, Kinv)
    # each plane's projected bounding box (its polygons' corners), where it is looked for
    vc = maps.vertices @ R.T + t
    pv = vc @ K.T
    with np.errstate(divide="ignore", invalid="ignore"):
        pv = pv[:, :2] / pv[:, 2:]
    # the planes in the new camera's frame: n_c . x = d_c
    ncs = maps.planes[:, :3] @ R.T
    dcs = maps.planes[:, 3] + ncs @ t
    for P in np.unique(maps.face_plane[covered > 0]).tolist():
        masks = [m[P] for m in maps.masks]
        others = [j for j, m in enumerate(masks) if m is not None]
        if not others:
            continue
        js = [j for j in ids[P].tolist() if j >= 0 and masks[j] is not None]
        corners = maps.plane_vertices[P]
        if (vc[corners, 2] > 1e-12).all():
            c = pv[corners]
            lx, ly = max(int(np.floor(c[:, 0].min())) - 1, 0), max(int(np.floor(c[:, 1].min())) - 1, 0)
            hx, hy = min(int(np.ceil(c[:, 0].max())) + 2, w), min(int(np.ceil(c[:, 1].max())) + 2, h)
            if hx <= lx or hy <= ly:
                continue
        else:
            lx, ly, hx, hy = 0, 0, w, h
        band = plane[ly:hy, lx:hx] == P
        rows, cols = np.flatnonzero(band.any(1)), np.flatnonzero(band.any(0))
        if not len(rows):
            continue
        y0, y1 = ly + int(rows[0]), ly + int(rows[-1]) + 1
        x0, x1 = lx + int(cols[0]), lx + int(cols[-1]) + 1
        inP = band[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
        bh, bw = inP.shape
        if not js or (len(others) > len(js) and bh * bw < SMALL_PLANE_PX
                      and inP.sum() < SMALL_PLANE_PX // 4):
            # none of the three sees the plane, or a few pixels (a sliver): the three
            # chosen over the whole plane may miss the photographs nearest these, and
            # warping costs more than asking all
            c, o = _plane_put(image, known, *np.nonzero(inP), x0, y0, K, R, t, C, maps, P,
                              others, photos, power, neighbours, channels, cams)
            count += c
            one = None if one is None else one + o
            continue
        nc, dc = ncs[P], dcs[P]
        # the angles on a grid placed as cv2.resize's linear upsampling samples it
        gw, gh = max(1, round(bw / ANGLE_STEP_PX)), max(1, round(bh / ANGLE_STEP_PX))
        gx = (np.arange(gw) + 0.5) * (bw / gw) + (x0 - 0.5)
        gy = (np.arange(gh) + 0.5) * (bh / gh) + (y0 - 0.5)
        r = (Kinv[:, 0] * gx[:, None])[None] + (Kinv[:, 1] * gy[:, None] + Kinv[:, 2])[:, None]
        r = r.reshape(-1, 3)
        X = ((r * (dc / (r @ nc))[:, None]) - t) @ R
        # the plane-induced homographies K_j (R_rel + t_rel n_c^T / d_c) K^-1 T, at once
        T = np.array([[1.0, 0, x0], [0, 1, y0], [0, 0, 1]])
        Hs = Ks[js] @ (Rr[js] + tr[js][:, :, None] * (nc / dc)[None, None, :]) @ (Kinv @ T)
        # the same into each mask's crop
        Hm = Hs.copy()
        off = np.array([masks[j][:2] for j in js], np.float64)
        Hm[:, :2] -= off[:, :, None] * Hs[:, 2][:, None, :]
        # the plane behind a photograph (its homogeneous w <= 0) is not seen there
        wz = Hs[:, 2] @ np.array([[0, bw - 1, 0, bw - 1], [0, 0, bh - 1, bh - 1], [1.0, 1, 1, 1]])
        behind = (wz <= 0).any(1).tolist()
        # the angles at the grid points (_angle_to, for every photograph at once)
        ray = _unit(X - C)
        dj = X[None] - centres[js][:, None]
        dj /= np.linalg.norm(dj, axis=2, keepdims=True)
        dj -= ray[None]
        ang = (2 * np.arcsin(np.minimum(np.sqrt(np.einsum("kgi,kgi->kg", dj, dj)) / 2, 1.0))
               ).astype(np.float32)
        th = np.empty((len(js), bh, bw), np.float32)
        for k, j in enumerate(js):
            vis = cv2.warpPerspective(masks[j][2], Hm[k], (bw, bh), flags=flags,
                                      borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            vis = vis < 128 if own[j] else vis < 255  # not seen
            if behind[k]:
                H = Hs[k]
                vis |= (H[2, 0] * np.arange(bw)[None] + H[2, 1] * np.arange(bh)[:, None]
                        + H[2, 2]) <= 0
            cv2.resize(ang[k].reshape(gh, gw), (bw, bh), dst=th[k], interpolation=cv2.INTER_LINEAR)
            np.copyto(th[k], np.float32(np.inf), where=vis)
        if len(js) <= 3:
            W, ws = _weights3(th, power, neighbours)
        else:
            W = _weights(th.reshape(len(js), -1), power, neighbours).reshape(th.shape).astype(np.float32)
            ws = W.sum(0)
        ok = inP & (ws > 0)
        # normalised on the plane's seen pixels, 0 elsewhere in the box (w / inf; no
        # weight is infinite): one plain division
        W /= np.where(ok, ws, np.float32(np.inf))
        # the photographs warped where they have weight only (with the blend's taper,
        # the third nearest has none wherever the two nearer ones see the point),
        # their weighted samples added into the frame
        for k, j in enumerate(js):
            Wk = W[k]
            rows = np.flatnonzero(Wk.any(1))
            if not len(rows):
                continue
            ya, yb = int(rows[0]), int(rows[-1]) + 1
            cols = np.flatnonzero(Wk[ya:yb].any(0))
            xa, xb = int(cols[0]), int(cols[-1]) + 1
            H = Hs[k] @ np.array([[1.0, 0, xa], [0, 1, ya], [0, 0, 1]])
            smp = _warp(photos[j].image, H, (xb - xa, yb - ya))
            smp = smp.reshape(yb - ya, xb - xa, channels)
            smp *= Wk[ya:yb, xa:xb, None]
            image[y0 + ya:y0 + yb, x0 + xa:x0 + xb] += smp
        has = W > 0
        count += int(np.count_nonzero(has))
        known[y0:y1, x0:x1] |= ok
        # seen by one: exact where the three are every photograph that sees the plane;
        # else the pixels that fewer than `need` of the three see are asked of all below,
        # and with need = 1 a pixel one of the three sees is not
        lone = inP & (np.isfinite(th).sum(0, dtype=np.int8) == 1)
        if len(others) == len(js):
            one = None if one is None else one + int(np.count_nonzero(lone))
        elif need < 2 and lone.any():
            one = None
        # where fewer of the three see the point than the blend would take (the plane
        # partly hidden from them) and other photographs see some of the plane: those
        # pixels blended from every photograph that sees the plane (as the blend)
        if len(others) > len(js):
            n = has.sum(0, dtype=np.int8)
            yy, xx = np.nonzero(inP & (n < need))
            if len(yy):
                count -= int(n[yy, xx].sum(dtype=np.int64))
                c, o = _plane_put(image, known, yy, xx, x0, y0, K, R, t, C, maps, P, others,
                                  photos, power, neighbours, channels, cams)
                count += c
                one = None if one is None else one + o
    if background != 0:
        image[~known] = background
    return image, known, count, one


def _warp(image, H, size, maps=None):
    """``image`` (H, W[, C]) as float32 warped by the inverse map ``H``
    (new-view pixel to photograph pixel, ``cv2.warpPerspective``) onto
    ``size``, or sampled at ``maps = (mx, my)`` (``cv2.remap``); bilinear,
    border replicated (as :func:`_sample`), at most four channels a call."""
    import cv2

    img = image if image.dtype == np.float32 else np.asarray(image, np.float32)

    def one(a):
        if maps is not None:
            return cv2.remap(a, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return cv2.warpPerspective(a, H, size, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                   borderMode=cv2.BORDER_REPLICATE)

    if img.ndim == 2 or img.shape[2] <= 4:
        return one(img)
    parts = [one(np.ascontiguousarray(img[..., c:c + 4])) for c in range(0, img.shape[2], 4)]
    return np.concatenate([q[..., None] if q.ndim == 2 else q for q in parts], -1)


# a plane showing fewer pixels than a quarter of this (in a box under this) is textured
# pixel by pixel from every photograph that sees it (_plane_pixels)
SMALL_PLANE_PX = 256


def _plane_put(image, known, yy, xx, x0, y0, *args):
    """:func:`_plane_pixels` of the box pixels ``(yy, xx)`` (offset ``x0,
    y0``) written into the frame's ``image`` and ``known``; returns the
    number of photographs blended summed over the pixels and the number of
    pixels one photograph alone sees."""
    yy, xx = yy + y0, xx + x0
    a, ws, c, seers = _plane_pixels(xx, yy, *args)
    good = ws > 0
    image[yy, xx] = np.where(good[:, None], a / np.where(good, ws, 1.0)[:, None], 0.0)
    known[yy, xx] = good
    return int(c.sum()), int(np.count_nonzero(seers == 1))


def _plane_pixels(xs, ys, K, R, t, C, maps, P, js, photos, power, neighbours, channels, cams):
    """The pixels ``(xs, ys)`` of the plane ``P`` blended from the
    photographs ``js`` as the blend does (every one that sees the point, the
    blend's weights from exact angles), visibility from the planes' masks:
    ``(acc (n, C), wsum (n,), count (n,), seers (n,))``: the number blended
    and the number of ``js`` that see each point. ``cams``: the photographs'
    ``K`` stacked, the rotations and translations from the new camera's
    frame to theirs, their centres, which is the new view, and ``K⁻¹``."""
    import cv2

    Ks, Rr, tr, centres, own, Kinv = cams
    n = len(xs)
    p3 = np.stack([xs, ys, np.ones(n)], 1).astype(np.float64)
    r = p3 @ Kinv.T
    nc = R @ maps.planes[P, :3]
    dc = maps.planes[P, 3] + nc @ t
    X = ((r * (dc / (r @ nc))[:, None]) - t) @ R
    ray = _unit(X - C)
    # every photograph's homography, pixel positions and angles at once
    Hs = Ks[js] @ (Rr[js] + tr[js][:, :, None] * (nc / dc)[None, None, :]) @ Kinv
    q = p3 @ Hs.transpose(0, 2, 1)  # (k, n, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (q[..., :2] / q[..., 2:]).astype(np.float32)
    d = X[None] - centres[js][:, None]
    d /= np.sqrt((d * d).sum(2))[..., None]
    d -= ray[None]
    ang = 2 * np.arcsin(np.minimum(np.sqrt((d * d).sum(2)) / 2, 1.0))
    th = np.full((len(js), n), np.inf)
    samples = []
    for k, j in enumerate(js):
        p = photos[j]
        mx0, my0, crop = maps.masks[j][P]
        vis = cv2.remap(crop, (uv[k, :, 0] - mx0)[None], (uv[k, :, 1] - my0)[None],
                        cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)[0]
        vis = (vis >= 128 if own[j] else vis == 255) & (q[k, :, 2] > 0)
        s = _warp(p.image, None, None, maps=(uv[k, :, 0][None], uv[k, :, 1][None]))
        samples.append(s.reshape(n, channels))
        th[k, vis] = ang[k, vis]
    W = _weights(th, power, neighbours)
    acc = np.zeros((n, channels))
    for k, s in enumerate(samples):
        acc += W[k][:, None] * s
    return acc, W.sum(0), (W > 0).sum(0), np.isfinite(th).sum(0)


def fill_holes(image: np.ndarray, known: np.ndarray, region: np.ndarray) -> np.ndarray:
    """``image`` (H, W, C) with the pixels of ``region`` that are not
    ``known`` filled by push–pull: weighted means over a pyramid of 2×2
    blocks, the finest level that has data used (Gortler et al., "The
    Lumigraph", SIGGRAPH 1996). Known pixels are unchanged; float32 in,
    float32 out, else float64."""
    out = np.array(image, np.float32 if np.asarray(image).dtype == np.float32 else np.float64,
                   copy=True)
    return _fill_inplace(out, known, region)


def _fill_inplace(out, known, region):
    """:func:`fill_holes` into ``out`` itself (float32 or float64)."""
    hole = region & ~known
    if not hole.any() or not known.any():
        return out
    # only the region's bounding box takes part (the rest is outside the model)
    rows, cols = np.flatnonzero(region.any(1)), np.flatnonzero(region.any(0))
    box = np.s_[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    if not known[box].any():
        box = np.s_[:, :]
    _push_pull(out[box], known[box], hole[box], inplace=True)  # out[box] is a view of out
    return out


def _resize(a, size, interp):
    """``cv2.resize`` of an (H, W, C) array keeping the channel axis (at most
    four channels a call)."""
    import cv2

    out = [cv2.resize(np.ascontiguousarray(a[..., c:c + 4]), size, interpolation=interp)
           for c in range(0, a.shape[2], 4)]
    out = [o[..., None] if o.ndim == 2 else o for o in out]
    return out[0] if len(out) == 1 else np.concatenate(out, 2)


def _push_pull(image, known, hole, *, inplace=False):
    """Push–pull of the holes (:func:`fill_holes`; into ``image`` itself
    with ``inplace``), computed on the aligned
    tiles of 2^L pixels that hold holes only: a hole's value depends only on
    its aligned blocks (level l: the 2^l block of the box holding it) up to
    the coarsest level the whole box's pyramid builds, or up to the first
    level where the block's weight is full (its coarser levels then have no
    share). Tiles of 16 pixels first, twice that for the holes they leave
    open, and so on. Equals :func:`_push_pull_full` up to float rounding."""
    h, w = known.shape
    # the level the whole box's pyramid stops at: every block holds a known pixel,
    # or a side of one block is a pixel
    k, top = known, 0
    while min(k.shape) > 1 and not k.all():
        k = _half_any(k)
        top += 1
    out = image if inplace else np.array(image, copy=True)
    hy, hx = np.nonzero(hole)
    levels = min(top, TILE_LEVELS)
    while len(hy):
        val, exact = _push_pull_tiles(image, known, hy, hx, levels, levels == top)
        out[hy[exact], hx[exact]] = val[exact]
        hy, hx = hy[~exact], hx[~exact]
        levels = min(top, levels + 1)
    return out


def _half_any(k):
    """``k (H, W)`` bool, its 2x2 blocks (zero-padded to even sides) any-ed:
    four strided views or-ed (a reduction over the small axes of a reshape
    costs several times more)."""
    h, w = k.shape
    a = k[0::2, 0::2].copy()
    a[:h // 2] |= k[1::2, 0::2]
    a[:, :w // 2] |= k[0::2, 1::2]
    a[:h // 2, :w // 2] |= k[1::2, 1::2]
    return a


def _push_pull_tiles(image, known, hy, hx, levels, at_top):
    """The push-pull values at the holes ``(hy, hx)`` from their aligned
    tiles of ``2^levels`` pixels, and which are exact (``at_top``: the whole
    box's pyramid stops at this level; else the hole's chain of blocks
    reaches full weight within the tile)."""
    h, w = known.shape
    n = 2 ** levels
    per_row = -(-w // n)
    key = (hy // n) * per_row + hx // n
    tiles, at = np.unique(key, return_inverse=True)
    ty, tx = tiles // per_row, tiles % per_row
    ys = ty[:, None] * n + np.arange(n)  # (T, n)
    xs = tx[:, None] * n + np.arange(n)
    inside = (ys < h)[:, :, None] & (xs < w)[:, None, :]
    yc, xc = np.minimum(ys, h - 1)[:, :, None], np.minimum(xs, w - 1)[:, None, :]
    wg = (known[yc, xc] & inside).astype(np.float32)[..., None]
    im = np.where(wg > 0, image[yc, xc], 0).astype(np.float32)
    pyramid = [(im, wg)]
    for _ in range(levels):
        T, m = im.shape[0], im.shape[1] // 2
        s = (im * wg).reshape(T, m, 2, m, 2, -1).sum((2, 4)) * np.float32(0.25)
        ws = wg.reshape(T, m, 2, m, 2, 1).sum((2, 4)) * np.float32(0.25)
        with np.errstate(divide="ignore", invalid="ignore"):
            im = np.where(ws > 0, s / ws, np.float32(0))
        wg = np.minimum(4 * ws, np.float32(1))
        pyramid.append((im, wg))
    up = pyramid[-1][0]
    exact = (pyramid[-1][1] == 1) | at_top
    for im, wg in reversed(pyramid[:-1]):
        up = wg * im + (1 - wg) * up.repeat(2, 1).repeat(2, 2)
        exact = exact.repeat(2, 1).repeat(2, 2) | (wg == 1)
    iy, ix = hy - ty[at] * n, hx - tx[at] * n
    return up[at, iy, ix], exact[at, iy, ix, 0]


# the push-pull's first tiles: 2^TILE_LEVELS pixels a side
TILE_LEVELS = 4


def _push_pull_full(image, known, hole):
    import cv2

    img = np.where(known[..., None], image, 0.0).astype(np.float32)
    wgt = known.astype(np.float32)[..., None]
    levels = [(img, wgt)]
    while min(img.shape[:2]) > 1 and wgt.min() == 0:
        h, w = img.shape[:2]
        ph, pw = h % 2, w % 2
        im = img * wgt
        wg = wgt
        if ph or pw:
            im = np.pad(im, ((0, ph), (0, pw), (0, 0)))
            wg = np.pad(wg, ((0, ph), (0, pw), (0, 0)))
        half = (im.shape[1] // 2, im.shape[0] // 2)
        # 2x2 block means (INTER_AREA at exactly half the size): their ratio is the
        # weighted mean, four times the weight mean the block's weight
        s = _resize(im, half, cv2.INTER_AREA)
        ws = _resize(wg, half, cv2.INTER_AREA)
        img = np.where(ws > 0, s / np.maximum(ws, 1e-30), 0.0).astype(np.float32)
        wgt = np.minimum(4 * ws, 1.0)
        levels.append((img, wgt))
    up = levels[-1][0]
    for im, wg in reversed(levels[:-1]):
        h, w = im.shape[:2]
        coarse = _resize(up, (2 * up.shape[1], 2 * up.shape[0]), cv2.INTER_NEAREST)[:h, :w]
        up = wg * im + (1 - wg) * coarse
    out = np.array(image, copy=True)
    out[hole] = up[hole]
    return out


_SOLIDS: dict = {}


def _outward_solids(v, f) -> bool:
    """The mesh is a union of closed solids, each consistently oriented
    with its normals outward: every directed edge once and its reverse once,
    and every connected part of positive volume (the last few meshes'
    answers kept)."""
    key = (v.tobytes(), f.tobytes())
    if key in _SOLIDS:
        return _SOLIDS[key]
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(v)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    fwd, rev = e[:, 0] * n + e[:, 1], e[:, 1] * n + e[:, 0]
    ok = bool(len(f)) and len(np.unique(fwd)) == len(fwd) and np.array_equal(np.sort(fwd),
                                                                             np.sort(rev))
    if ok:
        _, label = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])),
                                                   shape=(n, n)), directed=False)
        tri = v[f]
        vol = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))
        ok = bool((np.bincount(label[f[:, 0]], weights=vol) > 0).all())
    if len(_SOLIDS) >= 4:
        _SOLIDS.pop(next(iter(_SOLIDS)))
    _SOLIDS[key] = ok
    return ok


def _zbuffer(v, f, K, R, t, size, rays, labels=None):
    """The new view's z-buffer (:func:`rasterize`, no barycentrics; ``face``
    holds ``labels[m]`` for triangle ``m`` when given). When the
    mesh is a union of closed outward-facing solids (:func:`_outward_solids`)
    and the camera is outside all of them (the winding number of the
    surface around the centre, the sum of the triangles' solid angles over
    4π, is 0), the triangles facing away are left out: a ray reaching one
    has entered its solid through a nearer face of it, so none of them
    shows (the same depth; at an edge a tie may keep the front face's id
    where the back face's was kept)."""
    C = -R.T @ t
    if len(f) and _outward_solids(v, f):
        a, b, c = v[f[:, 0]] - C, v[f[:, 1]] - C, v[f[:, 2]] - C
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        num = np.einsum("ij,ij->i", a, np.cross(b, c))  # < 0: the face looks at C
        den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc
               + np.einsum("ij,ij->i", a, c) * lb + np.einsum("ij,ij->i", b, c) * la)
        winding = np.arctan2(num, den).sum() / (2 * np.pi)  # van Oosterom & Strackee 1983
        if abs(winding) < 0.5:
            keep = np.flatnonzero(num < 0)
            # the kept triangles' own ids (or labels) written by the rasteriser: no
            # pass over the frame to map them back
            r = rasterize(v, f[keep], K, R, t, size, rays=rays, bary=False,
                          labels=keep if labels is None else np.asarray(labels)[keep])
            covered = np.zeros(len(f), np.int64)
            covered[keep] = r.covered
            return replace(r, covered=covered)
    return rasterize(v, f, K, R, t, size, rays=rays, bary=False, labels=labels)


_RAYS: dict = {}


def _rays(K, size):
    """:func:`pixel_rays`, the last few cameras' kept (a viewer renders one
    camera size again and again)."""
    key = (np.asarray(K, np.float64).tobytes(), tuple(size))
    r = _RAYS.get(key)
    if r is None:
        if len(_RAYS) >= 4:
            _RAYS.pop(next(iter(_RAYS)))
        r = _RAYS[key] = pixel_rays(K, size)
        r.flags.writeable = False
    return r


def _mesh_and_photographs(mesh, photographs, tolerance):
    """``(vertices, faces, photographs, channels)``: the mesh checked, the
    photographs as a list, prepared when they have no depth maps, and their
    common number of channels (``InputError`` naming ``photographs`` when
    there are none or their channels differ)."""
    v, f = _mesh(mesh)
    photos = list(photographs)
    if not photos:
        raise InputError("photographs", "no photographs: VDTM needs at least one")
    if any(p.depth is None or p.whole is None for p in photos):
        photos = list(prepare_photographs((v, f), photos, tolerance=tolerance))
    first = np.asarray(photos[0].image)
    channels = 1 if first.ndim == 2 else first.shape[2]
    for i, p in enumerate(photos):
        img = np.asarray(p.image)
        if (1 if img.ndim == 2 else img.shape[2]) != channels:
            raise InputError("photographs", f"photograph {i} has {1 if img.ndim == 2 else img.shape[2]} "
                                            f"channels, photograph 0 has {channels}")
    return v, f, photos, channels


def render_vdtm(mesh, photographs, K, R, t, size, *, method: str = "blend",
                tolerance: float = 0.01, power: float = DEFAULT_POWER,
                neighbours: int = DEFAULT_NEIGHBOURS, background: float = 0.0,
                fill: bool = True, maps: ViewMaps | None = None,
                reflection=None) -> VDTMImage:
    """Render ``mesh`` from the camera ``K, R, t`` (``x_cam = R x_world +
    t``, ``size = (W, H)``) textured from ``photographs`` (see the module
    docstring for both methods).

    Parameters
    ----------
    mesh : ``(vertices, faces)`` or an object with ``vertices``/``faces``
        World coordinates.
    photographs : sequence of Photograph
        As :func:`prepare_photographs` returns them (with depth maps; those
        without are prepared here).
    method : {"blend", "view-map"}
    tolerance : float
        Visibility: relative depth difference still "the same surface".
    power : float
        Weights ``θ^−power``; 1 (the default) is the paper's.
    neighbours : int
        Only the ``neighbours`` nearest photographs by angle blend, tapered
        to 0 at the next nearest (:data:`DEFAULT_NEIGHBOURS`, chosen on the
        glossy facade scene); 0: every photograph that sees the point.
    background : float
        Value off the model.
    fill : bool
        Fill holes (model pixels no photograph sees).
    maps : ViewMaps, optional
        ``"view-map"``: the polygons' view maps, built once for many views
        by :func:`prepare_view_maps` (built here when not given).
    reflection : ReflectionLayer, optional
        ``"blend"``: move each photograph's sample to the new view by the
        reflection layer fitted to these photographs
        (:func:`~lumigraph.stereo.debevec1996.reflection.fit_reflection_layer`)
        before blending.

    Returns
    -------
    VDTMImage
        Float32 image with the photographs' channels, model and hole masks.
    """
    if method not in METHODS:
        raise InputError("method", f"expected one of {', '.join(METHODS)}, got {method!r}")
    if reflection is not None and method != "blend":
        raise InputError("reflection", "the reflection layer corrects the blend's samples: "
                                       "use method='blend'")
    if not (np.isfinite(tolerance) and tolerance > 0):
        raise InputError("tolerance", f"expected a positive relative depth tolerance, got {tolerance}")
    if not (np.isfinite(power) and power > 0):
        raise InputError("power", f"expected a positive weight exponent, got {power}")
    if isinstance(neighbours, bool) or not isinstance(neighbours, (int, np.integer)) or neighbours < 0:
        raise InputError("neighbours", f"expected a whole number >= 0 (0 = every photograph), "
                                       f"got {neighbours!r}")
    v, f, photos, channels = _mesh_and_photographs(mesh, photographs, tolerance)
    w, h = (int(s) for s in size)
    R = np.asarray(R, np.float64)
    t = np.asarray(t, np.float64).reshape(3)
    C = -R.T @ t
    t0 = time.perf_counter()
    rays = _rays(K, (w, h))
    if method == "view-map" and maps is None:
        maps = prepare_view_maps((v, f), photos, tolerance=tolerance)
    # the view map asks for each pixel's plane rather than its polygon
    r = _zbuffer(v, f, K, R, t, (w, h), rays,
                 labels=maps.face_plane if method == "view-map" else None)
    t1 = time.perf_counter()
    model = r.hit

    def points(at):  # the world points of the model pixels ``at``: their rays scaled to the depth
        Xc = rays.reshape(-1, 3)[at] * r.depth.ravel()[at, None]
        return (Xc - t) @ R  # R^T (x_cam - t)

    if method == "blend":
        idx = np.flatnonzero(model.ravel())
        acc, wsum, n, seers = _blend(points(idx), C, photos, tolerance, power, neighbours,
                                     channels, reflection,
                                     r.face.ravel()[idx] if reflection is not None else None)
        per_pixel = float(n.mean()) if len(n) else 0.0
        # where one photograph sees the point, its colour is that photograph's at
        # every view: nothing there can follow the view (highlights, reflections)
        seen_by_one = float((seers == 1).mean()) if len(seers) else 0.0
    else:
        ids = maps.choose_planes(C, power=power, neighbours=neighbours,
                                 planes=np.unique(maps.face_plane[r.covered > 0]))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            out, known, n, one = _view_map_planes(r.face, r.covered, K, R, t, C, ids, maps,
                                                  photos, power, neighbours, channels,
                                                  float(background))
        per_pixel = float(n / max(model.sum(), 1))
        seen_by_one = None if one is None else one / max(int(model.sum()), 1)
    t2 = time.perf_counter()
    if method == "blend":
        seen = wsum > 0
        out = np.full((h * w, channels), float(background), np.float32)
        out[idx[seen]] = acc[seen] / wsum[seen, None]
        known = np.zeros(h * w, bool)
        known[idx[seen]] = True
        out = out.reshape(h, w, channels)
        known = known.reshape(h, w)
    filled = model & ~known
    if fill and filled.any() and known.any():
        out = _fill_inplace(out, known, model)  # out is this call's own
    elif not fill:
        filled = np.zeros_like(model)
    t3 = time.perf_counter()
    info = {"method": method, "reflection": reflection is not None, "tolerance": tolerance, "power": power, "neighbours": neighbours,
            "photographs": len(photos),
            "photographs_per_pixel": per_pixel,
            "seen_by_one_fraction": seen_by_one,
            "hole_fraction": float(filled.sum() / max(model.sum(), 1)),
            "timings_s": {"rasterize": t1 - t0, "texture": t2 - t1, "fill": t3 - t2}}
    return VDTMImage(out.astype(np.float32, copy=False), model, filled, info)


def load_posed_camera(path):
    """A ``camera.json`` with its pose, ``"cam_from_world": {"R": 3x3, "t":
    [3]}`` (as ``lumigraph stereo facade solve`` writes per photograph and
    ``lumigraph render facade`` per view): ``(Camera, R, t)``.
    :class:`InputError` naming the file and the key: not a camera, no pose,
    ``R`` not a rotation, ``t`` not 3 finite numbers."""
    from lumigraph.capture.camera import Camera
    from lumigraph.capture.rig import require_rotation
    from lumigraph.capture.schema import require

    cam = Camera.load(path)
    pose = cam.extra.get("cam_from_world")
    if not isinstance(pose, dict):
        raise InputError(path, "key 'cam_from_world': missing; expected the camera's pose "
                               "{\"R\": 3x3, \"t\": [3]} (x_cam = R x_world + t)")
    R = require_rotation(pose, "R", path=path, where="cam_from_world")
    t = require(pose, "t", "matrix", shape=(3,), path=path, where="cam_from_world")
    return cam, np.asarray(R, float), np.asarray(t, float)


def load_model_mesh(path):
    """The mesh of a block model file: ``blocks.json``, or a solve's
    ``model.json`` (its fitted parameter values applied to the
    ``blocks.json`` beside it). Returns ``(mesh, model.json body or None)``."""
    from pathlib import Path

    from lumigraph.capture.artifact import load_json_artifact
    from lumigraph.stereo.debevec1996.model import load_blocks

    p = Path(path)
    body = load_json_artifact(p, "model", schemas=None) if p.is_file() else None
    if body is not None and body.get("schema") == "lumigraph.facade.model":
        blocks = p.parent / "blocks.json"
        if not blocks.is_file():
            raise InputError(p, f"a model.json needs its blocks.json beside it ({blocks} not found)")
        model = load_blocks(blocks)
        params = body.get("parameters")
        if not isinstance(params, dict):
            raise InputError(p, "key 'parameters': expected {name: {\"value\": ...}}")
        values = {}
        for n, v in params.items():
            if n in model.parameter_names:
                if not (isinstance(v, dict) and isinstance(v.get("value"), (int, float))):
                    raise InputError(p, f"key 'parameters.{n}': expected {{\"value\": number}}")
                values[n] = float(v["value"])
        return model.with_values(values).mesh(), body
    return load_blocks(p).mesh(), None


def load_fitted_model(path):
    """A solve's ``model.json`` as ``(BlockModel with the fitted values,
    {free name: value}, covariance (n, n) in that order)``: the covariance
    from its ``"parameter_covariance"``, or the ``"std"`` of each parameter
    squared on the diagonal (an older file). :class:`InputError` naming the
    file when it is not a solve's model.json (a blocks.json has no σ)."""
    from pathlib import Path

    from lumigraph.capture.artifact import load_json_artifact
    from lumigraph.stereo.debevec1996.model import load_blocks

    p = Path(path)
    body = load_json_artifact(p, "model", schemas=None) if p.is_file() else None
    if body is None or body.get("schema") != "lumigraph.facade.model":
        raise InputError(p, "expected a solve's model.json (fitted values with their standard "
                            "deviations); a blocks.json has no uncertainty")
    blocks = p.parent / "blocks.json"
    if not blocks.is_file():
        raise InputError(p, f"a model.json needs its blocks.json beside it ({blocks} not found)")
    mesh_model = load_blocks(blocks)
    params = body.get("parameters")
    names = list(mesh_model.parameter_names)
    try:
        values = {n: float(params[n]["value"]) for n in names}
        std = np.array([float(params[n]["std"]) for n in names])
    except (TypeError, KeyError, ValueError):
        raise InputError(p, "key 'parameters': expected {name: {\"value\": v, \"std\": s}} for "
                            f"every free parameter ({', '.join(names)})") from None
    cov = np.diag(std ** 2)
    pc = body.get("parameter_covariance")
    if isinstance(pc, dict) and pc.get("names") == names:
        m = np.asarray(pc.get("matrix"), dtype=float)
        if m.shape != (len(names), len(names)) or not np.isfinite(m).all():
            raise InputError(p, f"key 'parameter_covariance.matrix': expected a finite "
                                f"{len(names)}x{len(names)} matrix")
        cov = m
    return mesh_model.with_values(values), values, cov


def rig_between(key, offset):
    """The stereo rig of two posed cameras ``(Camera, R, t)`` (as
    :func:`load_posed_camera` returns them): left = ``key``, right =
    ``offset``, ``x_offset = R_rel x_key + T`` with ``R_rel = R_o R_kᵀ``,
    ``T = t_o − R_rel t_k`` — what ``lumigraph stereo model-based --rig``
    takes for a key/offset pair of a Façade solve.

    >>> from lumigraph.capture.camera import Camera
    >>> c = Camera(np.diag([100.0, 100, 1]), [], (64, 48))
    >>> rig = rig_between((c, np.eye(3), np.zeros(3)), (c, np.eye(3), np.array([-0.5, 0, 0])))
    >>> rig.T.tolist()
    [-0.5, 0.0, 0.0]
    """
    from lumigraph.capture.rig import Rig

    (ck, Rk, tk), (co, Ro, to) = key, offset
    R = np.asarray(Ro, float) @ np.asarray(Rk, float).T
    T = np.asarray(to, float) - R @ np.asarray(tk, float)
    if not np.linalg.norm(T) > 0:
        raise InputError("offset", "the two cameras share their centre: no baseline for stereo")
    return Rig.from_pose(ck, co, R, T)
