"""Images larger than memory: read, process and write in bands of rows.

A *tile* here is a band of ``rows`` full-width rows (:func:`bands`), read
with a *halo* of extra rows above and below where an operator's support
reaches past the band (a blur's radius, a remap's source rows). Bands,
not square tiles, because every chunked format a user can open is stored by
rows or by row-major tiles (scanline OpenEXR in blocks of 16 lines, TIFF
strips, PNG rows): a square tile of a striped file would decode each strip
``W / N`` times, and a band is written as soon as it is done, in file order,
so the output never waits in memory. Peak memory is bounded by ``rows × W``
(the band, its inputs and its halo), never by ``H × W``;
docs/decisions/tiles.md has the measurements and why not dask.array.

What is here (the ground floor of every stage's tiled path):

* :class:`RowSource` readers that return rows ``y0:y1`` of one image without
  reading the rest: :class:`TiffRows` (strips or tiles, any compression
  tifffile decodes), :class:`ExrRows` (scanline or tiled OpenEXR) and
  :class:`ArrayRows` (an array already in memory: formats that cannot be read
  by rows, PNG or JPEG, are read whole, and the meta says so);
  :func:`open_rows` picks one from the file.
* writers that take rows in order: :class:`ExrRowWriter` (scanline EXR, ZIP,
  the same bytes as :func:`capture.io.write_exr` writes for the whole image),
  :class:`PngRowWriter` (8/16-bit PNG through one zlib stream; the same pixels
  as :func:`capture.io.write_image`), :class:`TiffRowWriter` (striped TIFF,
  one strip per band).
* the tile plan: :func:`parse_memory`, :func:`plan_rows` (``--tile`` and
  ``--memory`` to a band height, or untiled), :func:`finish_artifact` (the
  sidecar of an artifact written through :func:`capture.artifact.atomic_path`).

Examples
--------
>>> [(b.y0, b.y1, b.r0, b.r1) for b in bands(10, 4, halo=1)]
[(0, 4, 0, 5), (4, 8, 3, 9), (8, 10, 7, 10)]
>>> parse_memory("1.5GB"), parse_memory("512MiB")
(1500000000, 536870912)
"""

from __future__ import annotations

import abc
import argparse
import math
import os
import re
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lumigraph.capture.errors import InputError

# Images whose untiled working set is under this many bytes are processed whole
# (the default budget of --memory; the working set is each operator's own estimate).
DEFAULT_MEMORY = 2 * 1000 ** 3
# What the process holds before any image: the interpreter, numpy, OpenEXR,
# tifffile and the stage's modules (measured ~0.15 GB; counted against the budget).
BASELINE_BYTES = 200 * 1000 ** 2
MIN_ROWS = 1

_UNITS = {"": 1, "b": 1, "k": 1000, "kb": 1000, "m": 1000 ** 2, "mb": 1000 ** 2,
          "g": 1000 ** 3, "gb": 1000 ** 3, "t": 1000 ** 4, "tb": 1000 ** 4,
          "kib": 1024, "mib": 1024 ** 2, "gib": 1024 ** 3, "tib": 1024 ** 4}


def parse_memory(text: str) -> int:
    """``--memory``: a byte count with an optional unit (``1GB``, ``512MiB``,
    ``1.5G``; decimal units are powers of 1000, ``KiB``/``MiB``/``GiB`` of
    1024), at least 64 MB (less cannot hold the interpreter and one band).

    Examples
    --------
    >>> parse_memory("2G"), parse_memory("100000000")
    (2000000000, 100000000)
    """
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([a-zA-Z]*)\s*", str(text))
    unit = m.group(2).lower() if m else ""
    if not m or unit not in _UNITS:
        raise argparse.ArgumentTypeError(f"expected a size such as 1GB, 512MB or 2GiB, got {text!r}")
    n = float(m.group(1)) * _UNITS[unit]
    if not math.isfinite(n) or n < 64 * 1000 ** 2:
        raise argparse.ArgumentTypeError(f"expected at least 64MB, got {text!r}")
    return int(n)


parse_memory.__name__ = "memory size"


