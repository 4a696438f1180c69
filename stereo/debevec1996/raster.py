"""A model's depth and visibility from a camera, through the z-buffer
rasteriser of :mod:`lumigraph.capture.raster`.

What Façade needs from a model: its depth from a camera (the rough model of
model-based stereo, Debevec, Taylor & Malik 1996, doi:10.1145/237170.237191,
reference §5.3.2 Stage 3, Fig. 5.12b) and which photograph sees which
surface point (visibility for view-dependent texture mapping, §5.3.2 Stage 2,
Fig. 5.11). Depth is exact (a ray–plane intersection per pixel, see
:func:`lumigraph.capture.raster.rasterize`).

Examples
--------
>>> K = np.array([[30.0, 0, 7.5], [0, 30.0, 5.5], [0, 0, 1]])
>>> quad = (np.array([[-1.0, -1, 5], [1, -1, 5], [1, 1, 5], [-1, 1, 5]]), [[0, 1, 2], [0, 2, 3]])
>>> z = model_depth(quad, K, np.eye(3), np.zeros(3), (16, 12))
>>> float(np.nanmin(z)), float(np.nanmax(z))
(5.0, 5.0)
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.raster import Raster, check_mesh, pixel_rays, rasterize

__all__ = ["Raster", "check_mesh", "model_depth", "pixel_rays", "rasterize", "visible"]


def model_depth(mesh, K, R, t, size, *, dist=None) -> np.ndarray:
    """The depth map of a model seen by a camera: what ``lumigraph stereo
    model-based --model`` takes (Debevec, Taylor & Malik 1996, Fig. 5.12b).

    Parameters
    ----------
    mesh : object with ``vertices`` (N, 3) and ``faces`` (M, 3), or a pair
        ``(vertices, faces)``; world coordinates, any unit.
    K, R, t, size, dist
        As :func:`rasterize` (``x_cam = R x_world + t``; ``size = (W, H)``).

    Returns
    -------
    ndarray, (H, W) float32
        Camera ``z`` of the model surface, in the mesh's unit; NaN where the
        ray misses the model (``model_stereo``'s "no model"; a PFM stores it
        as inf).

    Examples
    --------
    >>> K = np.array([[30.0, 0, 7.5], [0, 30.0, 5.5], [0, 0, 1]])
    >>> quad = (np.array([[-1.0, -1, 5], [1, -1, 5], [1, 1, 5], [-1, 1, 5]]), [[0, 1, 2], [0, 2, 3]])
    >>> z = model_depth(quad, K, np.eye(3), np.zeros(3), (16, 12))
    >>> z.dtype.name, float(np.nanmax(z)), bool(np.isnan(z[0, 0]))
    ('float32', 5.0, True)
    """
    if hasattr(mesh, "vertices"):
        vertices, faces = mesh.vertices, mesh.faces
    else:
        vertices, faces = mesh
    r = rasterize(vertices, faces, K, R, t, size, dist=dist)
    return np.where(r.hit, r.depth, np.nan).astype(np.float32)


def visible(points, K, R, t, depth, *, tolerance: float = 0.01) -> np.ndarray:
    """Which world ``points`` (…, 3) a camera sees, given its z-buffer
    ``depth`` (H, W) of the scene: in front, inside the frame, and not
    farther than ``depth`` at their (nearest) pixel by more than
    ``tolerance`` × their depth (relative, so one tolerance fits any scale).

    Returns ``(mask (…), pixel (…, 2))``: the points' pixel coordinates too.
    """
    P = np.asarray(points, np.float64)
    pc = P @ np.asarray(R, np.float64).T + np.asarray(t, np.float64)
    h, w = depth.shape
    with np.errstate(divide="ignore", invalid="ignore"):
        q = pc @ np.asarray(K, np.float64).T
        px = q[..., :2] / q[..., 2:3]
    z = pc[..., 2]
    ok = np.isfinite(px).all(-1) & (z > 0)
    xi = np.clip(np.rint(np.nan_to_num(px[..., 0])), 0, w - 1).astype(int)
    yi = np.clip(np.rint(np.nan_to_num(px[..., 1])), 0, h - 1).astype(int)
    ok &= (px[..., 0] > -0.5) & (px[..., 0] < w - 0.5) & (px[..., 1] > -0.5) & (px[..., 1] < h - 0.5)
    ok &= z <= depth[yi, xi] * (1 + tolerance)
    return ok, px
