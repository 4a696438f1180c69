"""HDR merge and tone mapping by bands of rows give what the whole image gives.

Small images with tiny bands (5-7 rows, not dividing the height; the local
tone map's 61-row halo spans several bands), asymmetric sizes, strip and tile
TIFF inputs, left-aligned 16-bit codes: every value must be the whole image's,
to the bit (the operators are per pixel or read their halo; the global
statistics are order-free integer sums, a max and histograms).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile

from lumigraph.capture.io import read_image, write_exr
from lumigraph.capture.tiles import (
    ArrayRows,
    ExrRows,
    ExrRowWriter,
    PngRowWriter,
    TiffRows,
    TiffRowWriter,
    bands,
    plan_rows,
    read_stack_rows,
)
from lumigraph.hdr.merge import merge
from lumigraph.hdr.reinhard2002 import local_halo, tonemap
from lumigraph.hdr.response import ResponseCurve
from lumigraph.hdr.tiled import merge_rows, tonemap_rows
from tests.conftest import assert_clean_error, lumigraph

TIMES = [0.01, 0.04, 0.16, 0.64]


def _bracket(folder, *, h=53, w=37, bits=8, shift=0, tiled=False, seed=1):
    """A bracket of TIFFs (strips of 7 rows, or 16x16 zlib tiles) with clipped
    and black pixels; codes ``bits`` deep, shifted left by ``shift``."""
    rng = np.random.default_rng(seed)
    x = np.exp(rng.normal(-1, 2.5, (h, w, 3)))
    top = 2 ** bits - 1
    folder.mkdir(parents=True, exist_ok=True)
    names, stack = [], []
    for i, t in enumerate(TIMES):
        noisy = x * t * top * 4 * (1 + 0.01 * rng.standard_normal(x.shape))
        z = (np.clip(np.round(noisy), 0, top).astype(np.uint16 if bits > 8 else np.uint8)
             << shift)
        names.append(f"e{i}.tif")
        kw = {"tile": (16, 16), "compression": "zlib"} if tiled else {"rowsperstrip": 7}
        tifffile.imwrite(folder / names[-1], z, photometric="rgb", **kw)
        stack.append(z >> shift)
    (folder / "stack.json").write_text(json.dumps({"schema": "lumigraph.stack",
                                                   "schema_version": 1, "images": names,
                                                   "exposure_times_s": TIMES}))
    return np.stack(stack)


@pytest.mark.parametrize(("bits", "shift", "tiled", "deghost", "rows"),
                         [(8, 0, False, False, 5), (8, 0, True, True, 7), (12, 4, False, True, 6)])
def test_merge_by_rows_is_the_whole_merge(tmp_path, bits, shift, tiled, deghost, rows):
    z = _bracket(tmp_path / "b", bits=bits, shift=shift, tiled=tiled)
    curve = ResponseCurve.linear(bits, 1)
    whole = merge(z, TIMES, curve, deghost=deghost)
    st = read_stack_rows([tmp_path / "b"], rows=rows)
    assert st.bit_depth == bits and st.shift == shift
    rad, flags = [], []
    r = merge_rows(st, st.exposure_times_s, curve, rows=rows, write_radiance=rad.append,
                   write_flags=flags.append, deghost=deghost)
    st.close()
    assert r.bands == -(-z.shape[1] // rows) and r.stats["clipped_everywhere"] > 0
    assert np.concatenate(rad).tobytes() == whole.radiance.tobytes()
    assert (np.concatenate(flags) == np.bitwise_or.reduce(whole.flags, axis=2)).all()
    assert r.stats == whole.stats and r.warnings == whole.warnings


def test_tiff_rows_reads_any_band_of_strips_and_tiles(tmp_path):
    img = np.random.default_rng(0).integers(0, 65535, (45, 70, 3), dtype=np.uint16)
    tifffile.imwrite(tmp_path / "s.tif", img, rowsperstrip=8, photometric="rgb")
    tifffile.imwrite(tmp_path / "t.tif", img, tile=(16, 32), photometric="rgb",
                     compression="zlib")
    for name in ("s.tif", "t.tif"):
        src = TiffRows(tmp_path / name)
        for y0, y1 in ((0, 45), (3, 4), (7, 33), (40, 45)):
            assert (src.read(y0, y1) == img[y0:y1]).all(), (name, y0, y1)
        src.close()


def test_row_writers_write_what_the_whole_image_writers_write(tmp_path):
    rng = np.random.default_rng(2)
    f = rng.random((41, 29, 3), dtype=np.float32)
    write_exr(tmp_path / "whole.exr", f)
    wr = ExrRowWriter(tmp_path / "rows.exr", 29, 41, 3)
    for b in bands(41, 6):
        wr.write(f[b.y0:b.y1])
    wr.close()
    assert (tmp_path / "rows.exr").read_bytes() == (tmp_path / "whole.exr").read_bytes()
    src = ExrRows(tmp_path / "rows.exr")
    assert src.read(5, 17).tobytes() == f[5:17].tobytes()
    src.close()
    for dtype, c in ((np.uint8, 1), (np.uint16, 3), (np.uint8, 4)):
        img = rng.integers(0, np.iinfo(dtype).max, (41, 29, c)).astype(dtype)
        writers = [(PngRowWriter, "r.png")] + ([(TiffRowWriter, "r.tif")] if c != 4 else [])
        for cls, name in writers:
            kw = {"rows": 6} if cls is TiffRowWriter else {}
            wr = cls(tmp_path / name, 29, 41, c, dtype, **kw)
            for b in bands(41, 6):
                wr.write(img[b.y0:b.y1])
            wr.close()
            got = read_image(tmp_path / name)
            assert got.dtype == dtype and (got.reshape(img.shape) == img).all(), (name, c)


@pytest.mark.parametrize("method", ["reinhard", "reinhard-local"])
def test_tonemap_by_rows_is_the_whole_tonemap(method):
    # taller than three halos, so bands far from both edges read a true halo
    rng = np.random.default_rng(3)
    h = 3 * local_halo() + 20
    x = np.exp(rng.normal(0, 2, (h, 31, 3))).astype(np.float32)
    x[40:45, 10:12] = 5e4  # a highlight a band boundary cuts
    for bit_depth in (8, 16):
        whole = tonemap(x, method=method, bit_depth=bit_depth)
        got = []
        r = tonemap_rows(ArrayRows(x), rows=7, write=got.append, method=method,
                         bit_depth=bit_depth)
        assert r.bands == -(-h // 7)
        assert np.concatenate(got).tobytes() == whole.tobytes()


def test_plan_rows_fits_the_budget_and_says_why():
    p = plan_rows(None, 10 ** 9, width=20000, height=20000, bytes_per_pixel=50)
    assert p.rows is not None and "over" in p.reason
    assert 200e6 + 50 * 20000 * p.rows <= 10 ** 9 < 200e6 + 50 * 20000 * (p.rows + 16)
    assert plan_rows("off", None, width=10, height=10, bytes_per_pixel=1).rows is None
    assert plan_rows(999, None, width=10, height=10, bytes_per_pixel=1).rows == 10


def test_cli_merge_and_tonemap_by_rows_match_whole(tmp_path):
    _bracket(tmp_path / "b", h=150, w=23, tiled=True)
    r = lumigraph("hdr", "response", tmp_path / "b", "--method", "linear",
                  "--out", tmp_path / "r.json")
    assert r.returncode == 0, r.stderr
    outs = {}
    for tag, extra in (("whole", ["--tile", "off"]), ("rows", ["--tile", "9"])):
        r = lumigraph("hdr", "merge", tmp_path / "b", "--response", tmp_path / "r.json",
                      "--deghost", "--out", tmp_path / f"{tag}.exr", *extra)
        assert r.returncode == 0, r.stderr
        r = lumigraph("hdr", "tonemap", tmp_path / f"{tag}.exr", "--method", "reinhard-local",
                      "--out", tmp_path / f"{tag}.png", *extra)
        assert r.returncode == 0, r.stderr
        outs[tag] = json.loads((tmp_path / f"{tag}.exr.meta.json").read_text())
    assert (tmp_path / "whole.exr").read_bytes() == (tmp_path / "rows.exr").read_bytes()
    for name in ("{}.mask.png", "{}.png"):
        a = read_image(tmp_path / name.format("whole"))
        b = read_image(tmp_path / name.format("rows"))
        assert a.dtype == b.dtype and (a == b).all(), name
    assert outs["rows"]["tiles"]["tiled"] and outs["rows"]["tiles"]["bands"] == 17
    assert not outs["whole"]["tiles"]["tiled"]
    assert outs["rows"]["quality"] == outs["whole"]["quality"]
    tm = json.loads((tmp_path / "rows.png.meta.json").read_text())
    assert tm["tiles"]["halo_rows"] == local_halo()
    # by rows the radiance is OpenEXR: another format is refused before any work
    r = lumigraph("hdr", "merge", tmp_path / "b", "--response", tmp_path / "r.json",
                  "--out", tmp_path / "x.hdr", "--tile", "9")
    assert_clean_error(r, "x.hdr", ".exr")
    assert not (tmp_path / "x.hdr").exists()


@pytest.mark.parametrize("suffix", [".png", ".tif"])
def test_cli_tonemap_by_rows_refuses_nan_found_mid_image(tmp_path, suffix):
    # the bad value sits in a band read after the first outputs were written: still
    # one line, exit 2, and no output left behind
    x = np.ones((150, 20, 3), np.float32)
    x[120, 3] = np.nan
    write_exr(tmp_path / "x.exr", x)
    out = tmp_path / f"t{suffix}"
    r = lumigraph("hdr", "tonemap", tmp_path / "x.exr", "--out", out, "--tile", "9")
    assert_clean_error(r, "x.exr", "NaN")
    assert not out.exists() and not list(tmp_path.glob(".t*"))
