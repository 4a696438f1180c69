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

__all__ = ["Raster", "check_mesh", "model_depth", "model_depth_sigma", "pixel_rays", "rasterize",
           "visible"]


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


def model_depth_sigma(model, values, covariance, K, R, t, size, *, k: float = 3.0,
                      dist=None) -> np.ndarray:
    """First-order standard deviation (H, W) of a fitted model's depth from
    a camera, from its parameters' covariance: the model is moved ``±k``
    standard deviations along each principal direction of ``covariance``
    (eigenvectors ``v_i``, variances ``λ_i``), and

        σ_z = sqrt(Σ_i (Δz_i / k)²),   Δz_i = max |z(p ± k √λ_i v_i) − z(p)|

    (exact to first order on a smooth surface; taken at ``±k σ`` rather than
    a derivative so that a pixel whose surface can change within ``k σ`` — a
    model edge moving across it — shows it: there ``σ_z`` is the depth jump
    over ``k``, or ``inf`` where the model can leave the pixel).

    ``model`` is a :class:`~lumigraph.stereo.debevec1996.model.BlockModel`,
    ``values`` {name: value} its fitted free parameters (a solve's
    ``params``), ``covariance`` (n, n) theirs in the order of ``values``
    (the parameter block of a solve's ``covariance``). Unit: the model's.

    >>> from lumigraph.stereo.debevec1996.model import BlockModel
    >>> m = BlockModel.from_dict({"blocks": [{"name": "b", "kind": "box",
    ...     "params": {"width": {"value": 2, "fixed": True}, "depth": 2, "height": 2}}]})
    >>> K = np.array([[40.0, 0, 15.5], [0, 40.0, 11.5], [0, 0, 1]])
    >>> R = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # looking along +y
    >>> t = -R @ np.array([0, -8.0, 1])
    >>> s = model_depth_sigma(m, {"b/depth": 2.0, "b/height": 2.0}, np.diag([0.01 ** 2, 0.0]),
    ...                       K, R, t, (32, 24))
    >>> round(float(s[12, 16]), 4)  # the front face moves by half the depth's σ
    0.005
    """
    names = list(values)
    p0 = np.array([values[n] for n in names], np.float64)
    cov = np.asarray(covariance, np.float64).reshape(len(names), len(names))
    lam, vec = np.linalg.eigh((cov + cov.T) / 2)
    def depth(vals):  # float64 (model_depth's float32 rounds a small move away)
        mesh = model.with_values(vals).mesh()
        r = rasterize(mesh.vertices, mesh.faces, K, R, t, size, dist=dist, bary=False)
        return np.where(r.hit, r.depth, np.nan)

    z0 = depth(values)
    var = np.zeros(z0.shape)
    for li, v in zip(lam, vec.T, strict=True):
        if not li > 0:
            continue
        worst = np.zeros(z0.shape)
        for sign in (1.0, -1.0):
            p = p0 + sign * k * np.sqrt(li) * v
            z = depth(dict(zip(names, p, strict=True)))
            with np.errstate(invalid="ignore"):
                d = np.where(np.isnan(z) & np.isnan(z0), 0.0, np.abs(z - z0))
            worst = np.maximum(worst, np.where(np.isnan(d), np.inf, d))
        var += (worst / k) ** 2
    return np.where(np.isnan(z0), np.nan, np.sqrt(var))
