"""Decompression bombs and the pixel limit: every reader refuses a header that
claims more pixels than the limit (``LUMIGRAPH_MAX_PIXELS``, default 2²⁸), or
more than its file can hold, before it allocates anything: each refusal is an
InputError naming the file, within a second, with a traced peak far below
what the claimed image would need. Writers refuse NaN/inf where their format
cannot hold them."""

from __future__ import annotations

import re
import struct
import time
import tracemalloc
import zlib

import numpy as np
import pytest
from conftest import assert_clean_error

from lumigraph.capture import io
from lumigraph.capture.errors import InputError
from lumigraph.hdr import formats

BIG = 60000  # 60000² = 3.6e9 pixels: over the default limit of 2**28
MB = 1 << 20


@pytest.fixture(autouse=True)
def _default_limit(monkeypatch):
    monkeypatch.delenv("LUMIGRAPH_MAX_PIXELS", raising=False)
    # the decoders' own imports happen here, not inside a measured call
    import cv2  # noqa: F401
    import OpenEXR  # noqa: F401
    from PIL import Image  # noqa: F401


def refused_quickly(read, path, *fragments) -> InputError:
    """``read(path)`` raises InputError naming ``path`` (and ``fragments``)
    within 1 s, having traced less than 50 MB at its peak."""
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(InputError) as err:
            read(path)
    finally:
        seconds = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert str(path) in str(err.value)
    for f in fragments:
        assert f in str(err.value), (f, str(err.value))
    assert seconds < 1.0, seconds
    assert peak < 50 * MB, peak / MB
    return err.value


# ----------------------------------------------------------------- bomb makers
def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def png_bomb(w=BIG, h=BIG) -> bytes:
    """A valid-looking PNG (correct CRCs) of a few dozen bytes claiming w×h."""
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr)
            + _chunk(b"IDAT", zlib.compress(b"\0" * 64)) + _chunk(b"IEND", b""))


def _patch_jpeg_size(data: bytes, w: int, h: int) -> bytes:
    at = data.index(b"\xff\xc0")
    return data[:at + 5] + struct.pack(">HH", h, w) + data[at + 9:]


def jpeg_bomb(tmp_path, w=BIG, h=BIG) -> bytes:
    from PIL import Image

    p = tmp_path / "seed.jpg"
    Image.fromarray(np.full((8, 8, 3), 128, np.uint8)).save(p)
    return _patch_jpeg_size(p.read_bytes(), w, h)


def _patch_tiff_size(data: bytes, w: int, h: int) -> bytes:
    """Set ImageWidth/ImageLength of a little-endian TIFF's first IFD."""
    out = bytearray(data)
    (off,) = struct.unpack("<I", data[4:8])
    (n,) = struct.unpack("<H", data[off:off + 2])
    for k in range(n):
        at = off + 2 + 12 * k
        tag, typ = struct.unpack("<HH", data[at:at + 4])
        if tag in (256, 257):
            value = w if tag == 256 else h
            out[at + 2:at + 12] = struct.pack("<HII", 4, 1, value)  # as LONG
    return bytes(out)


def _patch_exr_window(data: bytes, w: int, h: int) -> bytes:
    at = data.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    return data[:at] + struct.pack("<4i", 0, 0, w - 1, h - 1) + data[at + 16:]


# ------------------------------------------------------------------ the bombs
def test_png_bomb_of_a_few_dozen_bytes_is_refused_before_decoding(tmp_path):
    p = tmp_path / "bomb.png"
    p.write_bytes(png_bomb())
    assert len(p.read_bytes()) < 100
    refused_quickly(io.read_image, p, "60000x60000 = 3600000000 pixels", "LUMIGRAPH_MAX_PIXELS",
                    "--max-pixels")


def test_png_under_the_limit_but_with_no_data_for_it_is_refused(tmp_path):
    p = tmp_path / "short.png"
    p.write_bytes(png_bomb(16000, 16000))  # 256 MP: under the limit; 25 bytes cannot inflate to it
    refused_quickly(io.read_image, p, "cannot hold 16000x16000")


