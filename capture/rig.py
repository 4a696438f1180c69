"""A calibrated stereo rig: two cameras and the pose of the right one relative to
the left (``x_right = R x_left + T``, OpenCV's ``stereoCalibrate`` convention).

``rig.json`` holds ``left`` and ``right`` camera descriptions (as in
``camera.json``), ``R`` (3×3), ``T`` (3,) in the board's length unit, the
essential and fundamental matrices ``E``, ``F`` and fit diagnostics.

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.camera import Camera
>>> K = np.array([[700., 0, 320], [0, 700, 240], [0, 0, 1]])
>>> rig = Rig.from_pose(Camera(K, np.zeros(5), (640, 480)), Camera(K, np.zeros(5), (640, 480)),
...                     np.eye(3), np.array([-0.1, 0, 0]))
>>> round(rig.baseline, 6)
0.1
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lumigraph.capture.camera import GT_SCHEMA, Camera
from lumigraph.capture.schema import fail, key_path, require, require_object, shown

RIG_SCHEMA = "lumigraph.rig"


def _skew(t: np.ndarray) -> np.ndarray:
    return np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])


@dataclass(frozen=True)
class Rig:
    """Two cameras and ``right_from_left`` pose; ``E`` and ``F`` follow from them."""

    left: Camera
    right: Camera
    R: np.ndarray
    T: np.ndarray
    E: np.ndarray
    F: np.ndarray
    extra: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        R = np.asarray(self.R, np.float64)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
            raise ValueError("R: expected a 3x3 rotation matrix")
        T = np.asarray(self.T, np.float64).ravel()
        if T.shape != (3,) or not np.linalg.norm(T) > 0:
            raise ValueError(f"T: expected a non-zero 3-vector, got {T.tolist()}")
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "T", T)
        object.__setattr__(self, "E", np.asarray(self.E, np.float64))
        object.__setattr__(self, "F", np.asarray(self.F, np.float64))

    @classmethod
    def from_pose(cls, left: Camera, right: Camera, R, T, **extra) -> Rig:
        """Build a rig from the pose, deriving ``E = [T]x R`` and
        ``F = K_r^-T E K_l^-1`` (normalised so that ``F[2, 2]`` or its largest
        entry is 1)."""
        R = np.asarray(R, np.float64)
        T = np.asarray(T, np.float64).ravel()
        E = _skew(T) @ R
        F = np.linalg.inv(right.K).T @ E @ np.linalg.inv(left.K)
        F = F / (F[2, 2] if abs(F[2, 2]) > 1e-12 else np.abs(F).max())
        return cls(left, right, R, T, E, F, dict(extra))

    @property
    def baseline(self) -> float:
        """Distance between the optical centres, in the unit of ``T``."""
        return float(np.linalg.norm(self.T))

    def to_dict(self) -> dict:
        def cam(c: Camera) -> dict:
            d = c.to_dict()
            d.pop("schema", None)
            d.pop("schema_version", None)
            return d

        return {"schema": RIG_SCHEMA, "schema_version": 1, "left": cam(self.left),
                "right": cam(self.right), "R": self.R.tolist(), "T": self.T.tolist(),
                "E": self.E.tolist(), "F": self.F.tolist(), "baseline": self.baseline,
                **self.extra}

    def save(self, path: str | os.PathLike, *, meta: dict | None = None) -> Path:
        """Write ``rig.json`` atomically (with a sidecar when ``meta`` is given)."""
        from lumigraph.capture.artifact import save_json_artifact

        return save_json_artifact(path, self.to_dict(), meta=meta)

    @classmethod
    def from_dict(cls, d: dict, *, where: str | os.PathLike = "rig", key: str = "") -> Rig:
        """A rig from its ``rig.json`` layout (``left``, ``right``, ``R``, ``T``;
        ``E`` and ``F`` are derived from the pose when absent).

        ``where`` is the file (or the argument) and ``key`` the key path of
        ``d`` inside it (``"rig"`` in a ``gt.json``); :class:`InputError`
        names both and the key at fault: a missing key, a camera that is not
        one (:meth:`Camera.from_dict`), an ``R`` that is not a finite 3x3
        rotation, a ``T`` that is not a finite non-zero 3-vector, an ``E`` or
        ``F`` that is not a finite 3x3.
        """
        what = "a rig (left, right, R, T)"
        if not key:
            what += ": a rig.json, or a gt.json with a 'rig' entry"
        require_object(d, path=where, where=key, what=what, keys=("left", "right", "R", "T"))
        left = Camera.from_dict(d["left"], where=where, key=key_path(key, "left"))
        right = Camera.from_dict(d["right"], where=where, key=key_path(key, "right"))
        R = require_rotation(d, "R", path=where, where=key)
        T = require(d, "T", "matrix", shape=(3,), path=where, where=key)
        with np.errstate(over="ignore"):
            baseline = np.linalg.norm(T)
        if not 0 < baseline < np.inf:
            raise fail(where, key_path(key, "T"), f"expected a non-zero 3-vector of finite length "
                                                  f"(the right camera's position), got {T.tolist()}")
        E = require(d, "E", "matrix", shape=(3, 3), default=None, path=where, where=key)
        F = require(d, "F", "matrix", shape=(3, 3), default=None, path=where, where=key)
        extra = {k: v for k, v in d.items() if k not in _RIG_KEYS}
        try:
            with np.errstate(all="ignore"):  # extreme K or T: refused just below
                rig = cls(left, right, R, T, E, F, extra) if E is not None and F is not None \
                    else cls.from_pose(left, right, R, T, **extra)
        except (TypeError, ValueError) as e:  # the checks above should leave none
            raise fail(where, key, f"not a valid rig description ({e})") from None
        if not (np.isfinite(rig.E).all() and np.isfinite(rig.F).all()):
            raise fail(where, key, "the cameras' K and the pose T give no finite essential and "
                                   "fundamental matrices; check their magnitudes")
        return rig

    @classmethod
    def load(cls, path: str | os.PathLike) -> Rig:
        """Read ``rig.json``, or a rendered scene's ``gt.json`` that holds one
        under ``rig``: the one parser of rig files. InputError names the file
        and the key at fault (:meth:`from_dict`)."""
        from lumigraph.capture.artifact import load_json_artifact

        d = load_json_artifact(path, "rig", schemas=(RIG_SCHEMA, GT_SCHEMA))
        if "left" not in d and "rig" in d:
            return cls.from_dict(d["rig"], where=os.fspath(path), key="rig")
        return cls.from_dict(d, where=os.fspath(path))


def require_rotation(body: dict, name: str, *, path: str | os.PathLike, where: str = "") -> np.ndarray:
    """``body[name]`` as a 3x3 rotation (finite, ``R Rᵀ = I`` to 1e-6,
    ``det R = +1``), or :class:`InputError` naming ``path`` and the key.

    >>> require_rotation({"R": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}, "R", path="rig.json")
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: rig.json: key 'R': expected a rotation matrix (R R^T = I, det R = +1)
    """
    R = require(body, name, "matrix", shape=(3, 3), path=path, where=where)
    with np.errstate(all="ignore"):  # entries near 1e308 overflow: not a rotation either
        ok = np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0
    if not ok:
        raise fail(path, key_path(where, name), "expected a rotation matrix (R R^T = I, det R = +1)")
    return R


_RIG_KEYS = ("schema", "schema_version", "left", "right", "R", "T", "E", "F", "baseline")
CAMERA_ARRAY_SCHEMA = "lumigraph.camera-array"


@dataclass(frozen=True)
class CameraArray:
    """N posed cameras, in order (row-major for a light-field array).

    The file is ``{"cameras": [camera.json entries, each with "cam_from_world":
    {"R": 3x3, "t": [3]}]}`` (``lumigraph lightfield import --rig``); a
    two-camera ``rig.json`` (or a ``gt.json`` with a ``rig`` entry) reads as
    the array ``[left, right]`` in the left camera's frame.

    Attributes
    ----------
    cameras : tuple of Camera
    cam_from_world : tuple of (R (3, 3) float64, t (3,) float64)
        ``x_cam = R x_world + t`` of each camera.

    Examples
    --------
    >>> K = np.array([[700., 0, 320], [0, 700, 240], [0, 0, 1]])
    >>> cam = Camera(K, np.zeros(5), (640, 480))
    >>> rig = Rig.from_pose(cam, cam, np.eye(3), [-0.1, 0, 0])
    >>> arr = CameraArray.from_dict(rig.to_dict())
    >>> len(arr.cameras), arr.cam_from_world[1][1].tolist()
    (2, [-0.1, 0.0, 0.0])
    """

    cameras: tuple
    cam_from_world: tuple

    def __post_init__(self):
        cams = tuple(self.cameras)
        if not cams or not all(isinstance(c, Camera) for c in cams):
            raise TypeError("cameras: expected a non-empty sequence of Camera")
        poses = []
        for k, pose in enumerate(self.cam_from_world):
            R, t = (np.asarray(a, np.float64) for a in pose)
            if R.shape != (3, 3) or t.size != 3:
                raise ValueError(f"cam_from_world[{k}]: expected (R 3x3, t 3), got shapes "
                                 f"{R.shape}, {t.shape}")
            poses.append((R, t.reshape(3)))
        if len(poses) != len(cams):
            raise ValueError(f"cam_from_world: expected one pose per camera ({len(cams)}), got "
                             f"{len(poses)}")
        object.__setattr__(self, "cameras", cams)
        object.__setattr__(self, "cam_from_world", tuple(poses))

    @classmethod
    def from_dict(cls, d, *, where: str | os.PathLike = "cameras", key: str = "") -> CameraArray:
        """From ``{"cameras": [...]}``, a bare list of camera entries, or a
        two-camera rig description; :class:`InputError` naming ``where`` (the
        file) and the key at fault (``key`` is the key path of ``d`` in it)."""
        if isinstance(d, dict) and "cameras" not in d and ("left" in d or "rig" in d):
            rig = Rig.from_dict(d, where=where, key=key) if "left" in d else \
                Rig.from_dict(d["rig"], where=where, key=key_path(key, "rig"))
            return cls((rig.left, rig.right), ((np.eye(3), np.zeros(3)), (rig.R, rig.T)))
        if isinstance(d, dict):
            key = key_path(key, "cameras")
            d = d.get("cameras")
        if not isinstance(d, list) or not d:
            raise fail(where, key, f'expected {{"cameras": [camera.json entries with '
                                   f'cam_from_world {{R, t}}, row-major]}} or a rig.json, got '
                                   f"{shown(d)}")
        cams, poses = [], []
        for k, e in enumerate(d):
            name = key_path(key, k)
            cams.append(Camera.from_dict(e, where=where, key=name))
            pose = require(e, "cam_from_world", "object", path=where, where=name)
            poses.append((require_rotation(pose, "R", path=where, where=key_path(name, "cam_from_world")),
                          require(pose, "t", "matrix", shape=(3,), path=where,
                                  where=key_path(name, "cam_from_world"))))
        return cls(tuple(cams), tuple(poses))

    def to_dict(self) -> dict:
        cams = []
        for c, (R, t) in zip(self.cameras, self.cam_from_world, strict=True):
            d = c.to_dict()
            d.pop("schema", None)
            d.pop("schema_version", None)
            cams.append({**d, "cam_from_world": {"R": R.tolist(), "t": t.tolist()}})
        return {"schema": CAMERA_ARRAY_SCHEMA, "schema_version": 1, "cameras": cams}

    def save(self, path: str | os.PathLike, *, meta: dict | None = None) -> Path:
        """Write the camera array atomically (with a sidecar when ``meta`` is given)."""
        from lumigraph.capture.artifact import save_json_artifact

        return save_json_artifact(path, self.to_dict(), meta=meta)

    @classmethod
    def load(cls, path: str | os.PathLike) -> CameraArray:
        """Read a camera-array file, a ``rig.json`` or a ``gt.json`` with a
        ``rig`` entry: the one parser of posed-camera files."""
        from lumigraph.capture.artifact import load_json_artifact

        d = load_json_artifact(path, "rig", schemas=(CAMERA_ARRAY_SCHEMA, RIG_SCHEMA, GT_SCHEMA))
        return cls.from_dict(d, where=os.fspath(path))
