"""Image and artifact file formats: the one place lumigraph touches pixels on disk.

Every reader validates what it reads and raises :class:`capture.errors.InputError`
naming the file and the problem (missing, truncated, wrong kind, NaN/inf where
finite values are required). Every writer is atomic (see ``capture.artifact``).

Every reader checks the size a header claims before it allocates anything:
at most :func:`max_pixels` pixels (``LUMIGRAPH_MAX_PIXELS``, default
``DEFAULT_MAX_PIXELS`` = 2²⁸ ≈ 268 MP, 16384²), and no more than the file's
bytes can hold (:mod:`lumigraph.capture.headers`). A decoder's own failure
(libpng, libtiff, OpenEXR, Pillow) becomes an InputError naming the file, and
what the C libraries print is kept off the terminal.

Conventions (DESIGN §3): images are ``H×W`` or ``H×W×C`` in **RGB** order;
captured code values stay integers (``uint8``/``uint16``) with their true bit
depth recorded; linear data are ``float32``. OpenCV's BGR order is converted
by the readers on this floor only: here for images, in
:mod:`lumigraph.capture.video` for video frames.

==========  ================================  ======================================
format      reader / writer                   notes
==========  ================================  ======================================
PNG, TIFF   read_image / write_image           8/16-bit; PNG ``sBIT`` keeps bit depth
JPEG        read_image, read_exif              EXIF exposure time, f-number, ISO
(all LDR)   read_image, image_orientation      EXIF Orientation applied when read
RAW         read_raw                           rawpy, linear 16-bit, levels applied
OpenEXR     read_exr / write_exr               float32 or half, ZIP, deterministic
PFM         read_pfm / write_pfm               NaN in memory <-> inf in the file
.flo        read_flo / write_flo               Middlebury; NaN <-> 1e10 (unknown)
PLY         read_ply / write_ply               ascii and binary little-endian (read), faces
                                               (read_ply(faces=True)); float64 xyz, rgb
stack       read_stack / write_stack_json      file list or folder with stack.json
==========  ================================  ======================================

Examples
--------
>>> import numpy as np, tempfile, os
>>> d = tempfile.mkdtemp()
>>> flow = np.zeros((4, 6, 2), np.float32); flow[1, 2] = np.nan
>>> write_flo(os.path.join(d, "f.flo"), flow)
>>> back = read_flo(os.path.join(d, "f.flo"))
>>> back.shape, bool(np.isnan(back[1, 2]).all())
((4, 6, 2), True)
"""

from __future__ import annotations

import contextlib
import os
import re
import struct
import sys
import tempfile
import threading
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

from lumigraph.capture.artifact import atomic_path, dumps_json
from lumigraph.capture.commandline import DEFAULT_MAX_PIXELS  # beside --max-pixels
from lumigraph.capture.errors import InputError
from lumigraph.capture.exposure import (
    check_exposure_times,
    decide_bit_depth,
    effective_exposure_times,
)
from lumigraph.capture.headers import exr_header, image_header
from lumigraph.capture.rgbe import RGBE_EXTS as _RGBE_EXTS