def test_jpeg_bomb_is_refused_and_its_exif_still_reads(tmp_path):
    p = tmp_path / "bomb.jpg"
    p.write_bytes(jpeg_bomb(tmp_path))
    refused_quickly(io.read_image, p, "JPEG header claims 60000x60000")
    # 20000×10000 = 200 MP: past Pillow's own bomb error (2 × 89 MP), under ours;
    # reading EXIF decodes no pixel, so Pillow's limit must not refuse it
    q = tmp_path / "large.jpg"
    q.write_bytes(jpeg_bomb(tmp_path, 20000, 10000))
    assert io.read_exif(q).exposure_time_s is None
    refused_quickly(io.read_image, q, "cannot hold 20000x10000")


@pytest.mark.parametrize("kind", ["tiff", "logluv"])
def test_tiff_bombs_are_refused(tmp_path, kind):
    p = tmp_path / "bomb.tif"
    if kind == "tiff":
        io.write_image(p, np.zeros((6, 9, 3), np.uint8))
        read = io.read_image
    else:
        formats.write_logluv_tiff(p, np.ones((6, 9, 3), np.float32))
        read = formats.read_logluv_tiff
    seed = p.read_bytes()
    p.write_bytes(_patch_tiff_size(seed, BIG, BIG))
    refused_quickly(read, p, "60000x60000")
    p.write_bytes(_patch_tiff_size(seed, 10000, 10000))  # under the limit, no data for it
    refused_quickly(read, p, "10000x10000")


def test_exr_bomb_is_refused_before_openexr_reads_it(tmp_path):
    p = tmp_path / "bomb.exr"
    io.write_exr(p, np.ones((6, 9, 3), np.float32))
    seed = p.read_bytes()
    p.write_bytes(_patch_exr_window(seed, BIG, BIG))
    refused_quickly(io.read_exr, p, "OpenEXR header claims 60000x60000")
    refused_quickly(io.read_image, p, "over the limit")
    p.write_bytes(_patch_exr_window(seed, 10000, 10000))
    refused_quickly(io.read_exr, p, "truncated or corrupt")


@pytest.mark.parametrize("name, data, fragment", [
    ("bomb.pfm", b"PF\n60000 60000\n-1.0\n", "PFM header claims 60000x60000"),
    ("short.pfm", b"PF\n10000 10000\n-1.0\n" + bytes(64), "truncated: 64 of 1200000000"),
    ("negative.pfm", b"Pf\n-3 4\n-1.0\n" + bytes(64), "must be positive"),
    ("nan-scale.pfm", b"Pf\n3 4\nnan\n" + bytes(64), "scale nan"),
    ("bomb.flo", struct.pack("<fii", io.FLO_MAGIC, BIG, BIG), ".flo header claims 60000x60000"),
    ("short.flo", struct.pack("<fii", io.FLO_MAGIC, 10000, 10000) + bytes(8), "truncated"),
    ("bomb.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n"
                 b"property double x\nproperty double y\nproperty double z\nend_header\n",
     "4000000000 vertices, over the limit"),
    ("short.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000\n"
                  b"property double x\nproperty double y\nproperty double z\nend_header\n"
                  + bytes(48), "truncated"),
    ("bomb.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1000000000 +X 1000000000\n",
     "RGBE header claims 1000000000x1000000000"),
    ("short.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 10000 +X 10000\n" + bytes(64),
     "cannot hold 10000x10000"),
    ("bomb.pgm", b"P5\n60000 60000\n255\n" + bytes(64), "PNM header claims 60000x60000"),
    ("bomb.bmp", b"BM" + struct.pack("<IHHIIiiHHI", 0, 0, 0, 54, 40, BIG, -BIG, 1, 24, 0)
     + bytes(64), "BMP header claims 60000x60000"),
])
def test_header_bombs_of_every_format_are_refused(tmp_path, name, data, fragment):
    p = tmp_path / name
    p.write_bytes(data)
    read = {".pfm": io.read_pfm, ".flo": io.read_flo, ".ply": io.read_ply}.get(p.suffix,
                                                                              io.read_image)
    refused_quickly(read, p, fragment)


def test_raw_sizes_are_checked_before_unpacking(tmp_path, monkeypatch):
    import importlib.util
    from pathlib import Path

    pytest.importorskip("tifffile")
    spec = importlib.util.spec_from_file_location("raw_dng", Path(__file__).with_name("test_raw.py"))
    raw_dng = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(raw_dng)  # its minimal DNG writer
    p = tmp_path / "a.dng"
    raw_dng._write_dng(p, raw_dng._bayer(1000, 1500, 800))  # 32×48 sensor
    monkeypatch.setenv("LUMIGRAPH_MAX_PIXELS", "1000")
    refused_quickly(io.read_raw, p, "RAW sensor claims 48x32 = 1536 pixels, over the limit of 1000")


