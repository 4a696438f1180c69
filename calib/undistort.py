"""Undistortion: resample an image as the same camera without lens distortion.

The new camera has zero distortion and a matrix from OpenCV's
``getOptimalNewCameraMatrix``: ``keep_all=False`` (default) crops to the
rectangle of valid pixels, ``keep_all=True`` keeps every source pixel (black
corners). Bilinear resampling through ``initUndistortRectifyMap``.

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.camera import Camera
>>> cam = Camera(np.array([[90., 0, 41], [0, 88, 29], [0, 0, 1]]), [-0.2, 0.03, 0, 0, 0], (80, 60))
>>> u = undistorter(cam)
>>> out = u.apply(np.full((60, 80), 200, np.uint8))
>>> out.shape, out.dtype.name, u.camera.model, bool(np.all(u.camera.dist == 0))
((60, 80), 'uint8', 'none', True)
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from lumigraph.capture.camera import Camera


@dataclass(frozen=True)
class Undistortion:
    """Maps from an undistorted image to the source (distorted) one.

    Attributes
    ----------
    source : Camera
        The calibrated camera the images come from.
    camera : Camera
        The undistorted camera (``dist`` all zero, same image size).
    keep_all : bool
    """

    source: Camera
    camera: Camera
    keep_all: bool

    @cached_property
    def _maps(self):
        import cv2

        mx, my = cv2.initUndistortRectifyMap(self.source.K, self.source.dist, np.eye(3), self.camera.K,
                                             self.camera.image_size, cv2.CV_32FC1)
        return mx, my

    def maps(self) -> tuple[np.ndarray, np.ndarray]:
        """``(map_x, map_y)``, each ``(H, W)`` float32: the source pixel per output pixel."""
        return self._maps

    @cached_property
    def _device_maps(self) -> dict:
        return {}  # torch device -> (map_x, map_y) tensors, built on first use

    def apply(self, image: np.ndarray, *, device="cpu") -> np.ndarray:
        """Undistort an image of the source camera's size; same dtype and channels.

        ``device`` (:mod:`lumigraph.capture.device`): ``"cpu"`` remaps with
        OpenCV; ``"cuda"``/``"torch-cpu"`` build the same maps and resample on
        torch (:mod:`lumigraph.calib.undistort_torch`), equal within float32
        rounding (integer images: within one code, at halves only)."""
        import cv2

        from lumigraph.capture.device import resolve_device

        dev = resolve_device(device)
        a = np.asarray(image)
        if a.ndim not in (2, 3) or a.shape[1::-1] != tuple(self.source.image_size):
            raise ValueError(f"image: expected size {self.source.image_size} (w, h), got shape {a.shape}")
        if dev.uses_torch:
            from lumigraph.calib import undistort_torch

            maps = self._device_maps.get(dev.torch)
            if maps is None:
                maps = self._device_maps[dev.torch] = undistort_torch.maps_tensor(
                    self.source, np.eye(3), self.camera.K, self.camera.image_size, dev)
            out = undistort_torch.resample(a, maps, dev)
            return out[:, :, None] if a.ndim == 3 and out.ndim == 2 else out
        mx, my = self._maps
        out = cv2.remap(np.ascontiguousarray(a), mx, my, cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if a.ndim == 3 and out.ndim == 2:
            out = out[:, :, None]
        return out.astype(a.dtype, copy=False)


def undistorter(camera: Camera, *, keep_all: bool = False) -> Undistortion:
    """Build the undistortion of ``camera`` (see the module docstring)."""
    import cv2

    if not isinstance(camera, Camera):
        raise TypeError(f"camera: expected a capture.camera.Camera, got {type(camera).__name__}")
    K, _ = cv2.getOptimalNewCameraMatrix(camera.K, camera.dist, camera.image_size,
                                         1.0 if keep_all else 0.0, camera.image_size)
    K = np.asarray(K, np.float64)
    K[0, 1] = 0.0
    new = Camera(K, np.zeros(5), camera.image_size, "none",
                 {"undistorted_from": {"K": camera.K.tolist(), "dist": camera.dist.tolist(),
                                       "model": camera.model}, "keep_all": keep_all})
    return Undistortion(camera, new, keep_all)
