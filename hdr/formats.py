"""HDR exchange formats: Radiance RGBE ``.hdr`` (with RLE; its one codec is
:mod:`lumigraph.capture.rgbe`, re-exported here) and LogLuv TIFF (32-bit
``SGILOG`` and 24-bit ``SGILOG24``), encoded and decoded here.

Reference ch. 6.2 (RGBE: three 8-bit mantissas sharing an 8-bit exponent,
bias 128; LogLuv 32: sign, 15-bit ``Le = ⌊256 (log2 Y + 64)⌋``, 8-bit
``⌊410 u′⌋`` and ``⌊410 v′⌋``; LogLuv 24: 10-bit ``Le = ⌊64 (log2 Y + 12)⌋``
and a 14-bit index into Ward's table of ``u′v′`` cells of side 0.0035).
G. Ward Larson, "LogLuv encoding for full-gamut, high-dynamic range images",
J. Graphics Tools 3(1), 1998, doi:10.1080/10867651.1998.10487485.

Precision (relative, per pixel): RGBE ≤ 2⁻⁸ of the brightest channel;
LogLuv 32 ≈ 0.27 % steps in luminance (2^(1/256)); LogLuv 24 ≈ 1.1 %
(2^(1/64)) and a coarser chromaticity.

Colour: images are linear Rec. 709/sRGB primaries (D65) in memory; LogLuv
stores CIE XYZ, converted with the sRGB matrices. The 24-bit table's row
starts and lengths (``UV_USTART``, ``UV_NUS``) are the format's definition
(Ward's 1997 table as shipped with libtiff), kept as data.

Examples
--------
Grey radiance over 2⁻⁸…2⁸ through LogLuv 32: luminance is stored in steps of
2^(1/256), so a round trip keeps it within half a step (0.135 %):

>>> import tempfile, os
>>> rng = np.random.default_rng(0)
>>> img = np.repeat(np.exp2(rng.uniform(-8, 8, (5, 9, 1))), 3, axis=2).astype(np.float32)
>>> path = os.path.join(tempfile.mkdtemp(), "a.tif")
>>> write_logluv_tiff(path, img, bits=32)
>>> back = read_logluv_tiff(path)
>>> lum = lambda x: x.astype(np.float64) @ RGB_TO_XYZ[1]
>>> bool(np.max(np.abs(lum(back) / lum(img) - 1)) <= 2 ** (1 / 512) - 1)
True
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from lumigraph.capture.artifact import atomic_path
from lumigraph.capture.errors import InputError
from lumigraph.capture.rgbe import (  # noqa: F401  (re-exported: hdr's format surface)
    as_radiance_rgb,
    float_to_rgbe,
    read_rgbe,
    rgbe_to_float,
    write_rgbe,
)

# ------------------------------------------------------------------ colour
RGB_TO_XYZ = np.array([[0.4124564, 0.3575761, 0.1804375],
                       [0.2126729, 0.7151522, 0.0721750],
                       [0.0193339, 0.1191920, 0.9503041]])
XYZ_TO_RGB = np.linalg.inv(RGB_TO_XYZ)


# -------------------------------------------------------------------- RGBE
# The one RGBE codec is on the ground floor (lumigraph.capture.rgbe), so every
# reader of images (capture.io, inspect, the hdr verbs) decodes .hdr alike; it
# is part of this module's public surface.
# ------------------------------------------------------------------ LogLuv
UV_SQSIZ = 0.0035
UV_VSTART = 0.016940
UV_USTART = np.array([
    0.247663, 0.243779, 0.241684, 0.237874, 0.235906, 0.232153, 0.228352, 0.226259, 0.222371,
    0.220410, 0.214710, 0.212714, 0.210721, 0.204976, 0.202986, 0.199245, 0.195525, 0.193560,
    0.189878, 0.186216, 0.186216, 0.182592, 0.179003, 0.175466, 0.172001, 0.172001, 0.168612,
    0.168612, 0.163575, 0.158642, 0.158642, 0.158642, 0.153815, 0.153815, 0.149097, 0.149097,
    0.142746, 0.142746, 0.142746, 0.138270, 0.138270, 0.138270, 0.132166, 0.132166, 0.126204,
    0.126204, 0.126204, 0.120381, 0.120381, 0.120381, 0.120381, 0.112962, 0.112962, 0.112962,
    0.107450, 0.107450, 0.107450, 0.107450, 0.100343, 0.100343, 0.100343, 0.095126, 0.095126,
    0.095126, 0.095126, 0.088276, 0.088276, 0.088276, 0.088276, 0.081523, 0.081523, 0.081523,
    0.081523, 0.074861, 0.074861, 0.074861, 0.074861, 0.068290, 0.068290, 0.068290, 0.068290,
    0.063573, 0.063573, 0.063573, 0.063573, 0.057219, 0.057219, 0.057219, 0.057219, 0.050985,
    0.050985, 0.050985, 0.050985, 0.050985, 0.044859, 0.044859, 0.044859, 0.044859, 0.040571,
    0.040571, 0.040571, 0.040571, 0.036339, 0.036339, 0.036339, 0.036339, 0.032139, 0.032139,
    0.032139, 0.032139, 0.027947, 0.027947, 0.027947, 0.023739, 0.023739, 0.023739, 0.023739,
    0.019504, 0.019504, 0.019504, 0.016976, 0.016976, 0.016976, 0.016976, 0.012639, 0.012639,
    0.012639, 0.009991, 0.009991, 0.009991, 0.009016, 0.009016, 0.009016, 0.006217, 0.006217,
    0.005097, 0.005097, 0.005097, 0.003909, 0.003909, 0.002340, 0.002389, 0.001068, 0.001653,
    0.000717, 0.001614, 0.000270, 0.000484, 0.001103, 0.001242, 0.001188, 0.001011, 0.000709,
    0.000301, 0.002416, 0.003251, 0.003246, 0.004141, 0.005963, 0.008839, 0.010490, 0.016994,
    0.023659])
UV_NUS = np.array([
    4, 6, 7, 9, 10, 12, 14, 15, 17, 18, 21, 22, 23, 26, 27, 29, 31, 32, 34, 36, 36, 38, 40, 42,
    44, 44, 46, 46, 49, 52, 52, 52, 55, 55, 58, 58, 62, 62, 62, 65, 65, 65, 69, 69, 73, 73, 73,
    77, 77, 77, 77, 82, 82, 82, 86, 86, 86, 86, 91, 91, 91, 95, 95, 95, 95, 100, 100, 100, 100,
    105, 105, 105, 105, 110, 110, 110, 110, 115, 115, 115, 115, 119, 119, 119, 119, 124, 124,
    124, 124, 129, 129, 129, 129, 129, 134, 134, 134, 134, 138, 138, 138, 138, 142, 142, 142,
    142, 146, 146, 146, 146, 150, 150, 150, 154, 154, 154, 154, 158, 158, 158, 161, 161, 161,
    161, 165, 165, 165, 168, 168, 168, 170, 170, 170, 173, 173, 175, 175, 175, 177, 177, 177,
    170, 164, 157, 150, 143, 136, 129, 123, 115, 109, 103, 97, 89, 82, 76, 69, 62, 55, 47, 40,
    31, 21])
UV_NCUM = np.concatenate([[0], np.cumsum(UV_NUS)[:-1]])
UV_NDIVS = int(UV_NUS.sum())
U_NEU, V_NEU = 0.210526316, 0.473684211
TAG_PHOTOMETRIC_LOGLUV = 32845
COMPRESSION_SGILOG, COMPRESSION_SGILOG24 = 34676, 34677


def _xyz_uv(xyz):
    s = xyz[..., 0] + 15.0 * xyz[..., 1] + 3.0 * xyz[..., 2]
    ok = s > 0
    sd = np.where(ok, s, 1.0)
    u = np.where(ok, 4.0 * xyz[..., 0] / sd, U_NEU)
    v = np.where(ok, 9.0 * xyz[..., 1] / sd, V_NEU)
    return u, v


def _uv_to_xyz(y, u, v):
    s = 6.0 * u - 16.0 * v + 12.0
    x = 9.0 * u / s
    yy = 4.0 * v / s
    with np.errstate(divide="ignore", invalid="ignore"):
        big_x = np.where(yy > 0, x / yy * y, 0.0)
        big_z = np.where(yy > 0, (1.0 - x - yy) / yy * y, 0.0)
    return np.stack([big_x, y, big_z], axis=-1)


def uv_index(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The 14-bit ``u′v′`` cell index of LogLuv 24 (out-of-gamut values go
    to the nearest cell of their row/column).

    Examples
    --------
    >>> int(uv_index(np.array(U_NEU), np.array(V_NEU))) < UV_NDIVS
    True
    """
    vi = np.clip(np.floor((np.asarray(v) - UV_VSTART) / UV_SQSIZ), 0, UV_USTART.size - 1)
    vi = vi.astype(np.int64)
    ui = np.floor((np.asarray(u) - UV_USTART[vi]) / UV_SQSIZ)
    ui = np.clip(ui, 0, UV_NUS[vi] - 1).astype(np.int64)
    return UV_NCUM[vi] + ui