def _tiff_entry(data: bytes, tag: int) -> int:
    """Offset of a tag's 12-byte entry in a little-endian TIFF's first IFD."""
    (off,) = struct.unpack("<I", data[4:8])
    (n,) = struct.unpack("<H", data[off:off + 2])
    for k in range(n):
        at = off + 2 + 12 * k
        if struct.unpack("<H", data[at:at + 2])[0] == tag:
            return at
    raise KeyError(tag)


def test_logluv_tag_count_bomb_is_refused_quickly(tmp_path):
    # the slow mutant: a count of 2**28 values built a format string of
    # 2**28 characters before failing (25 s, 8 GB)
    p = tmp_path / "count.tif"
    formats.write_logluv_tiff(p, np.ones((6, 9, 3), np.float32))
    data = bytearray(p.read_bytes())
    at = _tiff_entry(bytes(data), 258)  # BitsPerSample: 3 SHORTs
    data[at + 4:at + 8] = struct.pack("<I", 1 << 28)
    p.write_bytes(bytes(data))
    refused_quickly(formats.read_logluv_tiff, p, "tag 258")
    refused_quickly(io.read_image, p, "tag 258")


def _malformed(tmp_path, kind):
    """Files from the fuzz's first findings, each once an internal fault."""
    f = np.ones((6, 9, 3), np.float32)
    if kind == "rgbe-literal-past-end":  # numpy broadcast error
        p = tmp_path / "a.hdr"
        formats.write_rgbe(p, np.random.default_rng(0).uniform(0.1, 2, (6, 18, 3)))
        data = p.read_bytes()
        p.write_bytes(data[:data.index(b"+X 18\n") + 14])  # a literal of 18, 3 bytes left
    elif kind in ("logluv-strip-counts", "logluv-no-width"):  # zip() error, KeyError
        p = tmp_path / "l.tif"
        formats.write_logluv_tiff(p, f, bits=24)
        data = bytearray(p.read_bytes())
        tag = 279 if kind == "logluv-strip-counts" else 256
        at = _tiff_entry(bytes(data), tag)
        data[at:at + 2] = struct.pack("<H", 330 if tag == 256 else 279)
        if tag == 279:
            data[at + 4:at + 8] = struct.pack("<I", 2)  # two counts for one strip
        p.write_bytes(bytes(data))
    elif kind == "ply-no-properties":  # numpy: cannot determine count if itemsize is 0
        p = tmp_path / "a.ply"
        p.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nend_header\n")
    elif kind == "ply-no-z":  # ValueError: no field of name z
        p = tmp_path / "b.ply"
        p.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
                      b"property float y\nend_header\n" + bytes(8))
    elif kind == "exr-negative-attribute":
        p = tmp_path / "a.exr"
        io.write_exr(p, f)
        data = bytearray(p.read_bytes())
        at = data.index(b"compression\0compression\0") + len(b"compression\0compression\0")
        data[at:at + 4] = struct.pack("<i", -5)
        p.write_bytes(bytes(data))
    return p


@pytest.mark.parametrize("kind", ["rgbe-literal-past-end", "logluv-strip-counts",
                                  "logluv-no-width", "ply-no-properties", "ply-no-z",
                                  "exr-negative-attribute"])
def test_malformed_files_are_input_errors(tmp_path, kind):
    p = _malformed(tmp_path, kind)
    read = {".hdr": formats.read_rgbe, ".tif": formats.read_logluv_tiff, ".ply": io.read_ply,
            ".exr": io.read_exr}[p.suffix]
    refused_quickly(read, p)


# ------------------------------------------------------------------- the limit
def test_the_limit_can_be_raised_and_lowered_by_the_environment(tmp_path, monkeypatch):
    bomb = tmp_path / "bomb.png"
    bomb.write_bytes(png_bomb())
    monkeypatch.setenv("LUMIGRAPH_MAX_PIXELS", str(2 ** 32))
    assert io.max_pixels() == 2 ** 32
    # past the limit now, the same file is still refused before decoding: its
    # 25 bytes of deflate data cannot hold 3.6e9 pixels
    refused_quickly(io.read_image, bomb, "cannot hold 60000x60000")
    small = tmp_path / "small.png"
    io.write_image(small, np.zeros((6, 9), np.uint8))
    monkeypatch.setenv("LUMIGRAPH_MAX_PIXELS", "53")
    refused_quickly(io.read_image, small, "9x6 = 54 pixels, over the limit of 53")
    monkeypatch.setenv("LUMIGRAPH_MAX_PIXELS", "54")
    assert io.read_image(small).shape == (6, 9)
    monkeypatch.setenv("LUMIGRAPH_MAX_PIXELS", "1e3")
    assert io.max_pixels() == 1000