@dataclass(frozen=True)
class Band:
    """Rows ``y0:y1`` of the output, computed from input rows ``r0:r1`` (the
    band and its halo, clipped to the image)."""

    y0: int
    y1: int
    r0: int
    r1: int

    @property
    def core(self) -> slice:
        """The band's rows within the rows read (``r0:r1``)."""
        return slice(self.y0 - self.r0, self.y1 - self.r0)


def bands(height: int, rows: int, *, halo: int = 0) -> list[Band]:
    """Cut ``height`` rows into bands of ``rows`` (the last one shorter), each
    read with ``halo`` rows above and below where the image has them."""
    if rows < 1 or halo < 0:
        raise ValueError(f"rows, halo: expected rows >= 1 and halo >= 0, got {rows}, {halo}")
    return [Band(y, min(y + rows, height), max(0, y - halo), min(height, y + rows + halo))
            for y in range(0, height, rows)]


@dataclass(frozen=True)
class TilePlan:
    """How a command processes its image: ``rows`` per band (``None``: whole)
    and why, for the meta."""

    rows: int | None
    halo: int
    reason: str

    def as_meta(self, height: int) -> dict:
        n = 1 if self.rows is None else -(-height // self.rows)
        return {"tiled": self.rows is not None, "rows": self.rows, "halo_rows": self.halo,
                "bands": n, "reason": self.reason}


def plan_rows(tile, memory: int | None, *, width: int, height: int, bytes_per_pixel: float,
              band_bytes_per_pixel: float = 0.0, halo: int = 0) -> TilePlan:
    """The band height for ``--tile`` and ``--memory``.

    Parameters
    ----------
    tile : int, "auto", "off" or None
        Rows per band; ``"auto"``: the tallest band whose working set fits
        ``memory``; ``"off"``: whole; ``None`` (the default): whole when the
        untiled working set fits ``memory``, else ``"auto"``.
    memory : int, optional
        The budget in bytes (default :data:`DEFAULT_MEMORY`), the process's
        :data:`BASELINE_BYTES` included.
    width, height : int
        The image.
    bytes_per_pixel : float
        The operator's working set per pixel of the rows it reads (inputs,
        temporaries, output before it is written).
    band_bytes_per_pixel : float
        Per pixel of the band's output rows held until they are written.
    halo : int
        Rows read above and below a band.

    Examples
    --------
    >>> plan_rows(None, None, width=100, height=100, bytes_per_pixel=40).rows is None
    True
    >>> plan_rows("auto", 10 ** 9, width=10000, height=10000, bytes_per_pixel=40).rows
    2000
    """
    budget = DEFAULT_MEMORY if memory is None else int(memory)
    whole = (bytes_per_pixel + band_bytes_per_pixel) * width * height
    if tile == "off":
        return TilePlan(None, halo, "--tile off: the whole image at once")
    if tile is None:
        if BASELINE_BYTES + whole <= budget:
            return TilePlan(None, halo, f"whole: its working set {whole / 1e9:.2f} GB fits the "
                                        f"{budget / 1e9:.2f} GB budget")
        why = (f"auto: the whole image's working set {whole / 1e9:.2f} GB is over the "
               f"{budget / 1e9:.2f} GB budget")
    elif tile == "auto":
        why = f"auto: the tallest band within the {budget / 1e9:.2f} GB budget"
    else:
        rows = max(MIN_ROWS, min(int(tile), height))
        return TilePlan(rows, halo, f"given: {rows} rows per band")
    free = budget - BASELINE_BYTES
    per_row = (bytes_per_pixel + band_bytes_per_pixel) * width
    rows = int((free - bytes_per_pixel * width * 2 * halo) // max(per_row, 1.0))
    if rows < MIN_ROWS:
        need = BASELINE_BYTES + (bytes_per_pixel * (1 + 2 * halo) + band_bytes_per_pixel) * width
        raise InputError("memory", f"{budget / 1e9:.2f} GB cannot hold one band of this "
                                   f"{width}-pixel-wide image (needs {need / 1e9:.2f} GB); raise it")
    if rows >= height:
        return TilePlan(height, halo, f"{why}: {height} rows per band (one band)")
    # round down to a multiple of 16 (OpenEXR's ZIP block), where that leaves any
    if rows >= 32:
        rows -= rows % 16
    return TilePlan(rows, halo, f"{why}: {rows} rows per band")


# ------------------------------------------------------------------- sources
class RowSource(abc.ABC):
    """Rows of one image: ``shape`` ``(H, W, C)``, ``dtype``, ``path``,
    ``read(y0, y1)`` -> ``(y1 - y0, W, C)`` and ``whole`` (read in full)."""

    shape: tuple[int, int, int]
    dtype: np.dtype
    path: str
    whole: bool = False
    orientation: int = 1  # the EXIF Orientation applied when read (1: as stored)

    @abc.abstractmethod
    def read(self, y0: int, y1: int) -> np.ndarray:
        """Rows ``y0:y1`` as ``(y1 - y0, W, C)``; each reader says how."""

    def close(self) -> None:  # noqa: B027 - readers without a file have nothing to close
        """Release the file, if the reader holds one."""


class ArrayRows(RowSource):
    """Rows of an array in memory (``(H, W)`` or ``(H, W, C)``)."""

    def __init__(self, array: np.ndarray, path: str = "<array>", *, whole: bool = True):
        a = np.asarray(array)
        self.array = a[..., None] if a.ndim == 2 else a
        self.shape, self.dtype, self.path, self.whole = self.array.shape, self.array.dtype, \
            str(path), whole

    def read(self, y0, y1):
        return self.array[y0:y1]


class TiffRows(RowSource):
    """Rows of the first page of a TIFF, decoding only the strips or tiles
    they touch (tifffile's decoders: any compression it reads)."""

    def __init__(self, path):
        import tifffile

        from lumigraph.capture.io import check_pixel_count

        self.path = str(path)
        self._tf = tifffile.TiffFile(self.path)
        try:
            page = self._tf.pages.first
            if page.is_tiled and page.tiledepth > 1 or page.planarconfig != 1 and \
                    page.samplesperpixel > 1:
                raise InputError(self.path, "TIFF is volumetric or planar-separated; tiled "
                                            "reading takes contiguous 2-D pages (--tile off reads "
                                            "it whole)")
            h, w = page.imagelength, page.imagewidth
            check_pixel_count(self.path, w, h, what="TIFF header")
            self.shape = (h, w, page.samplesperpixel)
            self.dtype = np.dtype(page.dtype)
            self._page = page
            self._offsets, self._counts = page.dataoffsets, page.databytecounts
            if page.is_tiled:
                self._seg_h, self._seg_w = page.tilelength, page.tilewidth
            else:
                self._seg_h, self._seg_w = (page.rowsperstrip or h), w
            self._per_row = -(-w // self._seg_w)
            tag = page.tags.get(274)  # EXIF/TIFF Orientation
            self.orientation = int(tag.value) if tag is not None else 1
        except Exception:
            self._tf.close()
            raise

    def read(self, y0, y1):
        h, w, c = self.shape
        out = np.empty((y1 - y0, w, c), self.dtype)
        fh = self._tf.filehandle
        for sy in range(y0 // self._seg_h, -(-y1 // self._seg_h)):
            for sx in range(self._per_row):
                i = sy * self._per_row + sx
                if self._counts[i] == 0:  # a segment never written: zeros (TIFF's rule)
                    seg = np.zeros((self._seg_h, self._seg_w, c), self.dtype)
                    ty, tx = sy * self._seg_h, sx * self._seg_w
                else:
                    fh.seek(self._offsets[i])
                    data = fh.read(self._counts[i])
                    try:
                        seg, idx, _ = self._page.decode(data, i)
                    except Exception as e:  # a decoder's own failure, quoted
                        raise InputError(self.path, f"TIFF segment {i} does not decode: {e}") \
                            from None
                    seg = np.asarray(seg).reshape(seg.shape[-3], seg.shape[-2], -1)
                    ty, tx = idx[-3], idx[-2]
                a, b = max(y0, ty), min(y1, ty + seg.shape[0], h)
                bx = min(w, tx + seg.shape[1])
                out[a - y0:b - y0, tx:bx] = seg[a - ty:b - ty, :bx - tx]
        return out

    def close(self):
        self._tf.close()


class ExrRows(RowSource):
    """Rows of an OpenEXR file (every channel as float32, RGB(A) order like
    :func:`capture.io.read_exr`), read by scanline range."""

    def __init__(self, path):
        import OpenEXR

        from lumigraph.capture.io import check_pixel_count

        self.path = str(path)
        try:
            self._f = OpenEXR.InputFile(self.path)
            hd = self._f.header()
        except Exception as e:
            raise InputError(self.path, f"OpenEXR file does not open: {e}") from None
        dw = hd["dataWindow"]
        w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
        check_pixel_count(self.path, w, h, what="OpenEXR header")
        self._y_min = dw.min.y
        names = list(hd["channels"])
        order = [c for c in ("R", "G", "B", "A") if c in names]
        self._names = order if len(order) == len(names) else sorted(names)
        self.shape, self.dtype = (h, w, len(self._names)), np.dtype(np.float32)

    def read(self, y0, y1):
        import Imath

        h, w, c = self.shape
        ft = Imath.PixelType(Imath.PixelType.FLOAT)
        out = np.empty((y1 - y0, w, c), np.float32)
        try:
            for k, n in enumerate(self._names):
                buf = self._f.channel(n, ft, self._y_min + y0, self._y_min + y1 - 1)
                out[..., k] = np.frombuffer(buf, np.float32).reshape(y1 - y0, w)
        except Exception as e:
            raise InputError(self.path, f"OpenEXR rows {y0}..{y1 - 1} do not decode: {e}") from None
        if not np.isfinite(out).all():  # capture.io.read_image's rule, band by band
            raise InputError(self.path, "contains NaN or inf values; an image must be finite")
        return out

    def close(self):
        self._f.close()


TIFF_EXTS = (".tif", ".tiff")


def open_rows(path) -> RowSource:
    """A :class:`RowSource` for an image file: TIFF and OpenEXR by rows, any
    other format read whole (:func:`capture.io.read_image`; ``whole`` is set).
    A TIFF whose EXIF orientation turns it (not 1) is read whole too, so it
    comes as meant to be seen, like every reader's."""
    from lumigraph.capture.io import EXR_EXTS, read_image

    p = Path(path)
    ext = p.suffix.lower()
    if ext in EXR_EXTS:
        return ExrRows(p)
    if ext in TIFF_EXTS and is_tiff(p):
        src = TiffRows(p)
        if src.orientation == 1:
            return src
        src.close()
    src = ArrayRows(read_image(p), str(p), whole=True)
    from lumigraph.capture.io import image_orientation

    src.orientation = image_orientation(p)
    return src


def is_tiff(path) -> bool:
    """The file starts with a TIFF or BigTIFF signature."""
    try:
        with open(path, "rb") as fh:
            return fh.read(4) in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
    except OSError:
        return False


def rows_readable(path) -> bool:
    """``path`` can be read by rows (OpenEXR, or TIFF by its signature)."""
    from lumigraph.capture.io import EXR_EXTS

    ext = Path(path).suffix.lower()
    return ext in EXR_EXTS or (ext in TIFF_EXTS and is_tiff(path))


@dataclass(frozen=True)
class StackRows:
    """A stack read by rows (:func:`read_stack_rows`): what
    :class:`capture.io.Stack` holds, with :class:`RowSource` readers in place
    of the images, and the first pass's facts: per image the histogram of its
    codes (integer stacks), and the strided sample
    :func:`capture.exposure.check_brightness_order` looks at."""

    sources: tuple
    paths: tuple[str, ...]
    shape: tuple[int, int, int]
    dtype: np.dtype
    bit_depth: int | None
    bit_depth_source: str | None
    exposure_times_s: tuple[float, ...] | None
    info: dict
    times_given: bool
    histograms: tuple
    sample: np.ndarray | None
    shift: int = 0

    @property
    def effective_exposure_times_s(self):
        from lumigraph.capture.exposure import effective_exposure_times

        if self.exposure_times_s is None or self.times_given or "f_numbers" not in self.info:
            return self.exposure_times_s
        return effective_exposure_times(self.exposure_times_s, self.info["f_numbers"],
                                        f_number_ref=self.info.get("f_number_ref"))

    def read(self, y0: int, y1: int) -> np.ndarray:
        """Rows ``y0:y1`` of every image, ``(P, y1 - y0, W, C)``, codes shifted
        right where they were left-aligned (as :func:`capture.io.read_stack`)."""
        h, w, c = self.shape
        out = np.empty((len(self.sources), y1 - y0, w, c), self.dtype)
        for i, s in enumerate(self.sources):
            out[i] = s.read(y0, y1)
        if self.shift:
            out >>= self.shift
        return out

    def close(self) -> None:
        for s in self.sources:
            s.close()


def read_stack_rows(inputs, *, times=None, need_times: bool = False, bit_depth: int | None = None,
                    rows: int, sample_pixels: int = 65536) -> StackRows:
    """Open a stack for reading by rows, with :func:`capture.io.read_stack`'s
    rules: one size and dtype, the bit depth given, declared or detected
    (:func:`capture.exposure.decide_bit_depth`, on each image's largest code
    and the OR of its codes, which is all it looks at), the times given, from
    stack.json or EXIF. One pass over the rows (``rows`` at a time) gathers
    the histograms and the brightness-order sample.

    Raises
    ------
    InputError
        As :func:`capture.io.read_stack`.
    """
    from lumigraph.capture.exposure import decide_bit_depth
    from lumigraph.capture.io import _stack_files, _stack_times, png_significant_bits

    files, info, sj = _stack_files(inputs)
    sources: list[RowSource] = []
    try:
        significant = []
        for f in files:
            s = open_rows(f)
            if sources and (s.shape != sources[0].shape or s.dtype != sources[0].dtype):
                a, b = s.shape, sources[0].shape
                raise InputError(f, f"is {a[1]}x{a[0]}x{a[2]} {s.dtype}, but {files[0].name} is "
                                    f"{b[1]}x{b[0]}x{b[2]} {sources[0].dtype}; a stack needs one "
                                    "size and type")
            sources.append(s)
            sb = png_significant_bits(f) if f.suffix.lower() == ".png" else None
            significant.append(None if sb is None else (sb, "PNG sBIT"))
        h, w, c = sources[0].shape
        dt = np.dtype(sources[0].dtype)
        hists, sample = [], None
        if dt.kind in "ui":
            n_codes = 1 << (8 * dt.itemsize)
            step = max(1, int(np.ceil(np.sqrt(h * w / sample_pixels))))
            sample = np.empty((len(sources), -(-h // step), -(-w // step), c), dt)
            for i, s in enumerate(sources):
                hist = np.zeros(n_codes, np.int64)
                for b in bands(h, rows):
                    z = s.read(b.y0, b.y1)
                    hist += np.bincount(z.ravel(), minlength=n_codes)
                    first = b.y0 + (-b.y0) % step
                    sample[i, first // step:-(-b.y1 // step)] = z[first - b.y0::step, ::step]
                hists.append(hist)
            # decide_bit_depth looks at each image's largest code and at the OR of its
            # codes: the largest code and the OR's single bits have both (every bit of
            # the OR is at most the largest code's top bit)
            summary = []
            for hh in hists:
                present = np.flatnonzero(hh)
                top = int(present.max()) if present.size else 0
                ored = int(np.bitwise_or.reduce(present)) if present.size else 0
                summary.append(np.array([top] + [1 << k for k in range(8 * dt.itemsize)
                                                 if ored >> k & 1], dt))
            depth = decide_bit_depth(summary, files, given=bit_depth,
                                     declared=info.get("bit_depth"), declared_where=sj,
                                     significant=significant)
            bits, source, shift = depth.bits, depth.source, depth.shift
            if shift:
                sample >>= shift
                hists = [np.bincount(np.arange(n_codes) >> shift, weights=hh,
                                     minlength=n_codes >> shift).astype(np.int64) for hh in hists]
        else:
            bits, source, shift = None, "float data (linear, no code values)", 0
        t = _stack_times(files, info, sj, times=times, need_times=need_times)
    except BaseException:
        for s in sources:
            s.close()
        raise
    return StackRows(tuple(sources), tuple(str(f) for f in files), (h, w, c), dt, bits, source,
                     t, info, times is not None, tuple(hists), sample, shift)


# ------------------------------------------------------------------- writers
class ExrRowWriter:
    """Scanline OpenEXR, ZIP compression, float32 (or half) channels, written
    by rows in order: the same bytes :func:`capture.io.write_exr` writes for
    the whole image (the same header attributes, the same 16-line blocks)."""

    def __init__(self, path, width: int, height: int, channels: int, *, half: bool = False):
        import Imath
        import OpenEXR

        self.names = ["Y"] if channels == 1 else list("RGBA"[:channels]) if channels in (3, 4) \
            else [f"C{i}" for i in range(channels)]
        hd = OpenEXR.Header(width, height)
        hd["compression"] = Imath.Compression(Imath.Compression.ZIP_COMPRESSION)
        pt = Imath.PixelType(Imath.PixelType.HALF if half else Imath.PixelType.FLOAT)
        hd["channels"] = {n: Imath.Channel(pt) for n in self.names}
        hd["type"] = b"scanlineimage"  # the attribute OpenEXR.File writes
        self.dtype = np.float16 if half else np.float32
        self.rows_left = height
        self._f = OpenEXR.OutputFile(str(path), hd)

    def write(self, rows: np.ndarray) -> None:
        a = np.asarray(rows)
        a = a[..., None] if a.ndim == 2 else a
        self._f.writePixels({n: np.ascontiguousarray(a[..., i].astype(self.dtype)).tobytes()
                             for i, n in enumerate(self.names)}, a.shape[0])
        self.rows_left -= a.shape[0]

    def close(self) -> None:
        """Finish the file; one cut short (an error upstream) is closed
        without raising, its temporary discarded by the caller."""
        if self._f is not None:
            f, self._f = self._f, None
            try:
                f.close()
            except Exception:
                if self.rows_left == 0:
                    raise


class PngRowWriter:
    """PNG (grey, RGB or RGBA; 8 or 16 bits) through one zlib stream, rows in
    order: the same pixels :func:`capture.io.write_image` writes, in a file
    of any height without the image in memory."""

    def __init__(self, path, width: int, height: int, channels: int, dtype, *,
                 bit_depth: int | None = None):
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.uint8, np.uint16) or channels not in (1, 3, 4):
            raise ValueError(f"PNG rows: expected uint8/uint16 grey, RGB or RGBA, got "
                             f"{self.dtype} x {channels}")
        self._fh = open(path, "wb")
        colour = {1: 0, 3: 2, 4: 6}[channels]
        self._fh.write(b"\x89PNG\r\n\x1a\n")
        self._chunk(b"IHDR", np.array([width, height], ">u4").tobytes()
                    + bytes([8 * self.dtype.itemsize, colour, 0, 0, 0]))
        if bit_depth is not None and bit_depth != 8 * self.dtype.itemsize:
            self._chunk(b"sBIT", bytes([bit_depth] * channels))  # as write_image records it
        self._z = zlib.compressobj(6)
        self._pending = b""

    def _chunk(self, kind: bytes, data: bytes) -> None:
        self._fh.write(len(data).to_bytes(4, "big") + kind + data
                       + (zlib.crc32(kind + data) & 0xFFFFFFFF).to_bytes(4, "big"))

    def write(self, rows: np.ndarray) -> None:
        a = np.asarray(rows, self.dtype)
        a = a.reshape(a.shape[0], -1).astype(self.dtype.newbyteorder(">"), copy=False)
        raw = np.zeros((a.shape[0], 1 + a.shape[1] * self.dtype.itemsize), np.uint8)
        raw[:, 1:] = a.view(np.uint8).reshape(a.shape[0], -1)  # filter type 0 per row
        data = self._z.compress(raw.tobytes())
        if data:
            self._chunk(b"IDAT", data)

    def close(self) -> None:
        if not self._fh.closed:
            try:
                self._chunk(b"IDAT", self._z.flush())
                self._chunk(b"IEND", b"")
            finally:
                self._fh.close()


class TiffRowWriter:
    """A striped TIFF (uncompressed), one strip per :meth:`write`: grey or RGB
    of any dtype tifffile writes. Every band but the last must have
    the same height (``rows``), the strips' height."""

    def __init__(self, path, width: int, height: int, channels: int, dtype, rows: int):
        import threading

        import tifffile

        if channels not in (1, 3):
            raise ValueError(f"channels: TIFF rows are grey or RGB, got {channels}")
        self.shape = (height, width, channels) if channels > 1 else (height, width)
        self.rows_left = height
        self._q: list = []
        self._cv = threading.Condition()
        self._error: BaseException | None = None
        self._done = False

        def strips():
            while True:
                with self._cv:
                    self._cv.wait_for(lambda: self._q or self._done)
                    if not self._q:
                        return
                    item = self._q.pop(0)
                    self._cv.notify_all()
                yield item

        def run():
            try:
                tifffile.imwrite(str(path), strips(), shape=self.shape, dtype=np.dtype(dtype),
                                 rowsperstrip=rows,
                                 photometric="rgb" if channels == 3 else "minisblack")
            except BaseException as e:  # re-raised in the caller's thread
                self._error = e

        # tifffile pulls the strips from an iterator; a thread lets the caller push them
        self._t = threading.Thread(target=run, daemon=True)
        self._t.start()

    def write(self, rows: np.ndarray) -> None:
        a = np.asarray(rows)
        a = a[..., 0] if len(self.shape) == 2 and a.ndim == 3 else a
        with self._cv:
            self._cv.wait_for(lambda: len(self._q) < 1 or self._error is not None)
            self._q.append(np.ascontiguousarray(a))
            self.rows_left -= a.shape[0]
            self._cv.notify_all()
        if self._error is not None:
            raise self._error

    def close(self) -> None:
        with self._cv:
            self._done = True
            self._cv.notify_all()
        self._t.join()
        if self._error is not None:
            e, self._error = self._error, None
            if self.rows_left == 0:  # a file cut short (an error upstream) is discarded quietly
                raise e


def row_writer(path, width: int, height: int, channels: int, dtype, *, rows: int):
    """A writer by rows for ``path``'s extension (.exr float, .png/.tif 8/16-bit)."""
    ext = Path(path).suffix.lower()
    if ext == ".exr":
        return ExrRowWriter(path, width, height, channels)
    if ext == ".png":
        return PngRowWriter(path, width, height, channels, dtype)
    if ext in TIFF_EXTS:
        return TiffRowWriter(path, width, height, channels, dtype, rows)
    raise ValueError(f"path: no writer by rows for {ext!r}")


def finish_artifact(final, tmp, meta: dict) -> None:
    """Write the sidecar of an artifact written to ``tmp`` (inside
    :func:`capture.artifact.atomic_path` for ``final``), as
    :func:`capture.artifact.write_artifact` does: the output's hash in it,
    sidecar before the primary."""
    from lumigraph.capture.artifact import file_sha256, meta_path, write_json

    meta = dict(meta)
    meta["output"] = {"path": str(final), "sha256": file_sha256(tmp)}
    write_json(meta_path(final), meta)


def peak_rss_bytes() -> int:
    """This process's peak resident memory (``VmHWM``; ``ru_maxrss`` where
    /proc is missing), in bytes."""
    try:
        with open(f"/proc/{os.getpid()}/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def stack_geometry(inputs) -> tuple[int, int, int, int, int] | None:
    """``(P, H, W, C, itemsize)`` of a stack from its files' headers, or
    ``None`` when some file cannot be read by rows (:func:`rows_readable`)."""
    from lumigraph.capture.io import _stack_files

    files, _, _ = _stack_files(inputs)
    if not all(rows_readable(f) for f in files):
        return None
    s = open_rows(files[0])
    try:
        h, w, c = s.shape
        return len(files), h, w, c, np.dtype(s.dtype).itemsize
    finally:
        s.close()


def add_tile_options(parser, what: str, writes: str) -> None:
    """``--tile`` and ``--memory`` on a verb that can work by bands of rows
    (``what`` it reads, the formats it ``writes`` by rows)."""
    from lumigraph.capture.commandline import number

    parser.add_argument(
        "--tile", type=number(int, lo=MIN_ROWS, allow=("auto", "off")), default=None,
        metavar="ROWS|auto|off",
        help=f"work on {what} in bands of ROWS full-width rows (plus the rows the operator "
             "reads around them), read and written by rows, so memory is bounded by the band, "
             "not the image; the result is the same as whole. auto: the tallest band within "
             "--memory; off: whole. Default: whole when it fits --memory, else auto (the meta's "
             "'tiles' says which). Read by rows: TIFF and OpenEXR (other formats are read "
             f"whole); written by rows: {writes}")
    parser.add_argument(
        "--memory", type=parse_memory, default=None, metavar="SIZE",
        help=f"memory budget for --tile auto and the default, e.g. 1GB, 512MB, 2GiB (default "
             f"{DEFAULT_MEMORY // 1000 ** 3}GB)")