def uv_from_index(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cell centres ``(u′, v′)`` of LogLuv 24 indices."""
    c = np.asarray(c, dtype=np.int64)
    vi = np.searchsorted(UV_NCUM, c, side="right") - 1
    ui = c - UV_NCUM[vi]
    return UV_USTART[vi] + (ui + 0.5) * UV_SQSIZ, UV_VSTART + (vi + 0.5) * UV_SQSIZ


def encode_logluv32(rgb: np.ndarray) -> np.ndarray:
    """Linear RGB ``(H, W, 3)`` -> LogLuv 32 words ``(H, W)`` uint32."""
    xyz = as_radiance_rgb(rgb, "LogLuv") @ RGB_TO_XYZ.T
    y = xyz[..., 1]
    with np.errstate(divide="ignore"):
        le = np.floor(256.0 * (np.log2(np.abs(y)) + 64.0))
    le = np.where(np.abs(y) > 5.4136769e-20, np.clip(le, 0, 0x7FFF), 0).astype(np.uint32)
    sign = (y < 0).astype(np.uint32) << 15
    u, v = _xyz_uv(np.abs(xyz))
    ue = np.clip(np.floor(410.0 * u), 0, 255).astype(np.uint32)
    ve = np.clip(np.floor(410.0 * v), 0, 255).astype(np.uint32)
    return ((sign | le) << 16) | (ue << 8) | ve


def decode_logluv32(words: np.ndarray) -> np.ndarray:
    """LogLuv 32 words -> linear RGB float32."""
    w = np.asarray(words, dtype=np.uint32)
    le = (w >> 16) & 0x7FFF
    y = np.where(le > 0, np.exp2((le + 0.5) / 256.0 - 64.0), 0.0)
    y = np.where((w >> 31) & 1, -y, y)
    u = (((w >> 8) & 0xFF) + 0.5) / 410.0
    v = ((w & 0xFF) + 0.5) / 410.0
    return (_uv_to_xyz(y, u, v) @ XYZ_TO_RGB.T).astype(np.float32)


def encode_logluv24(rgb: np.ndarray) -> np.ndarray:
    """Linear RGB -> LogLuv 24 words ``(H, W)`` uint32 (low 24 bits)."""
    xyz = np.maximum(as_radiance_rgb(rgb, "LogLuv") @ RGB_TO_XYZ.T, 0.0)
    y = xyz[..., 1]
    with np.errstate(divide="ignore"):
        le = np.floor(64.0 * (np.log2(y) + 12.0))
    le = np.where(y >= 15.742, 0x3FF, np.where(y <= 0.00024283, 0, np.clip(le, 0, 0x3FF)))
    u, v = _xyz_uv(xyz)
    return (le.astype(np.uint32) << 14) | uv_index(u, v).astype(np.uint32)


def decode_logluv24(words: np.ndarray) -> np.ndarray:
    """LogLuv 24 words -> linear RGB float32."""
    w = np.asarray(words, dtype=np.uint32)
    le = (w >> 14) & 0x3FF
    y = np.where(le > 0, np.exp2((le + 0.5) / 64.0 - 12.0), 0.0)
    c = np.minimum(w & 0x3FFF, UV_NDIVS - 1)
    u, v = uv_from_index(c)
    return (_uv_to_xyz(y, u, v) @ XYZ_TO_RGB.T).astype(np.float32)


def _rle32_row(words: np.ndarray) -> bytes:
    """SGILOG byte-plane run-length coding of one row: for each byte plane
    (most significant first) runs ``(126 + n, byte)`` with ``n`` in 2..129 for
    4+ repeats, literals ``(n ≤ 127, bytes…)`` otherwise."""
    out = bytearray()
    for shift in (24, 16, 8, 0):
        plane = ((words >> shift) & 0xFF).astype(np.uint8)
        n = plane.size
        change = np.flatnonzero(np.diff(plane.astype(np.int16))) + 1
        starts = np.concatenate([[0], change]).tolist()
        lens = np.diff(np.concatenate([starts, [n]])).tolist()
        lit = bytearray()

        def flush(lit=lit):
            for k in range(0, len(lit), 127):
                chunk = lit[k:k + 127]
                out.append(len(chunk))
                out.extend(chunk)
            lit.clear()

        for s, ln in zip(starts, lens, strict=True):
            b = int(plane[s])
            while ln >= 4:
                k = min(ln, 129)
                if ln - k in (1, 2, 3) and k > 4:
                    k -= 4 - (ln - k) if ln - k < 4 else 0
                flush()
                out.extend((126 + k, b))
                ln -= k
            lit.extend([b] * ln)
        flush()
    return bytes(out)


def _unrle32_row(buf: np.ndarray, pos: int, w: int, where) -> tuple[np.ndarray, int]:
    """Decode one SGILOG row from ``buf[pos:]``; a run or literal that passes
    the row's end or the data's end is corrupt (libtiff's encoder never
    writes one)."""
    words = np.zeros(w, np.uint32)
    for shift in (24, 16, 8, 0):
        x = 0
        while x < w:
            if pos >= buf.size:
                raise InputError(where, "truncated SGILOG data")
            n = int(buf[pos])
            if n >= 128:
                n -= 126
                if x + n > w or pos + 1 >= buf.size:
                    raise InputError(where, "corrupt SGILOG run (past the end of its row)")
                words[x:x + n] |= np.uint32(int(buf[pos + 1]) << shift)
                pos += 2
            else:
                if n == 0 or x + n > w or pos + 1 + n > buf.size:
                    raise InputError(where, "corrupt or truncated SGILOG literal")
                words[x:x + n] |= buf[pos + 1:pos + 1 + n].astype(np.uint32) << np.uint32(shift)
                pos += 1 + n
            x += n
    return words, pos


def write_logluv_tiff(path, img: np.ndarray, *, bits: int = 32) -> None:
    """Write a LogLuv TIFF (Photometric 32845), 32-bit (``SGILOG``, RLE) or
    24-bit (``SGILOG24``), one strip, little-endian.

    BitsPerSample 32 with SampleFormat IEEEFP tells libtiff the data are XYZ
    floats, so ``tiffcp``/``tiff2rgba`` decode it.
    """
    if bits not in (24, 32):
        raise ValueError(f"bits: expected 24 or 32, got {bits}")
    a = as_radiance_rgb(img, "LogLuv")
    h, w = a.shape[:2]
    if bits == 32:
        words = encode_logluv32(a)
        body = b"".join(_rle32_row(words[y]) for y in range(h))
        comp = COMPRESSION_SGILOG
    else:
        words = encode_logluv24(a)
        b3 = np.stack([(words >> 16) & 0xFF, (words >> 8) & 0xFF, words & 0xFF], axis=-1)
        body = b3.astype(np.uint8).tobytes()
        comp = COMPRESSION_SGILOG24
    n_tags = 11
    ifd_off = 8
    ifd_size = 2 + 12 * n_tags + 4
    extra_off = ifd_off + ifd_size
    bps_off, sf_off = extra_off, extra_off + 6
    data_off = extra_off + 12
    tags = [(256, 4, 1, w), (257, 4, 1, h), (258, 3, 3, bps_off), (259, 3, 1, comp),
            (262, 3, 1, TAG_PHOTOMETRIC_LOGLUV), (273, 4, 1, data_off), (277, 3, 1, 3),
            (278, 4, 1, h), (279, 4, 1, len(body)), (284, 3, 1, 1), (339, 3, 3, sf_off)]
    ifd = struct.pack("<H", n_tags)
    for tag, typ, cnt, val in tags:
        if typ == 3 and cnt == 1:
            ifd += struct.pack("<HHIHH", tag, typ, cnt, val, 0)
        else:
            ifd += struct.pack("<HHII", tag, typ, cnt, val)
    ifd += struct.pack("<I", 0)
    extra = struct.pack("<3H", 32, 32, 32) + struct.pack("<3H", 3, 3, 3)
    with atomic_path(path) as tmp:
        tmp.write_bytes(b"II*\x00" + struct.pack("<I", ifd_off) + ifd + extra + body)


def read_logluv_tiff(path) -> np.ndarray:
    """Read a LogLuv TIFF (``SGILOG`` or ``SGILOG24``, strips, contiguous) as
    linear RGB ``(H, W, 3)`` float32.

    The header is parsed by :func:`lumigraph.capture.headers.tiff_pages`; its
    size is checked against the pixel limit
    (:func:`lumigraph.capture.io.check_pixel_count`) and against the strip
    bytes (3 per pixel for SGILOG24, at least 8 per 129 pixels of a row for
    SGILOG) before anything is allocated.
    """
    from lumigraph.capture.headers import tiff_pages, tiff_strips
    from lumigraph.capture.io import check_pixel_count

    p = Path(path)
    if not p.is_file():
        raise InputError(p, "file not found")
    data = p.read_bytes()
    tags = tiff_pages(data, p)[0]
    if tags.get(262, [None])[0] != TAG_PHOTOMETRIC_LOGLUV:
        raise InputError(p, "not a LogLuv TIFF (Photometric is not 32845)")
    comp = tags.get(259, [1])[0]
    if comp not in (COMPRESSION_SGILOG, COMPRESSION_SGILOG24):
        raise InputError(p, f"LogLuv compression {comp} unsupported (expected SGILOG 34676 or "
                            "SGILOG24 34677)")
    if 322 in tags or 324 in tags:
        raise InputError(p, "tiled LogLuv TIFF is not supported; convert with tiffcp -s")
    if tags.get(284, [1])[0] != 1:
        raise InputError(p, "planar LogLuv TIFF is not supported; convert with tiffcp -p contig")
    if 256 not in tags or 257 not in tags or 273 not in tags or 279 not in tags:
        raise InputError(p, "corrupt TIFF: no ImageWidth, ImageLength or strips")
    w, h = tags[256][0], tags[257][0]
    check_pixel_count(p, w, h, what="LogLuv TIFF header")
    offsets, counts = tiff_strips(tags, p)
    if any(o + c > len(data) for o, c in zip(offsets.tolist(), counts.tolist(), strict=True)):
        raise InputError(p, "truncated TIFF: a strip lies past the end of the file")
    body = b"".join(data[o:o + c] for o, c in zip(offsets.tolist(), counts.tolist(), strict=True))
    buf = np.frombuffer(body, np.uint8)
    need = 3 * w * h if comp == COMPRESSION_SGILOG24 else h * 8 * -(-w // 129)
    if buf.size < need:
        raise InputError(p, f"truncated {'SGILOG24' if comp == COMPRESSION_SGILOG24 else 'SGILOG'} "
                            f"data: {buf.size} bytes cannot hold {w}x{h} pixels")
    if comp == COMPRESSION_SGILOG24:
        b3 = buf[:3 * w * h].reshape(h, w, 3).astype(np.uint32)
        return decode_logluv24((b3[..., 0] << 16) | (b3[..., 1] << 8) | b3[..., 2])
    words = np.empty((h, w), np.uint32)
    pos = 0
    for y in range(h):
        words[y], pos = _unrle32_row(buf, pos, w, p)
    return decode_logluv32(words)


# ------------------------------------------------------------------ dispatch
HDR_EXTS = (".exr", ".hdr", ".pic", ".tif", ".tiff", ".pfm")


def read_hdr_image(path) -> np.ndarray:
    """Read linear radiance from EXR, RGBE ``.hdr``, LogLuv ``.tif`` or PFM."""
    from lumigraph.capture.io import read_exr, read_pfm

    p = Path(path)
    ext = p.suffix.lower()
    if ext == ".exr":
        return read_exr(p) if p.is_file() else _missing(p)
    if ext in (".hdr", ".pic"):
        return read_rgbe(p)
    if ext in (".tif", ".tiff"):
        return read_logluv_tiff(p)
    if ext == ".pfm":
        return read_pfm(p) if p.is_file() else _missing(p)
    raise InputError(p, f"unknown HDR extension {p.suffix!r}; expected one of {', '.join(HDR_EXTS)}")


def _missing(p):
    raise InputError(p, "file not found")


def write_hdr_image(path, img: np.ndarray, *, logluv_bits: int = 32, half: bool = False) -> None:
    """Write linear radiance by extension: ``.exr``, ``.hdr``, ``.tif`` (LogLuv), ``.pfm``."""
    from lumigraph.capture.io import write_exr, write_pfm

    ext = os.path.splitext(str(path))[1].lower()
    if ext == ".exr":
        write_exr(path, np.asarray(img, np.float32), half=half)
    elif ext in (".hdr", ".pic"):
        write_rgbe(path, img)
    elif ext in (".tif", ".tiff"):
        write_logluv_tiff(path, img, bits=logluv_bits)
    elif ext == ".pfm":
        write_pfm(path, img)
    else:
        raise InputError(path, f"unknown HDR extension; expected one of {', '.join(HDR_EXTS)}")
