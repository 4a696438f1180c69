"""Stereo rectification: rotate both cameras of a rig so epipolar lines become
image rows (Bouguet's method as in OpenCV ``stereoRectify``).

After rectification a scene point seen at ``(x_l, y)`` in the left image is seen
at ``(x_r, y)`` in the right one, with disparity ``d = x_l - x_r > 0`` (left is
the reference, DESIGN §3) and depth along the rectified left optical axis
``Z = f B / d`` (reference ch. 5, the stereo depth relation; Hartley &
Zisserman, *Multiple View Geometry*, 2nd ed., §11.12). The rig must be
horizontal with its right camera to the right of the left one
(``T[0] < 0`` in ``x_right = R x_left + T``); any other rig would give negative
or vertical disparities and is refused.

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.camera import Camera
>>> from lumigraph.capture.rig import Rig
>>> K = np.array([[300., 0, 82], [0, 310, 58], [0, 0, 1]])
>>> cam = Camera(K, np.zeros(5), (160, 120))
>>> rig = Rig.from_pose(cam, cam, np.eye(3), [-0.1, 0, 0])
>>> rect = rectify(rig)
>>> X = np.array([[0.05, -0.02, 2.0]])
>>> xl = rect.project_left(X); xr = rect.project_right(X)
>>> bool(np.isclose(xl[0, 1], xr[0, 1])), bool(np.isclose(xl[0, 0] - xr[0, 0], rect.focal_px * rect.baseline / 2.0))
(True, True)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.capture.rig import Rig

RECTIFICATION_SCHEMA = "lumigraph.rectification"
ALPHA_RANGE = (0.0, 1.0)  # rectify's alpha: 0 crops to valid pixels, 1 keeps all


def _mat(name: str, a, shape: tuple[int, ...]) -> np.ndarray:
    m = np.asarray(a, dtype=np.float64)
    if m.shape != shape or not np.all(np.isfinite(m)):
        raise ValueError(f"{name}: expected a finite {shape} array, got shape {m.shape}")
    return m


@dataclass(frozen=True)
class Rectification:
    """The rectifying transforms of a stereo rig.

    Attributes
    ----------
    rig : Rig
        The input rig (``x_right = R x_left + T``).
    R1, R2 : ndarray, (3, 3) float64
        Rectifying rotations ``rect_from_cam`` of the left and right camera.
    P1, P2 : ndarray, (3, 4) float64
        Projection matrices of the rectified cameras, both in the rectified
        LEFT frame: ``P1 = [K' | 0]``, ``P2 = [K' | K' (-B, 0, 0)^T]``.
    Q : ndarray, (4, 4) float64
        Disparity-to-depth matrix (OpenCV convention):
        ``(X, Y, Z, W)^T = Q (x, y, d, 1)^T``.
    image_size : (int, int)
        ``(width, height)`` of the rectified images.
    extra : dict
        Diagnostics (e.g. ``alpha``), saved unchanged.
    """

    rig: Rig
    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray
    image_size: tuple[int, int]
    extra: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        if not isinstance(self.rig, Rig):
            raise TypeError(f"rig: expected a capture.rig.Rig, got {type(self.rig).__name__}")
        for name in ("R1", "R2"):
            m = _mat(name, getattr(self, name), (3, 3))
            if not np.allclose(m @ m.T, np.eye(3), atol=1e-6):
                raise ValueError(f"{name}: expected a rotation matrix")
            object.__setattr__(self, name, m)
        for name in ("P1", "P2"):
            object.__setattr__(self, name, _mat(name, getattr(self, name), (3, 4)))
        object.__setattr__(self, "Q", _mat("Q", self.Q, (4, 4)))
        w, h = (int(v) for v in self.image_size)
        if w <= 0 or h <= 0:
            raise ValueError(f"image_size: expected positive (width, height), got {self.image_size}")
        object.__setattr__(self, "image_size", (w, h))
        if not self.P1[0, 0] > 0:
            raise ValueError(f"P1: rectified focal length must be positive, got {self.P1[0, 0]}")
        if not self.P2[0, 3] < 0:
            raise ValueError("P2: expected the right camera to the right of the left one "
                             f"(P2[0, 3] = -f B < 0), got {self.P2[0, 3]}")

    # ------------------------------------------------------------ properties
    @property
    def focal_px(self) -> float:
        """Focal length of both rectified cameras, in pixels (``P1[0, 0]``)."""
        return float(self.P1[0, 0])

    @property
    def baseline(self) -> float:
        """Distance between the optical centres, in the unit of ``rig.T``."""
        return float(-self.P2[0, 3] / self.P2[0, 0])

    # -------------------------------------------------------------- geometry
    def project_left(self, points: np.ndarray) -> np.ndarray:
        """Pixels ``(N, 2)`` in the rectified left image of points ``(N, 3)``
        given in the ORIGINAL left camera frame."""
        return self._project(self.P1, np.asarray(points, np.float64).reshape(-1, 3) @ self.R1.T)

    def project_right(self, points: np.ndarray) -> np.ndarray:
        """Pixels ``(N, 2)`` in the rectified right image of points ``(N, 3)``
        given in the ORIGINAL left camera frame."""
        return self._project(self.P2, np.asarray(points, np.float64).reshape(-1, 3) @ self.R1.T)

    @staticmethod
    def _project(P: np.ndarray, X: np.ndarray) -> np.ndarray:
        h = X @ P[:, :3].T + P[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            return h[:, :2] / h[:, 2:3]

    @cached_property
    def _maps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        import cv2

        out = []
        for cam, R, P in ((self.rig.left, self.R1, self.P1), (self.rig.right, self.R2, self.P2)):
            mx, my = cv2.initUndistortRectifyMap(cam.K, cam.dist, R, P[:, :3], self.image_size,
                                                 cv2.CV_32FC1)
            mx.flags.writeable = False
            my.flags.writeable = False
            out += [mx, my]
        return tuple(out)

    def maps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Remap tables ``left_x, left_y, right_x, right_y``.

        Each is ``(H, W)`` float32 (``image_size`` of the rectified images):
        the source pixel in the ORIGINAL (distorted) image to sample for each
        rectified pixel, for ``cv2.remap``. The arrays are read-only views of a
        cache; copy them before editing.
        """
        return self._maps

    @cached_property
    def _device_maps(self) -> dict:
        return {}  # torch device -> the four map tensors, built on first use

    def apply(self, left: np.ndarray, right: np.ndarray, *,
              device="cpu") -> tuple[np.ndarray, np.ndarray]:
        """Rectify an image pair (bilinear; pixels from outside the source are 0).

        Parameters
        ----------
        left, right : ndarray, (H, W) or (H, W, C)
            Images of the rig's image size, any dtype ``cv2.remap`` accepts
            (uint8, uint16, float32, ...).

        device : str
            ``"cpu"`` remaps with OpenCV; ``"cuda"``/``"torch-cpu"`` build the
            same maps and resample on torch (:mod:`lumigraph.calib.undistort_torch`),
            equal within float32 rounding (integer images: within one code,
            at halves only). :meth:`maps` stays OpenCV's.

        Returns
        -------
        left_rect, right_rect : ndarray
            ``image_size`` (w, h) rectified images, same dtype and channels.
        """
        import cv2

        from lumigraph.capture.device import resolve_device

        dev = resolve_device(device)
        if dev.uses_torch:
            from lumigraph.calib import undistort_torch

            dmaps = self._device_maps.get(dev.torch)
            if dmaps is None:
                dmaps = self._device_maps[dev.torch] = tuple(
                    undistort_torch.maps_tensor(cam, R, P, self.image_size, dev)
                    for cam, R, P in ((self.rig.left, self.R1, self.P1),
                                      (self.rig.right, self.R2, self.P2)))
        lx, ly, rx, ry = (None,) * 4 if dev.uses_torch else self._maps
        out = []
        for k, (name, img, cam, mx, my) in enumerate((("left", left, self.rig.left, lx, ly),
                                                      ("right", right, self.rig.right, rx, ry))):
            a = np.asarray(img)
            if a.ndim not in (2, 3) or a.shape[1::-1] != tuple(cam.image_size):
                raise ValueError(f"{name}: expected an image of size {cam.image_size} (w, h), "
                                 f"got array shape {a.shape}")
            if dev.uses_torch:
                r = undistort_torch.resample(a, dmaps[k], dev)
                out.append(r[:, :, None] if a.ndim == 3 and r.ndim == 2 else r)
                continue
            r = cv2.remap(np.ascontiguousarray(a), mx, my, cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            if a.ndim == 3 and r.ndim == 2:
                r = r[:, :, None]
            out.append(r.astype(a.dtype, copy=False))
        return out[0], out[1]

    def disparity_to_depth(self, disparity: np.ndarray) -> np.ndarray:
        """Depth ``Z`` along the rectified left optical axis, ``(H, W)`` float32
        in the unit of ``rig.T``; NaN where the disparity is NaN or ``<= 0``.

        ``Z = Q[2,3] / (Q[3,2] d + Q[3,3])``, which is ``f B / d`` when the
        rectified principal points coincide (the default).
        """
        d = np.asarray(disparity, dtype=np.float64)
        if d.ndim != 2:
            raise ValueError(f"disparity: expected an (H, W) array, got shape {d.shape}")
        with np.errstate(divide="ignore", invalid="ignore"):
            z = self.Q[2, 3] / (self.Q[3, 2] * d + self.Q[3, 3])
        z[~(d > 0) | ~np.isfinite(z) | (z <= 0)] = np.nan
        return z.astype(np.float32)

    def reproject(self, disparity: np.ndarray) -> np.ndarray:
        """3-D points ``(H, W, 3)`` float32 in the rectified LEFT camera frame
        (unit of ``rig.T``) for a left-reference disparity map ``(H, W)``;
        NaN where the disparity is NaN or ``<= 0``.

        To get points in the original left camera frame apply ``R1.T``.
        """
        d = np.asarray(disparity, dtype=np.float64)
        if d.ndim != 2:
            raise ValueError(f"disparity: expected an (H, W) array, got shape {d.shape}")
        h, w = d.shape
        y, x = np.mgrid[0:h, 0:w].astype(np.float64)
        hom = np.stack([x, y, d, np.ones_like(d)], axis=-1) @ self.Q.T
        with np.errstate(divide="ignore", invalid="ignore"):
            pts = hom[..., :3] / hom[..., 3:4]
        bad = ~(d > 0) | ~np.all(np.isfinite(pts), axis=-1) | (pts[..., 2] <= 0)
        pts[bad] = np.nan
        return pts.astype(np.float32)

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict:
        rig = self.rig.to_dict()
        rig.pop("schema", None)
        rig.pop("schema_version", None)
        return {"schema": RECTIFICATION_SCHEMA, "schema_version": 1, "rig": rig,
                "R1": self.R1.tolist(), "R2": self.R2.tolist(), "P1": self.P1.tolist(),
                "P2": self.P2.tolist(), "Q": self.Q.tolist(), "image_size": list(self.image_size),
                "focal_px": self.focal_px, "baseline": self.baseline, **self.extra}

    @classmethod
    def from_dict(cls, d: dict, *, where: str | os.PathLike = "rectification",
                  key: str = "") -> Rectification:
        """From a ``rectification.json`` body; :class:`InputError` naming
        ``where`` (the file) and the key at fault: the rig
        (:meth:`Rig.from_dict`), ``R1``/``R2`` not finite 3x3 rotations,
        ``P1``/``P2`` not finite 3x4 with a positive focal length and the
        right camera to the right (``P2[0][3] < 0``), ``Q`` not a finite 4x4,
        ``image_size`` not two positive integers."""
        from lumigraph.capture.camera import MAX_IMAGE_SIDE
        from lumigraph.capture.rig import require_rotation
        from lumigraph.capture.schema import fail, key_path, require, require_object

        require_object(d, path=where, where=key, keys=("rig", "R1", "R2", "P1", "P2", "Q",
                                                       "image_size"),
                       what="the rectification.json of 'lumigraph calib rectify' (rig, R1, R2, "
                            "P1, P2, Q, image_size)")
        rig = Rig.from_dict(d["rig"], where=where, key=key_path(key, "rig"))
        R1, R2 = (require_rotation(d, n, path=where, where=key) for n in ("R1", "R2"))
        P1, P2 = (require(d, n, "matrix", shape=(3, 4), path=where, where=key)
                  for n in ("P1", "P2"))
        Q = require(d, "Q", "matrix", shape=(4, 4), path=where, where=key)
        size = require(d, "image_size", "list", length=2, items="integer", low=1,
                       high=MAX_IMAGE_SIDE, path=where, where=key)
        if not P1[0, 0] > 0:
            raise fail(where, key_path(key, "P1", 0, 0), f"expected the rectified focal length "
                                                          f"(positive), got {P1[0, 0]}")
        if not P2[0, 3] < 0:
            raise fail(where, key_path(key, "P2", 0, 3), f"expected -f B < 0 (the right camera "
                                                          f"to the right), got {P2[0, 3]}")
        extra = {k: v for k, v in d.items() if k not in
                 ("schema", "schema_version", "rig", "R1", "R2", "P1", "P2", "Q",
                  "image_size", "focal_px", "baseline")}
        try:
            return cls(rig, R1, R2, P1, P2, Q, tuple(size), extra)
        except (TypeError, ValueError) as e:  # the checks above should leave none
            raise fail(where, key, f"not a valid rectification description ({e})") from None

    def save(self, path: str | os.PathLike, *, meta: dict | None = None) -> Path:
        """Write ``rectification.json`` atomically (with a sidecar when ``meta`` is given)."""
        from lumigraph.capture.artifact import save_json_artifact

        return save_json_artifact(path, self.to_dict(), meta=meta)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Rectification:
        """Read ``rectification.json`` (as ``lumigraph calib rectify`` writes
        it): the one parser of rectification files. The transforms are used
        as saved, never recomputed from the rig."""
        from lumigraph.capture.artifact import load_json_artifact

        return cls.from_dict(load_json_artifact(path, "rectification",
                                                schemas=(RECTIFICATION_SCHEMA,)), where=str(path))


def check_rectify_options(*, alpha: float) -> float:
    """Check :func:`rectify`'s options before any input is loaded; ``alpha`` as
    a float, or :class:`InputError` naming it.

    >>> check_rectify_options(alpha=1)
    1.0
    >>> check_rectify_options(alpha=1.5)
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: alpha: expected a value in [0, 1], got 1.5
    """
    alpha = float(alpha)
    if not ALPHA_RANGE[0] <= alpha <= ALPHA_RANGE[1]:
        raise InputError("alpha", f"expected a value in [0, 1], got {alpha}")
    return alpha


def rectify(rig: Rig, *, alpha: float = 0.0, image_size: tuple[int, int] | None = None) -> Rectification:
    """Rectify a horizontal stereo rig (Bouguet's method, OpenCV ``stereoRectify``
    with ``CALIB_ZERO_DISPARITY`` so both rectified principal points coincide).

    Parameters
    ----------
    rig : Rig
        ``x_right = R x_left + T`` with the right camera to the right
        (``T[0] < 0``) and a mostly horizontal baseline (``|T_x| > |T_y|``).
    alpha : float, keyword-only
        0 keeps only valid pixels (crop), 1 keeps every source pixel (black
        borders); values between blend the two. Must lie in [0, 1].
    image_size : (int, int), optional
        ``(w, h)`` of the rectified images; the left camera's size by default.

    Returns
    -------
    Rectification
        Disparity convention: ``x_right = x_left - d`` with ``d = f B / Z > 0``.

    Raises
    ------
    InputError
        ``alpha`` outside [0, 1] (:func:`check_rectify_options`).
    ValueError, TypeError
        A rig that is not horizontal, or whose cameras differ in image size.
    """
    import cv2

    if not isinstance(rig, Rig):
        raise TypeError(f"rig: expected a capture.rig.Rig, got {type(rig).__name__}")
    alpha = check_rectify_options(alpha=alpha)
    T = rig.T
    if not (T[0] < 0 and abs(T[0]) > abs(T[1])):
        raise ValueError("rig: expected a horizontal rig with the right camera to the right of the left "
                         f"(T[0] < 0, |T[0]| > |T[1]|), got T = {T.tolist()}; swap left and right "
                         "or rotate the images")
    if rig.left.image_size != rig.right.image_size:
        raise ValueError(f"rig: left and right image sizes differ ({rig.left.image_size} vs "
                         f"{rig.right.image_size})")
    size = tuple(int(v) for v in (image_size or rig.left.image_size))
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(
        rig.left.K, rig.left.dist, rig.right.K, rig.right.dist, rig.left.image_size, rig.R,
        T.reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha, newImageSize=size)
    return Rectification(rig, R1, R2, P1, P2, Q, size, {"alpha": alpha})