LDR_EXTS = {".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".ppm", ".pgm"}
RAW_EXTS = {".dng", ".cr2", ".cr3", ".nef", ".arw", ".orf", ".rw2", ".raf", ".pef", ".srw"}
EXR_EXTS = {".exr"}
# Radiance RGBE has one codec, lumigraph.capture.rgbe (re-exported by
# lumigraph.hdr.formats); read_image decodes .hdr through it.
RGBE_EXTS = set(_RGBE_EXTS)
FLOAT_EXTS = EXR_EXTS | {".pfm"} | RGBE_EXTS
STACK_SCHEMA = "lumigraph.stack"


# ---------------------------------------------------------------- pixel limit
MAX_PIXELS_ENV = "LUMIGRAPH_MAX_PIXELS"


def max_pixels() -> int:
    """The most pixels a reader accepts: ``LUMIGRAPH_MAX_PIXELS`` (read at each
    call, so ``--max-pixels`` and tests can set it), else ``DEFAULT_MAX_PIXELS``.

    Raises
    ------
    InputError
        ``LUMIGRAPH_MAX_PIXELS`` is not a positive whole number.

    Examples
    --------
    >>> max_pixels() == int(os.environ.get("LUMIGRAPH_MAX_PIXELS", DEFAULT_MAX_PIXELS))
    True
    """
    raw = os.environ.get(MAX_PIXELS_ENV, "").strip()
    if not raw:
        return DEFAULT_MAX_PIXELS
    try:
        n = int(raw)
    except ValueError:
        try:
            f = float(raw)  # 1e9 is a whole number too
        except ValueError:
            f = float("nan")
        n = int(f) if f == f and f not in (float("inf"), float("-inf")) and f.is_integer() else 0
    if n <= 0:
        raise InputError(MAX_PIXELS_ENV, f"expected a positive whole number of pixels, got {raw!r}")
    return n


def check_pixel_count(path, width: int, height: int, *, what: str = "image") -> int:
    """Refuse a size a header claims before anything is allocated for it.

    Parameters
    ----------
    path : path-like
        The file, named in the error.
    width, height : int
        The claimed size in pixels.
    what : str
        What claims it (``"PNG header"``, ``"TIFF page 2"``, …).

    Returns
    -------
    int
        ``width * height``.

    Raises
    ------
    InputError
        ``width`` or ``height`` ≤ 0, or more than :func:`max_pixels` pixels.

    Examples
    --------
    >>> check_pixel_count("a.png", 640, 480)
    307200
    >>> try:
    ...     check_pixel_count("bomb.png", 60000, 60000, what="PNG header")
    ... except InputError as e:
    ...     print(e.problem.partition(" (set")[0])
    PNG header claims 60000x60000 = 3600000000 pixels, over the limit of 268435456
    """
    w, h = int(width), int(height)
    if w <= 0 or h <= 0:
        raise InputError(path, f"{what} claims a size of {w}x{h}; width and height must be "
                               "positive (corrupt file?)")
    n = w * h
    limit = max_pixels()
    if n > limit:
        raise InputError(path, f"{what} claims {w}x{h} = {n} pixels, over the limit of {limit} "
                               f"(set {MAX_PIXELS_ENV} or --max-pixels to read larger images)")
    return n


def _check_header(path, header) -> None:
    """The limit for every size a header claims, then whether the file can hold it."""
    check_pixel_count(path, header.width, header.height, what=f"{header.kind} header")
    for what, w, h in header.pages:
        check_pixel_count(path, w, h, what=what)
    if header.short:
        raise InputError(path, header.short)


# ------------------------------------------------------- C libraries' messages
_FD_LOCK = threading.Lock()
_FD_STATE: dict = {}  # 2 or "stdout" -> {"depth", "saved", "file"} while redirected


def _flush_c_stdio() -> None:
    # C stdio buffers what a library prints (fully, when not on a terminal):
    # flush it while the redirection is in place, so it lands where we look
    import ctypes

    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


@contextlib.contextmanager
def _c_messages(*, python_stdout: bool = False):
    """Route file descriptor 2 into a temporary file while a C library decodes
    (libpng, libtiff and OpenEXR print their complaints there, and the command
    line promises one error line); with ``python_stdout`` also ``sys.stdout``
    (OpenEXR's binding prints a warning there and returns what it has). Yields
    a list that receives the captured text, to quote in an error. Nested and
    concurrent uses share one redirection (what another thread prints
    meanwhile is captured too)."""
    import io as _textio

    with _FD_LOCK:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (AttributeError, ValueError, OSError):
                pass
        _flush_c_stdio()
        st = _FD_STATE.get(2)
        if st is None:
            tmp = tempfile.TemporaryFile()
            st = _FD_STATE[2] = {"depth": 0, "saved": os.dup(2), "file": tmp}
            os.dup2(tmp.fileno(), 2)
        st["depth"] += 1
        start = os.fstat(st["file"].fileno()).st_size
        py = None
        if python_stdout:
            py = _FD_STATE.get("stdout")
            if py is None:
                py = _FD_STATE["stdout"] = {"depth": 0, "saved": sys.stdout,
                                            "file": _textio.StringIO()}
                sys.stdout = py["file"]
            py["depth"] += 1
            py_start = py["file"].tell()
    text: list[str] = []
    try:
        yield text
    finally:
        with _FD_LOCK:
            _flush_c_stdio()
            f = st["file"].fileno()
            end = os.fstat(f).st_size
            text.append(os.pread(f, min(end - start, 4096), start).decode("utf-8", "replace"))
            st["depth"] -= 1
            if st["depth"] == 0:
                os.dup2(st["saved"], 2)
                os.close(st["saved"])
                st["file"].close()
                del _FD_STATE[2]
            if py is not None:
                text.append(py["file"].getvalue()[py_start:py_start + 4096])
                py["depth"] -= 1
                if py["depth"] == 0:
                    sys.stdout = py["saved"]
                    del _FD_STATE["stdout"]


def _decoder_failed(path, what: str, exc: BaseException | None, messages: list[str]) -> InputError:
    """An InputError for a decoder's failure, quoting the library's last words.
    Memory exhaustion is not the file's fault: it propagates."""
    said = " ".join(" ".join(messages).split())
    text = f"{exc}" if exc is not None else ""
    if isinstance(exc, MemoryError) or "insufficient memory" in text.lower() \
            or "failed to allocate" in text.lower():
        raise MemoryError(f"{path}: {text}") from exc
    reason = said or " ".join(text.split()) or "undecodable data"
    if len(reason) > 200:
        reason = reason[:200] + "…"
    return InputError(path, f"cannot decode {what} (truncated or corrupt file?): {reason}")


def _cv2():
    # OpenCV's own stderr warnings would break the one-line error convention;
    # our readers report every problem themselves.
    os.environ.setdefault("OPENCV_LOG_LEVEL", "OFF")
    # OpenCV's own pixel limit (2**30, read once) would contradict ours when
    # LUMIGRAPH_MAX_PIXELS is raised past it; ours is checked before every decode
    os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", str(1 << 40))
    import cv2  # imported lazily: `import capture` must stay cheap

    return cv2


def _existing(path) -> Path:
    p = Path(path)
    if not p.exists():
        raise InputError(p, "file not found")
    if p.is_dir():
        raise InputError(p, "is a folder, expected a file")
    if p.stat().st_size == 0:
        raise InputError(p, "file is empty")
    return p


# --------------------------------------------------------------------- PNG sBIT
def _png_chunks(data: bytes):
    pos = 8
    while pos + 8 <= len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        kind = data[pos + 4:pos + 8]
        yield kind, pos, data[pos + 8:pos + 8 + length]
        pos += 12 + length


def png_significant_bits(path) -> int | None:
    """The true bit depth a PNG declares in its ``sBIT`` chunk, or ``None``."""
    data = Path(path).read_bytes()
    if not data.startswith(b"\x89PNG\r\n\x1a\n"):
        return None
    for kind, _, body in _png_chunks(data):
        if kind == b"sBIT" and body:
            return max(body[:3]) if len(body) >= 3 else body[0]
        if kind == b"IDAT":
            return None
    return None


def _png_with_sbit(data: bytes, bits: int, channels: int) -> bytes:
    """Insert an ``sBIT`` chunk after IHDR so a 16-bit container carrying 10/12-bit
    data says so (readers such as libpng and ours then know the true depth)."""
    n = {1: 1, 2: 2, 3: 3, 4: 4}[channels]
    body = bytes([bits] * n)
    chunk = struct.pack(">I", len(body)) + b"sBIT" + body
    chunk += struct.pack(">I", zlib.crc32(b"sBIT" + body) & 0xFFFFFFFF)
    ihdr_end = 8 + 12 + 13
    return data[:ihdr_end] + chunk + data[ihdr_end:]


# ------------------------------------------------------------------ LDR images
def read_image(path) -> np.ndarray:
    """Read an image as captured, RGB order.

    Parameters
    ----------
    path : path-like
        PNG/TIFF (8 or 16 bit), JPEG, EXR, PFM, Radiance RGBE ``.hdr``
        (through the one codec, :func:`lumigraph.capture.rgbe.read_rgbe`) or a
        RAW file.

    Returns
    -------
    ndarray
        ``(H, W)`` or ``(H, W, 3|4)``; ``uint8``/``uint16`` code values for LDR
        and RAW files (RAW: linear 16-bit, see :func:`read_raw`), ``float32``
        linear values for EXR/PFM/RGBE. JPEG, PNG and TIFF come as meant to be
        seen: their EXIF Orientation applied (:func:`apply_orientation`;
        :func:`image_orientation` says which), so a portrait phone photo is
        portrait and every frame of a bracket has one orientation.

    Raises
    ------
    InputError
        Missing, empty, truncated or undecodable file, unknown extension or
        content, a header claiming more than :func:`max_pixels` pixels or more
        than the file can hold (checked before decoding), or NaN/inf in a
        float image.
    """
    p = _existing(path)
    ext = p.suffix.lower()
    if ext in EXR_EXTS | {".pfm"}:
        img = read_exr(p) if ext in EXR_EXTS else read_pfm(p)
        check_finite(img, p)  # an image must be finite; masks travel separately
        return img
    if ext in RAW_EXTS:
        return read_raw(p).codes
    if ext in RGBE_EXTS:
        from lumigraph.capture.rgbe import read_rgbe

        return read_rgbe(p)  # RGBE cannot hold NaN/inf
    if ext not in LDR_EXTS:
        raise InputError(p, f"unsupported image extension {p.suffix!r}; expected one of "
                            + ", ".join(sorted(LDR_EXTS | FLOAT_EXTS | RAW_EXTS)))
    data = p.read_bytes()
    # the header is checked before any decoder sees the file; the content,
    # not the extension, says which decoder that is
    header = image_header(data, p)
    _check_header(p, header)
    if header.kind == "JPEG":
        img = _read_jpeg(p, data, header.width * header.height)
        img = apply_orientation(img, _orientation(data, header.kind, p))
    else:
        if header.kind == "TIFF" and not _tiff_channels_ok(data, p):
            raise InputError(p, "TIFF has more than 4 samples per pixel; read_image reads "
                                "grey, RGB and RGBA")
        if header.kind == "PNG" and not _png_complete(data):
            raise InputError(p, "PNG is truncated (no IEND chunk)")
        cv2 = _cv2()
        with _c_messages() as said:
            try:
                img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
                failure = None
            except cv2.error as e:
                img, failure = None, e
        if img is None:
            raise _decoder_failed(p, header.kind, failure, said)
        if img.ndim == 3:
            img = img[..., ::-1] if img.shape[2] == 3 else img[..., [2, 1, 0, 3]]
        o = _orientation(data, header.kind, p)
        # OpenCV's TIFF decoder orients the pixels itself, IMREAD_UNCHANGED or not (its
        # PNG decoder does not); 5-8 swap the sides, which tells whether it did
        if header.kind == "TIFF" and not (o >= 5 and img.shape[:2] == (header.height, header.width)
                                          and header.height != header.width):
            o = 1
        img = np.ascontiguousarray(apply_orientation(img, o))
    if img.dtype.kind == "f":
        img = img.astype(np.float32, copy=False)
        check_finite(img, p)
    return img


# ----------------------------------------------------------- EXIF orientation
ORIENTATION_TAG = 0x0112


def apply_orientation(img: np.ndarray, orientation: int) -> np.ndarray:
    """The image as it is meant to be seen: EXIF ``Orientation`` (1..8, TIFF 6.0
    tag 274) applied to an ``(H, W[, C])`` array, as Pillow's ``exif_transpose``
    does (6: rotate 90° clockwise, 8: 90° counter-clockwise, 2/4: mirror, 3: 180°,
    5/7: transpose/transverse). Other values leave it as stored.

    Examples
    --------
    >>> a = np.arange(6).reshape(2, 3)
    >>> apply_orientation(a, 6).tolist(), apply_orientation(a, 8).tolist()
    ([[3, 0], [4, 1], [5, 2]], [[2, 5], [1, 4], [0, 3]])
    """
    o = int(orientation)
    if o == 2:
        return img[:, ::-1]
    if o == 3:
        return img[::-1, ::-1]
    if o == 4:
        return img[::-1]
    if o == 5:
        return img.swapaxes(0, 1)
    if o == 6:
        return np.rot90(img, k=-1)
    if o == 7:
        return img.swapaxes(0, 1)[::-1, ::-1]
    if o == 8:
        return np.rot90(img, k=1)
    return img


def _exif_block_orientation(block: bytes) -> int:
    """Orientation from a TIFF-structured EXIF block (PNG ``eXIf``), 1 if absent."""
    from PIL import Image

    ex = Image.Exif()
    try:
        ex.load(block)
    except Exception:  # a broken block orients nothing; the pixels are still good
        return 1
    return int(ex.get(ORIENTATION_TAG, 1) or 1)


def _orientation(data: bytes, kind: str, p: Path) -> int:
    """EXIF Orientation of an image file's bytes (JPEG APP1, TIFF tag 274, PNG
    ``eXIf``); 1 (as stored) when absent or out of range."""
    o = 1
    if kind == "JPEG":
        import io as _bytesio

        from PIL import Image

        try:
            with _pil_allows(max_pixels()), Image.open(_bytesio.BytesIO(data)) as im:
                o = int(im.getexif().get(ORIENTATION_TAG, 1) or 1)
        except Exception:  # the pixels decoded; a broken EXIF block orients nothing
            o = 1
    elif kind == "TIFF":
        from lumigraph.capture.headers import tiff_pages

        o = tiff_pages(data, p, tags={ORIENTATION_TAG})[0].get(ORIENTATION_TAG, [1])[0]
    elif kind == "PNG":
        for name, _pos, body in _png_chunks(data):
            if name == b"eXIf":
                o = _exif_block_orientation(body)
                break
            if name == b"IDAT":
                break  # eXIf must precede the image data (PNG 1.5 extensions)
    return o if 1 <= o <= 8 else 1


def image_orientation(path) -> int:
    """The EXIF Orientation (1..8) that :func:`read_image` applied to ``path``;
    1 for files without one (RAW: LibRaw applies the camera's own flip)."""
    p = _existing(path)
    if p.suffix.lower() not in LDR_EXTS:
        return 1
    data = p.read_bytes()
    return _orientation(data, image_header(data, p).kind, p)


def _png_complete(data: bytes) -> bool:
    return data[-12:].find(b"IEND") >= 0


def _tiff_channels_ok(data: bytes, p: Path) -> bool:
    from lumigraph.capture.headers import tiff_pages

    return tiff_pages(data, p)[0].get(277, [1])[0] <= 4


_PIL_LOCK = threading.Lock()


@contextlib.contextmanager
def _pil_allows(pixels: int):
    """Pillow has its own bomb limit (a warning past 89 MP, an error past twice
    that); ours has been checked already, so Pillow's must not contradict it.
    Pillow also warns and logs what it skips in a corrupt file; the error we
    raise says it once."""
    import logging
    import warnings

    from PIL import Image

    log = logging.getLogger("PIL")
    with _PIL_LOCK:
        before, level = Image.MAX_IMAGE_PIXELS, log.level
        if before is not None and pixels > before // 2:
            Image.MAX_IMAGE_PIXELS = 2 * pixels
        log.setLevel(logging.CRITICAL + 1)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                yield
        finally:
            Image.MAX_IMAGE_PIXELS = before
            log.setLevel(level)


def _read_jpeg(p: Path, data: bytes, pixels: int) -> np.ndarray:
    import io as _bytesio

    from PIL import Image

    try:
        with _pil_allows(pixels), Image.open(_bytesio.BytesIO(data)) as im:
            im.load()  # Pillow raises on truncated JPEG data; OpenCV would not
            if im.mode not in ("L", "RGB"):
                im = im.convert("RGB")
            return np.asarray(im).copy()
    except MemoryError:
        raise
    except Exception as e:  # Pillow raises OSError, ValueError, SyntaxError, …
        raise InputError(p, f"cannot decode JPEG ({' '.join(str(e).split())[:200]})") from None


def write_image(path, img: np.ndarray, *, bit_depth: int | None = None) -> None:
    """Write 8/16-bit code values to PNG or TIFF (RGB order in memory).

    Parameters
    ----------
    img : ndarray, uint8 or uint16, ``(H, W)`` or ``(H, W, 3|4)``
    bit_depth : int, optional
        True bit depth of uint16 data (e.g. 12). Recorded in the PNG's ``sBIT``
        chunk; values must fit in it.
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in {".png", ".tif", ".tiff"}:
        raise InputError(p, "write_image writes PNG or TIFF; use write_exr for linear float data")
    if img.dtype.kind == "f" and not np.isfinite(img).all():
        raise InputError("img", f"{ext[1:].upper()} code values are integers and cannot hold "
                                "NaN/inf; fill or mask them, then convert to uint8/uint16")
    if img.dtype not in (np.uint8, np.uint16):
        raise TypeError(f"img: expected uint8 or uint16 code values, got {img.dtype}")
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 3, 4)):
        raise ValueError(f"img: expected (H, W) or (H, W, 1|3|4), got {img.shape}")
    container = 8 * img.dtype.itemsize
    if bit_depth is not None:
        if not 1 <= bit_depth <= container:
            raise ValueError(f"bit_depth: expected 1..{container} for {img.dtype}, got {bit_depth}")
        if img.size and int(img.max()) >= 2 ** bit_depth:
            raise ValueError(f"img: values up to {int(img.max())} do not fit in {bit_depth} bits")
    cv2 = _cv2()
    arr = img
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim == 3:
        arr = arr[..., ::-1] if arr.shape[2] == 3 else arr[..., [2, 1, 0, 3]]
    params = [cv2.IMWRITE_PNG_COMPRESSION, 6] if ext == ".png" else []
    ok, enc = cv2.imencode(ext, np.ascontiguousarray(arr), params)
    if not ok:
        raise RuntimeError(f"OpenCV could not encode {p}")
    data = enc.tobytes()
    if ext == ".png" and bit_depth is not None and bit_depth != container:
        data = _png_with_sbit(data, bit_depth, 1 if arr.ndim == 2 else arr.shape[2])
    with atomic_path(p) as tmp:
        tmp.write_bytes(data)


def check_finite(arr: np.ndarray, where) -> None:
    """Raise InputError if a float array holds NaN or inf."""
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        bad = int((~np.isfinite(arr)).sum())
        raise InputError(where, f"contains {bad} NaN/inf values; expected finite linear values")


# ------------------------------------------------------------------------ EXIF
@dataclass(frozen=True)
class Exif:
    """Exposure settings read from EXIF (``None`` where absent)."""

    exposure_time_s: float | None
    f_number: float | None
    iso: float | None


def _rational(v) -> float | None:
    if v is None:
        return None
    if isinstance(v, tuple) and len(v) == 2:
        return float(Fraction(int(v[0]), int(v[1]))) if v[1] else None
    try:
        return float(v)
    except (TypeError, ValueError, ZeroDivisionError):
        return None


def read_exif(path) -> Exif:
    """Exposure time (s), f-number and ISO from a JPEG/TIFF/RAW file's EXIF."""
    p = _existing(path)
    if p.suffix.lower() in RAW_EXTS:
        import exifread

        try:
            with open(p, "rb") as f:
                tags = exifread.process_file(f, details=False)
        except MemoryError:
            raise
        except Exception as e:  # exifread raises whatever its parser trips on
            raise InputError(p, f"cannot read EXIF ({type(e).__name__}: {e})") from None

        def tag(name):
            t = tags.get(name)
            if t is None:
                return None
            v = t.values[0] if t.values else None
            return float(v.num) / float(v.den) if hasattr(v, "num") and v.den else _rational(v)

        return Exif(tag("EXIF ExposureTime"), tag("EXIF FNumber"), tag("EXIF ISOSpeedRatings"))
    from PIL import Image

    try:  # Image.open parses the header only; no pixel is decoded here
        with _pil_allows(max_pixels()), Image.open(p) as im:
            exif = im.getexif()
            sub = exif.get_ifd(0x8769)
    except MemoryError:
        raise
    except Exception as e:  # OSError, SyntaxError, struct.error, … from Pillow's parsers
        raise InputError(p, f"cannot read EXIF ({' '.join(str(e).split())[:200]})") from None
    iso = sub.get(0x8827)
    if isinstance(iso, tuple):
        iso = iso[0]
    return Exif(_rational(sub.get(0x829A)), _rational(sub.get(0x829D)), _rational(iso))


# ------------------------------------------------------------------------- RAW
@dataclass(frozen=True)
class RawImage:
    """A RAW file developed linearly: ``codes`` uint16 ``(H, W, 3)`` with the black
    level subtracted and the white level mapped to ``2**bit_depth - 1``."""

    codes: np.ndarray
    bit_depth: int
    black_level: float
    white_level: float
    exif: Exif


def read_raw(path, *, color: str = "srgb") -> RawImage:
    """Develop a RAW file without gamma or auto-brightening (rawpy defaults to both).

    Parameters
    ----------
    path : path-like
        DNG, CR2, NEF, ARW, … (anything LibRaw reads).
    color : {"srgb", "raw"}
        Output primaries: linear sRGB through the camera's colour matrix, or
        the camera's own RGB (no channel mixing: exactly proportional to the
        sensor values, which is what response recovery and merging need).

    Returns
    -------
    RawImage
        ``codes`` uint16 ``(H, W, 3)``, demosaicked, black level subtracted,
        camera white balance applied, white level mapped to
        ``2**bit_depth - 1``; ``bit_depth`` is the sensor's, from its levels.
    """
    p = _existing(path)
    if color not in ("srgb", "raw"):
        raise ValueError(f"color: expected 'srgb' or 'raw', got {color!r}")
    import rawpy

    try:
        with _c_messages(), rawpy.imread(str(p)) as raw:
            sizes = raw.sizes  # known once the file is opened, before unpacking
            check_pixel_count(p, sizes.raw_width, sizes.raw_height, what="RAW sensor")
            check_pixel_count(p, sizes.width, sizes.height, what="RAW image")
            white = float(raw.white_level)
            black = float(np.mean(raw.black_level_per_channel))
            space = rawpy.ColorSpace.sRGB if color == "srgb" else rawpy.ColorSpace.raw
            rgb = raw.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16,
                                  use_camera_wb=True, user_flip=0, output_color=space)
    except (InputError, MemoryError):
        raise
    except Exception as e:  # rawpy raises a family of LibRaw errors
        raise InputError(p, f"cannot decode RAW file ({type(e).__name__}: {e})") from None
    bit_depth = max(8, int(np.ceil(np.log2(max(white - black, 2.0) + 1))))
    # postprocess maps the white level to 65535; return codes in the sensor's range.
    scale = (2 ** bit_depth - 1) / 65535.0
    codes = np.round(rgb.astype(np.float64) * scale).astype(np.uint16)
    return RawImage(codes, bit_depth, black, white, read_exif(p))


