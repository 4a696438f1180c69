"""Merging and HDR file formats (interop with OpenCV and libtiff)."""

import json
import subprocess

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph, need_shared, need_tool

from lumigraph.capture.render import render
from lumigraph.hdr.formats import (
    RGB_TO_XYZ,
    read_logluv_tiff,
    read_rgbe,
    write_logluv_tiff,
    write_rgbe,
)
from lumigraph.hdr.merge import BLACK, CLIPPED, GHOST, merge
from lumigraph.hdr.response import ResponseCurve


def test_units_do_not_depend_on_bit_depth():
    out = {}
    for bd in (8, 16):
        s = render("bracket", response="linear", bit_depth=bd, noise=0.0)
        z = np.stack(s.images)
        out[bd] = merge(z, s.stack["exposure_times_s"], ResponseCurve.linear(bd)).radiance
    both = (out[8] > 0.05) & (out[16] > 0.05)
    # 8-bit quantisation: <= 0.5/13 relative at the lowest used code (5 %).
    assert np.median(np.abs(out[8][both] / out[16][both] - 1)) < 0.01


def test_clipped_and_black_everywhere_are_bounded_and_flagged():
    x = np.array([[[1e-5], [0.3], [50.0]]])
    t = [0.1, 1.0]
    z = np.stack([np.clip(np.round(x * ti * 255), 0, 255) for ti in t]).astype(np.uint8)
    m = merge(z, t, ResponseCurve.linear(8, 1))
    assert m.flags[0, 0, 0] == BLACK and m.radiance[0, 0, 0] >= x[0, 0, 0]
    assert m.flags[0, 2, 0] == CLIPPED and 0 < m.radiance[0, 2, 0] <= x[0, 2, 0]
    assert m.flags[0, 1, 0] == 0 and m.radiance[0, 1, 0] == pytest.approx(0.3, rel=0.01)


def test_deghost_leaves_out_moving_content():
    s = render("bracket_video", frames=2, light_speed=0.0, pan=6.0, noise=0.0)
    z = np.stack(s.images)
    rc = ResponseCurve("gt", 8, s.gt_arrays["g"])
    plain = merge(z, s.stack["exposure_times_s"], rc)
    clean = merge(z, s.stack["exposure_times_s"], rc, deghost=True, reference=1)
    truth = s.gt_arrays["radiance"][1] * s.gt["exposure_scale"]
    # Where the reference exposure is itself valid, the other frame's moved
    # content must be left out.
    ok = (z[1] > 0.02 * 255) & (z[1] < 0.98 * 255) & (z[0] > 0.02 * 255)
    err_plain = np.abs(plain.radiance / truth - 1)[ok].mean()
    err_clean = np.abs(clean.radiance / truth - 1)[ok].mean()
    assert (clean.flags & GHOST).any() and err_clean < 0.5 * err_plain


def _rel_to_max(a, b):
    return float(np.max(np.abs(a - b) / b.max(axis=2, keepdims=True)))


def test_rgbe_interop_with_opencv(tmp_path):
    import cv2

    rng = np.random.default_rng(0)
    img = np.exp(rng.uniform(-6, 6, (30, 40, 3))).astype(np.float32)
    img[5:20, 3:30] = img[0, 0]  # long runs exercise the RLE
    write_rgbe(tmp_path / "ours.hdr", img)
    theirs = cv2.imread(str(tmp_path / "ours.hdr"), cv2.IMREAD_UNCHANGED)[..., ::-1]
    assert _rel_to_max(theirs, img) <= 2.0 ** -7  # 8-bit mantissa (OpenCV decodes at m, not m+.5)
    cv2.imwrite(str(tmp_path / "cv.hdr"), np.ascontiguousarray(img[..., ::-1]))
    assert _rel_to_max(read_rgbe(tmp_path / "cv.hdr"), img) <= 2.0 ** -7
    assert (tmp_path / "ours.hdr").stat().st_size < 0.8 * img.size * 4 / 3 * 4


