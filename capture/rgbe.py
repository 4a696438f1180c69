"""Radiance RGBE ``.hdr``: the one codec, read and written here (flat or
new-style RLE scanlines).

Reference ch. 6.2: three 8-bit mantissas share an 8-bit exponent (bias 128), so
each pixel is stored to 2⁻⁸ of its brightest channel (G. Ward, "Real pixels",
Graphics Gems II, 1991).

The codec sits on the ground floor so every image reader uses it:
:func:`lumigraph.capture.io.read_image` decodes ``.hdr``/``.pic`` through it,
and :mod:`lumigraph.hdr.formats` (the HDR exchange formats, with LogLuv TIFF)
re-exports it.

Examples
--------
>>> import tempfile, os
>>> rng = np.random.default_rng(0)
>>> img = np.exp(rng.uniform(-8, 8, (5, 9, 3))).astype(np.float32)
>>> d = tempfile.mkdtemp()
>>> write_rgbe(os.path.join(d, "a.hdr"), img)
>>> back = read_rgbe(os.path.join(d, "a.hdr"))
>>> bool(np.all(np.abs(back - img) <= img.max(axis=2, keepdims=True) * 2.0 ** -8))
True
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from lumigraph.capture.artifact import atomic_path
from lumigraph.capture.errors import InputError

RGBE_EXTS = frozenset({".hdr", ".pic"})


def as_radiance_rgb(img, where: str) -> np.ndarray:
    """``(H, W)`` or ``(H, W, 3)`` finite float radiance as ``(H, W, 3)`` float64;
    ``where`` names the format that cannot store NaN/inf (an InputError naming
    ``img`` says so).

    >>> as_radiance_rgb(np.array([[np.nan]]), "RGBE")
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: img: RGBE cannot store NaN/inf (1 values); fill or \
mask them first, or write OpenEXR/PFM
    """
    a = np.asarray(img)
    if a.dtype.kind != "f":
        raise TypeError(f"img: expected float linear radiance, got {a.dtype}")
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] != 3):
        raise ValueError(f"img: expected (H, W) or (H, W, 3), got {np.shape(img)}")
    if not np.isfinite(a).all():
        bad = int((~np.isfinite(a)).sum())
        raise InputError("img", f"{where} cannot store NaN/inf ({bad} values); fill or mask "
                                "them first, or write OpenEXR/PFM")
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    return a.astype(np.float64)


def float_to_rgbe(img: np.ndarray) -> np.ndarray:
    """``(H, W, 3)`` float -> ``(H, W, 4)`` uint8 RGBE (negative values become 0).

    Examples
    --------
    >>> float_to_rgbe(np.array([[[1.0, 0.5, 0.0]]])).tolist()
    [[[128, 64, 0, 129]]]
    """
    a = np.maximum(np.asarray(img, dtype=np.float64), 0.0)
    m = a.max(axis=2)
    mant, ex = np.frexp(m)
    out = np.zeros(a.shape[:2] + (4,), np.uint8)
    ok = m > 1e-38
    scale = np.where(ok, mant * 256.0 / np.where(ok, m, 1.0), 0.0)
    out[..., :3] = np.clip(np.floor(a * scale[..., None]), 0, 255).astype(np.uint8)
    out[..., 3] = np.where(ok, ex + 128, 0).astype(np.uint8)
    return out


def rgbe_to_float(rgbe: np.ndarray) -> np.ndarray:
    """``(H, W, 4)`` uint8 -> ``(H, W, 3)`` float32; mantissas decode at their
    centres (``(m + 0.5)·2^(e−136)``), as Radiance does."""
    # float32 throughout: (m + 0.5) has 9 significant bits and 2^(e-136) is a
    # power of two no smaller than 2^-135, so every product is exact in float32
    # (and a large image needs no float64 temporaries)
    e = rgbe[..., 3].astype(np.int32)
    f = np.where(e > 0, np.ldexp(np.float32(1.0), e - 136), np.float32(0.0)).astype(np.float32)
    out = rgbe[..., :3].astype(np.float32)
    out += np.float32(0.5)
    out *= f[..., None]
    return out


def _rle_bytes(row: np.ndarray) -> bytes:
    """Radiance's new RLE for one component of one scanline: runs (``128 + n``,
    value; ``n`` ≤ 127) for 3+ repeats, literal dumps (``n`` ≤ 128) otherwise."""
    out = bytearray()
    n = row.size
    change = np.flatnonzero(np.diff(row.astype(np.int16))) + 1
    starts = np.concatenate([[0], change])
    lens = np.diff(np.concatenate([starts, [n]]))
    lit = bytearray()

    def flush():
        for k in range(0, len(lit), 128):
            chunk = lit[k:k + 128]
            out.append(len(chunk))
            out.extend(chunk)
        lit.clear()

    for s, ln in zip(starts.tolist(), lens.tolist(), strict=True):
        v = int(row[s])
        if ln >= 3:
            flush()
            while ln > 0:
                k = min(ln, 127)
                if k < 3:
                    lit.extend([v] * k)
                else:
                    out.extend((128 + k, v))
                ln -= k
        else:
            lit.extend([v] * ln)
    flush()
    return bytes(out)


def write_rgbe(path, img: np.ndarray) -> None:
    """Write Radiance RGBE (``-Y H +X W``, top row first, new-style RLE).

    Parameters
    ----------
    img : ndarray, ``(H, W, 3)`` or ``(H, W)`` float, linear, finite.
    """
    a = as_radiance_rgb(img, "RGBE")
    h, w = a.shape[:2]
    rgbe = float_to_rgbe(a)
    parts = [b"#?RADIANCE\n# lumigraph\nFORMAT=32-bit_rle_rgbe\n\n", f"-Y {h} +X {w}\n".encode()]
    if 8 <= w <= 0x7FFF:
        head = bytes([2, 2, w >> 8, w & 0xFF])
        for y in range(h):
            parts.append(head)
            for c in range(4):
                parts.append(_rle_bytes(rgbe[y, :, c]))
    else:  # flat scanlines: RLE is only defined for widths 8..32767
        parts.append(rgbe.tobytes())
    with atomic_path(path) as tmp:
        tmp.write_bytes(b"".join(parts))


def read_rgbe(path) -> np.ndarray:
    """Read Radiance RGBE (flat or RLE scanlines) as ``(H, W, 3)`` float32,
    top row first. Tolerates header lines before ``#?RADIANCE`` (some files,
    such as Debevec's ``memorial.hdr``, start with ``VIEW=``).

    The size the resolution line claims is checked against the pixel limit
    (:func:`lumigraph.capture.io.check_pixel_count`) and against the bytes
    that follow (a flat scanline takes ``4 W`` bytes, an RLE one at least
    ``4 + 8 ⌈W/127⌉``) before anything is allocated.
    """
    from lumigraph.capture.io import check_pixel_count

    p = Path(path)
    if not p.is_file():
        raise InputError(p, "file not found")
    data = p.read_bytes()
    m = re.search(rb"\n\n([-+][YX]) (\d{1,18}) ([-+][YX]) (\d{1,18})\n", data[:65536])
    head = data[:m.start()] if m else b""
    if m is None or not (b"#?RADIANCE" in head or b"#?RGBE" in head or b"FORMAT=" in head):
        raise InputError(p, "not a Radiance RGBE file (no header with a resolution line)")
    if b"FORMAT=" in head and b"32-bit_rle_rgbe" not in head:
        raise InputError(p, "only FORMAT=32-bit_rle_rgbe is supported (not XYZE)")
    if (m.group(1), m.group(3)) != (b"-Y", b"+X"):
        raise InputError(p, f"unsupported orientation {m.group(0).strip().decode()}; expected -Y H +X W")
    h, w = int(m.group(2)), int(m.group(4))
    check_pixel_count(p, w, h, what="RGBE header")
    pos = m.end()
    rle = 8 <= w <= 0x7FFF
    line_min = min(4 * w, 4 + 8 * -(-w // 127)) if rle else 4 * w
    if h * line_min > len(data) - pos:
        raise InputError(p, f"RGBE data ({len(data) - pos} bytes) cannot hold {w}x{h} pixels: "
                            "truncated or corrupt")
    out = np.empty((h, w, 4), np.uint8)
    buf = np.frombuffer(data, np.uint8)
    n = buf.size
    for y in range(h):
        if rle and pos + 4 <= n and buf[pos] == 2 and buf[pos + 1] == 2 and buf[pos + 2] < 128:
            if (int(buf[pos + 2]) << 8 | int(buf[pos + 3])) != w:
                raise InputError(p, f"scanline {y}: width mismatch in RLE header")
            pos += 4
            for c in range(4):
                x = 0
                while x < w:
                    if pos >= n:
                        raise InputError(p, f"truncated RGBE data at scanline {y} of {h}")
                    k = int(buf[pos])
                    if k > 128:
                        k -= 128
                        if x + k > w or pos + 1 >= n:
                            raise InputError(p, f"scanline {y}: run overflows the line")
                        out[y, x:x + k, c] = buf[pos + 1]
                        pos += 2
                    else:
                        if k == 0 or x + k > w:
                            raise InputError(p, f"scanline {y}: bad literal count {k}")
                        if pos + 1 + k > n:
                            raise InputError(p, f"truncated RGBE data at scanline {y} of {h}")
                        out[y, x:x + k, c] = buf[pos + 1:pos + 1 + k]
                        pos += 1 + k
                    x += k
        else:
            if pos + 4 * w > n:
                raise InputError(p, f"truncated at scanline {y} of {h}")
            out[y] = buf[pos:pos + 4 * w].reshape(w, 4)
            pos += 4 * w
    return rgbe_to_float(out)
