"""The one luma conversion (two units) and the two noise estimates."""

import numpy as np
import pytest

from lumigraph.stereo.luma import (
    luma_codes,
    luma_normalised,
    noise_sigma_immerkaer,
    noise_sigma_smooth_blocks,
)


@pytest.mark.parametrize("dtype, top", [(np.uint8, 255), (np.uint16, 65535)])
def test_normalised_is_codes_over_the_dtype_maximum(dtype, top):
    img = np.random.default_rng(0).integers(0, top + 1, (12, 16, 3)).astype(dtype)
    assert np.array_equal(luma_normalised(img), luma_codes(img) * np.float32(1 / top))
    f = img.astype(np.float32) / top
    assert np.array_equal(luma_normalised(f), luma_codes(f))


@pytest.mark.parametrize("shape", [(6, 7), (6, 7, 1), (6, 7, 3), (6, 7, 4)])
def test_shapes_accepted(shape):
    img = np.full(shape, 200, np.uint8)
    assert luma_codes(img).shape == (6, 7) and luma_codes(img).dtype == np.float32
    assert np.allclose(luma_codes(img), 200)


def test_bad_shape_names_the_argument():
    with pytest.raises(ValueError, match="image"):
        luma_codes(np.zeros((4, 5, 2)))


def test_texture_leaks_into_the_global_estimate_not_the_block_one():
    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:96, 0:128]
    flat = 100 + rng.normal(0, 2, (96, 128))
    textured = flat + 30 * (((x // 4) + (y // 4)) % 2) * (x > 64)  # checker on the right half
    for img in (flat, textured):
        assert 1.8 < noise_sigma_smooth_blocks(img.astype(np.float32)) < 2.4
    assert 1.8 < noise_sigma_immerkaer(flat) < 2.2
    assert noise_sigma_immerkaer(textured) > 3.0
