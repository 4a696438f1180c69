"""Video files as frame stacks: a reader over OpenCV's FFmpeg backend.

A video (MPEG-1/2, MPEG-4, H.264, FFV1, MJPG, … in ``.mpg``, ``.avi``,
``.mkv``, ``.mp4``, …) is read as its decoded frames, ``(N, H, W, 3)`` uint8
in **RGB** order (OpenCV's BGR is converted here, as in
:mod:`lumigraph.capture.io`). Like every reader it refuses before it
allocates: the frame size the container claims is checked against
:func:`lumigraph.capture.io.max_pixels` before the first frame is decoded, and
the frames kept are counted against it as they come (``max_frames`` and
``stride`` keep a long video within memory). A file FFmpeg cannot open or
decode is an :class:`InputError` naming the file; what FFmpeg prints is kept
off the terminal.

Video codes are gamma-encoded. Streams that declare no transfer curve (the
MPEG-2 sequence display extension is optional) are taken, by the MPEG-2 /
H.262 default for an absent ``transfer_characteristics``, to use ITU-R BT.709:
:func:`bt709_to_linear` inverts its opto-electronic transfer function.

Examples
--------
>>> import numpy as np, tempfile, os
>>> d = tempfile.mkdtemp()
>>> frames = np.zeros((5, 16, 24, 3), np.uint8); frames[:, :, :, 0] = np.arange(5)[:, None, None] * 50
>>> p = write_video(os.path.join(d, "v.avi"), frames)
>>> v = read_video(p, stride=2)
>>> v.frames.shape, v.indices, v.frames[:, 0, 0, 0].tolist()
((3, 16, 24, 3), (0, 2, 4), [0, 100, 200])
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lumigraph.capture.errors import InputError

VIDEO_EXTS = {".mpg", ".mpeg", ".m2v", ".m1v", ".vob", ".ts", ".avi", ".mkv", ".mp4", ".m4v",
              ".mov", ".webm", ".wmv", ".flv"}


def is_video(path) -> bool:
    """Whether ``path`` names a video file (by its extension).

    >>> is_video("Curtain.mpg"), is_video("frame_000.png")
    (True, False)
    """
    return Path(path).suffix.lower() in VIDEO_EXTS


@dataclass(frozen=True)
class Video:
    """Decoded frames of a video.

    Attributes
    ----------
    frames : ndarray, ``(N, H, W, 3)`` uint8
        8-bit code values, RGB order (gamma-encoded, as stored).
    indices : tuple of int
        Frame number (from 0) of each kept frame in the file.
    fps : float or None
        Frame rate the container claims.
    path : str
        The file.
    decoded : int
        Frames decoded (kept or skipped) before reading stopped.
    complete : bool
        The whole stream was read (False when ``max_frames`` stopped it).
    """

    frames: np.ndarray
    indices: tuple[int, ...]
    fps: float | None
    path: str
    decoded: int
    complete: bool

    @property
    def names(self) -> tuple[str, ...]:
        """One name per kept frame, ``<file>#<frame number>``, for messages."""
        return tuple(f"{self.path}#{i}" for i in self.indices)


def check_read_options(*, max_frames: int | None = None, stride: int = 1, start: int = 0) -> None:
    """Check :func:`read_video`'s options (so a command can before it opens anything).

    Raises
    ------
    InputError
        Naming ``max_frames`` (not an integer >= 1), ``stride`` (not >= 1) or
        ``start`` (not >= 0).

    >>> try:
    ...     check_read_options(stride=0)
    ... except InputError as e:
    ...     print(e)
    stride: expected an integer >= 1 (keep every stride-th frame), got 0
    """
    def whole(v):
        return isinstance(v, int | np.integer) and not isinstance(v, bool)

    if max_frames is not None and not (whole(max_frames) and max_frames >= 1):
        raise InputError("max_frames", f"expected an integer >= 1, got {max_frames!r}")
    if not (whole(stride) and stride >= 1):
        raise InputError("stride", f"expected an integer >= 1 (keep every stride-th frame), "
                                   f"got {stride!r}")
    if not (whole(start) and start >= 0):
        raise InputError("start", f"expected a frame number >= 0, got {start!r}")