@pytest.mark.parametrize("value", ["lots", "0", "-5", "1.5", "nan", "inf"])
def test_a_bad_limit_names_the_variable(monkeypatch, value):
    monkeypatch.setenv("LUMIGRAPH_MAX_PIXELS", value)
    with pytest.raises(InputError) as err:
        io.max_pixels()
    assert err.value.where == "LUMIGRAPH_MAX_PIXELS" and repr(value) in err.value.problem


def test_check_pixel_count_refuses_empty_and_negative_sizes():
    assert io.check_pixel_count("a.png", 16384, 16384) == io.DEFAULT_MAX_PIXELS == 2 ** 28
    for w, h in [(0, 5), (5, 0), (-1, -1)]:
        with pytest.raises(InputError, match="must be positive"):
            io.check_pixel_count("a.png", w, h)
    with pytest.raises(InputError, match=r"TIFF page 2 claims 16385x16384"):
        io.check_pixel_count("a.tif", 16385, 16384, what="TIFF page 2")


# ------------------------------------------------------- decoders' own failures
def test_a_corrupt_png_is_one_error_quoting_libpng_and_nothing_printed(tmp_path, capfd):
    p = tmp_path / "crc.png"
    io.write_image(p, np.arange(54, dtype=np.uint8).reshape(6, 9))
    data = bytearray(p.read_bytes())
    data[data.index(b"IDAT") + 6] ^= 0xFF  # damage the compressed data, not the CRC
    p.write_bytes(bytes(data))
    err = refused_quickly(io.read_image, p, "cannot decode PNG")
    assert "libpng" in err.problem or "CRC" in err.problem
    out, errs = capfd.readouterr()
    assert out == "" and errs == ""


def test_a_corrupt_exr_is_refused_not_read_as_zeros(tmp_path, capfd):
    p = tmp_path / "cut.exr"
    io.write_exr(p, np.ones((64, 80, 3), np.float32))
    data = bytearray(p.read_bytes())
    data[-40:] = bytes(40)  # the last chunk's compressed data
    p.write_bytes(bytes(data))
    refused_quickly(io.read_exr, p, "cannot decode OpenEXR")
    out, errs = capfd.readouterr()
    assert out == "" and errs == ""


@pytest.mark.parametrize("name", ["bomb.png", "bomb.hdr", "bomb.jpg"])
def test_cli_reports_a_bomb_in_one_line_with_exit_2(tmp_path, run_cli, name):
    p = tmp_path / name
    if name.endswith(".png"):
        p.write_bytes(png_bomb())
    elif name.endswith(".jpg"):
        p.write_bytes(jpeg_bomb(tmp_path))
    else:
        p.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1000000000 +X 1000000000\n")
    proc = run_cli("inspect", p, timeout=60)
    assert_clean_error(proc, name, "over the limit")
    assert proc.stdout == ""


# -------------------------------------------------------------------- writers
@pytest.mark.parametrize("write", [
    lambda p, a: formats.write_rgbe(p.with_suffix(".hdr"), a),
    lambda p, a: formats.write_logluv_tiff(p.with_suffix(".tif"), a, bits=32),
    lambda p, a: formats.write_logluv_tiff(p.with_suffix(".tif"), a, bits=24),
    lambda p, a: io.write_image(p.with_suffix(".png"), a),
    lambda p, a: io.write_image(p.with_suffix(".tif"), a),
], ids=["rgbe", "logluv32", "logluv24", "png", "tiff"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_writers_refuse_nan_and_inf_naming_the_argument(tmp_path, write, bad):
    img = np.ones((4, 5, 3), np.float32)
    img[1, 2, 0] = bad
    with pytest.raises(InputError) as err:
        write(tmp_path / "out", img)
    assert err.value.where == "img"
    assert re.search(r"NaN/inf", err.value.problem)
    assert not list(tmp_path.iterdir())  # nothing half-written