# ------------------------------------------------------------------------- EXR
def read_exr(path) -> np.ndarray:
    """Read an OpenEXR file as float32, ``(H, W)`` for one channel, ``(H, W, 3)``
    for RGB, ``(H, W, 4)`` for RGBA; other channel sets in sorted name order."""
    p = _existing(path)
    size, n = p.stat().st_size, 1 << 20
    while True:  # the header, not the file: a larger head only for a long header
        with open(p, "rb") as fh:
            head = fh.read(n)
        try:
            header = exr_header(head, p, file_size=size)
            break
        except InputError:
            if len(head) >= size:
                raise
            n *= 16
    check_pixel_count(p, header.width, header.height, what="OpenEXR header")
    for what, w, h in header.pages:
        check_pixel_count(p, w, h, what=what)
    if header.samples > 4 * max_pixels():
        raise InputError(p, f"OpenEXR header claims {header.samples} values (pixels x channels), "
                            f"over 4 x the limit of {max_pixels()} pixels (set {MAX_PIXELS_ENV} "
                            "or --max-pixels to read larger images)")
    if header.short:
        raise InputError(p, header.short)
    import OpenEXR

    with _c_messages(python_stdout=True) as said:
        try:
            with OpenEXR.File(str(p), separate_channels=True) as f:
                chans = {k: np.asarray(v.pixels) for k, v in f.channels().items()}
            failure = None
        except MemoryError:
            raise
        except Exception as e:  # OpenEXR raises RuntimeError, ValueError, TypeError, …
            failure = e
    # OpenEXR's File catches a failure while reading pixels, prints a warning
    # (on stdout) and returns what it has: a corrupt file read as zeros
    if failure is not None or "Exception raised reading pixel data" in "".join(said):
        raise _decoder_failed(p, "OpenEXR file", failure, said)
    if not chans:
        raise InputError(p, "OpenEXR file has no channels")
    order = [c for c in ("R", "G", "B", "A") if c in chans]
    if len(order) != len(chans):
        order = sorted(chans)
    if order == ["A"] or len(order) == 1:
        out = chans[order[0]].astype(np.float32)
    else:
        out = np.stack([chans[c] for c in order], axis=-1).astype(np.float32)
    return np.ascontiguousarray(out)


