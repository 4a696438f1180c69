"""A z-buffer rasteriser of a triangle mesh: exact depth, face id and
perspective-correct barycentrics per pixel.

On the ground floor because the synthetic scenes render through it (the
Façade building, ``capture.scenes.facade``) as well as the stereo stage
(a model's depth for model-based stereo and visibility for view-dependent
texture mapping, ``lumigraph.stereo.debevec1996.raster``).

Method: homogeneous rasterisation (M. Olano and T. Greer, "Triangle scan
conversion using 2D homogeneous coordinates", Graphics Hardware 1997). With
the triangle's corners ``a, b, c`` in the camera frame (``x_cam = R x_world +
t``) and the pixel's unit-``z`` ray ``r = K⁻¹ (x, y, 1)`` (lens distortion
inverted by :meth:`Camera.unproject`), write ``r = α a + β b + γ c``:

    α = det(r, b, c) / det(a, b, c),  β = det(a, r, c) / det(a, b, c),
    γ = det(a, b, r) / det(a, b, c)

The ray meets the triangle in front of the camera iff ``α, β, γ ≥ 0``; the
hit is ``X = r / (α + β + γ)``, so its depth (camera ``z``) is exactly
``z = 1 / (α + β + γ)`` and ``(α, β, γ) z`` are its barycentrics —
perspective-correct by construction, with no near-plane clipping (a triangle
crossing the camera plane is handled by the signs). Nearest ``z`` wins.
Pixel centres are at integer coordinates (OpenCV).

Examples
--------
>>> import numpy as np
>>> K = np.array([[50.0, 0, 15.5], [0, 50.0, 11.5], [0, 0, 1]])
>>> quad = np.array([[-5.0, -5, 4], [5, -5, 4], [5, 5, 4], [-5, 5, 4]])  # the plane z = 4
>>> r = rasterize(quad, np.array([[0, 1, 2], [0, 2, 3]]), K, np.eye(3), np.zeros(3), (32, 24))
>>> bool(np.allclose(r.depth, 4.0)), sorted(np.unique(r.face).tolist())
(True, [0, 1])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import InputError


@dataclass(frozen=True)
class Raster:
    """What a camera sees of a mesh, per pixel.

    Attributes
    ----------
    depth : ndarray, (H, W) float64
        Camera ``z`` of the nearest surface (unit of the mesh); ``inf`` where
        no triangle is hit.
    face : ndarray, (H, W) int32
        Index of the triangle seen; ``-1`` where none.
    bary : ndarray, (H, W, 3) float64, or None
        Perspective-correct barycentrics of the hit in its triangle (sum 1);
        0 where none (``None`` when :func:`rasterize` was asked not to keep
        them).
    covered : ndarray, (M,) int64
        Pixel centres inside each triangle's projection (in the frame), before
        the depth test: a triangle is wholly visible (in the frame) when as
        many pixels show it.
    """

    depth: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    covered: np.ndarray | None = None

    @property
    def hit(self) -> np.ndarray:
        """``(H, W)`` bool: a triangle is seen."""
        return self.face >= 0

    def points(self, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """``(H, W, 3)`` world points of the hits (NaN where none), from the
        barycentrics: exact for the mesh's own vertices."""
        if self.bary is None:  # a caller's slip, not bad input
            raise ValueError("this Raster kept no barycentrics (rasterize(..., bary=False))")
        f = np.maximum(self.face, 0)
        tri = np.asarray(vertices, np.float64)[np.asarray(faces)[f]]  # (H, W, 3, 3)
        p = np.einsum("hwk,hwkc->hwc", self.bary, tri)
        return np.where(self.hit[..., None], p, np.nan)


