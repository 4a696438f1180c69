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
