"""Hard cases of bit depth (issue 13): 12-bit data in 16-bit PNG/TIFF without
sBIT, 10-bit data left-aligned in 16 bits, a bit depth given that the codes
contradict. Each is detected (and the meta says how) or refused naming the file."""

import json

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture.errors import InputError
from lumigraph.capture.io import read_image, read_stack, write_image
from lumigraph.capture.render import render
from lumigraph.hdr.debevec1997 import response_debevec1997
from lumigraph.hdr.response import ResponseCurve

OPTS = {"size": (48, 36), "exposures": 5, "stops": 2.0}


def _bracket(tmp_path, bit_depth, *, ext=".png", shift=0, sbit=None, seed=2):
    """Write a rendered bracket's codes (shifted left by ``shift``) as 16-bit
    files without stack.json; ``sbit`` writes that sBIT chunk (PNG)."""
    s = render("bracket", seed=seed, bit_depth=bit_depth, **OPTS)
    paths = []
    for j, im in enumerate(s.images):
        p = tmp_path / f"e{j}{ext}"
        write_image(p, (im.astype(np.uint16) << shift), bit_depth=sbit)
        paths.append(p)
    times = ",".join(repr(t) for t in s.stack["exposure_times_s"])
    return s, paths, times


def _meta(path):
    return json.loads(open(f"{path}.meta.json").read())


def test_12bit_in_16bit_png_without_sbit_gives_4096_codes_and_saturates_at_4095(tmp_path):
    s, paths, times = _bracket(tmp_path, 12)
    assert read_image(paths[0]).dtype == np.uint16
    out = tmp_path / "r.json"
    r = lumigraph("hdr", "response", *paths, "--times", times, "--samples", "200", "--out", out)
    assert r.returncode == 0, r.stderr
    curve = ResponseCurve.load(out)
    assert curve.bit_depth == 12 and curve.g.shape == (3, 4096)
    src = _meta(out)["params"]["bit_depth_source"]
    assert "largest code 4095" in src, src
    rad = tmp_path / "rad.exr"
    r = lumigraph("hdr", "merge", *paths, "--times", times, "--response", out, "--out", rad,
                  "--bit-depth", "12")
    assert r.returncode == 0, r.stderr
    assert _meta(rad)["params"]["bit_depth_source"] == "given"
    # Codes clipped at 4095 are saturation: a pixel at 4095 in every exposure
    # is flagged "clipped everywhere" (bit 1), as at 16 bits it would not be.
    z = np.stack(s.images)
    clipped = (z == 4095).all(axis=0).any(axis=-1)
    assert clipped.any()
    mask = read_image(tmp_path / "rad.mask.png")
    assert np.all(mask[clipped] & 1)


def test_12bit_in_16bit_tiff_without_sbit(tmp_path):
    s, paths, times = _bracket(tmp_path, 12, ext=".tif")
    st = read_stack(paths, times=[float(t) for t in times.split(",")])
    assert st.bit_depth == 12 and "largest code 4095" in st.bit_depth_source
    assert np.array_equal(st.images, np.stack(s.images))
    r = response_debevec1997(st.images, st.exposure_times_s, bit_depth=st.bit_depth, samples=200)
    assert r.g.shape == (3, 4096)


def test_10bit_left_aligned_is_shifted_back_and_fits_as_the_10bit_codes(tmp_path):
    s, paths, times = _bracket(tmp_path, 10, shift=6, seed=4)
    st = read_stack(paths)
    assert st.bit_depth == 10 and "left-aligned" in st.bit_depth_source
    assert np.array_equal(st.images, np.stack(s.images))  # exactly the sensor's 10-bit codes
    out = tmp_path / "r.json"
    r = lumigraph("hdr", "response", *paths, "--times", times, "--samples", "200", "--seed", "5",
                  "--out", out)
    assert r.returncode == 0, r.stderr
    assert "left-aligned" in _meta(out)["params"]["bit_depth_source"]
    curve = ResponseCurve.load(out)
    ref = response_debevec1997(np.stack(s.images), s.stack["exposure_times_s"], bit_depth=10,
                               samples=200, rng=np.random.default_rng(5))
    assert curve.g.shape == (3, 1024)
    assert np.allclose(curve.g, ref.g)  # the same fit as on the right-aligned codes


def test_bit_depth_given_below_the_codes_is_exit_2_naming_the_file(tmp_path):
    s, paths, times = _bracket(tmp_path, 12)
    first = next(p for p, im in zip(paths, s.images, strict=True) if im.max() > 1023)
    r = lumigraph("hdr", "response", *paths, "--times", times, "--bit-depth", "10",
                  "--out", tmp_path / "r.json")
    assert_clean_error(r, first.name, "do not fit in 10 bits")
    assert not (tmp_path / "r.json").exists()


def test_sbit_contradicted_by_the_codes_names_the_file(tmp_path):
    s, paths, _ = _bracket(tmp_path, 12)
    bad = tmp_path / "bad.png"
    im = s.images[-1]
    write_image(bad, im >> 2, bit_depth=10)  # a valid 10-bit file ...
    data = bytearray(bad.read_bytes())
    write_image(bad, im)  # ... then the 12-bit codes under its 10-bit sBIT
    raw = bytearray(bad.read_bytes())
    i = data.index(b"sBIT") - 4
    n = 12 + int.from_bytes(data[i:i + 4], "big")
    raw[33:33] = data[i:i + n]  # after the IHDR chunk (8 + 25 bytes)
    bad.write_bytes(bytes(raw))
    with pytest.raises(InputError) as e:
        read_stack([*paths[:-1], bad])
    assert str(e.value.where) == str(bad) and "PNG sBIT" in e.value.problem


@pytest.mark.parametrize("bits,expect", [(8, 8), (16, 16)])
def test_detected_depth_of_other_containers(tmp_path, bits, expect):
    s = render("bracket", seed=1, bit_depth=bits, **OPTS)
    paths = []
    for j, im in enumerate(s.images):
        paths.append(tmp_path / f"e{j}.png")
        write_image(paths[-1], im.astype(np.uint16))  # 8-bit codes in a 16-bit PNG, too
    st = read_stack(paths)
    assert st.bit_depth == expect and np.array_equal(st.images, np.stack(s.images))
