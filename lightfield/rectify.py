"""Rectify a posed camera array to a regular two-plane light field (reference §5.4.1-5.4.2).

A light slab needs views on a regular planar grid of cameras sharing one
orientation and one image plane. A real array is close to that but not exact:
each camera has its own intrinsics ``K_i``, distortion and pose
``x_cam = R_i x_world + t_i`` (``cam_from_world``). We

1. fit the virtual array: the common viewing direction ``z`` is the mean of
   the cameras' optical axes; ``x`` follows the grid's columns (``y`` its rows)
   orthogonalised against ``z``; the camera centres ``C_i = -R_i^T t_i``,
   expressed in that frame, are fitted by a regular grid
   ``C_i ~ C0 + s ((v - vc) x + (u - uc) y)`` (least squares in ``C0, s``);
   a centre farther than ``tolerance * s`` from its grid node (in the plane
   or out of it) is refused, naming the view;
2. warp each view into the virtual camera at its grid node, with orientation
   ``R_ref = [x; y; z]`` and common intrinsics ``K_ref`` (square pixels, mean
   focal length, principal point at the image centre): an output pixel's ray
   meets the reference plane ``z = plane_depth`` (virtual-array frame) at a
   point that is projected into the real camera with its distortion. That is
   the homography induced by the reference plane (Hartley-Zisserman eq.
   13.2, ``H = K_i (R - t n^T / d) K_ref^-1``) composed with the lens
   distortion; with ``plane_depth = inf`` (default) it is the infinite
   homography ``K_i R_i R_ref^T K_ref^-1``, exact for any depth when a
   centre sits on its node, and the remaining parallax of an off-node centre
   is ``f * offset / depth`` px (zero on the reference plane).

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.camera import Camera
>>> cam = Camera(np.array([[40.0, 0, 15.5], [0, 40.0, 11.5], [0, 0, 1]]), np.zeros(5), (32, 24))
>>> poses = [(np.eye(3), -np.array([0.1 * (j - 1), 0.1 * (i - 1), 0.0]))
...          for i in range(2) for j in range(3)]
>>> arr = fit_array(poses, grid=(2, 3))
>>> round(arr.spacing, 6), float(arr.residuals.max()) < 1e-9
(0.1, True)
>>> views = np.random.default_rng(0).random((6, 24, 32, 3)).astype(np.float32)
>>> out = rectify_views(views, [cam] * 6, poses, grid=(2, 3))
>>> float(np.abs(out.views - views.reshape(2, 3, 24, 32, 3)).max()) < 1e-4   # already ideal
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import InputError


@dataclass(frozen=True)
class VirtualArray:
    """The regular planar grid fitted to the camera centres.

    Attributes
    ----------
    ref_from_world : (3, 3) float64
        Rotation of the virtual cameras (rows: x, y, z axes in world coordinates).
    origin : (3,) float64
        Grid centre in world coordinates.
    spacing : float
        Grid step (world units).
    nodes : (U, V, 3) float64
        Grid node of each view (world).
    residuals : (U, V) float64
        Distance of each camera centre from its node, in units of ``spacing``.
    """

    ref_from_world: np.ndarray
    origin: np.ndarray
    spacing: float
    nodes: np.ndarray
    residuals: np.ndarray

    def __post_init__(self):
        if not self.spacing > 0:
            raise ValueError(f"spacing: expected > 0, got {self.spacing}")


@dataclass(frozen=True)
class Rectified:
    """Rectified views and the geometry they were mapped to.

    Attributes
    ----------
    views : (U, V, H, W, C) float32
        Views of the virtual cameras (linear radiance, as given).
    K : (3, 3) float64
        Common intrinsics of the virtual cameras.
    array : VirtualArray
    outside : (U, V) float64
        Fraction of each output view that maps outside its source image
        (filled by mirror extension).
    """

    views: np.ndarray
    K: np.ndarray
    array: VirtualArray
    outside: np.ndarray


def _centre(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    return -R.T @ t


def fit_array(poses, *, grid: tuple[int, int], tolerance: float = 0.1,
              names=None) -> VirtualArray:
    """Fit a regular planar grid to the camera centres (row-major views).

    Parameters
    ----------
    poses : sequence of (R (3, 3), t (3,))
        ``cam_from_world`` of each view, row-major over the ``U x V`` grid.
    grid : (U, V)
    tolerance : float
        Largest allowed distance of a centre from its node, in grid steps.
    names : sequence of str, optional
        View names for error messages.

    Raises
    ------
    InputError
        When the count does not match the grid, a rotation is not orthonormal,
        the centres do not span a grid, or a centre is off its node.
    """
    u, v = grid
    names = list(names) if names is not None else [f"view {k}" for k in range(u * v)]
    if not (np.isfinite(tolerance) and tolerance > 0):
        raise InputError("tolerance", f"expected a finite number of grid steps > 0, got {tolerance}")
    if len(poses) != u * v:
        raise InputError("poses", f"a {u}x{v} grid needs {u * v} poses, got {len(poses)}")
    Rs, Cs = [], []
    for (R, t), name in zip(poses, names, strict=True):
        R, t = np.asarray(R, float), np.asarray(t, float).reshape(3)
        if R.shape != (3, 3) or np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
            raise InputError(name, "cam_from_world R is not a rotation matrix")
        Rs.append(R)
        Cs.append(_centre(R, t))
    Rs, C = np.array(Rs), np.array(Cs).reshape(u, v, 3)
    z = Rs[:, 2, :].mean(0)
    z /= np.linalg.norm(z)
    ou = np.arange(u) - (u - 1) / 2
    ov = np.arange(v) - (v - 1) / 2
    # Grid directions from the centres (the weighted differences are the
    # least-squares slopes along each axis).
    dx = (C * ov[None, :, None]).sum((0, 1)) if v > 1 else None
    dy = (C * ou[:, None, None]).sum((0, 1)) if u > 1 else None
    if dx is not None:
        x = dx - (dx @ z) * z
        if np.linalg.norm(x) < 1e-12:
            raise InputError("poses", "the camera centres do not spread along the grid's columns")
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
    else:
        y = dy - (dy @ z) * z
        if np.linalg.norm(y) < 1e-12:
            raise InputError("poses", "the camera centres do not spread along the grid's rows")
        y /= np.linalg.norm(y)
        x = np.cross(y, z)
    R_ref = np.stack([x, y, z])
    p = (C - C.mean((0, 1))) @ R_ref.T                      # (U, V, 3) in the array frame
    gu, gv = np.meshgrid(ou, ov, indexing="ij")
    s = float((p[..., 0] * gv + p[..., 1] * gu).sum() / (gv ** 2 + gu ** 2).sum())
    if not s > 0:
        raise InputError("poses", f"the camera centres run against the grid order (fitted "
                                  f"spacing {s:.4g}): views must be row-major, rows top to bottom")
    model = np.stack([s * gv, s * gu, np.zeros_like(gu)], -1)
    res = np.linalg.norm(p - model, axis=-1) / s
    worst = int(res.argmax())
    if res.flat[worst] > tolerance:
        du, dv = divmod(worst, v)
        raise InputError(names[worst], f"camera centre is {res.flat[worst]:.3g} grid steps from "
                                       f"its node ({du}, {dv}) of the fitted {u}x{v} grid "
                                       f"(spacing {s:.4g}); allowed {tolerance:g}: not a planar "
                                       "regular array")
    origin = C.mean((0, 1))
    nodes = origin + model @ R_ref
    return VirtualArray(R_ref, origin, s, nodes, res)


def rectify_views(views, cameras, poses, *, grid: tuple[int, int], tolerance: float = 0.1,
                  plane_depth: float = float("inf"), names=None,
                  interpolation: str = "lanczos4") -> Rectified:
    """Undistort and warp posed views onto the virtual regular array.

    Parameters
    ----------
    views : sequence of (H, W, C) float32
        Linear views, row-major.
    cameras : sequence of capture.camera.Camera
        Intrinsics and distortion (OpenCV order) of each view.
    poses : sequence of (R, t)
        ``cam_from_world`` of each view.
    grid : (U, V)
    tolerance : float
        See :func:`fit_array`.
    plane_depth : float
        Depth of the reference plane in the virtual-array frame (world
        units), > 0; ``inf``: the plane at infinity.
    interpolation : {"lanczos4", "cubic", "linear"}

    Returns
    -------
    Rectified
    """
    import cv2

    flags = {"lanczos4": cv2.INTER_LANCZOS4, "cubic": cv2.INTER_CUBIC,
             "linear": cv2.INTER_LINEAR}
    if interpolation not in flags:
        raise ValueError(f"interpolation: expected one of {', '.join(flags)}, got "
                         f"{interpolation!r}")
    if not plane_depth > 0:
        raise InputError("plane_depth", f"expected > 0, got {plane_depth}")
    u, v = grid
    names = list(names) if names is not None else [f"view {k}" for k in range(u * v)]
    if not len(views) == len(cameras) == u * v:
        raise InputError("cameras", f"a {u}x{v} grid needs {u * v} views and cameras, got "
                                    f"{len(views)} and {len(cameras)}")
    h, w = views[0].shape[:2]
    for img, cam, name in zip(views, cameras, names, strict=True):
        if tuple(cam.image_size) != (img.shape[1], img.shape[0]):
            raise InputError(name, f"is {img.shape[1]}x{img.shape[0]} but its camera says "
                                   f"{cam.image_size[0]}x{cam.image_size[1]}")
    arr = fit_array(poses, grid=grid, tolerance=tolerance, names=names)
    f = float(np.mean([np.mean(c.focal_px) for c in cameras]))
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
    xs, ys = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays = np.stack([(xs - K[0, 2]) / f, (ys - K[1, 2]) / f, np.ones_like(xs)], -1)
    out = np.empty((u, v) + tuple(np.shape(views[0])), np.float32)
    outside = np.zeros((u, v))
    for k, (img, cam, (R, t)) in enumerate(zip(views, cameras, poses, strict=True)):
        i, j = divmod(k, v)
        R, t = np.asarray(R, float), np.asarray(t, float).reshape(3)
        dirs = rays.reshape(-1, 3) @ arr.ref_from_world          # world directions
        if np.isinf(plane_depth):
            pts_cam = dirs @ R.T                                 # directions in camera i
        else:
            node = arr.nodes[i, j]
            depth_node = float((node - arr.origin) @ arr.ref_from_world[2])
            world = node + dirs * (plane_depth - depth_node)     # rays have z = 1
            pts_cam = world @ R.T + t
        if (pts_cam[:, 2] <= 0).any():
            raise InputError(names[k], "the reference plane is behind this camera")
        px = cam.project(pts_cam).reshape(h, w, 2).astype(np.float32)
        outside[i, j] = float(((px[..., 0] < -0.5) | (px[..., 0] > w - 0.5)
                               | (px[..., 1] < -0.5) | (px[..., 1] > h - 0.5)).mean())
        src = np.asarray(img, np.float32)
        warped = cv2.remap(src, px[..., 0], px[..., 1], flags[interpolation],
                           borderMode=cv2.BORDER_REFLECT101)
        out[i, j] = warped.reshape(out.shape[2:])
    return Rectified(out, K, arr, outside)
