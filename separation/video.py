"""Separation from a video: a moving occluder filmed (Nayar et al. 2006, §5).

The paper's authors "used a video camera and moved the pole across the image
continuously" (reference ch. 8, §8.3.4). This module turns a video file into
the :class:`~lumigraph.capture.io.Stack` the separation reads from still
frames, so ``lumigraph separate VIDEO --method occluder`` and
``lumigraph separate frame_*.png --method occluder --response R`` run the same
code on the same codes:

- :func:`read_video_stack` decodes the frames through
  :func:`lumigraph.capture.video.read_video` (``max_frames``/``stride`` bound
  the memory; the frame size is checked against ``max_pixels()`` first);
- :func:`video_response` is the response curve a video's codes are linearised
  with when no ``--response`` is given: ITU-R BT.709, the MPEG-2 default for
  a stream that declares no transfer characteristics (none of the CAVE
  videos does). It is an assumption, said on stderr and kept in the meta.

Examples
--------
>>> import numpy as np, tempfile, os
>>> from lumigraph.capture.video import write_video
>>> p = write_video(os.path.join(tempfile.mkdtemp(), "v.avi"), np.full((4, 8, 8, 3), 200, np.uint8))
>>> st = read_video_stack(p, stride=2)
>>> st.images.shape, st.bit_depth, st.info["video"]["frames"]
((2, 8, 8, 3), 8, [0, 2])
>>> round(float(video_response().linearize(st.images)[0, 0, 0, 0]), 4)
0.6154
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.capture.io import Stack
from lumigraph.capture.video import bt709_to_linear, check_read_options, is_video, read_video

VIDEO_TRANSFER = "bt709"


def video_input(inputs, *, max_frames: int | None = None, stride: int = 1) -> Path | None:
    """The video among ``inputs`` (one video file), else ``None``.

    Raises
    ------
    InputError
        A video among other inputs (naming it), or ``max_frames``/``stride``
        set for still frames (naming the option).

    >>> video_input(["a.png", "b.png"]), video_input(["Curtain.mpg"], stride=2)
    (None, PosixPath('Curtain.mpg'))
    """
    paths = [Path(p) for p in inputs]
    videos = [p for p in paths if is_video(p)]
    check_read_options(max_frames=max_frames, stride=stride)
    if videos and len(paths) > 1:
        raise InputError(videos[0], "a video is read alone: give one video, or its frames "
                                    "as images")
    if not videos:
        if max_frames is not None:
            raise InputError("max_frames", "applies to a video input only")
        if stride != 1:
            raise InputError("stride", "applies to a video input only")
        return None
    return videos[0]


def read_video_stack(path, *, max_frames: int | None = None, stride: int = 1) -> Stack:
    """A video's frames as an 8-bit :class:`Stack` (``paths`` are ``<file>#<frame>``).

    ``info["video"]`` records the file, the frame numbers kept, the frame
    rate and whether the whole stream was read.

    Raises
    ------
    InputError
        From :func:`lumigraph.capture.video.read_video` (naming the file).
    """
    v = read_video(path, max_frames=max_frames, stride=stride)
    info = {"video": {"path": v.path, "frames": list(v.indices), "fps": v.fps,
                      "decoded": v.decoded, "complete": v.complete, "stride": stride}}
    return Stack(v.frames, v.names, 8, None, False, info)


def video_response(channels: int = 3):
    """The BT.709 transfer curve as an 8-bit response (``g = ln f⁻¹(z)``).

    Code 0 is stored at half a code's light (``g`` must be finite), as
    :meth:`lumigraph.hdr.response.ResponseCurve.linear` does.
    """
    from lumigraph.hdr.response import ResponseCurve

    z = np.arange(256, dtype=np.float64)
    lin = bt709_to_linear(z).astype(np.float64)
    lin[0] = bt709_to_linear(np.array([0.5]))[0]
    g = np.tile(np.log(lin), (int(channels), 1))
    return ResponseCurve(VIDEO_TRANSFER, 8, g, None,
                         {"model": VIDEO_TRANSFER, "reason": "video codes: ITU-R BT.709 transfer "
                                                             "(the MPEG-2 default when a stream "
                                                             "declares none)"})
