"""Zhang's planar-target calibration with a fixed distortion model.

Z. Zhang, "A flexible new technique for camera calibration", IEEE TPAMI 22(11),
1330–1334, 2000, doi:10.1109/34.888718 (reference ch. 5, §5.1.1): a closed-form
start from the plane-to-image homographies, then the maximum-likelihood
refinement of all intrinsics, distortion and per-view poses by Levenberg–
Marquardt on the reprojection error. OpenCV's ``calibrateCameraExtended``
implements both steps (and the parameter covariance from the Jacobian); this
module fixes which distortion terms are free.

Distortion models, simple to rich (the ``--model`` names)::

    none         no distortion                      0 terms
    k1           radial k1                          1
    k1k2         radial k1, k2                      2
    k1k2p1p2     + tangential p1, p2                4
    k1k2p1p2k3   + radial k3 (OpenCV's default)     5
    rational     k1..k6 rational radial + p1, p2    8

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.camera import Camera
>>> cam = Camera(np.array([[400., 0, 165], [0, 392, 118], [0, 0, 1]]), np.zeros(5), (320, 240))
>>> obj = np.array([[x, y, 0.0] for y in range(6) for x in range(8)]) * 30
>>> import cv2
>>> poses = [(cv2.Rodrigues(np.array(r))[0], np.array(t)) for r, t in
...          [((0.3, 0.1, 0), (-100, -80, 600)), ((-0.2, 0.3, 0.1), (-120, -60, 650)),
...           ((0.1, -0.35, -0.1), (-90, -70, 580))]]
>>> img = [cam.project_world(obj, R, t) for R, t in poses]
>>> fit = calibrate_fixed([obj] * 3, img, (320, 240), model="none")
>>> bool(np.allclose(fit.K, cam.K, atol=1e-3)), fit.rms_px < 1e-4  # float32 points: ~1e-5 px
(True, True)
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import EstimationError

MODELS = ("none", "k1", "k1k2", "k1k2p1p2", "k1k2p1p2k3", "rational")
# which of the 8 OpenCV coefficients (k1, k2, p1, p2, k3, k4, k5, k6) each model frees
FREE = {
    "none": (),
    "k1": ("k1",),
    "k1k2": ("k1", "k2"),
    "k1k2p1p2": ("k1", "k2", "p1", "p2"),
    "k1k2p1p2k3": ("k1", "k2", "p1", "p2", "k3"),
    "rational": ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}
# order of OpenCV's stdDeviationsIntrinsics
STD_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


@contextmanager
def _one_opencv_thread() -> Iterator[None]:
    """Run OpenCV on one thread inside the block, then restore the caller's count.

    With several threads OpenCV's (5.0) ``calibrateCamera[Extended]`` returns
    K, distortion and poses that differ in their last bits from run to run on
    the same points (5 distinct results in 6 runs on 2 threads, one on one
    thread: its parallel parts depend on the threads' timing), and
    ``--model auto``'s choice and every figure in camera.json follow them. ``solvePnP``, ``projectPoints`` and ``stereoCalibrate`` with
    fixed intrinsics were stable, so only the calibration solve is pinned; it
    takes milliseconds either way. ``setNumThreads`` is process-wide: OpenCV
    work on other Python threads meanwhile also runs on one thread.
    """
    import cv2

    previous = cv2.getNumThreads()
    if previous == 1:  # already pinned (an enclosing block): setNumThreads costs ~0.6 ms a call
        yield
        return
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(previous)


def model_flags(model: str) -> int:
    """OpenCV ``calibrateCamera`` flags that leave exactly the model's terms free."""
    import cv2

    if model not in FREE:
        raise ValueError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    free = set(FREE[model])
    flags = cv2.CALIB_RATIONAL_MODEL if model == "rational" else 0
    if "p1" not in free:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    for name, flag in (("k1", cv2.CALIB_FIX_K1), ("k2", cv2.CALIB_FIX_K2), ("k3", cv2.CALIB_FIX_K3)):
        if name not in free:
            flags |= flag
    if model != "rational":
        flags |= cv2.CALIB_FIX_K4 | cv2.CALIB_FIX_K5 | cv2.CALIB_FIX_K6
    return flags


def n_intrinsics(model: str) -> int:
    """Free intrinsic parameters: fx, fy, cx, cy plus the model's distortion terms."""
    return 4 + len(FREE[model])


@dataclass(frozen=True)
class ZhangFit:
    """One fixed-model calibration.

    Attributes
    ----------
    model : str
    K : ndarray, (3, 3) float64
    dist : ndarray, (5,) or (8,) float64, OpenCV order
    rvecs, tvecs : ndarray, (V, 3) float64
        ``cam_from_world`` (world = board frame) per view, Rodrigues vectors.
    rms_px : float
        ``sqrt(sum |residual|² / N)`` over all N corners (OpenCV's figure).
    std : dict of str -> float
        Standard deviation of every free intrinsic (from the Jacobian at the
        optimum, scaled by the residual variance).
    view_rms_px : ndarray, (V,) float64
    n_points : int
    """

    model: str
    K: np.ndarray
    dist: np.ndarray
    rvecs: np.ndarray
    tvecs: np.ndarray
    rms_px: float
    std: dict
    view_rms_px: np.ndarray
    n_points: int

    @property
    def n_params(self) -> int:
        """All fitted parameters: intrinsics plus 6 per view."""
        return n_intrinsics(self.model) + 6 * len(self.rvecs)


def calibrate_fixed(object_points, image_points, image_size, *, model: str,
                    K0: np.ndarray | None = None, dist0: np.ndarray | None = None,
                    uncertainties: bool = True, rvecs0=None, tvecs0=None,
                    max_iter: int = 60, eps: float = 1e-9) -> ZhangFit:
    """Zhang calibration with the distortion terms of ``model`` free.

    Parameters
    ----------
    object_points : list of ndarray, (N_v, 3)
        Board-frame corners per view (any length unit).
    image_points : list of ndarray, (N_v, 2)
        Detected distorted pixels per view.
    image_size : (int, int)
        ``(w, h)``.
    model : str, keyword-only
        One of :data:`MODELS`.
    K0, dist0 : ndarray, optional
        A starting point (skips Zhang's closed-form initialisation: used to
        refit subsets of views quickly).
    uncertainties : bool, keyword-only
        Compute ``std`` and ``view_rms_px`` (``calibrateCameraExtended``);
        without them (``std`` empty, ``view_rms_px`` NaN) a refit is ~2x faster.
    rvecs0, tvecs0 : array_like, (V, 3), optional
        Starting poses (with ``K0``): skips the per-view pose initialisation.
    max_iter, eps : keyword-only
        Levenberg–Marquardt stopping rule (iterations, parameter change). The
        defaults converge fully; a warm-started refit of a subset of views
        needs only a few iterations.

    Returns
    -------
    ZhangFit

    Raises
    ------
    EstimationError
        When OpenCV's optimiser fails or returns non-finite parameters.
    """
    import cv2

    flags = model_flags(model)
    obj = [np.ascontiguousarray(o, np.float32).reshape(-1, 1, 3) for o in object_points]
    img = [np.ascontiguousarray(p, np.float32).reshape(-1, 1, 2) for p in image_points]
    if len(obj) != len(img) or not obj:
        raise ValueError(f"object_points, image_points: expected equal non-empty lists, got {len(obj)} "
                         f"and {len(img)}")
    K = np.eye(3)
    dist = np.zeros(8 if model == "rational" else 5)
    if K0 is not None:
        K = np.array(K0, np.float64)
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
        if dist0 is not None:
            d = np.asarray(dist0, np.float64).ravel()
            n = min(d.size, dist.size)
            dist[:n] = d[:n]
            # a guess may not set a term the model keeps fixed at zero
            for i, name in enumerate(("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")[:dist.size]):
                if name not in FREE[model]:
                    dist[i] = 0.0
    # parameter steps below 1e-9 change no pixel measurably
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, int(max_iter), float(eps))
    size = tuple(int(v) for v in image_size)
    rv = tv = None
    if K0 is not None and rvecs0 is not None and tvecs0 is not None:
        rv = [np.asarray(r, np.float64).reshape(3, 1) for r in rvecs0]
        tv = [np.asarray(t, np.float64).reshape(3, 1) for t in tvecs0]
        flags |= cv2.CALIB_USE_EXTRINSIC_GUESS
    try:
        with _one_opencv_thread():  # byte-stable results (see _one_opencv_thread)
            if uncertainties:
                rms, K, dist, rv, tv, std_i, _, per_view = cv2.calibrateCameraExtended(
                    obj, img, size, K, dist, rv, tv, flags=flags, criteria=criteria)
            else:
                rms, K, dist, rv, tv = cv2.calibrateCamera(obj, img, size, K, dist, rv, tv, flags=flags,
                                                           criteria=criteria)
                std_i, per_view = np.zeros(18), np.full(len(obj), np.nan)
    except cv2.error as e:
        raise EstimationError("calibration", f"model {model}: OpenCV failed ({str(e).strip().splitlines()[-1]})") from None
    K = np.asarray(K, np.float64)
    dist = np.asarray(dist, np.float64).ravel()[: 8 if model == "rational" else 5]
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(dist)) and K[0, 0] > 0 and K[1, 1] > 0):
        raise EstimationError("calibration", f"model {model}: the optimiser diverged")
    std_all = np.asarray(std_i, np.float64).ravel()
    free = ("fx", "fy", "cx", "cy") + FREE[model]
    std = {n: float(std_all[STD_NAMES.index(n)]) for n in free} if uncertainties else {}
    n_points = sum(len(o) for o in obj)
    return ZhangFit(model, K, dist, np.array(rv, np.float64).reshape(-1, 3),
                    np.array(tv, np.float64).reshape(-1, 3), float(rms), std,
                    np.asarray(per_view, np.float64).ravel(), n_points)


_DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


def _free_columns(model: str) -> np.ndarray:
    """Columns of ``cv2.projectPoints``' Jacobian (after its 6 pose columns:
    fx, fy, cx, cy, then the distortion terms in OpenCV order) that ``model`` frees."""
    return np.array([0, 1, 2, 3] + [4 + _DIST_NAMES.index(n) for n in FREE[model]])


@dataclass(frozen=True)
class _Normal:
    """Per-view blocks of the Gauss–Newton normal equations at one point
    (``a`` the free intrinsics, ``p`` a view's 6 pose parameters): ``A = Jaᵀ Ja``,
    ``B = Jaᵀ Jp``, ``C = Jpᵀ Jp``, ``ga = Jaᵀ r``, ``gp = Jpᵀ r`` and the residual
    sum of squares, stacked over views."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    ga: np.ndarray
    gp: np.ndarray
    sq: np.ndarray

    def take(self, views) -> _Normal:
        return _Normal(*(x[views] for x in (self.A, self.B, self.C, self.ga, self.gp, self.sq)))


def _normal(obj, img, views, K, dist, rvecs, tvecs, cols) -> _Normal:
    import cv2

    n, m = len(views), len(cols)
    A, B, C = np.empty((n, m, m)), np.empty((n, m, 6)), np.empty((n, 6, 6))
    ga, gp, sq = np.empty((n, m)), np.empty((n, 6)), np.empty(n)
    for i, v in enumerate(views):
        proj, jac = cv2.projectPoints(obj[v], rvecs[v], tvecs[v], K, dist)
        r = proj.reshape(-1) - img[v].reshape(-1)
        Jp, Ja = jac[:, :6], jac[:, 6:][:, cols]
        A[i], B[i], C[i] = Ja.T @ Ja, Ja.T @ Jp, Jp.T @ Jp
        ga[i], gp[i], sq[i] = Ja.T @ r, Jp.T @ r, r @ r
    return _Normal(A, B, C, ga, gp, sq)


def _intrinsics(a: np.ndarray, n_dist: int) -> tuple[np.ndarray, np.ndarray]:
    K = np.array([[a[0], 0.0, a[2]], [0.0, a[1], a[3]], [0.0, 0.0, 1.0]])
    return K, np.asarray(a[4:4 + n_dist], np.float64).copy()


def refine(object_points, image_points, *, model: str, K: np.ndarray, dist: np.ndarray,
           rvecs: np.ndarray, tvecs: np.ndarray, views=None, max_iter: int = 30,
           rtol: float = 1e-8, start: _Normal | None = None):
    """Levenberg–Marquardt refinement of Zhang's maximum-likelihood problem from a
    nearby start, the poses eliminated by their Schur complement.

    The same objective as ``cv2.calibrateCamera`` (the squared reprojection error of
    every corner over the model's free intrinsics and each view's Rodrigues pose),
    solved on the reduced normal equations ``(Σ_v A_v − B_v C_v⁻¹ B_vᵀ) Δa =
    −Σ_v (ga_v − B_v C_v⁻¹ gp_v)`` (Triggs et al. 2000, "Bundle adjustment — a
    modern synthesis", §6.1): a (≤ 12)-square solve per step instead of OpenCV's
    (18 + 6V)-square one, and the Jacobians from ``cv2.projectPoints``. Meant for
    starts near the optimum (the held-out refits of model choice, a candidate
    started from a richer one's solution); a step is kept only if it lowers the
    error (Marquardt's diagonal damping otherwise grows tenfold).

    Parameters
    ----------
    object_points, image_points : list of ndarray, (N_v, 3) and (N_v, 2) float64
    model : str
        One of :data:`MODELS`; its fixed terms are zeroed in the start.
    K, dist, rvecs, tvecs : ndarray
        The start (``rvecs``, ``tvecs`` (V, 3) for every view of the lists).
    views : sequence of int, optional
        The views fitted (default all); the others' poses are returned as given.
    max_iter, rtol
        Stop after ``max_iter`` accepted steps, or when a step lowers the
        squared error by less than ``rtol`` of it.
    start : _Normal, optional
        The normal-equation blocks at the start for ``views``, when the caller
        has them (refits of several subsets from one solution of ``model``).

    Returns
    -------
    K, dist, rvecs, tvecs, sq, steps
        ``sq`` the residual sum of squares (px²) over the fitted views.

    Raises
    ------
    EstimationError
        A singular system, or no step that lowers the error at the start.

    Examples
    --------
    >>> import cv2
    >>> obj = np.array([[x, y, 0.0] for y in range(6) for x in range(8)]) * 30
    >>> K = np.array([[400., 0, 165], [0, 392, 118], [0, 0, 1]])
    >>> poses = np.array([[0.3, 0.1, 0, -100, -80, 600], [-0.2, 0.3, 0.1, -120, -60, 650],
    ...                   [0.1, -0.35, -0.1, -90, -70, 580]])
    >>> img = [cv2.projectPoints(obj, p[:3], p[3:], K, None)[0].reshape(-1, 2) for p in poses]
    >>> K1, d1, rv, tv, sq, _ = refine([obj] * 3, img, model="none", K=K * [[1.01], [0.99], [1]],
    ...                                dist=np.zeros(5), rvecs=poses[:, :3] + 0.01, tvecs=poses[:, 3:])
    >>> bool(np.allclose(K1, K, atol=1e-6)), bool(sq < 1e-12)
    (True, True)
    """
    cols = _free_columns(model)
    n_dist = 8 if model == "rational" else 5
    d0 = np.zeros(n_dist)
    d = np.asarray(dist, np.float64).ravel()[:n_dist]
    d0[:d.size] = d
    free = np.zeros(n_dist, bool)
    free[cols[4:] - 4] = True
    d0[~free] = 0.0
    a = np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], d0]
    views = np.arange(len(object_points)) if views is None else np.asarray(views, int)
    rv = np.array(rvecs, np.float64).reshape(-1, 3)
    tv = np.array(tvecs, np.float64).reshape(-1, 3)
    if start is None:
        start = _normal(object_points, image_points, views, *_intrinsics(a, n_dist), rv, tv, cols)
    ne, lam, steps = start, 1e-6, 0
    eye6 = np.eye(6, dtype=bool)
    while steps < max_iter:
        sq = float(ne.sq.sum())
        while True:
            try:
                Sa = ne.A.sum(0)
                Sa[np.diag_indices_from(Sa)] *= 1.0 + lam
                C = ne.C.copy()
                C[:, eye6] *= 1.0 + lam
                Ci = np.linalg.inv(C)
                BCi = ne.B @ Ci
                S = Sa - np.einsum("vij,vkj->ik", BCi, ne.B)
                h = ne.ga.sum(0) - np.einsum("vij,vj->i", BCi, ne.gp)
                da = -np.linalg.solve(S, h)
            except np.linalg.LinAlgError:
                raise EstimationError("calibration", f"model {model}: singular normal equations") from None
            dp = -np.einsum("vij,vj->vi", Ci, ne.gp + np.einsum("vji,j->vi", ne.B, da))
            a1 = a.copy()
            a1[cols] += da
            rv1, tv1 = rv.copy(), tv.copy()
            rv1[views] += dp[:, :3]
            tv1[views] += dp[:, 3:]
            ne1 = (_normal(object_points, image_points, views, *_intrinsics(a1, n_dist), rv1, tv1, cols)
                   if np.all(np.isfinite(a1)) and np.all(np.isfinite(dp)) else None)
            if ne1 is not None and float(ne1.sq.sum()) <= sq:
                break
            lam *= 10.0
            if lam > 1e8:
                if steps == 0:
                    raise EstimationError("calibration", f"model {model}: no step lowers the error")
                return (*_intrinsics(a, n_dist), rv, tv, sq, steps)
        a, rv, tv, ne = a1, rv1, tv1, ne1
        steps += 1
        lam = max(lam / 10.0, 1e-9)
        if sq - float(ne.sq.sum()) <= rtol * sq:
            break
    return (*_intrinsics(a, n_dist), rv, tv, float(ne.sq.sum()), steps)
