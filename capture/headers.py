"""Image sizes read from file headers, before any pixel is decoded.

A decoder given a header that claims 60 000 × 60 000 pixels allocates the
image first and finds out that the data are missing afterwards; a 74-byte
file then costs gigabytes. The readers of :mod:`lumigraph.capture.io`,
:mod:`lumigraph.capture.rgbe` and :mod:`lumigraph.hdr.formats` therefore parse
the header here, check the size against the pixel limit
(:func:`lumigraph.capture.io.check_pixel_count`) and against what the file can
hold, and only then call the decoder.

Each parser returns an :class:`ImageHeader` or raises
:class:`~lumigraph.capture.errors.InputError` naming the file. Besides the
size, a header carries ``short``: the reason the file cannot hold that many
pixels, where the format gives a sound lower bound on the bytes it needs
(raw data: exactly; deflate: 1032 bytes out per byte in; a Huffman-coded JPEG:
at least one bit per 8×8 block), else ``None``. The caller checks the limit
first, so an over-limit file is reported as such, and ``short`` second.

Examples
--------
A PNG of 1 × 1 pixels that claims 60 000 × 60 000:

>>> import struct, zlib
>>> def chunk(kind, body):
...     crc = zlib.crc32(kind + body) & 0xFFFFFFFF
...     return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)
>>> png = (b"\\x89PNG\\r\\n\\x1a\\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 60000, 60000, 8, 0, 0, 0, 0))
...        + chunk(b"IDAT", zlib.compress(b"\\0\\0")) + chunk(b"IEND", b""))
>>> h = image_header(png, "bomb.png")
>>> h.kind, h.width, h.height
('PNG', 60000, 60000)
>>> h.short
'PNG image data (10 bytes) cannot hold 60000x60000 pixels: truncated or corrupt'
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

from lumigraph.capture.errors import InputError

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
EXR_MAGIC = b"\x76\x2f\x31\x01"
# deflate's best case: a 258-byte match in two one-bit codes
DEFLATE_MAX_RATIO = 1032


@dataclass(frozen=True)
class ImageHeader:
    """What a header claims.

    Attributes
    ----------
    kind : str
        ``"PNG"``, ``"JPEG"``, ``"TIFF"``, ``"BMP"``, ``"PNM"`` or ``"OpenEXR"``.
    width, height : int
        Pixels, as claimed (may be ≤ 0 in a corrupt file: the caller refuses it).
    short : str or None
        Why the file's data cannot hold ``width × height`` pixels, or ``None``.
    pages : tuple of (str, int, int)
        Every further size the decoder may allocate: ``(what, width, height)``
        of TIFF pages and tiles, OpenEXR parts and tiles.
    samples : int
        Values the decoded image holds (pixels × channels, all pages/parts),
        for formats with many channels (OpenEXR), else ``width × height``.
    """

    kind: str
    width: int
    height: int
    short: str | None = None
    pages: tuple = field(default=())
    samples: int = 0


def _need(kind: str, have: int, width: int, height: int, need_bytes: float,
          ratio: float | None) -> str | None:
    """The ``short`` reason when ``have`` bytes, expanded at most ``ratio``
    times, cannot make ``need_bytes``; ``ratio=None`` is an unbounded codec."""
    if ratio is None or width <= 0 or height <= 0:
        return None
    if need_bytes > ratio * max(have, 0) + ratio:  # + ratio: a few bytes of slack
        return (f"{kind} image data ({max(have, 0)} bytes) cannot hold {width}x{height} pixels: "
                "truncated or corrupt")
    return None


# ------------------------------------------------------------------------ sniff
def sniff(data: bytes) -> str | None:
    """The format of an image's bytes from its magic number, or ``None``.

    >>> sniff(b"\\xff\\xd8\\xff\\xe0"), sniff(b"II*\\x00"), sniff(b"hello")
    ('JPEG', 'TIFF', None)
    """
    if data.startswith(PNG_MAGIC):
        return "PNG"
    if data.startswith(b"\xff\xd8\xff"):
        return "JPEG"
    if data[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return "TIFF"
    if data.startswith(b"BM"):
        return "BMP"
    if len(data) >= 3 and data[0:1] == b"P" and data[1:2] in b"123456" and data[1:2] \
            and data[2:3] in b" \t\r\n#":
        return "PNM"
    if data.startswith(EXR_MAGIC):
        return "OpenEXR"
    return None


def image_header(data: bytes, where) -> ImageHeader:
    """Parse the header of a PNG, JPEG, TIFF, BMP or PNM image (by content).

    Raises
    ------
    InputError
        Unrecognised content, or a header too short or malformed to give a size.
    """
    kind = sniff(data)
    parsers = {"PNG": png_header, "JPEG": jpeg_header, "TIFF": tiff_header,
               "BMP": bmp_header, "PNM": pnm_header}
    if kind not in parsers:
        raise InputError(where, "not a PNG, JPEG, TIFF, BMP or PNM image (unrecognised content)")
    return parsers[kind](data, where)


# -------------------------------------------------------------------------- PNG
def png_header(data: bytes, where) -> ImageHeader:
    """PNG: the IHDR chunk, and the IDAT bytes against deflate's best ratio."""
    if not data.startswith(PNG_MAGIC) or len(data) < 33 or data[12:16] != b"IHDR":
        raise InputError(where, "not a PNG file, or truncated before its IHDR header")
    w, h, depth, colour = struct.unpack(">IIBB", data[16:26])
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}.get(colour, 1)
    idat, pos = 0, 8
    while pos + 8 <= len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        if data[pos + 4:pos + 8] == b"IDAT":
            idat += max(0, min(length, len(data) - pos - 8))
        pos += 12 + length
    need = w * h * channels * max(depth, 1) / 8  # filter bytes only add to it
    return ImageHeader("PNG", w, h, _need("PNG", idat, w, h, need, DEFLATE_MAX_RATIO))


