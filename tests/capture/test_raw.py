"""RAW development through rawpy, on DNG files written here with known sensor
values (no RAW sample ships in ../shared/data). A minimal DNG: 12-bit RGGB
Bayer data, black level 64, white level 4095, identity colour matrix, neutral
white balance, so the developed output is exactly predictable."""

import numpy as np
import pytest

from lumigraph.capture import io
from lumigraph.capture.errors import InputError

BLACK, WHITE = 64, 4095


def _write_dng(path, bayer):
    tifffile = pytest.importorskip("tifffile")
    ident = []
    for v in (1, 0, 0, 0, 1, 0, 0, 0, 1):
        ident += [v * 10000, 10000]
    tags = [
        (254, "I", 1, 0, True),                      # NewSubfileType: main image
        (33421, "H", 2, (2, 2), True),               # CFARepeatPatternDim
        (33422, "B", 4, (0, 1, 1, 2), True),         # CFAPattern RGGB
        (50706, "B", 4, (1, 4, 0, 0), True),         # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), True),         # DNGBackwardVersion
        (50708, "s", 0, "lumigraph synthetic", True),  # UniqueCameraModel
        (50714, "H", 1, BLACK, True),                # BlackLevel
        (50717, "H", 1, WHITE, True),                # WhiteLevel
        (50721, "2i", 9, ident, True),               # ColorMatrix1
        (50778, "H", 1, 21, True),                   # CalibrationIlluminant1 D65
        (50728, "2I", 3, [1, 1, 1, 1, 1, 1], True),  # AsShotNeutral
    ]
    tifffile.imwrite(path, bayer.astype(np.uint16), photometric=32803, extratags=tags)


def _bayer(r, g, b, shape=(32, 48)):
    out = np.empty(shape)
    out[0::2, 0::2], out[0::2, 1::2], out[1::2, 0::2], out[1::2, 1::2] = r, g, g, b
    return BLACK + out


def test_raw_is_linear_with_levels_applied_and_bit_depth_12(tmp_path):
    _write_dng(tmp_path / "a.dng", _bayer(1000, 1500, 800))
    _write_dng(tmp_path / "b.dng", _bayer(2000, 3000, 1600))
    a = io.read_raw(tmp_path / "a.dng", color="raw")
    b = io.read_raw(tmp_path / "b.dng", color="raw")
    assert a.bit_depth == 12 and a.black_level == BLACK and a.white_level == WHITE
    # codes = (sensor - black) / (white - black) * 4095, away from the border
    # (demosaicking is exact on flat colour); rounding twice gives <= 1 code.
    want = np.array([1000, 1500, 800]) / (WHITE - BLACK) * 4095
    got = a.codes[8:24, 8:40].reshape(-1, 3).astype(float)
    assert np.abs(got - want).max() <= 1.0
    # doubling the light doubles the codes: no gamma, no auto-brightening
    ratio = b.codes[8:24, 8:40].astype(float) / a.codes[8:24, 8:40]
    assert np.abs(ratio - 2.0).max() < 2.0 / 800


def test_raw_stack_is_linear_and_srgb_output_has_shape(tmp_path):
    for i, s in enumerate((1, 2, 4)):
        _write_dng(tmp_path / f"r{i}.dng", _bayer(200 * s, 300 * s, 150 * s))
    st = io.read_stack([tmp_path / f"r{i}.dng" for i in range(3)], times=[1, 2, 4])
    assert st.linear and st.bit_depth == 12 and st.images.shape == (3, 32, 48, 3)
    assert io.read_raw(tmp_path / "r0.dng").codes.dtype == np.uint16


def test_truncated_raw_is_refused(tmp_path):
    p = tmp_path / "cut.dng"
    _write_dng(p, _bayer(1000, 1500, 800, shape=(64, 96)))
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    with pytest.raises(InputError, match="cut.dng"):
        io.read_raw(p)