def write_exr(path, img: np.ndarray, *, half: bool = False,
              channels: Sequence[str] | None = None) -> None:
    """Write linear float data to OpenEXR (ZIP compression, deterministic bytes).

    Parameters
    ----------
    img : ndarray, float, ``(H, W)`` or ``(H, W, C)``
        NaN/inf are written as they are (masks travel in separate files).
    half : bool
        Store as 16-bit half floats (range ±65504, 11-bit mantissa).
    channels : sequence of str, optional
        Channel names; default ``Y`` for one channel, ``RGB``/``RGBA`` for 3/4.
    """
    import OpenEXR

    arr = np.asarray(img)
    if arr.dtype.kind != "f":
        raise TypeError(f"img: expected a float array of linear values, got {arr.dtype}")
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3:
        raise ValueError(f"img: expected (H, W) or (H, W, C), got {np.asarray(img).shape}")
    c = arr.shape[2]
    names = list(channels) if channels is not None else (
        ["Y"] if c == 1 else list("RGBA"[:c]) if c in (3, 4) else [f"C{i}" for i in range(c)])
    if len(names) != c:
        raise ValueError(f"channels: {len(names)} names for {c} channels")
    dtype = np.float16 if half else np.float32
    data = {n: np.ascontiguousarray(arr[..., i].astype(dtype)) for i, n in enumerate(names)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp, OpenEXR.File(header, data) as f:
        f.write(str(tmp))


# ------------------------------------------------------------------------- PFM
def read_pfm(path) -> np.ndarray:
    """Read a PFM file top-row-first as float32; ``inf`` (unknown) becomes NaN."""
    p = _existing(path)
    with open(p, "rb") as f:
        kind = f.readline(8).strip()
        if kind not in (b"PF", b"Pf"):
            raise InputError(p, "not a PFM file (header must start with PF or Pf)")
        try:  # header lines are short; a line of megabytes is not a header
            dims = f.readline(256).split()
            if len(dims) != 2:
                raise ValueError
            w, h = int(dims[0]), int(dims[1])
            scale = float(f.readline(256).strip())
        except (ValueError, IndexError):
            raise InputError(p, "malformed PFM header (expected 'PF' or 'Pf', 'W H', "
                                "then a scale)") from None
        if not np.isfinite(scale):
            raise InputError(p, f"malformed PFM header: scale {scale} (must be a finite "
                                "number; its sign gives the byte order)")
        check_pixel_count(p, w, h, what="PFM header")
        c = 3 if kind == b"PF" else 1
        endian = "<" if scale < 0 else ">"
        need = w * h * c * 4
        have = os.fstat(f.fileno()).st_size - f.tell()
        if have < need:  # said before a buffer of `need` bytes is asked for
            raise InputError(p, f"PFM is truncated: {have} of {need} data bytes")
        raw = f.read(need)
    if len(raw) < need:
        raise InputError(p, f"PFM is truncated: {len(raw)} of {need} data bytes")
    arr = np.frombuffer(raw, dtype=endian + "f4").reshape(h, w, c)
    arr = np.flipud(arr).astype(np.float32)
    if c == 1:
        arr = arr[..., 0]
    arr = np.ascontiguousarray(arr)
    arr[np.isinf(arr)] = np.nan
    return arr


def write_pfm(path, img: np.ndarray) -> None:
    """Write float data as little-endian PFM; NaN (unknown) is stored as ``inf``
    (the Middlebury convention)."""
    arr = np.asarray(img, dtype=np.float32)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] != 3):
        raise ValueError(f"img: expected (H, W) or (H, W, 3), got {np.asarray(img).shape}")
    h, w = arr.shape[:2]
    kind = b"Pf" if arr.ndim == 2 else b"PF"
    out = np.where(np.isnan(arr), np.float32(np.inf), arr)
    body = np.flipud(out).astype("<f4").tobytes()
    with atomic_path(path) as tmp:
        tmp.write_bytes(kind + b"\n" + f"{w} {h}\n".encode() + b"-1.0\n" + body)