def test_reads_debevecs_memorial_hdr():
    m = read_rgbe(need_shared("data", "hdr-real", "memorial", "memorial.hdr"))
    assert m.shape == (768, 512, 3) and np.isfinite(m).all() and m.max() / m[m > 0].min() > 1e4


def test_inspect_convert_and_tonemap_share_the_one_rgbe_codec(tmp_path):
    # inspect, convert, tonemap and the ground-floor image reader all decode RGBE
    # through the one codec (lumigraph.capture.rgbe, re-exported by hdr.formats).
    from lumigraph.capture import io, rgbe
    from lumigraph.hdr import formats

    memorial = need_shared("data", "hdr-real", "memorial", "memorial.hdr")
    r = lumigraph("inspect", memorial)
    assert r.returncode == 0, r.stderr
    (info,) = json.loads(r.stdout)["files"]
    ref = read_rgbe(memorial)
    assert info["format"] == "Radiance RGBE" and info["shape"] == [768, 512, 3]
    assert info["dtype"] == "float32" and info["unknown"] == 0
    assert info["min"] == float(ref.min()) and info["max"] == float(ref.max())
    # a file of ours, and two RGBE files are described one by one (not read as a stack)
    write_rgbe(tmp_path / "a.hdr", np.full((4, 9, 3), 2.0, np.float32))
    r = lumigraph("inspect", tmp_path / "a.hdr", memorial)
    assert r.returncode == 0, r.stderr
    assert [f["shape"] for f in json.loads(r.stdout)["files"]] == [[4, 9, 3], [768, 512, 3]]
    assert json.loads(r.stdout)["files"][0]["max"] == float(read_rgbe(tmp_path / "a.hdr").max())
    for verb in (("convert", memorial, tmp_path / "m.exr"),
                 ("tonemap", memorial, "--out", tmp_path / "m.png")):
        r = lumigraph("hdr", *verb, "-q")
        assert r.returncode == 0, r.stderr
    assert np.array_equal(io.read_exr(tmp_path / "m.exr"), ref)
    assert formats.read_rgbe is rgbe.read_rgbe and formats.write_rgbe is rgbe.write_rgbe
    assert np.array_equal(io.read_image(memorial), ref)
    assert_clean_error(lumigraph("inspect", tmp_path / "a.hdr", tmp_path / "b.hdr"), "b.hdr",
                       "not found")


def _lum(x):
    return x.astype(np.float64) @ RGB_TO_XYZ[1]


@pytest.mark.parametrize("bits, step", [(32, 2 ** (1 / 256) - 1), (24, 2 ** (1 / 64) - 1)])
def test_logluv_roundtrip_and_libtiff_interop(tmp_path, bits, step):
    tiffcp = need_tool("tiffcp", "libtiff-tools")
    need_tool("tiffinfo", "libtiff-tools")
    rng = np.random.default_rng(1)
    img = np.exp(rng.uniform(-7, 2.5, (24, 37, 3))).astype(np.float32)  # inside LogLuv24's range
    ours = tmp_path / f"ours{bits}.tif"
    write_logluv_tiff(ours, img, bits=bits)
    back = read_logluv_tiff(ours)
    # Floor encoding, centre decoding: within one luminance step (0.27 % / 1.1 %).
    assert np.max(np.abs(_lum(back) / _lum(img) - 1)) <= step
    info = subprocess.run(["tiffinfo", str(ours)], capture_output=True, text=True, check=True)
    assert "SGILog" in info.stdout and "Log2(L)" in info.stdout
    # libtiff decodes ours and re-encodes with its own SGILOG (32-bit) codec; ours reads that.
    cp = tmp_path / "libtiff.tif"
    subprocess.run([tiffcp, "-c", "sgilog", str(ours), str(cp)], check=True, capture_output=True)
    assert np.max(np.abs(_lum(read_logluv_tiff(cp)) / _lum(img) - 1)) <= step + 2 ** (1 / 256) - 1
