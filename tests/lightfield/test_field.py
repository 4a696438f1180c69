"""LightField container: validation, conversions, folder round trip."""

import numpy as np
import pytest

from lumigraph.capture.errors import InputError
from lumigraph.lightfield.field import LightField, from_images, srgb_to_linear


def test_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    lf = LightField(rng.random((2, 3, 5, 7, 3)).astype(np.float32), spacing=0.25, focal_px=80.0)
    lf.save(tmp_path / "lf")
    back = LightField.load(tmp_path / "lf")
    assert np.array_equal(back.data, lf.data)
    assert (back.spacing, back.focal_px, back.alpha_scale, back.grid) == (0.25, 80.0, 3.0, (2, 3))
    assert (tmp_path / "lf" / "lightfield.json.meta.json").exists()


def test_validation_names_the_argument():
    with pytest.raises(ValueError, match="data"):
        LightField(np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match="spacing"):
        LightField(np.zeros((2, 2, 3, 3, 1)), spacing=0.0)
    with pytest.raises(InputError, match="focal_px"):
        LightField(np.zeros((2, 2, 3, 3, 1))).slope_from_depth(2.0)


def test_slope_depth_alpha_are_consistent():
    lf = LightField(np.zeros((5, 5, 4, 4, 1)), spacing=0.1, focal_px=400.0)
    assert lf.slope_from_depth(40.0) == pytest.approx(1.0)
    for a in (0.8, 1.0, 1.1, 3.0):
        assert lf.alpha_from_slope(lf.slope_from_alpha(a)) == pytest.approx(a)
    lo, hi = lf.alpha_range()                    # |s| <= 1 <=> alpha in [5/6, 5/4]
    assert abs(lf.slope_from_alpha(lo)) == pytest.approx(1.0)
    assert abs(lf.slope_from_alpha(hi)) == pytest.approx(1.0)


def test_from_images_decodes_srgb_and_checks_sizes():
    a = np.full((4, 5, 3), 128, np.uint8)
    lf = from_images([a] * 4, grid=(2, 2), spacing=1.0)
    assert lf.data[0, 0, 0, 0, 0] == pytest.approx(0.2158605, abs=1e-6)   # sRGB 128
    lin = from_images([a] * 4, grid=(2, 2), spacing=1.0, linear=True)
    assert lin.data[0, 0, 0, 0, 0] == pytest.approx(128 / 255)
    with pytest.raises(InputError, match="b.png"):
        from_images([a, a[:3]], grid=(1, 2), spacing=1.0, names=["a.png", "b.png"])
    with pytest.raises(InputError, match="^grid: "):      # the argument, not a flag
        from_images([a] * 3, grid=(2, 2), spacing=1.0)
    assert srgb_to_linear(np.array([65535], np.uint16))[0] == pytest.approx(1.0)
