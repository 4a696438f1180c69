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

from lumigraph.capture.camera import Camera
from lumigraph.capture.errors import InputError

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
    def load(cls, path: str | os.PathLike) -> Rig:
        from lumigraph.capture.artifact import load_json_artifact

        d = load_json_artifact(path, "rig")
        try:
            extra = {k: v for k, v in d.items()
                     if k not in ("schema", "schema_version", "left", "right", "R", "T", "E", "F", "baseline")}
            return cls(Camera.from_dict(d["left"], where=f"{path}:left"),
                       Camera.from_dict(d["right"], where=f"{path}:right"),
                       np.array(d["R"]), np.array(d["T"]), np.array(d["E"]), np.array(d["F"]), extra)
        except InputError:
            raise
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(path, f"not a valid rig description ({e})") from None
