"""Triangulation of 3-D points from two or more calibrated views.

A scene point ``x`` seen at pixel ``x̄_v`` in view ``v`` lies on the ray
``c_v + t_v P_v x̄_v`` (reference ch. 5, eq. 5.2); with noisy pixels the rays
miss each other and ``x`` is chosen to minimise an error in the least-squares
sense. Three estimators:

- **midpoint** (two views): the ``t_1, t_2`` minimising ``|c_1 + t_1 d_1 −
  c_2 − t_2 d_2|²`` (eq. 5.2 solved in closed form), ``x`` the midpoint of the
  two closest points;
- **DLT** (any number of views): the homogeneous ``X`` minimising
  ``|A X|`` with two rows ``x P_v³ − P_v¹``, ``y P_v³ − P_v²`` per view, in
  normalised (undistorted) coordinates; a point at infinity is the solution
  with ``X_4 = 0`` and is reported as such;
- **refined** (default): DLT, then Gauss–Newton on the reprojection error in
  pixels through each camera's full model (distortion included), the
  maximum-likelihood estimate for Gaussian pixel noise.

Every point carries a first-order covariance ``σ² (JᵀJ)⁻¹`` (``J`` the
Jacobian of its reprojections, ``σ`` the pixel noise), the largest angle
between its rays, and flags: ``near_parallel`` when that angle is below
``min_angle_deg`` (depth is then ill-conditioned), ``at_infinity`` when the
rays are parallel to working precision.

Reference: R. Hartley and P. Sturm, "Triangulation", CVIU 68(2), 1997,
doi:10.1006/cviu.1997.0547; Hartley & Zisserman, *Multiple View Geometry*,
2nd ed., §12.2 (DLT) and §5.2 (first-order covariance).

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.camera import Camera
>>> cam = Camera(np.array([[500., 0, 160], [0, 480, 120], [0, 0, 1]]), np.zeros(5), (320, 240))
>>> poses = [(np.eye(3), np.zeros(3)), (np.eye(3), np.array([-0.2, 0.0, 0.0]))]
>>> X = np.array([[0.1, -0.05, 2.0], [0.3, 0.2, 3.0]])
>>> px = np.stack([cam.project_world(X, R, t) for R, t in poses])
>>> tri = triangulate(px, [cam, cam], poses)
>>> bool(np.allclose(tri.points, X, rtol=1e-9)), tri.near_parallel.tolist()
(True, [False, False])
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.capture.registry import Method, Registry

# The --method choices of `lumigraph stereo triangulate`: three modes of the one
# pipeline in triangulate() (they share the rays, the angle test and the
# covariance), so each entry binds triangulate's own ``method``.
_OPTIONS = ("pixel_sigma", "min_angle_deg", "iterations")
ANGLE_RANGE_DEG = (0.0, 180.0)  # the angle between two rays
METHODS = Registry("triangulation", [
    Method("refined", "lumigraph.stereo.triangulate:triangulate",
           "DLT, then Gauss-Newton on the reprojection error (default)", _OPTIONS,
           {"method": "refined"}),
    Method("dlt", "lumigraph.stereo.triangulate:triangulate",
           "linear (DLT) solution in normalised coordinates", _OPTIONS, {"method": "dlt"}),
    Method("midpoint", "lumigraph.stereo.triangulate:triangulate",
           "midpoint of the two rays' common perpendicular (two views only)", _OPTIONS,
           {"method": "midpoint"}),
])


@dataclass(frozen=True)
class Triangulation:
    """Triangulated points and how well each is determined.

    Attributes
    ----------
    points : ndarray, (N, 3) float64
        World points (the frame the poses map from); NaN where at infinity.
    points_h : ndarray, (N, 4) float64
        Homogeneous points (unit norm, ``w >= 0``); ``w = 0`` at infinity, where
        ``points_h[:, :3]`` is the direction.
    covariance : ndarray, (N, 3, 3) float64
        First-order covariance of ``points`` for the given pixel noise
        (world units²); NaN where at infinity.
    angle_deg : ndarray, (N,) float64
        Largest angle between two of the point's rays.
    reprojection_rms : ndarray, (N,) float64
        RMS reprojection error over the observing views (pixels).
    near_parallel, at_infinity : ndarray, (N,) bool
        Flags (see the module docstring).
    info : dict
        Method, pixel noise, angle threshold, counts.
    """

    points: np.ndarray
    points_h: np.ndarray
    covariance: np.ndarray
    angle_deg: np.ndarray
    reprojection_rms: np.ndarray
    near_parallel: np.ndarray
    at_infinity: np.ndarray
    info: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        n = len(self.points)
        for name, shape in (("points", (n, 3)), ("points_h", (n, 4)), ("covariance", (n, 3, 3)),
                            ("angle_deg", (n,)), ("reprojection_rms", (n,)),
                            ("near_parallel", (n,)), ("at_infinity", (n,))):
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f"{name}: expected shape {shape}, got {np.shape(getattr(self, name))}")

    @property
    def sigma(self) -> np.ndarray:
        """``(N,)`` predicted RMS 3-D error, ``sqrt(trace(covariance))``."""
        return np.sqrt(np.trace(self.covariance, axis1=1, axis2=2))

    @property
    def warnings(self) -> list[str]:
        out = []
        k = int(self.near_parallel.sum())
        if k:
            out.append(f"{k} of {len(self.points)} points have rays closer than "
                       f"{self.info.get('min_angle_deg', 0.5)} deg to parallel: their depth is "
                       "ill-conditioned (see covariance)")
        k = int(self.at_infinity.sum())
        if k:
            out.append(f"{k} points are at infinity (parallel rays): reported as directions")
        return out


# ------------------------------------------------------------------- rays
def rays(camera, cam_from_world_R, cam_from_world_t, pixels):
    """World rays through pixels: centre ``(3,)`` and unit directions ``(N, 3)``.

    ``pixels (N, 2)`` are distorted pixel coordinates of ``camera``; the pose
    is ``x_cam = R x_world + t``.
    """
    R = np.asarray(cam_from_world_R, np.float64)
    t = np.asarray(cam_from_world_t, np.float64).ravel()
    d = camera.unproject(np.asarray(pixels, np.float64).reshape(-1, 2)) @ R
    return -R.T @ t, d / np.linalg.norm(d, axis=1, keepdims=True)


def midpoint(c1, d1, c2, d2):
    """Two-view midpoint triangulation (eq. 5.2 in the least-squares sense).

    Parameters
    ----------
    c1, c2 : ndarray, (3,)
        Ray origins (camera centres), world frame.
    d1, d2 : ndarray, (N, 3)
        Ray directions (any length).

    Returns
    -------
    ndarray, (N, 3)
        Midpoints of the closest points of each pair of rays; NaN where the
        rays are parallel (no unique closest points).

    Examples
    --------
    >>> midpoint(np.zeros(3), np.array([[0., 0, 1]]), np.array([1., 0, 0]),
    ...          np.array([[-1., 0, 2]])).round(6).tolist()
    [[0.0, 0.0, 2.0]]
    """
    c1, c2 = np.asarray(c1, float), np.asarray(c2, float)
    d1, d2 = np.atleast_2d(d1).astype(float), np.atleast_2d(d2).astype(float)
    b = c2 - c1
    a11 = np.einsum("ij,ij->i", d1, d1)
    a22 = np.einsum("ij,ij->i", d2, d2)
    a12 = np.einsum("ij,ij->i", d1, d2)
    r1, r2 = d1 @ b, d2 @ b
    det = a11 * a22 - a12 ** 2
    # normal equations of min |t1 d1 - t2 d2 - b|^2
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (a22 * r1 - a12 * r2) / det
        t2 = (a12 * r1 - a11 * r2) / det
    bad = det <= 1e-15 * a11 * a22
    X = 0.5 * ((c1 + t1[:, None] * d1) + (c2 + t2[:, None] * d2))
    X[bad] = np.nan
    return X


def _dlt(norm, Ps, seen):
    """Batched DLT: ``norm (V, N, 2)`` normalised coordinates, ``Ps (V, 3, 4)``,
    ``seen (V, N)`` -> unit homogeneous points ``(N, 4)``. Rows are scaled so
    each view weighs about equally (Hartley's conditioning)."""
    V, N = seen.shape
    A = np.zeros((N, 2 * V, 4))
    for v in range(V):
        x, y = norm[v, :, 0:1], norm[v, :, 1:2]
        r1 = x * Ps[v, 2] - Ps[v, 0]
        r2 = y * Ps[v, 2] - Ps[v, 1]
        w = seen[v][:, None]
        A[:, 2 * v] = np.where(w, r1, 0) / np.maximum(np.linalg.norm(r1, axis=1, keepdims=True), 1e-300)
        A[:, 2 * v + 1] = np.where(w, r2, 0) / np.maximum(np.linalg.norm(r2, axis=1, keepdims=True),
                                                          1e-300)
    _, _, vt = np.linalg.svd(A)
    X = vt[:, -1]
    return X * np.where(X[:, 3:4] < 0, -1.0, 1.0)


def _project_all(X, cameras, poses):
    """Pixels ``(V, N, 2)`` of world points ``X (N, 3)`` in every view."""
    return np.stack([cam.project_world(X, R, t) for cam, (R, t) in zip(cameras, poses, strict=True)])


def _jacobian(X, cameras, poses, eps):
    """Central-difference Jacobian of the reprojections, ``(V, N, 2, 3)``."""
    J = np.empty((len(cameras), len(X), 2, 3))
    for k in range(3):
        dX = np.zeros(3)
        dX[k] = eps
        J[..., k] = (_project_all(X + dX, cameras, poses) - _project_all(X - dX, cameras, poses)) / (2 * eps)
    return J


def triangulate(pixels, cameras, poses, *, method: str = "refined", pixel_sigma: float = 0.5,
                min_angle_deg: float = 0.5, iterations: int = 10) -> Triangulation:
    """Triangulate tracks seen in ``V >= 2`` calibrated views.

    Parameters
    ----------
    pixels : ndarray, (V, N, 2)
        Distorted pixel coordinates ``(x, y)`` of N tracks in V views; NaN
        where a view does not see the track (each track needs >= 2 views).
    cameras : sequence of capture.camera.Camera, length V
    poses : sequence of (R (3, 3), t (3,)), length V
        ``cam_from_world``: ``x_cam = R x_world + t``.
    method : {"refined", "dlt", "midpoint"}
        ``midpoint`` needs exactly two views.
    pixel_sigma : float
        Standard deviation of the pixel noise (px), for the covariance; > 0.
    min_angle_deg : float
        Tracks whose largest ray angle is below this are flagged ``near_parallel``.
    iterations : int
        Gauss–Newton iterations of ``refined``.

    Returns
    -------
    Triangulation

    Raises
    ------
    InputError
        ``pixel_sigma`` not finite and > 0, ``min_angle_deg`` outside [0, 180]
        (naming it).
    ValueError
        Inconsistent shapes, unknown method, a track seen in fewer than 2 views.
    """
    px = np.asarray(pixels, np.float64)
    if px.ndim != 3 or px.shape[2] != 2:
        raise ValueError(f"pixels: expected (V, N, 2), got shape {px.shape}")
    V, N = px.shape[:2]
    if V < 2 or len(cameras) != V or len(poses) != V:
        raise ValueError(f"cameras, poses: expected one per view (V = {V} >= 2), got "
                         f"{len(cameras)} cameras and {len(poses)} poses")
    if method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if method == "midpoint" and V != 2:
        raise ValueError(f"method: midpoint triangulates two views, got {V}")
    if not (np.isfinite(pixel_sigma) and pixel_sigma > 0):
        raise InputError("pixel_sigma", f"expected > 0, got {pixel_sigma}")
    if not ANGLE_RANGE_DEG[0] <= min_angle_deg <= ANGLE_RANGE_DEG[1]:  # NaN too
        raise InputError("min_angle_deg", f"expected an angle in [0, 180] degrees, got "
                                          f"{min_angle_deg}")
    poses = [(np.asarray(R, np.float64), np.asarray(t, np.float64).ravel()) for R, t in poses]
    seen = np.isfinite(px).all(axis=2)
    if np.any(seen.sum(axis=0) < 2):
        bad = np.flatnonzero(seen.sum(axis=0) < 2)[:5].tolist()
        raise ValueError(f"pixels: every track needs at least 2 views; tracks {bad} have fewer")

    centres, dirs, norm = [], [], np.zeros((V, N, 2))
    for v, (cam, (R, t)) in enumerate(zip(cameras, poses, strict=True)):
        ok = seen[v]
        c, d = rays(cam, R, t, np.where(ok[:, None], px[v], 0.0))
        d[~ok] = np.nan
        centres.append(c)
        dirs.append(d)
        norm[v] = cam.unproject(np.where(ok[:, None], px[v], 0.0))[:, :2]
    dirs = np.stack(dirs)

    # largest angle between any two observing rays
    angle = np.zeros(N)
    for a in range(V):
        for b in range(a + 1, V):
            cosang = np.clip(np.einsum("ij,ij->i", dirs[a], dirs[b]), -1, 1)
            ang = np.degrees(np.arccos(cosang))
            angle = np.where(seen[a] & seen[b], np.fmax(angle, ang), angle)

    Ps = np.stack([np.hstack([R, t[:, None]]) for R, t in poses])
    if method == "midpoint":
        X = midpoint(centres[0], dirs[0], centres[1], dirs[1])
        Xh = np.column_stack([X, np.ones(N)])
        Xh /= np.linalg.norm(Xh, axis=1, keepdims=True)
    else:
        Xh = _dlt(norm, Ps, seen)
    scale = max(1.0, float(np.max(np.linalg.norm(np.stack(centres), axis=1))))
    # At infinity: w vanishes relative to the point's extent (rays parallel to
    # working precision; 1e-12 rad of angle leaves ~1e-12 relative w).
    at_inf = ~(np.abs(Xh[:, 3]) > 1e-10 * np.linalg.norm(Xh[:, :3], axis=1) / scale) | ~np.isfinite(Xh).all(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        X = Xh[:, :3] / Xh[:, 3:4]
    X[at_inf] = np.nan
    # a direction at infinity points where the rays go (the sign of a null
    # vector is arbitrary)
    first = np.argmax(seen, axis=0)
    along = np.einsum("ij,ij->i", Xh[:, :3], dirs[first, np.arange(N)])
    Xh[at_inf] *= np.where(along[at_inf] < 0, -1.0, 1.0)[:, None]

    fin = ~at_inf
    eps = 1e-6 * np.maximum(1.0, np.linalg.norm(np.nan_to_num(X), axis=1))[:, None]
    eps_scalar = float(np.median(eps)) if N else 1e-6
    if method == "refined" and fin.any():
        Xf = X[fin]
        cams_seen = seen[:, fin]
        for _ in range(iterations):
            r = _project_all(Xf, cameras, poses) - px[:, fin]
            J = _jacobian(Xf, cameras, poses, eps_scalar)
            r = np.where(cams_seen[..., None], r, 0.0)
            J = np.where(cams_seen[..., None, None], J, 0.0)
            JtJ = np.einsum("vnik,vnil->nkl", J, J)
            Jtr = np.einsum("vnik,vni->nk", J, r)
            ok = np.linalg.cond(JtJ) < 1e14
            step = np.zeros_like(Xf)
            step[ok] = np.linalg.solve(JtJ[ok], Jtr[ok][..., None])[..., 0]
            Xf = Xf - step
            if np.max(np.abs(step)) <= 1e-12 * max(1.0, float(np.max(np.abs(Xf)))):
                break
        X[fin] = Xf
        Xh[fin] = np.column_stack([Xf, np.ones(len(Xf))]) / np.linalg.norm(
            np.column_stack([Xf, np.ones(len(Xf))]), axis=1, keepdims=True)

    cov = np.full((N, 3, 3), np.nan)
    rms = np.full(N, np.nan)
    if fin.any():
        Xf = X[fin]
        m = seen[:, fin]
        J = np.where(m[..., None, None], _jacobian(Xf, cameras, poses, eps_scalar), 0.0)
        JtJ = np.einsum("vnik,vnil->nkl", J, J)
        with np.errstate(invalid="ignore"):
            cov[fin] = pixel_sigma ** 2 * np.linalg.pinv(JtJ)
        r = np.where(m[..., None], _project_all(Xf, cameras, poses) - px[:, fin], 0.0)
        rms[fin] = np.sqrt((r ** 2).sum(axis=(0, 2)) / m.sum(axis=0))
    near = angle < min_angle_deg
    info = {"method": method, "pixel_sigma": pixel_sigma, "min_angle_deg": min_angle_deg,
            "views": V, "tracks": N, "near_parallel": int(near.sum()), "at_infinity": int(at_inf.sum())}
    return Triangulation(X, Xh, cov, angle, rms, near, at_inf, info)


def read_tracks(path) -> tuple[list, list, np.ndarray, float | None]:
    """Read a ``tracks.json``: the one parser of track files.

    The file is ``{"views": [{"camera": <camera.json body>, "cam_from_world":
    {"R": 3x3, "t": [3]}}, ...], "tracks": [[[x, y] or null per view], ...],
    "pixel_sigma": s}``; a view without ``cam_from_world`` is at the origin,
    ``pixel_sigma`` is optional (its range is :func:`triangulate`'s rule).

    Returns
    -------
    cameras : list of Camera, length V
    poses : list of (R (3, 3), t (3,)) float64, ``cam_from_world``
    pixels : ndarray, (V, N, 2) float64
        NaN where a view does not see the track.
    pixel_sigma : float or None

    Raises
    ------
    InputError
        Naming the file and the key at fault (``views[1].camera.K``,
        ``tracks[3][0]``, ...).
    """
    from lumigraph.capture.artifact import load_json_artifact
    from lumigraph.capture.camera import Camera
    from lumigraph.capture.rig import require_rotation
    from lumigraph.capture.schema import check, key_path, require

    body = load_json_artifact(path, "tracks")
    views = require(body, "views", "list", min_length=2, path=path)
    cameras, poses = [], []
    for i, view in enumerate(views):
        where = key_path("views", i)
        check(view, "object", path=path, key=where)
        cameras.append(Camera.from_dict(require(view, "camera", "object", path=path, where=where),
                                        where=path, key=key_path(where, "camera")))
        pose = require(view, "cam_from_world", "object", default=None, path=path, where=where)
        if pose is None:
            poses.append((np.eye(3), np.zeros(3)))
        else:
            at = key_path(where, "cam_from_world")
            poses.append((require_rotation(pose, "R", path=path, where=at),
                          require(pose, "t", "matrix", shape=(3,), path=path, where=at)))
    tracks = require(body, "tracks", "list", min_length=1, path=path)
    px = np.full((len(views), len(tracks), 2), np.nan)
    for j, track in enumerate(tracks):
        check(track, "list", length=len(views), path=path, key=key_path("tracks", j))
        for v, xy in enumerate(track):
            if xy is not None:
                px[v, j] = check(xy, "matrix", shape=(2,), path=path,
                                 key=key_path("tracks", j, v))
    sigma = require(body, "pixel_sigma", "number", nullable=True, default=None, path=path)
    return cameras, poses, px, sigma
