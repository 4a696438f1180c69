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
        # in bands of rows: the float64 work of a band, not of the image, at once
        w, h = self.camera.image_size
        mx, my = np.empty((h, w), np.float32), np.empty((h, w), np.float32)
        step = max(1, (1 << 18) // max(w, 1))
        for y in range(0, h, step):
            mx[y:y + step], my[y:y + step] = self.map_rows(y, min(y + step, h))
        return mx, my

    def map_rows(self, y0: int, y1: int) -> tuple[np.ndarray, np.ndarray]:
        """``(map_x, map_y)`` of output rows ``y0:y1``, each ``(y1 - y0, W)``
        float32: where each output pixel samples the source image (OpenCV's
        undistortion model, :meth:`Camera.distort_normalized`). Computed per
        pixel from its own coordinates (no running sums along a row, as
        ``initUndistortRectifyMap`` has), so a band's map is, to the bit, its
        rows of the whole image's."""
        w = self.camera.image_size[0]
        kn, ks = self.camera.K, self.source.K
        u = np.arange(w, dtype=np.float64)[None, :]
        v = np.arange(y0, y1, dtype=np.float64)[:, None]
        y = np.broadcast_to((v - kn[1, 2]) / kn[1, 1], (y1 - y0, w))
        x = np.broadcast_to((u - kn[0, 2]) / kn[0, 0], (y1 - y0, w))
        d = self.source.distort_normalized(np.stack([x.ravel(), y.ravel()], axis=1))
        mx = ks[0, 0] * d[:, 0] + ks[0, 1] * d[:, 1] + ks[0, 2]
        my = ks[1, 1] * d[:, 1] + ks[1, 2]
        return (mx.reshape(y1 - y0, w).astype(np.float32),
                my.reshape(y1 - y0, w).astype(np.float32))

    def maps(self) -> tuple[np.ndarray, np.ndarray]:
        """``(map_x, map_y)``, each ``(H, W)`` float32: the source pixel per output pixel."""
        return self._maps

    @cached_property
    def _device_maps(self) -> dict:
        return {}  # torch device -> (map_x, map_y) tensors, built on first use

    def source_rows(self, map_y: np.ndarray) -> tuple[int, int]:
        """The source rows ``r0:r1`` a band with ``map_y`` samples: bilinear
        reads ``⌊y⌋`` and ``⌊y⌋ + 1`` after OpenCV rounds ``y`` to 1/32 px,
        so one row more on each side covers every sample inside the image."""
        h = self.source.image_size[1]
        finite = map_y[np.isfinite(map_y)]
        if finite.size == 0:
            return 0, 0
        lo = int(np.floor(float(finite.min()))) - 1
        hi = int(np.floor(float(finite.max()))) + 3
        return max(0, min(lo, h)), max(0, min(hi, h))

    def apply(self, image: np.ndarray, *, device="cpu") -> np.ndarray:
        """Undistort an image of the source camera's size; same dtype and channels.

        ``device`` (:mod:`lumigraph.capture.device`): ``"cpu"`` remaps with
        OpenCV; ``"cuda"``/``"torch-cpu"`` build the same maps and resample on
        torch (:mod:`lumigraph.calib.undistort_torch`), equal within float32
        rounding (integer images: within one code, at halves only)."""
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
        return _remap(a, mx, my)

    def apply_rows(self, read, y0: int, y1: int) -> np.ndarray:
        """Output rows ``y0:y1`` of :meth:`apply`, reading only the source rows
        they sample: ``read(r0, r1)`` returns source rows ``r0:r1``. The same
        values as :meth:`apply`'s rows (the sub-image's rows are the image's,
        the map is shifted by a whole number of rows, which float32 does
        exactly, and beyond the sub-image only pixels beyond the image are
        sampled)."""
        mx, my = self.map_rows(y0, y1)
        r0, r1 = self.source_rows(my)
        src = read(r0, r1) if r1 > r0 else read(0, 1)
        if r1 <= r0:  # nothing inside the image: every sample is the border
            my = np.full_like(my, -10.0)
        else:
            my -= np.float32(r0)
        return _remap(src, mx, my)


def _remap(a: np.ndarray, mx: np.ndarray, my: np.ndarray) -> np.ndarray:
    import cv2

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