# ------------------------------------------------------------------------ .flo
FLO_MAGIC = 202021.25
FLO_UNKNOWN = 1e10  # Middlebury: components above 1e9 mean unknown


def read_flo(path) -> np.ndarray:
    """Read Middlebury ``.flo`` as ``(H, W, 2)`` float32 ``(dx, dy)``; unknown -> NaN."""
    p = _existing(path)
    with open(p, "rb") as f:
        head = f.read(12)
        if len(head) < 12 or struct.unpack("<f", head[:4])[0] != FLO_MAGIC:
            raise InputError(p, "not a Middlebury .flo file (bad magic number)")
        w, h = struct.unpack("<ii", head[4:12])
        check_pixel_count(p, w, h, what=".flo header")
        need = w * h * 2 * 4
        have = os.fstat(f.fileno()).st_size - 12
        if have < need:  # said before a buffer of `need` bytes is asked for
            raise InputError(p, f".flo is truncated: {have} of {need} data bytes")
        raw = f.read(need)
    if len(raw) < need:
        raise InputError(p, f".flo is truncated: {len(raw)} of {need} data bytes")
    flow = np.frombuffer(raw, "<f4").reshape(h, w, 2).astype(np.float32)
    unknown = (np.abs(flow) > 1e9).any(axis=2) | ~np.isfinite(flow).all(axis=2)
    flow[unknown] = np.nan
    return flow


def write_flo(path, flow: np.ndarray) -> None:
    """Write ``(H, W, 2)`` forward flow; NaN (unknown) becomes 1e10 in the file."""
    arr = np.asarray(flow, dtype=np.float32)
    if arr.ndim != 3 or arr.shape[2] != 2:
        raise ValueError(f"flow: expected (H, W, 2), got {np.asarray(flow).shape}")
    h, w = arr.shape[:2]
    unknown = ~np.isfinite(arr).all(axis=2)
    out = arr.copy()
    out[unknown] = FLO_UNKNOWN
    with atomic_path(path) as tmp:
        tmp.write_bytes(struct.pack("<fii", FLO_MAGIC, w, h) + out.astype("<f4").tobytes())