def check_mesh(vertices, faces, *, where: str = "mesh") -> tuple[np.ndarray, np.ndarray]:
    """``vertices`` (N, 3) finite float64 and ``faces`` (M, 3) int64 indices
    into them; :class:`InputError` naming ``where`` otherwise."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
        raise InputError(where, f"expected finite vertices of shape (N, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and f.dtype.kind not in "iu"):
        raise InputError(where, f"expected integer faces of shape (M, 3), got {f.shape} {f.dtype}")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise InputError(where, f"a face indexes a vertex outside 0..{len(v) - 1}")
    return v, f.astype(np.int64)


def pixel_rays(K, size, dist=None) -> np.ndarray:
    """Unit-``z`` rays ``(H, W, 3)`` of every pixel centre in the camera frame
    (``K⁻¹ (x, y, 1)``; through :meth:`Camera.unproject` when ``dist`` has a
    non-zero coefficient)."""
    w, h = size
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    if dist is not None and np.any(np.asarray(dist) != 0):
        from lumigraph.capture.camera import Camera

        cam = Camera(K, dist, (w, h))
        return cam.unproject(np.stack([xs.ravel(), ys.ravel()], 1)).reshape(h, w, 3)
    Ki = np.linalg.inv(np.asarray(K, np.float64))
    return np.stack([xs, ys, np.ones_like(xs)], -1) @ Ki.T


def rasterize(vertices, faces, K, R, t, size, *, dist=None, rays=None, bary: bool = True,
              labels=None) -> Raster:
    """Z-buffer the triangles ``faces`` of ``vertices`` (world) seen by the
    camera ``K, R, t`` (``x_cam = R x_world + t``) on a ``size = (W, H)``
    image; see the module docstring for the method.

    Parameters
    ----------
    vertices : (N, 3) float
    faces : (M, 3) int
    K : (3, 3) float
        Intrinsics (pixels); ``dist`` optional OpenCV distortion.
    R, t : (3, 3), (3,) float
        ``cam_from_world``.
    size : (int, int)
        ``(width, height)``.
    rays : (H, W, 3) float, optional
        Precomputed :func:`pixel_rays` (saves their cost when rendering the
        same camera often).
    bary : bool
        Keep the barycentrics (``False``: ``Raster.bary`` is ``None``, for
        callers that need only depth and face ids; a little faster).
    labels : (M,) int, optional
        What ``Raster.face`` holds where triangle ``m`` is seen: ``labels[m]``
        instead of ``m`` (a caller rasterising a subset of its mesh, or
        wanting each pixel's plane rather than its triangle, gets its own ids
        without a pass over the frame); ``covered`` stays per triangle.

    Returns
    -------
    Raster
        Depth, face id and barycentrics per pixel.

    Examples
    --------
    A triangle whose plane tilts: depth along the ray is exact.

    >>> K = np.array([[40.0, 0, 9.5], [0, 40.0, 9.5], [0, 0, 1]])
    >>> tri = np.array([[-3.0, -3, 2], [3, -3, 4], [0, 3, 3]])
    >>> r = rasterize(tri, np.array([[0, 1, 2]]), K, np.eye(3), np.zeros(3), (20, 20))
    >>> X = r.points(tri, np.array([[0, 1, 2]]))[10, 10]  # on the plane z = 3 + x/3
    >>> bool(abs(X[2] - (3 + X[0] / 3)) < 1e-12)
    True
    """
    v, f = check_mesh(vertices, faces)
    w, h = (int(s) for s in size)
    R = np.asarray(R, np.float64)
    t = np.asarray(t, np.float64).reshape(3)
    if rays is None:
        rays = pixel_rays(K, (w, h), dist)
    vc = v @ R.T + t  # camera frame
    depth = np.full((h, w), np.inf)
    face = np.full((h, w), -1, np.int32)
    bary = np.zeros((h, w, 3)) if bary else None
    covered = np.zeros(len(f), np.int64)
    if not len(f):
        return Raster(depth, face, bary, covered)
    K = np.asarray(K, np.float64)
    distorted = dist is not None and np.any(np.asarray(dist) != 0)
    tri = vc[f]  # (M, 3, 3): corners a, b, c
    det = np.einsum("mi,mi->m", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))
    # the bounding box of each triangle's projection; a triangle reaching
    # behind (or onto) the camera plane, or a distorted camera, takes the frame
    zc = tri[..., 2]
    scale = np.abs(tri).max(axis=(1, 2))
    front = (zc > 1e-9 * scale[:, None]).all(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = tri @ K.T
        px = p[..., :2] / p[..., 2:3]
    lo = np.where(front[:, None], np.floor(px.min(1)) - 1, 0)
    hi = np.where(front[:, None], np.ceil(px.max(1)) + 1, [w - 1, h - 1])
    if distorted:
        lo[:] = 0
        hi[:] = [w - 1, h - 1]
    lo = np.clip(lo, 0, [w - 1, h - 1]).astype(int)
    hi = np.clip(hi, -1, [w - 1, h - 1]).astype(int)
    # a triangle wholly behind the camera, edge-on (its plane through the
    # centre) or off the frame is skipped
    todo = (zc > 0).any(1) & (np.abs(det) > 1e-12 * scale ** 3) & (hi >= lo).all(1)
    # α, β, γ through the edge normals: det(r, b, c) = r · (b × c), … (all
    # triangles at once: per-triangle np.cross calls cost more than the pixels)
    a_, b_, c_ = tri[:, 0], tri[:, 1], tri[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        normals = np.stack([np.cross(b_, c_), np.cross(c_, a_), np.cross(a_, b_)], 2) / det[:, None, None]
    dflat, fflat = depth.ravel(), face.ravel()
    bflat = bary.reshape(-1, 3) if bary is not None else None
    ids = np.arange(len(f)) if labels is None else np.asarray(labels)
    for m in np.flatnonzero(todo):
        x0, y0 = lo[m]
        x1, y1 = hi[m]
        bw = x1 - x0 + 1
        # the box's rays as they lie (a stacked matmul; reshaping the box first copies
        # it and takes several times longer), the inside rows by np.take (a fancy
        # index of an (n, 3) array is several times slower): the same numbers
        abc = np.matmul(rays[y0:y1 + 1, x0:x1 + 1], normals[m]).reshape(-1, 3)
        inside = np.flatnonzero((abc[:, 0] >= 0) & (abc[:, 1] >= 0) & (abc[:, 2] >= 0))
        if not len(inside):
            continue
        abc = np.take(abc, inside, axis=0)
        ssum = abc[:, 0] + abc[:, 1] + abc[:, 2]
        # α, β, γ >= 0 sum to > 0 unless all are 0 (a ray at the camera centre):
        # the filter is only paid for when it removes something
        front = ssum > 0
        if not front.all():
            inside, abc, ssum = inside[front], abc[front], ssum[front]
        covered[m] = len(inside)
        z = 1.0 / ssum
        flat = inside + (y0 * w + x0) + (inside // bw) * (w - bw)  # box index -> frame index
        win = z < dflat[flat]
        if not win.all():  # (the gathers only where a nearer surface is already there)
            if not win.any():
                continue
            flat, z, abc = flat[win], z[win], abc[win] if bflat is not None else abc
        dflat[flat] = z
        fflat[flat] = ids[m]
        if bflat is not None:
            bflat[flat] = abc * z[:, None]
    return Raster(depth, face, bary, covered)
