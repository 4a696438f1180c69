"""The pinhole camera with lens distortion, in OpenCV's model and conventions.

``x_cam = R x_world + t`` (``cam_from_world``); pixel ``(x, y)``, x right, y
down, pixel centres at integer coordinates. Distortion ``(k1, k2, p1, p2, k3[,
k4, k5, k6])`` acts on normalised coordinates (Brown–Conrady radial and
tangential terms, OpenCV's rational model when k4..k6 are present):

    r² = x² + y²
    radial = (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)
    x_d = x·radial + 2 p1 x y + p2 (r² + 2x²)
    y_d = y·radial + p1 (r² + 2y²) + 2 p2 x y
    u = fx x_d + s y_d + cx,   v = fy y_d + cy

Reference: Z. Zhang, "A flexible new technique for camera calibration", IEEE
TPAMI 22(11), 2000, doi:10.1109/34.888718 (reference ch. 5, §5.1.1).

Examples
--------
>>> import numpy as np
>>> cam = Camera(np.array([[800., 0, 330], [0, 780, 238], [0, 0, 1]]),
...              np.array([-0.2, 0.05, 1e-3, -5e-4, 0.0]), (640, 480))
>>> px = cam.project(np.array([[0.1, -0.05, 2.0]]))
>>> np.allclose(cam.unproject(px)[0], [0.05, -0.025, 1.0])
True
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CAMERA_SCHEMA = "lumigraph.camera"
GT_SCHEMA = "lumigraph.gt"  # a rendered scene's gt.json (capture.render writes it)
MAX_IMAGE_SIDE = 100_000  # pixels: a larger width or height in a file is a typo
DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


def _as_dist(dist) -> np.ndarray:
    d = np.asarray(dist, dtype=np.float64).ravel()
    if d.size not in (0, 4, 5, 8):
        raise ValueError(f"dist: expected 0, 4, 5 or 8 coefficients in OpenCV order, got {d.size}")
    out = np.zeros(8)
    out[: d.size] = d
    return out if d.size == 8 else out[:5]


@dataclass(frozen=True)
class Camera:
    """Intrinsics and distortion of one camera.

    Attributes
    ----------
    K : ndarray, (3, 3) float64
        ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` in pixels.
    dist : ndarray, (5,) or (8,) float64
        OpenCV order ``(k1, k2, p1, p2, k3[, k4, k5, k6])``; fewer terms given
        are padded with zeros.
    image_size : (int, int)
        ``(width, height)`` in pixels the calibration holds for.
    model : str
        Distortion model name (``none``, ``k1``, ``k1k2``, ``k1k2p1p2``,
        ``k1k2p1p2k3``, ``rational``).
    extra : dict
        Everything else a calibration records (RMS, std, views, candidates,
        warnings), saved to and loaded from ``camera.json`` unchanged.
    """

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    model: str = "k1k2p1p2k3"
    extra: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        K = np.asarray(self.K, dtype=np.float64)
        if K.shape != (3, 3) or not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
            raise ValueError(f"K: expected an upper-triangular 3x3 with last row [0, 0, 1], got {K.tolist()}")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"K: focal lengths must be positive, got fx={K[0, 0]}, fy={K[1, 1]}")
        w, h = (int(v) for v in self.image_size)
        if w <= 0 or h <= 0:
            raise ValueError(f"image_size: expected positive (width, height), got {self.image_size}")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", _as_dist(self.dist))
        object.__setattr__(self, "image_size", (w, h))

    # --------------------------------------------------------------- geometry
    @property
    def focal_px(self) -> tuple[float, float]:
        return float(self.K[0, 0]), float(self.K[1, 1])

    @property
    def principal_point(self) -> tuple[float, float]:
        return float(self.K[0, 2]), float(self.K[1, 2])

    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Apply the distortion model to normalised coordinates ``(N, 2)``."""
        d = np.zeros(8)
        d[: self.dist.size] = self.dist
        k1, k2, p1, p2, k3, k4, k5, k6 = d
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=1)

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Project camera-frame points ``(N, 3)`` to distorted pixels ``(N, 2)``.

        Points at or behind the camera (z <= 0) give NaN.
        """
        P = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
        z = P[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = P[:, :2] / z[:, None]
        xy[z <= 0] = np.nan
        xd = self.distort_normalized(xy)
        K = self.K
        u = K[0, 0] * xd[:, 0] + K[0, 1] * xd[:, 1] + K[0, 2]
        v = K[1, 1] * xd[:, 1] + K[1, 2]
        return np.stack([u, v], axis=1)

    def project_world(self, points_world: np.ndarray, cam_from_world_R: np.ndarray,
                      cam_from_world_t: np.ndarray) -> np.ndarray:
        """Project world points ``(N, 3)`` seen from pose ``x_cam = R x + t``."""
        P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        return self.project(P @ np.asarray(cam_from_world_R).T + np.asarray(cam_from_world_t).ravel())

    def _distort_with_jacobian(self, xy: np.ndarray):
        """Distorted coordinates ``(N, 2)`` and the 2×2 Jacobian entries of the
        model at ``xy`` (analytic, from the formula in the module docstring)."""
        d = np.zeros(8)
        d[: self.dist.size] = self.dist
        k1, k2, p1, p2, k3, k4, k5, k6 = d
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        a = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        b = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        radial = a / b
        # d(radial)/d(r²) by the quotient rule
        dr = ((k1 + r2 * (2 * k2 + 3 * k3 * r2)) * b - a * (k4 + r2 * (2 * k5 + 3 * k6 * r2))) / (b * b)
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        jxx = radial + 2 * x * x * dr + 2 * p1 * y + 6 * p2 * x
        jxy = 2 * x * y * dr + 2 * p1 * x + 2 * p2 * y
        jyx = 2 * x * y * dr + 2 * p1 * x + 2 * p2 * y
        jyy = radial + 2 * y * y * dr + 6 * p1 * y + 2 * p2 * x
        return xd, yd, jxx, jxy, jyx, jyy

    def unproject(self, pixels: np.ndarray, *, iterations: int = 30) -> np.ndarray:
        """Undistorted rays ``(N, 3)`` as ``(x, y, 1)`` for distorted pixels ``(N, 2)``.

        The distortion is inverted by Newton's method on the forward model
        with its analytic Jacobian, started at the distorted point and stopped
        when every step is below 1e-14 (normalised units), so the round trip
        ``project(unproject(p))`` is exact to ~1e-10 px for the distortion of
        real lenses. Pixels whose inversion does not converge (outside the
        region where the model is invertible) give NaN.
        """
        uv = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        K = self.K
        yd = (uv[:, 1] - K[1, 2]) / K[1, 1]
        xd = (uv[:, 0] - K[0, 2] - K[0, 1] * yd) / K[0, 0]
        if not np.any(self.dist):
            return np.column_stack([xd, yd, np.ones(len(xd))])
        xy = np.stack([xd, yd], axis=1)
        converged = False
        for _ in range(iterations):
            fx, fy, jxx, jxy, jyx, jyy = self._distort_with_jacobian(xy)
            ex, ey = fx - xd, fy - yd
            det = jxx * jyy - jxy * jyx
            step = np.stack([(jyy * ex - jxy * ey) / det, (-jyx * ex + jxx * ey) / det], axis=1)
            xy = xy - step
            if np.all(np.abs(step) < 1e-14):
                converged = True
                break
        if not converged:
            fx, fy, *_ = self._distort_with_jacobian(xy)
            bad = ~((np.abs(fx - xd) < 1e-9) & (np.abs(fy - yd) < 1e-9))
            xy[bad] = np.nan
        return np.column_stack([xy, np.ones(len(xy))])

    # ------------------------------------------------------------------- files
    def to_dict(self) -> dict:
        n = 8 if self.dist.size == 8 else 5
        return {"schema": CAMERA_SCHEMA, "schema_version": 1,
                "image_size": list(self.image_size), "K": self.K.tolist(),
                "dist": self.dist[:n].tolist(), "dist_names": list(DIST_NAMES[:n]),
                "model": self.model, **self.extra}

    @classmethod
    def from_dict(cls, d: dict, *, where: str | os.PathLike = "camera", key: str = "") -> Camera:
        """A camera from its ``camera.json`` layout.

        ``where`` is the file (or the argument) ``d`` came from and ``key`` its
        key path inside it (``"left"`` in a ``rig.json``). :class:`InputError`
        names both, and the key at fault: a missing ``K``, ``dist`` or
        ``image_size``; a ``K`` that is not a finite upper-triangular 3x3 with
        last row ``[0, 0, 1]`` and positive focal lengths; other than 0, 4, 5
        or 8 finite distortion coefficients; an image size that is not two
        positive integers (at most :data:`MAX_IMAGE_SIDE`).

        >>> Camera.from_dict({"K": [[0, 0, 1], [0, 1, 1], [0, 0, 1]], "dist": [],
        ...                   "image_size": [4, 3]}, where="rig.json", key="left")
        Traceback (most recent call last):
        ...
        lumigraph.capture.errors.InputError: rig.json: key 'left.K[0][0]': expected a positive focal length in pixels, got 0.0
        """
        from lumigraph.capture.schema import check, fail, key_path, require, require_object

        require_object(d, path=where, where=key, what="a camera (K, dist, image_size)",
                       keys=("K", "dist", "image_size"))
        K = require(d, "K", "matrix", shape=(3, 3), path=where, where=key)
        if not np.allclose(K[2], [0, 0, 1]):
            raise fail(where, key_path(key, "K", 2), f"expected [0, 0, 1], got {K[2].tolist()}")
        if K[1, 0] != 0:
            raise fail(where, key_path(key, "K", 1, 0), f"expected 0 (K is upper-triangular), "
                                                         f"got {K[1, 0]}")
        for i in (0, 1):
            if not K[i, i] > 0:
                raise fail(where, key_path(key, "K", i, i), f"expected a positive focal length "
                                                              f"in pixels, got {K[i, i]}")
        dist = require(d, "dist", "list", items="number", path=where, where=key)
        if len(dist) not in (0, 4, 5, 8):
            raise fail(where, key_path(key, "dist"), f"expected 0, 4, 5 or 8 coefficients in "
                                                      f"OpenCV order {DIST_NAMES}, got {len(dist)}")
        size = require(d, "image_size", "list", length=2, items="integer", low=1,
                       high=MAX_IMAGE_SIDE, path=where, where=key)
        model = require(d, "model", "string", default="k1k2p1p2k3", path=where, where=key)
        check(d.get("dist_names", []), "list", path=where, key=key_path(key, "dist_names"))
        extra = {k: v for k, v in d.items() if k not in
                 ("schema", "schema_version", "image_size", "K", "dist", "dist_names", "model")}
        try:
            return cls(K, np.array(dist, float), tuple(size), model, extra)
        except (TypeError, ValueError) as e:  # the checks above should leave none
            raise fail(where, key, f"not a valid camera description ({e})") from None

    def save(self, path: str | os.PathLike, *, meta: dict | None = None) -> Path:
        """Write ``camera.json`` atomically (with a sidecar when ``meta`` is given)."""
        from lumigraph.capture.artifact import save_json_artifact

        return save_json_artifact(path, self.to_dict(), meta=meta)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Camera:
        """Read ``camera.json``, or a rendered scene's ``gt.json`` that holds
        one under ``camera``: the one parser of camera files. InputError
        names the file and the key at fault (:meth:`from_dict`)."""
        from lumigraph.capture.artifact import load_json_artifact

        d = load_json_artifact(path, "camera", schemas=(CAMERA_SCHEMA, GT_SCHEMA))
        if "K" not in d and "camera" in d:
            return cls.from_dict(d["camera"], where=os.fspath(path), key="camera")
        return cls.from_dict(d, where=os.fspath(path))
