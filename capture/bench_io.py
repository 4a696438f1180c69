"""Bench stage ``io``: write+read round trips of linear float images.

Ours: OpenEXR float32 and half (``capture.io``), PFM. Peers: OpenCV's float
TIFF and Radiance RGBE (the OpenCV 5 wheel has no EXR codec). Knob: image
size in megapixels. Error: the largest round-trip error relative to the pixel's
brightest channel, which shows each format's precision (float32 exact, half
<= 2^-11, RGBE <= 2^-7).
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from lumigraph.capture.bench import Case, Check, Method, Results, Stage


def _image(mp: float) -> np.ndarray:
    w = int(round(np.sqrt(mp * 1e6 * 4 / 3)))
    h = int(round(w * 3 / 4))
    rng = np.random.default_rng(7)
    # Radiance spread over 4 decades, like an HDR scene (within half's range).
    return np.exp(rng.uniform(np.log(1e-2), np.log(1e2), (h, w, 3))).astype(np.float32)


def _roundtrip(ext: str, write, read):
    def run(images, mp):
        img = images[mp]
        fd, path = tempfile.mkstemp(suffix=ext)
        os.close(fd)
        try:
            write(path, img)
            return img, read(path)
        finally:
            os.unlink(path)

    return run


def _cv2_write(path, img):
    import cv2

    if not cv2.imwrite(path, np.ascontiguousarray(img[..., ::-1])):
        raise RuntimeError(f"cv2.imwrite refused {path}")


def _cv2_read(path):
    import cv2

    return cv2.imread(path, cv2.IMREAD_UNCHANGED)[..., ::-1]


def _error(_data, out) -> float:
    """Largest round-trip error relative to the pixel's brightest channel: the
    precision each format states (RGBE shares one exponent per pixel)."""
    ref, back = out
    scale = np.max(np.abs(ref), axis=-1, keepdims=True).astype(np.float64)
    return float(np.max(np.abs(back.astype(np.float64) - ref) / scale))


def _checks(res: Results, _ctx) -> list[Check]:
    out = []
    for case in ("float image",):
        ours = res.get(case, "exr float32 (ours)", res.of(case, "exr float32 (ours)")[-1].value)
        tif = res.get(case, "float TIFF (OpenCV)", ours.value)
        out.append(Check("EXR float32 round trip is exact", ours.error, 0.0, ours.error == 0.0))
        out.append(Check(f"EXR float32 write+read time / OpenCV float TIFF at {ours.value} MP",
                         ours.time_s / tif.time_s, 1.0, True,
                         "informational: EXR is ZIP-compressed, TIFF is not"))
    return out


def stage(*, quick: bool = False) -> Stage:
    from lumigraph.capture import io

    sizes = (0.1, 0.5) if quick else (0.25, 1.0, 4.0)
    case = Case("float image", lambda: {mp: _image(mp) for mp in sizes},
                "random log-uniform radiance 1e-2..1e2, 3 channels")
    methods = (
        Method("exr float32 (ours)", _roundtrip(".exr", io.write_exr, io.read_exr), "MP", sizes),
        Method("exr half (ours)", _roundtrip(".exr", lambda p, a: io.write_exr(p, a, half=True),
                                             io.read_exr), "MP", sizes),
        Method("pfm (ours)", _roundtrip(".pfm", io.write_pfm, io.read_pfm), "MP", sizes),
        Method("float TIFF (OpenCV)", _roundtrip(".tiff", _cv2_write, _cv2_read), "MP", sizes,
               peer="opencv"),
        Method("RGBE .hdr (OpenCV)", _roundtrip(".hdr", _cv2_write, _cv2_read), "MP", sizes,
               peer="opencv"),
    )
    return Stage("io", (case,), methods, _error, "max round-trip error / pixel max",
                 checks=_checks,
                 description="Write+read throughput of linear float images; the error axis "
                             "shows each format's precision (0 is plotted off-axis on log scales).")