# ------------------------------------------------------------------------- JPEG
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
_SOF_HUFFMAN = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7}


def jpeg_header(data: bytes, where) -> ImageHeader:
    """JPEG: the first SOFn frame header (markers walked from SOI).

    A Huffman-coded frame spends at least one bit per 8×8 block of each
    component (the DC difference, sequential or progressive), which bounds the
    pixels a file of its size can hold; arithmetic coding has no such bound.
    """
    if not data.startswith(b"\xff\xd8"):
        raise InputError(where, "not a JPEG file (no SOI marker)")
    n, pos = len(data), 2
    while True:
        # as libjpeg's next_marker: bytes other than a marker are skipped
        # (it warns of "extraneous bytes"), fill bytes 0xFF too, and FF 00 is
        # a stuffed zero, not a marker
        while True:
            while pos < n and data[pos] != 0xFF:
                pos += 1
            while pos < n and data[pos] == 0xFF:
                pos += 1
            if pos >= n:
                raise InputError(where, "JPEG is truncated before its frame header")
            marker = data[pos]
            pos += 1
            if marker != 0:
                break
        if marker == 0x01 or 0xD0 <= marker <= 0xD8:
            continue  # markers without a length
        if marker in (0xD9, 0xDA):
            raise InputError(where, "corrupt JPEG: no frame header (SOFn) before the image data")
        if pos + 2 > n:
            raise InputError(where, "JPEG is truncated before its frame header")
        (length,) = struct.unpack(">H", data[pos:pos + 2])
        if length < 2:
            raise InputError(where, f"corrupt JPEG: marker segment of length {length}")
        if marker in _SOF:
            seg = data[pos + 2:pos + length]
            if len(seg) < 6 or len(seg) < 6 + 3 * seg[5] or seg[5] == 0:
                raise InputError(where, "corrupt or truncated JPEG frame header")
            h, w = struct.unpack(">HH", seg[1:5])
            comps = [(seg[7 + 3 * i] >> 4, seg[7 + 3 * i] & 15) for i in range(seg[5])]
            hmax = max(c[0] for c in comps) or 1
            vmax = max(c[1] for c in comps) or 1
            # floor divisions: a lower bound on the blocks libjpeg decodes
            blocks = sum((w * hc // hmax // 8) * (h * vc // vmax // 8) for hc, vc in comps)
            have = n - (pos + length)
            ratio = 8.0 if marker in _SOF_HUFFMAN else None  # blocks per byte at one bit each
            return ImageHeader("JPEG", w, h, _need("JPEG", have, w, h, blocks, ratio))
        pos += length


# ------------------------------------------------------------------------- TIFF
_TIFF_INT = {1: "B", 3: "H", 4: "I", 6: "b", 8: "h", 9: "i", 13: "I", 16: "Q", 17: "q", 18: "Q"}
_TIFF_SIZE = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 10: 8, 11: 4, 12: 8,
              13: 4, 16: 8, 17: 8, 18: 8}
# tags whose values a reader needs; others are skipped unread
TIFF_TAGS = {256, 257, 258, 259, 262, 273, 277, 278, 279, 284, 322, 323, 324, 325, 339}
TIFF_STRIP_TAGS = {273, 279, 324, 325}  # StripOffsets/ByteCounts, TileOffsets/ByteCounts
MAX_TIFF_PAGES = 4096
# best expansion per compressed byte: none, PackBits, LZW (≤ 4096-byte strings per
# 12-bit code), deflate; other codecs (JPEG, CCITT, LZMA, ZSTD, …) have no bound used here
TIFF_MAX_RATIO = {1: 1, 32773: 64, 5: 2731, 8: DEFLATE_MAX_RATIO, 32946: DEFLATE_MAX_RATIO}


def tiff_pages(data: bytes, where, *, tags=TIFF_TAGS) -> list[dict[int, list[int]]]:
    """The integer tags of every page (IFD) of a classic or Big TIFF.

    Only ``tags`` are read: strip and tile offsets and byte counts as int64
    arrays, the others as lists of (at most 64) ints. A value whose bytes lie
    outside the file, or a broken IFD chain after the first page, ends the
    walk there (the first page must be whole).

    >>> import struct
    >>> ifd = struct.pack("<H", 2) + struct.pack("<HHII", 256, 4, 1, 640)
    >>> ifd += struct.pack("<HHIHH", 257, 3, 1, 480, 0) + struct.pack("<I", 0)
    >>> tiff_pages(b"II*\\x00" + struct.pack("<I", 8) + ifd, "a.tif")
    [{256: [640], 257: [480]}]
    """
    if data[:2] not in (b"II", b"MM") or len(data) < 8:
        raise InputError(where, "not a TIFF file")
    e = "<" if data[:2] == b"II" else ">"
    (version,) = struct.unpack(e + "H", data[2:4])
    if version == 42:
        off_fmt, cnt_fmt, entry, head = "I", "H", 12, 8
        (off,) = struct.unpack(e + "I", data[4:8])
    elif version == 43 and len(data) >= 16:
        off_fmt, cnt_fmt, entry, head = "Q", "Q", 20, 16
        (off,) = struct.unpack(e + "Q", data[8:16])
    else:
        raise InputError(where, "not a TIFF file (bad version number)")
    off_size, cnt_size = struct.calcsize(off_fmt), struct.calcsize(cnt_fmt)
    pages, seen = [], set()
    while off and len(pages) < MAX_TIFF_PAGES:
        first = not pages
        if off in seen or off < head or off + cnt_size > len(data):
            if first:
                raise InputError(where, "corrupt or truncated TIFF: first IFD lies outside the file")
            break
        seen.add(off)
        (n,) = struct.unpack(e + cnt_fmt, data[off:off + cnt_size])
        end = off + cnt_size + n * entry
        if end > len(data):
            if first:
                raise InputError(where, "truncated TIFF: the first IFD runs past the end of the file")
            break
        page, ok = {}, True
        for k in range(n):
            at = off + cnt_size + k * entry
            tag, typ = struct.unpack(e + "HH", data[at:at + 4])
            (cnt,) = struct.unpack(e + off_fmt, data[at + 4:at + 4 + off_size])
            if tag not in tags or typ not in _TIFF_INT:
                continue
            size = _TIFF_SIZE[typ] * cnt
            vo = at + 4 + off_size
            if size > off_size:
                (vo,) = struct.unpack(e + off_fmt, data[vo:vo + off_size])
            if cnt == 0 or vo + size > len(data):
                ok = False
                if first:
                    raise InputError(where, f"corrupt or truncated TIFF: tag {tag} has {cnt} values "
                                            "outside the file")
                break
            if tag in TIFF_STRIP_TAGS:  # one value per strip: an array, never a long list
                vals = np.frombuffer(data, np.dtype(e + _TIFF_INT[typ]), cnt, vo)
                page[tag] = np.clip(vals.astype(np.float64), 0, 2.0 ** 62).astype(np.int64)
            else:  # a few values matter (BitsPerSample: one per sample)
                k = min(cnt, 64)
                page[tag] = list(struct.unpack(f"{e}{k}{_TIFF_INT[typ]}",
                                               data[vo:vo + k * _TIFF_SIZE[typ]]))
        if not ok:
            break
        pages.append(page)
        if end + off_size > len(data):
            break  # no next-IFD offset: libtiff reads the pages before it
        (off,) = struct.unpack(e + off_fmt, data[end:end + off_size])
    if not pages:
        raise InputError(where, "TIFF has no image (its first IFD offset is 0)")
    return pages


def tiff_data_bytes(data: bytes, page: dict) -> int | None:
    """Bytes of a page's strips or tiles that lie inside the file, or ``None``
    when the byte counts are missing or do not match the offsets (libtiff
    then estimates them)."""
    offsets = page.get(324, page.get(273))
    counts = page.get(325, page.get(279))
    if offsets is None or counts is None or len(offsets) != len(counts):
        return None
    return int(np.clip(np.minimum(counts, len(data) - offsets), 0, None).sum())


def tiff_strips(page: dict, where) -> tuple[np.ndarray, np.ndarray]:
    """A page's strip (or tile) offsets and byte counts, as int64 arrays."""
    offsets = page.get(324, page.get(273, np.zeros(0, np.int64)))
    counts = page.get(325, page.get(279, np.zeros(0, np.int64)))
    if len(offsets) != len(counts):
        raise InputError(where, f"corrupt TIFF: {len(offsets)} strip/tile offsets but "
                                f"{len(counts)} byte counts")
    return offsets, counts


def tiff_header(data: bytes, where) -> ImageHeader:
    """TIFF: the first page's size (the one a decoder reads), every page's and
    tile's size in ``pages``, and the first page's strip or tile bytes against
    its codec's best ratio (a tiled page needs whole tiles)."""
    pages = tiff_pages(data, where)
    if 256 not in pages[0] or 257 not in pages[0]:
        raise InputError(where, "corrupt TIFF: no ImageWidth/ImageLength tag")
    sizes = []
    for i, pg in enumerate(pages):
        if 256 in pg and 257 in pg:
            sizes.append((f"TIFF page {i + 1}", pg[256][0], pg[257][0]))
        if 322 in pg and 323 in pg:
            sizes.append((f"TIFF page {i + 1}'s tile", pg[322][0], pg[323][0]))
    first = pages[0]
    w, h = first[256][0], first[257][0]
    spp = max(first.get(277, [1])[0], 1)
    bps = first.get(258, [1])
    bits = sum(bps[:spp]) if len(bps) >= spp else bps[0] * spp
    pixels = w * h
    if 322 in first and 323 in first and first[322][0] > 0 and first[323][0] > 0:
        tw, th = first[322][0], first[323][0]
        pixels = max(pixels, -(-w // tw) * -(-h // th) * tw * th)
    comp = first.get(259, [1])[0]
    have = tiff_data_bytes(data, first)
    short = None if have is None else _need("TIFF", have, w, h, pixels * bits / 8,
                                            TIFF_MAX_RATIO.get(comp))
    return ImageHeader("TIFF", w, h, short, tuple(sizes))


# -------------------------------------------------------------------------- BMP
def bmp_header(data: bytes, where) -> ImageHeader:
    """BMP: the DIB header; uncompressed rows against the file's length."""
    if not data.startswith(b"BM") or len(data) < 26:
        raise InputError(where, "not a BMP file, or truncated before its header")
    (pixel_off,) = struct.unpack("<I", data[10:14])
    (dib,) = struct.unpack("<I", data[14:18])
    if dib == 12:
        w, h, _, bpp = struct.unpack("<HHHH", data[18:26])
        comp = 0
    elif dib >= 40 and len(data) >= 34:
        w, h, _, bpp, comp = struct.unpack("<iiHHI", data[18:34])
        h = abs(h)  # negative: rows stored top-down
    else:
        raise InputError(where, f"corrupt BMP: unknown DIB header size {dib}")
    need = h * ((w * bpp + 31) // 32 * 4) if w > 0 else 0
    short = None
    if comp in (0, 3, 6):  # uncompressed rows (RLE can skip whole rows: no bound)
        short = _need("BMP", len(data) - pixel_off, w, h, need, 1)
    return ImageHeader("BMP", w, h, short)


# -------------------------------------------------------------------------- PNM
def pnm_header(data: bytes, where) -> ImageHeader:
    """Netpbm P1–P6: magic, width, height and (not for bitmaps) maxval, each
    token separated by whitespace, ``#`` comments to the end of a line."""
    kind = data[1:2]
    tokens, pos = [], 2
    want = 2 if kind in (b"1", b"4") else 3
    while len(tokens) < want:
        while pos < len(data) and (data[pos:pos + 1].isspace() or data[pos:pos + 1] == b"#"):
            if data[pos:pos + 1] == b"#":
                nl = data.find(b"\n", pos)
                pos = len(data) if nl < 0 else nl
            pos += 1
        start = pos
        while pos < len(data) and data[pos:pos + 1].isdigit() and pos - start < 20:
            pos += 1
        if pos == start:
            raise InputError(where, "malformed PNM header (expected width, height and maxval)")
        tokens.append(int(data[start:pos]))
    pos += 1  # the single whitespace byte before raster data
    w, h = tokens[0], tokens[1]
    maxval = tokens[2] if want == 3 else 1
    channels = 3 if kind in (b"3", b"6") else 1
    if kind == b"4":
        need = (w + 7) // 8 * h
    elif kind in (b"5", b"6"):
        need = w * h * channels * (2 if maxval > 255 else 1)
    else:  # ASCII: at least one character per sample
        need = w * h * channels
    return ImageHeader("PNM", w, h, _need("PNM", len(data) - pos, w, h, need, 1))


# ---------------------------------------------------------------------- OpenEXR
# scanlines per chunk and best expansion ratio of each compression
# (NO, RLE, ZIPS, ZIP, PIZ, PXR24, B44, B44A, DWAA, DWAB, HTJ2K256, HTJ2K32, …);
# a codec not listed (or None) has no ratio bound here, and is taken to hold
# 256 lines per chunk (the most of any: the fewest chunks)
_EXR_LINES = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256, 10: 256, 11: 32}
_EXR_RATIO = {0: 1, 1: 64, 2: DEFLATE_MAX_RATIO, 3: DEFLATE_MAX_RATIO,
              5: DEFLATE_MAX_RATIO * 4 / 3, 6: 3, 7: 11}
_EXR_BYTES = {0: 4, 1: 2, 2: 4}  # UINT, HALF, FLOAT


def _cstring(data: bytes, pos: int, where) -> tuple[bytes, int]:
    end = data.find(b"\0", pos, pos + 256)
    if end < 0:
        raise InputError(where, "corrupt or truncated OpenEXR header (unterminated name)")
    return data[pos:end], end + 1


def _exr_attributes(data: bytes, pos: int, where) -> tuple[dict, int]:
    attrs = {}
    while True:
        name, pos = _cstring(data, pos, where)
        if not name:
            return attrs, pos
        typ, pos = _cstring(data, pos, where)
        if pos + 4 > len(data):
            raise InputError(where, "truncated OpenEXR header")
        (size,) = struct.unpack("<i", data[pos:pos + 4])
        pos += 4
        if size < 0 or pos + size > len(data):
            raise InputError(where, f"corrupt or truncated OpenEXR header: attribute "
                                    f"{name.decode('latin-1')!r} of {size} bytes")
        attrs[name] = (typ, data[pos:pos + size])
        pos += size


def _exr_channels(value: bytes, where) -> list[tuple[int, int, int]]:
    out, pos = [], 0
    while pos < len(value) and value[pos] != 0:
        _, pos = _cstring(value, pos, where)
        if pos + 16 > len(value):
            raise InputError(where, "corrupt OpenEXR channel list")
        pixel_type, _, xs, ys = struct.unpack("<iB3xii", value[pos:pos + 16])
        if pixel_type not in _EXR_BYTES or xs < 1 or ys < 1:
            raise InputError(where, f"corrupt OpenEXR channel list (type {pixel_type}, "
                                    f"sampling {xs}x{ys})")
        out.append((pixel_type, xs, ys))
        pos += 16
    return out


def exr_header(data: bytes, where, *, file_size: int | None = None) -> ImageHeader:
    """OpenEXR: every part's dataWindow, channels, tiles and compression.

    ``width``/``height`` are the first part's; ``pages`` holds every part and
    tile size; ``samples`` counts the values of all parts. ``data`` may be the
    file's head only, with ``file_size`` its length. ``short`` compares
    the chunk offset tables (8 bytes per chunk of the first level) and, for
    codecs with a bounded ratio, the pixel bytes with the file's length.

    >>> import struct
    >>> def attr(name, typ, value):
    ...     return name + b"\\0" + typ + b"\\0" + struct.pack("<i", len(value)) + value
    >>> head = EXR_MAGIC + struct.pack("<i", 2)
    >>> head += attr(b"channels", b"chlist", b"Y\\0" + struct.pack("<iB3xii", 2, 0, 1, 1) + b"\\0")
    >>> head += attr(b"compression", b"compression", b"\\0")
    >>> head += attr(b"dataWindow", b"box2i", struct.pack("<4i", 0, 0, 59999, 59999)) + b"\\0"
    >>> h = exr_header(head, "bomb.exr")
    >>> h.width, h.height, h.short is not None
    (60000, 60000, True)
    """
    if not data.startswith(EXR_MAGIC) or len(data) < 8:
        raise InputError(where, "not an OpenEXR file")
    (version,) = struct.unpack("<i", data[4:8])
    if version & 0xFF != 2:
        raise InputError(where, f"unsupported OpenEXR version {version & 0xFF}")
    if version & 0x800:
        raise InputError(where, "deep OpenEXR images are not supported")
    multipart = bool(version & 0x1000)
    pos, parts = 8, []
    while True:
        attrs, pos = _exr_attributes(data, pos, where)
        parts.append(attrs)
        if not multipart or pos >= len(data) or data[pos] == 0:
            pos += 1 if multipart else 0
            break
    sizes, samples, need, have_ratio, chunks = [], 0, 0.0, 1.0, 0
    for i, attrs in enumerate(parts):
        what = "OpenEXR" if len(parts) == 1 else f"OpenEXR part {i + 1}"
        if b"dataWindow" not in attrs or len(attrs[b"dataWindow"][1]) != 16:
            raise InputError(where, f"corrupt {what} header: no dataWindow")
        if b"channels" not in attrs:
            raise InputError(where, f"corrupt {what} header: no channel list")
        typ = attrs.get(b"type", (b"", b""))[1].rstrip(b"\0")
        if typ.startswith(b"deep"):
            raise InputError(where, "deep OpenEXR images are not supported")
        x0, y0, x1, y1 = struct.unpack("<4i", attrs[b"dataWindow"][1])
        w, h = x1 - x0 + 1, y1 - y0 + 1
        sizes.append((what, w, h))
        channels = _exr_channels(attrs[b"channels"][1], where)
        comp = attrs.get(b"compression", (b"", b"\0"))[1][:1]
        comp = comp[0] if comp else 0
        ratio = _EXR_RATIO.get(comp)
        have_ratio = None if ratio is None or have_ratio is None else max(have_ratio, ratio)
        if w > 0 and h > 0:
            samples += sum(-(-w // xs) * -(-h // ys) for _, xs, ys in channels)
            # (edge tiles are stored clipped to the data window: the image's bytes)
            need += sum(-(-w // xs) * -(-h // ys) * _EXR_BYTES[t] for t, xs, ys in channels)
            tiles = attrs.get(b"tiles", (b"", b""))[1]
            if len(tiles) >= 8 and (typ in (b"", b"tiledimage") or typ.startswith(b"tiled")):
                tw, th = struct.unpack("<II", tiles[:8])
                sizes.append((f"{what} tile", tw, th))
                if tw > 0 and th > 0:
                    chunks += -(-w // tw) * -(-h // th)
            else:
                chunks += -(-h // _EXR_LINES.get(comp, 256))
    w, h = sizes[0][1], sizes[0][2]
    size = len(data) if file_size is None else file_size
    have = size - pos
    short = None
    if chunks * 8 > have:
        short = (f"OpenEXR file ({size} bytes) is too short for the offset table of "
                 f"{chunks} chunks its header claims: truncated or corrupt")
    else:
        short = _need("OpenEXR", have, w, h, need, have_ratio)
    return ImageHeader("OpenEXR", w, h, short, tuple(sizes[1:]), samples)