def read_video(path, *, max_frames: int | None = None, stride: int = 1,
               start: int = 0) -> Video:
    """Decode a video's frames: every ``stride``-th from frame ``start``, at most ``max_frames``.

    Parameters
    ----------
    path : path-like
        A video file FFmpeg (through OpenCV) can decode.
    max_frames : int, optional
        Keep at most this many frames (default: all, within the pixel limit).
    stride : int
        Keep every ``stride``-th frame (skipped frames are decoded, not kept).
    start : int
        First frame number kept.

    Returns
    -------
    Video

    Raises
    ------
    InputError
        Naming the file: missing or empty, not a video FFmpeg can open, no
        decodable frame (at or after ``start``), a frame size over
        :func:`~lumigraph.capture.io.max_pixels` (checked before decoding),
        frames that change size, or more kept pixels in total than
        ``max_pixels()`` (give ``max_frames`` or ``stride``). Naming an option
        out of range (:func:`check_read_options`).
    """
    from lumigraph.capture.io import (
        _c_messages,
        _cv2,
        _existing,
        check_pixel_count,
        max_pixels,
    )

    check_read_options(max_frames=max_frames, stride=stride, start=start)
    p = _existing(path)
    # FFmpeg's own log would break the one-line error convention
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
    cv2 = _cv2()
    limit = max_pixels()
    frames: list[np.ndarray] = []
    indices: list[int] = []
    with _c_messages() as said:
        cap = cv2.VideoCapture(str(p), cv2.CAP_FFMPEG)
        try:
            if not cap.isOpened():
                raise InputError(p, "cannot be opened as a video (FFmpeg through OpenCV does not "
                                    "recognise it); give a video file or the frames as images")
            w = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
            h = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
            if w > 0 and h > 0:  # the container's claim, before any frame is decoded
                check_pixel_count(p, w, h, what="video frame size")
            fps = float(cap.get(cv2.CAP_PROP_FPS)) or None
            k = 0
            complete = True
            while True:
                if max_frames is not None and len(frames) >= max_frames:
                    complete = False
                    break
                keep = k >= start and (k - start) % stride == 0
                ok = cap.grab()
                if not ok:
                    break
                if keep:
                    ok, img = cap.retrieve()
                    if not ok or img is None:
                        break
                    if img.ndim == 2:
                        img = np.repeat(img[..., None], 3, axis=2)
                    hh, ww = img.shape[:2]
                    if not frames:
                        check_pixel_count(p, ww, hh, what="video frame")
                    elif img.shape != frames[0].shape:
                        raise InputError(p, f"frame {k} is {ww}x{hh}, frame {indices[0]} is "
                                            f"{frames[0].shape[1]}x{frames[0].shape[0]}; "
                                            "a stack needs one size")
                    if (len(frames) + 1) * ww * hh > limit:
                        raise InputError(p, f"more than {len(frames)} frames of {ww}x{hh} exceed "
                                            f"the limit of {limit} pixels; keep fewer frames "
                                            "(max_frames) or every n-th (stride)")
                    frames.append(np.ascontiguousarray(img[..., :3][..., ::-1]))
                    indices.append(k)
                k += 1
        finally:
            cap.release()
    if not frames:
        quoted = " ".join(" ".join(said).split())[:200]
        raise InputError(p, ("no decodable video frame" if start == 0 else
                             f"no decodable video frame at or after frame {start} "
                             f"({k} decoded)") + (f": {quoted}" if quoted else
                                                  " (truncated or not a video?)"))
    return Video(np.stack(frames), tuple(indices), fps, str(p), k, complete)


def write_video(path, frames: np.ndarray, *, fps: float = 25.0, codec: str | None = None) -> Path:
    """Write ``(N, H, W, 3)`` uint8 RGB frames as a video (for tests and fixtures).

    ``codec`` is a FourCC; by default ``FFV1`` (lossless) for ``.avi``/``.mkv``,
    ``mp4v`` for ``.mp4``, ``MJPG`` otherwise. Not atomic: a scratch writer.

    Raises
    ------
    ValueError
        ``frames`` not ``(N, H, W, 3)`` uint8, or OpenCV has no writer for the codec.
    """
    from lumigraph.capture.io import _cv2

    a = np.asarray(frames)
    if a.ndim != 4 or a.shape[-1] != 3 or a.dtype != np.uint8 or len(a) == 0:
        raise ValueError(f"frames: expected (N, H, W, 3) uint8, got {a.shape} {a.dtype}")
    p = Path(path)
    ext = p.suffix.lower()
    codec = codec or ("FFV1" if ext in (".avi", ".mkv") else "mp4v" if ext == ".mp4" else "MJPG")
    cv2 = _cv2()
    w = cv2.VideoWriter(str(p), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*codec), float(fps),
                        (a.shape[2], a.shape[1]))
    if not w.isOpened():
        raise ValueError(f"codec: OpenCV cannot write {codec!r} to {p.name}")
    try:
        for f in a:
            w.write(np.ascontiguousarray(f[..., ::-1]))
    finally:
        w.release()
    return p


def bt709_to_linear(codes: np.ndarray, *, bit_depth: int = 8) -> np.ndarray:
    """Relative linear light from BT.709-encoded codes (ITU-R BT.709-6, §1.2, inverted).

    ``V = z / z_max``; ``L = V / 4.5`` for ``V < 0.081``, else
    ``((V + 0.099) / 1.099)^(1/0.45)``. Returns float32 in [0, 1].

    >>> bt709_to_linear(np.array([0, 255])).tolist()
    [0.0, 1.0]
    >>> round(float(bt709_to_linear(np.array([128]))[0]), 4)
    0.2615
    """
    v = np.asarray(codes, np.float64) / (2 ** bit_depth - 1)
    lin = np.where(v < 0.081, v / 4.5, ((v + 0.099) / 1.099) ** (1 / 0.45))
    return lin.astype(np.float32)


def linear_to_bt709(linear: np.ndarray) -> np.ndarray:
    """BT.709 OETF: relative linear light in [0, 1] to ``V`` in [0, 1] (float).

    >>> round(float(linear_to_bt709(bt709_to_linear(np.array([128])))[0]) * 255, 3)
    128.0
    """
    x = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    return np.where(x < 0.018, 4.5 * x, 1.099 * x ** 0.45 - 0.099)