# ------------------------------------------------------------------------- PLY
def write_ply(path, points: np.ndarray, colors: np.ndarray | None = None) -> None:
    """Write a binary little-endian PLY point cloud.

    Parameters
    ----------
    points : ndarray, ``(N, 3)`` float, world units
        Stored as ``double x, y, z`` (geometry keeps float64).
    colors : ndarray, ``(N, 3)`` uint8, optional
        Stored as ``uchar red, green, blue``.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points: expected (N, 3), got {np.asarray(points).shape}")
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if colors is not None:
        col = np.asarray(colors)
        if col.shape != pts.shape or col.dtype != np.uint8:
            raise ValueError(f"colors: expected (N, 3) uint8, got {col.shape} {col.dtype}")
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    rec = np.empty(len(pts), dtype=fields)
    rec["x"], rec["y"], rec["z"] = pts.T
    if colors is not None:
        rec["red"], rec["green"], rec["blue"] = np.asarray(colors).T
    names = {"<f8": "double", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(pts)}"]
    header += [f"property {names[t]} {n}" for n, t in fields]
    header += ["end_header"]
    with atomic_path(path) as tmp:
        tmp.write_bytes(("\n".join(header) + "\n").encode("ascii") + rec.tobytes())


_PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "<i2", "ushort": "<u2", "int": "<i4",
              "uint": "<u4", "float": "<f4", "double": "<f8", "int8": "i1", "uint8": "u1",
              "int16": "<i2", "uint16": "<u2", "int32": "<i4", "uint32": "<u4",
              "float32": "<f4", "float64": "<f8"}
_PLY_FORMATS = ("ascii", "binary_little_endian")
# the face element's list of vertex indices, under its two usual names
_PLY_FACE_LISTS = ("vertex_indices", "vertex_index")


def _ply_header(p: Path, raw: bytes) -> tuple[str, list, int]:
    """``(format, elements, body offset)`` of a PLY: each element ``(name, count,
    properties)``, a property ``(name, dtype)`` or ``(name, (count dtype, item dtype))``
    for a list."""
    m = re.search(rb"end_header\r?\n", raw[:1 << 16])
    if not raw.startswith((b"ply\n", b"ply\r\n")) or m is None:
        raise InputError(p, "not a PLY file (missing 'ply' magic or end_header)")
    lines = raw[:m.start()].decode("ascii", "replace").splitlines()
    fmt = [ln.split() for ln in lines if ln.split()[:1] == ["format"]]
    if len(fmt) != 1 or len(fmt[0]) != 3 or fmt[0][1] not in _PLY_FORMATS:
        raise InputError(p, "only ascii and binary_little_endian PLY are supported")
    elements: list = []
    for line in lines:
        parts = line.split()
        if parts[:1] == ["element"]:
            if len(parts) != 3 or not (parts[2].isascii() and parts[2].isdigit()):
                raise InputError(p, f"malformed PLY header line: {line!r}")
            count = int(parts[2])
            if count > max_pixels():  # one point (or face) per pixel of the largest image
                noun = "vertices" if parts[1] == "vertex" else f"{parts[1]} records"
                raise InputError(p, f"PLY header claims {count} {noun}, over the limit of "
                                    f"{max_pixels()} (set {MAX_PIXELS_ENV} or --max-pixels to "
                                    "read larger files)")
            elements.append((parts[1], count, []))
        elif parts[:1] == ["property"]:
            if not elements:
                raise InputError(p, f"PLY property before any element: {line!r}")
            props = elements[-1][2]
            if len(parts) == 5 and parts[1] == "list" and parts[2] in _PLY_TYPES \
                    and parts[3] in _PLY_TYPES and np.dtype(_PLY_TYPES[parts[2]]).kind in "iu":
                props.append((parts[4], (_PLY_TYPES[parts[2]], _PLY_TYPES[parts[3]])))
            elif len(parts) == 3 and parts[1] in _PLY_TYPES:
                props.append((parts[2], _PLY_TYPES[parts[1]]))
            else:
                raise InputError(p, f"unsupported PLY property: {line!r}")
            if [n for n, _ in props].count(props[-1][0]) > 1:
                raise InputError(p, f"PLY property {props[-1][0]!r} given twice")
    return fmt[0][1], elements, m.end()


def _ply_binary(p: Path, body: bytes, pos: int, name: str, count: int, props) -> tuple:
    """One element's records from ``body[pos:]`` (binary little-endian): ``(scalars, lists,
    next pos)``, scalars a structured array, lists ``{name: list of int arrays}``."""
    scalars = [(n, t) for n, t in props if isinstance(t, str)]
    if all(isinstance(t, str) for _, t in props):
        dtype = np.dtype(scalars)
        need = count * dtype.itemsize
        if len(body) - pos < need:
            raise InputError(p, f"PLY is truncated: {len(body) - pos} of {need} bytes of the "
                                f"{name} element")
        return np.frombuffer(body, dtype, count, pos), {}, pos + need
    # Lists: records of one length throughout (a triangle mesh) are read at once, as
    # fixed records with the first record's lengths; anything else record by record.
    fields, at = [], pos
    for n, t in props:
        if isinstance(t, str):
            fields.append((n, t))
            at += np.dtype(t).itemsize
            continue
        ct, it = np.dtype(t[0]), np.dtype(t[1])
        if len(body) - at < ct.itemsize:
            break
        k = int(np.frombuffer(body, ct, 1, at)[0])
        if not 0 <= k * it.itemsize <= len(body) - at - ct.itemsize:
            break  # a list past the data (or negative): the record walk says truncated
        fields += [(n + " count", ct), (n, it, (k,))]
        at += ct.itemsize + k * it.itemsize
    else:
        dtype = np.dtype(fields)
        if count and len(body) - pos >= count * dtype.itemsize:
            rec = np.frombuffer(body, dtype, count, pos)
            if all((rec[n + " count"] == rec[n + " count"][0]).all()
                   for n, t in props if not isinstance(t, str)):
                lists = {n: rec[n].astype(np.int64) for n, t in props if not isinstance(t, str)}
                return rec[[n for n, _ in scalars]] if scalars else None, lists, \
                    pos + count * dtype.itemsize
    rows: list = []
    lists = {n: [] for n, t in props if not isinstance(t, str)}
    for r in range(count):
        row = []
        for n, t in props:
            size = np.dtype(t if isinstance(t, str) else t[0]).itemsize
            if len(body) - pos < size:
                raise InputError(p, f"PLY is truncated in record {r} of the {name} element")
            v = np.frombuffer(body, t if isinstance(t, str) else t[0], 1, pos)[0]
            pos += size
            if isinstance(t, str):
                row.append(v)
                continue
            it = np.dtype(t[1])
            if v < 0 or len(body) - pos < int(v) * it.itemsize:
                raise InputError(p, f"PLY is truncated in record {r} of the {name} element")
            lists[n].append(np.frombuffer(body, it, int(v), pos).astype(np.int64))
            pos += int(v) * it.itemsize
        rows.append(tuple(row))
    return (np.array(rows, np.dtype(scalars)) if scalars else None), lists, pos


def _ply_ascii(p: Path, tokens: np.ndarray, pos: int, name: str, count: int, props) -> tuple:
    """As :func:`_ply_binary`, from the body's numbers (``tokens``, float64); the
    scalars stay float64 (the declared types matter to the binary layout only)."""
    dtype = np.dtype([(n, np.float64) for n, t in props if isinstance(t, str)])
    # records of one length (all scalars; a triangle mesh) are read at once, as a
    # table with the first record's length; anything else record by record
    lengths, at = [], pos
    for _, t in props:
        k = 0
        if not isinstance(t, str):
            k = tokens[at] if at < tokens.size else -1.0
            k = int(k) if np.isfinite(k) and k >= 0 and k == int(k) else -1
            if k < 0:
                break
        lengths.append(k)
        at += 1 + k if not isinstance(t, str) else 1
    else:
        width = at - pos
        if tokens.size - pos >= count * width:
            block = tokens[pos:pos + count * width].reshape(count, width)
            rec, lists, col = np.empty(count, dtype), {}, 0
            for (n, t), k in zip(props, lengths, strict=True):
                if isinstance(t, str):
                    rec[n] = block[:, col]
                    col += 1
                    continue
                if not (block[:, col] == k).all():
                    break  # lists of several lengths
                lists[n] = block[:, col + 1:col + 1 + k]
                col += 1 + k
            else:
                for n, v in lists.items():
                    if not (np.isfinite(v) & (v == np.round(v))).all():
                        raise InputError(p, f"the {name} element's {n} holds a non-integer")
                    lists[n] = v.astype(np.int64)
                return rec, lists, pos + count * width
    rows: list = []
    lists = {n: [] for n, t in props if not isinstance(t, str)}
    for r in range(count):
        row = []
        for n, t in props:
            if pos >= tokens.size:
                raise InputError(p, f"PLY is truncated in record {r} of the {name} element")
            v = tokens[pos]
            pos += 1
            if isinstance(t, str):
                row.append(v)
                continue
            if not (np.isfinite(v) and v >= 0 and v == int(v) and tokens.size - pos >= v):
                raise InputError(p, f"record {r} of the {name} element: list length {v:g} is "
                                    "not a count the file holds")
            items = tokens[pos:pos + int(v)]
            if not (np.isfinite(items) & (items == np.round(items))).all():
                raise InputError(p, f"record {r} of the {name} element: {n} holds a "
                                    "non-integer")
            lists[n].append(items.astype(np.int64))
            pos += int(v)
        rows.append(tuple(row))
    return np.array(rows, dtype), lists, pos


def _fan(p: Path, polygons, n_vertices: int) -> np.ndarray:
    """Faces ``(M, 3)`` int64: each polygon ``(v0, v1, ..., vk)`` as the fan
    ``(v0, vi, vi+1)`` (its winding kept), indices checked against ``n_vertices``."""
    if isinstance(polygons, np.ndarray):  # all of one length: (F, k)
        k = polygons.shape[1] if polygons.ndim == 2 else 0
        polys, lengths = polygons, np.full(len(polygons), k)
    else:
        lengths = np.array([len(f) for f in polygons], np.int64)
        polys = None
    short = np.flatnonzero(lengths < 3)
    if short.size:
        raise InputError(p, f"face {short[0]} has {lengths[short[0]]} vertices; a face needs 3 "
                            "or more")
    if polys is not None:
        k = polys.shape[1] if len(polys) else 3
        tris = np.stack([np.stack([polys[:, 0], polys[:, i], polys[:, i + 1]], axis=1)
                         for i in range(1, k - 1)], axis=1).reshape(-1, 3) if len(polys) \
            else np.zeros((0, 3), np.int64)
    else:
        tris = np.array([(f[0], f[i], f[i + 1]) for f in polygons for i in range(1, len(f) - 1)],
                        np.int64).reshape(-1, 3)
    bad = np.flatnonzero(((tris < 0) | (tris >= n_vertices)).any(axis=1))
    if bad.size:
        v = tris[bad[0]][(tris[bad[0]] < 0) | (tris[bad[0]] >= n_vertices)][0]
        raise InputError(p, f"a face refers to vertex {v}, and there are {n_vertices} "
                            f"(indices 0..{n_vertices - 1})")
    return tris


def read_ply(path, *, faces: bool = False):
    """Read a PLY (``ascii`` or ``binary_little_endian``): the vertex element's
    ``x, y, z`` and, when present, ``red, green, blue``; with ``faces=True`` also
    the ``face`` element's ``vertex_indices`` (or ``vertex_index``) lists.

    Every element is read in the header's order (others are skipped). A
    polygon of ``k > 3`` vertices becomes the fan of triangles ``(v0, vi, vi+1)``,
    keeping its winding. One reader for point clouds (``write_ply``) and meshes
    (the Façade solve's ``model.ply``).

    Returns
    -------
    points : ndarray, ``(N, 3)`` float64
    colors : ndarray, ``(N, 3)`` uint8, or None
    faces : ndarray, ``(M, 3)`` int64 (with ``faces=True`` only; ``(0, 3)``
        when the file has none): 0-based vertex indices.

    Raises
    ------
    InputError
        Naming the file: not a PLY, another format, a header bomb, truncated
        data, a face with fewer than 3 vertices or an index out of range.

    Examples
    --------
    >>> import tempfile, os
    >>> p = os.path.join(tempfile.mkdtemp(), "quad.ply")
    >>> _ = open(p, "w").write("ply\\nformat ascii 1.0\\nelement vertex 4\\nproperty float x\\n"
    ...     "property float y\\nproperty float z\\nelement face 1\\n"
    ...     "property list uchar int vertex_indices\\nend_header\\n"
    ...     "0 0 0\\n1 0 0\\n1 1 0\\n0 1 0\\n4 0 1 2 3\\n")
    >>> pts, cols, tris = read_ply(p, faces=True)
    >>> pts.shape, cols, tris.tolist()
    ((4, 3), None, [[0, 1, 2], [0, 2, 3]])
    """
    p = _existing(path)
    raw = p.read_bytes()
    fmt, elements, start = _ply_header(p, raw)
    if fmt == "ascii":
        try:
            data = np.array(raw[start:].split(), dtype=np.float64)
        except ValueError as e:
            raise InputError(p, f"ascii PLY body holds a token that is not a number ({e})") \
                from None
        read = _ply_ascii
    else:
        data, read = raw, _ply_binary
    pos = 0 if fmt == "ascii" else start
    vertex = polygons = None
    for name, count, props in elements:
        if not props:
            if count:
                raise InputError(p, f"PLY element {name!r} has records but no properties")
            continue
        rec, lists, pos = read(p, data, pos, name, count, props)
        if name == "vertex" and vertex is None:
            vertex = rec
        elif name == "face" and polygons is None:
            polygons = next((lists[n] for n in _PLY_FACE_LISTS if n in lists), None)
        if vertex is not None and (polygons is not None or not faces):
            break  # what the caller asked for is read
    names = vertex.dtype.names if vertex is not None else ()
    if vertex is None or not {"x", "y", "z"} <= set(names):
        raise InputError(p, "PLY has no vertex element with x, y, z properties (each once)")
    pts = np.stack([vertex["x"], vertex["y"], vertex["z"]], axis=1).astype(np.float64)
    cols = None
    if {"red", "green", "blue"} <= set(names):
        cols = np.stack([vertex["red"], vertex["green"], vertex["blue"]], axis=1)
        if cols.dtype != np.uint8:  # ascii numbers, or wider types: to codes, saturated
            cols = np.clip(np.nan_to_num(cols.astype(np.float64)), 0, 255).astype(np.uint8)
    if not faces:
        return pts, cols
    tris = np.zeros((0, 3), np.int64) if polygons is None else _fan(p, polygons, len(pts))
    return pts, cols, tris


# ----------------------------------------------------------------------- stacks
@dataclass(frozen=True)
class Stack:
    """A set of images of one scene, as captured.

    Attributes
    ----------
    images : ndarray, ``(N, H, W, C)``
        Integer code values as captured (LDR/RAW) or float32 linear values.
    paths : tuple of str
        Source files, in stack order.
    bit_depth : int or None
        True bit depth of integer codes (``None`` for float data).
    exposure_times_s : tuple of float or None
        Per-image exposure times (EXIF, stack.json or given), or ``None``.
    linear : bool
        True for RAW-developed or float data (no response curve needed).
    info : dict
        Everything else ``stack.json`` carried (scene-specific keys).
    times_given : bool
        The times were given to :func:`read_stack` (``--times``), overriding
        EXIF and stack.json: they are the exposures, whatever the apertures.
    orientations : tuple of int
        The EXIF Orientation applied to each image when read (1: as stored).
    """

    images: np.ndarray
    paths: tuple[str, ...]
    bit_depth: int | None
    exposure_times_s: tuple[float, ...] | None = None
    linear: bool = False
    info: dict = field(default_factory=dict)
    times_given: bool = False
    bit_depth_source: str | None = None  # how bit_depth was decided (capture.exposure.BitDepth)
    orientations: tuple[int, ...] = ()  # EXIF Orientation read_image applied to each (1: none)

    def __post_init__(self):
        if self.images.ndim != 4:
            raise ValueError(f"images: expected (N, H, W, C), got {self.images.shape}")
        if len(self.paths) != len(self.images):
            raise ValueError(f"paths: {len(self.paths)} paths for {len(self.images)} images")
        if self.exposure_times_s is not None:
            check_exposure_times(self.exposure_times_s, len(self.images))

    @property
    def effective_exposure_times_s(self) -> tuple[float, ...] | None:
        """The relative exposure of each image, what HDR works with: the times,
        or for an aperture bracket (``f_numbers`` in stack.json, times not
        given) ``Δt · (N_ref / N)²`` (:func:`capture.exposure.effective_exposure_times`)."""
        if self.exposure_times_s is None or self.times_given or "f_numbers" not in self.info:
            return self.exposure_times_s
        return effective_exposure_times(self.exposure_times_s, self.info["f_numbers"],
                                        f_number_ref=self.info.get("f_number_ref"))


def read_stack_json(path: str | os.PathLike) -> dict:
    """Read and check ``stack.json``: the one parser of its keys.

    Every key a command reads is checked here, once, so a hand-edited file
    with wrong content is refused naming the key: ``images`` (a non-empty
    list of file names); optional ``bit_depth`` (1..16 or null), ``linear``
    (true/false), ``exposure_times_s`` and ``f_numbers`` (one positive
    number per image), ``f_number_ref`` (positive), ``scene``, ``kind`` and
    ``board`` (strings); a projector capture's ``sets`` (named lists of file
    names, ``flat`` a black and a white one) and ``patterns`` (per set,
    ``complement_of`` an index into the set or -1, ``lit_fraction`` in
    [0, 1]); a light-field array's ``lightfield`` (``grid`` [U, V],
    ``spacing`` and ``focal_px`` positive; its ``cameras`` are read by
    :meth:`capture.rig.CameraArray.from_dict`); a lenslet capture's
    ``lenslet`` (``views`` per side, 2..64). Other keys are kept unchecked.

    Returns
    -------
    dict
        The body as read.

    Raises
    ------
    InputError
        Naming the file and the key at fault.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "stack.json").write_text('{"images": ["a.png", 42]}')
    >>> try:
    ...     read_stack_json(d / "stack.json")
    ... except InputError as e:
    ...     print(e.problem)
    key 'images[1]': expected a file name (string), got 42
    """
    from lumigraph.capture.artifact import load_json_artifact
    from lumigraph.capture.schema import check, fail, key_path, require

    body = load_json_artifact(path, "stack", schemas=(STACK_SCHEMA,))
    n = len(require(body, "images", "list", items="file name", min_length=1, path=path))
    require(body, "bit_depth", "integer", low=1, high=16, nullable=True, default=None, path=path)
    require(body, "linear", "boolean", default=False, path=path)
    for name, what in (("exposure_times_s", "exposure times"), ("f_numbers", "f-numbers")):
        values = require(body, name, "list", items="number", above=0, default=None, path=path)
        if values is not None and len(values) != n:
            raise fail(path, name, f"{len(values)} {what} for {n} images")
    require(body, "f_number_ref", "number", above=0, default=None, path=path)
    for name in ("scene", "kind", "board"):
        require(body, name, "string", default=None, path=path)
    sets = require(body, "sets", "object", default={}, path=path)
    for name, files in sets.items():
        check(files, "list", items="file name", min_length=1, path=path,
              key=key_path("sets", name))
    if "flat" in sets and len(sets["flat"]) != 2:
        raise fail(path, "sets.flat", f"expected a black and a white image, got "
                                      f"{len(sets['flat'])} files")
    for name, pattern in require(body, "patterns", "object", default={}, path=path).items():
        where = key_path("patterns", name)
        check(pattern, "object", path=path, key=where)
        size = len(sets[name]) if name in sets else None
        require(pattern, "complement_of", "list", items="integer", low=-1,
                high=None if size is None else size - 1, length=size, default=None, path=path,
                where=where)
        require(pattern, "lit_fraction", "list", items="number", low=0, high=1, default=None,
                path=path, where=where)
    lightfield = require(body, "lightfield", "object", default={}, path=path)
    require(lightfield, "grid", "list", length=2, items="integer", low=1, default=None,
            path=path, where="lightfield")
    for name in ("spacing", "focal_px"):
        require(lightfield, name, "number", above=0, default=None, path=path, where="lightfield")
    lenslet = require(body, "lenslet", "object", default={}, path=path)
    require(lenslet, "views", "list", items="integer", low=2, high=64, min_length=1,
            default=None, path=path, where="lenslet")
    return body


def _stack_files(inputs: Sequence[str | os.PathLike]) -> tuple[list[Path], dict, Path | None]:
    inputs = [Path(i) for i in inputs]
    if not inputs:
        raise InputError("<inputs>", "no input images given")
    if len(inputs) == 1 and (inputs[0].is_dir() or inputs[0].name == "stack.json"):
        folder = inputs[0] if inputs[0].is_dir() else inputs[0].parent
        sj = folder / "stack.json"
        if not sj.exists():
            raise InputError(folder, "folder has no stack.json; pass the image files instead")
        info = read_stack_json(sj)
        for i, name in enumerate(info["images"]):
            if not (folder / name).is_file():
                raise InputError(sj, f"key 'images[{i}]': {name} is not a file in {folder}")
        return [folder / f for f in info["images"]], info, sj
    return inputs, {}, None


def _stack_times(files: Sequence[Path], info: dict, sj: Path | None, *,
                 times: Sequence[float] | None, need_times: bool) -> tuple[float, ...] | None:
    """The exposure times of a stack's files: given, stack.json's, or EXIF
    (:func:`read_stack`'s rule; the tiled reader uses it too)."""
    if times is not None:
        t = tuple(float(x) for x in check_exposure_times(times, len(files), where="times"))
    elif "exposure_times_s" in info:
        t = tuple(float(x) for x in check_exposure_times(info["exposure_times_s"], len(files),
                                                         where=sj))
    else:
        found = []
        for f in files:
            et = read_exif(f).exposure_time_s if f.suffix.lower() in {".jpg", ".jpeg", ".tif",
                                                                      ".tiff"} | RAW_EXTS else None
            if et is None and need_times:
                raise InputError(f, "no EXIF exposure time; give --times T1,T2,... "
                                    "or a folder with stack.json")
            found.append(et)
        t = tuple(found) if all(x is not None for x in found) else None
        if t is not None:  # EXIF: an implausible time names its file
            for f, x in zip(files, t, strict=True):
                check_exposure_times([x], 1, where=f)
    if t is not None and times is None and "f_numbers" in info:
        effective_exposure_times(t, info["f_numbers"], f_number_ref=info.get("f_number_ref"),
                                 where=sj)
    return t


def _read_stack_image(f: Path) -> tuple[np.ndarray, tuple[int, str] | None, bool]:
    """One file of a stack as :func:`read_stack` reads it: ``(H, W, C)`` codes
    or floats, the bits its header declares (and which header) or None, and
    whether it is linear (RAW developed, float)."""
    ext = f.suffix.lower()
    linear = False
    if ext in RAW_EXTS:
        raw = read_raw(f)
        img, bd, linear = raw.codes, (raw.bit_depth, "RAW black/white levels"), True
    else:
        img = read_image(f)
        if img.dtype.kind == "f":
            bd, linear = None, True
        else:
            sb = png_significant_bits(f) if ext == ".png" else None
            bd = None if sb is None else (sb, "PNG sBIT")
    if img.ndim == 2:
        img = img[..., None]
    return img, bd, linear


def _check_like(f: Path, img: np.ndarray, first: Path, like) -> None:
    """A stack needs one size and type: ``img`` (of ``f``) against the first
    file's (an array, or its ``(shape, dtype)``)."""
    shape, dtype = (like.shape, like.dtype) if isinstance(like, np.ndarray) else like
    if img.shape != shape or img.dtype != dtype:
        raise InputError(f, f"is {img.shape[1]}x{img.shape[0]}x{img.shape[2]} {img.dtype}, "
                            f"but {first.name} is {shape[1]}x{shape[0]}x"
                            f"{shape[2]} {dtype}; a stack needs one size and type")


def read_stack(inputs: Sequence[str | os.PathLike], *, times: Sequence[float] | None = None,
               need_times: bool = False, bit_depth: int | None = None) -> Stack:
    """Read an image stack from a list of files or a folder holding ``stack.json``.

    Parameters
    ----------
    inputs : sequence of path-like
        Image files in stack order, or a single folder (or its ``stack.json``).
    times : sequence of float, optional
        Exposure times in seconds; override EXIF and stack.json (and, for an
        aperture bracket, its f-numbers: see :attr:`Stack.effective_exposure_times_s`).
    need_times : bool
        Raise InputError (naming the file) when an exposure time is missing.
    bit_depth : int, optional
        The codes' bit depth, overriding stack.json, sBIT and detection
        (:func:`capture.exposure.decide_bit_depth`, which also decides it when
        not given and records how in :attr:`Stack.bit_depth_source`).

    Raises
    ------
    InputError
        Missing/unreadable files, mixed sizes, channels or dtypes, missing or
        non-positive exposure times (:func:`capture.exposure.check_exposure_times`),
        f-numbers not one per image.
    """
    files, info, sj = _stack_files(inputs)
    imgs, bit_depths, linear = [], [], False
    for f in files:
        img, bd, lin = _read_stack_image(f)
        linear = linear or lin
        if imgs:
            _check_like(f, img, files[0], imgs[0])
        imgs.append(img)
        bit_depths.append(bd)
    # given, stack.json's (a claim checked against the codes), sBIT/RAW, or detected
    depth = decide_bit_depth(imgs, files, given=bit_depth, declared=info.get("bit_depth"),
                             declared_where=sj, significant=bit_depths)
    if depth.shift:
        imgs = [im >> depth.shift for im in imgs]
    t = _stack_times(files, info, sj, times=times, need_times=need_times)
    return Stack(np.stack(imgs), tuple(str(f) for f in files), depth.bits, t,
                 bool(info.get("linear", linear)), info, times_given=times is not None,
                 bit_depth_source=depth.source,
                 orientations=tuple(image_orientation(f) for f in files))


@dataclass(frozen=True)
class StackHeader:
    """What :func:`read_stack` learns about a stack, without its images
    (:func:`scan_stack`): a stack of any length in constant memory.

    Attributes
    ----------
    paths, bit_depth, bit_depth_source, exposure_times_s, linear, info, times_given
        As :class:`Stack`.
    shape : tuple of int
        ``(H, W, C)`` of every image.
    dtype : numpy.dtype
        Of every image's codes (or floats).
    shift : int
        The codes are left-aligned: :func:`read_stack` shifts them right by
        this many bits (:class:`capture.exposure.BitDepth`).
    """

    paths: tuple[str, ...]
    shape: tuple[int, int, int]
    dtype: np.dtype
    bit_depth: int | None
    bit_depth_source: str | None
    exposure_times_s: tuple[float, ...] | None = None
    linear: bool = False
    info: dict = field(default_factory=dict)
    times_given: bool = False
    shift: int = 0

    effective_exposure_times_s = Stack.effective_exposure_times_s


def scan_stack(inputs: Sequence[str | os.PathLike], *, times: Sequence[float] | None = None,
               need_times: bool = False, bit_depth: int | None = None) -> StackHeader:
    """:func:`read_stack` without keeping the images: the same checks (each
    file readable, one size and type, times), the same bit depth, from one
    decoded image at a time. :func:`capture.exposure.decide_bit_depth` looks
    at each image's largest code and the OR of its codes only, so it is fed
    those (:func:`capture.exposure.code_summary`) and decides as it would on
    the whole stack.

    Parameters
    ----------
    inputs, times, need_times, bit_depth
        As :func:`read_stack`.

    Returns
    -------
    StackHeader

    Raises
    ------
    InputError
        As :func:`read_stack`, the same messages.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for i, top in enumerate((100, 4095)):
    ...     write_image(d / f"f{i}.png", np.full((2, 3), top, np.uint16))
    >>> h = scan_stack([d / "f0.png", d / "f1.png"], times=[0.01, 0.04])
    >>> h.shape, h.bit_depth, h.bit_depth == read_stack([d / "f0.png", d / "f1.png"]).bit_depth
    ((2, 3, 1), 12, True)
    """
    from lumigraph.capture.exposure import code_summary

    files, info, sj = _stack_files(inputs)
    summaries, bit_depths, linear, like = [], [], False, None
    for f in files:
        img, bd, lin = _read_stack_image(f)  # decoded, summarised, dropped
        linear = linear or lin
        if like is None:
            like = (img.shape, img.dtype)
        else:
            _check_like(f, img, files[0], like)
        summaries.append(code_summary(img))
        bit_depths.append(bd)
        del img
    depth = decide_bit_depth(summaries, files, given=bit_depth, declared=info.get("bit_depth"),
                             declared_where=sj, significant=bit_depths)
    t = _stack_times(files, info, sj, times=times, need_times=need_times)
    return StackHeader(tuple(str(f) for f in files), like[0], np.dtype(like[1]), depth.bits,
                       depth.source, t, bool(info.get("linear", linear)), info,
                       times_given=times is not None, shift=depth.shift)


def write_stack_json(folder, images: Sequence[str], **info) -> Path:
    """Write ``folder/stack.json`` naming ``images`` (relative file names) plus
    any stack-wide facts (``bit_depth``, ``exposure_times_s``, ``linear``, …)."""
    body = {"schema": STACK_SCHEMA, "schema_version": 1, "images": list(images), **info}
    path = Path(folder) / "stack.json"
    with atomic_path(path) as tmp:
        tmp.write_text(dumps_json(body))
    return path
