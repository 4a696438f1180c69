"""The torch resampler (``capture.remap_torch``) against ``cv2.remap``, and the
pixel conventions of kornia/grid_sample checked rather than assumed.

Fixtures are asymmetric (width != height, a ramp that differs along x and y,
shifts that differ per axis), so a swapped axis, a half-pixel offset or an
``align_corners`` slip shows as a difference, never cancels.

Float bounds, from the arithmetic: both implementations form the same convex
(bilinear) or Keys-cubic combination of the same taps in float32, each with a
few rounded operations. A sum of products ``Σ w_i p_i`` computed with ``k``
roundings is off by at most ``k·u·Σ|w_i||p_i| ≤ k·u·S·max|p|``, ``u = 2⁻²⁴``,
``S = Σ|w_i|`` (1 for bilinear; at most 1.375² < 1.9 for the Keys kernel with
a = −0.75). Bilinear: about 4 roundings per implementation (fraction, two
weighted sums, one more level), so two implementations differ by at most
``8·u·max|p|``. Cubic: each weight carries up to ~6 roundings, then 16
products and 15 sums: ``(6 + 2 + 16)·u·1.9 < 46u`` each, ``92u·max|p|`` apart.
Integer images: the float values agree within that bound, so after rounding
to nearest they differ by at most one code, and only where the float value
lies within the bound of a half-integer.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("kornia")
cv2 = pytest.importorskip("cv2")

from lumigraph.capture.remap_torch import remap  # noqa: E402

U = 2.0 ** -24
LIN_K, CUBIC_K = 8.0, 92.0


def _ramp(h=37, w=53, dtype=np.float32, seed=0):
    """An asymmetric image: a ramp steeper in x than in y plus texture."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    img = 3.0 * x + 1.0 * y + 20.0 * rng.random((h, w))
    if dtype == np.uint8:
        return np.clip(img * 255 / img.max(), 0, 255).astype(np.uint8)
    if dtype == np.uint16:
        return np.clip(img * 65535 / img.max(), 0, 65535).astype(np.uint16)
    return img.astype(dtype)


def _cv(img, mx, my, interp, border, value=0.0):
    flags = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC}[interp]
    mode = {"constant": cv2.BORDER_CONSTANT, "replicate": cv2.BORDER_REPLICATE}[border]
    return cv2.remap(img, mx, my, flags, borderMode=mode, borderValue=value)


def _shift_maps(h, w, dx, dy):
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    return x + np.float32(dx), y + np.float32(dy)


@pytest.mark.parametrize("interp", ["linear", "cubic"])
@pytest.mark.parametrize("border", ["constant", "replicate"])
@pytest.mark.parametrize("shift", [(0.0, 0.0), (0.25, -0.75), (-2.5, 1.125), (3.0, -4.0)])
def test_float_shift_matches_cv2(interp, border, shift):
    img = _ramp()
    mx, my = _shift_maps(*img.shape, *shift)
    ref = _cv(img, mx, my, interp, border)
    got = remap(img, mx, my, interpolation=interp, border=border, device="torch-cpu")
    tol = (LIN_K if interp == "linear" else CUBIC_K) * U * float(np.abs(img).max())
    assert got.shape == ref.shape and got.dtype == ref.dtype
    np.testing.assert_allclose(got, ref, rtol=0, atol=tol)
    if shift == (0.0, 0.0):  # the identity is exact (weights 1 and 0)
        np.testing.assert_array_equal(got, img)


@pytest.mark.parametrize("interp", ["linear", "cubic"])
@pytest.mark.parametrize("border", ["constant", "replicate"])
def test_random_maps_reaching_outside(interp, border):
    img = _ramp(seed=1)
    h, w = img.shape
    rng = np.random.default_rng(2)
    mx = rng.uniform(-3, w + 2, (29, 41)).astype(np.float32)
    my = rng.uniform(-3, h + 2, (29, 41)).astype(np.float32)
    ref = _cv(img, mx, my, interp, border)
    got = remap(img, mx, my, interpolation=interp, border=border, device="torch-cpu")
    tol = (LIN_K if interp == "linear" else CUBIC_K) * U * float(np.abs(img).max())
    np.testing.assert_allclose(got, ref, rtol=0, atol=tol)


def test_nan_border_follows_cv2():
    """With a NaN constant border a tap outside the image poisons the sample
    even at weight 0 (the last column, x = W − 1), as cv2.remap does."""
    img = _ramp(6, 8)
    xs = np.array([-1.0, -0.5, 0.0, 0.5, 6.5, 7.0, 7.5], np.float32)[None]
    mx, my = np.repeat(xs, 3, 0), np.array([[0.0], [2.5], [5.0]], np.float32) + 0 * xs
    ref = _cv(img, mx, my, "linear", "constant", np.nan)
    got = remap(img, mx, my, border="constant", border_value=np.nan, device="torch-cpu")
    np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
    assert np.isnan(ref[:, 5]).all()  # x = 7 = W - 1: NaN in cv2 as well
    ok = np.isfinite(ref)
    np.testing.assert_allclose(got[ok], ref[ok], rtol=0, atol=LIN_K * U * float(img.max()))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_integer_images_round_like_cv2(dtype):
    img = _ramp(dtype=dtype, seed=3)
    h, w = img.shape
    rng = np.random.default_rng(4)
    mx = rng.uniform(-1, w, (60, 70)).astype(np.float32)
    my = rng.uniform(-1, h, (60, 70)).astype(np.float32)
    ref = _cv(img, mx, my, "linear", "constant")
    got = remap(img, mx, my, device="torch-cpu")
    assert got.dtype == dtype
    diff = got.astype(np.int64) - ref.astype(np.int64)
    assert np.abs(diff).max() <= 1
    # where they differ, the float value sits within the float32 bound of a half
    fl = remap(img.astype(np.float32), mx, my, device="torch-cpu").astype(np.float64)
    near_half = np.abs(fl - np.floor(fl) - 0.5) <= 2 * LIN_K * U * float(np.iinfo(dtype).max)
    assert near_half[diff != 0].all()


def test_colour_channels_and_shapes():
    img = np.stack([_ramp(seed=s) for s in range(3)], -1)
    mx, my = _shift_maps(20, 30, 0.5, 0.25)
    ref = _cv(img, mx, my, "linear", "constant")
    got = remap(img, mx, my, device="torch-cpu")
    assert got.shape == (20, 30, 3)
    np.testing.assert_allclose(got, ref, rtol=0, atol=LIN_K * U * float(img.max()))


def _kornia_remap(img, mx, my, align_corners):
    import kornia

    t = torch.from_numpy(img)[None, None]
    out = kornia.geometry.transform.remap(t, torch.from_numpy(mx)[None], torch.from_numpy(my)[None],
                                          mode="bilinear", padding_mode="zeros",
                                          align_corners=align_corners)
    return out[0, 0].numpy()


@pytest.mark.parametrize("shift", [(0.0, 0.0), (0.5, -0.25), (1.0, 2.0)])
def test_kornia_pixel_convention(shift):
    """kornia's remap (grid_sample inside) agrees with cv2.remap only with
    ``align_corners=True``; with False every sample moves by up to half a
    pixel towards the centre. Interior only: the border rules differ. The
    bound adds the normalisation round trip, ``(W − 1)/2 · 2u`` px of
    position times the steepest slope (at most max|p| per pixel)."""
    img = _ramp()
    h, w = img.shape
    mx, my = _shift_maps(h, w, *shift)
    ref = _cv(img, mx, my, "linear", "constant")
    inner = (slice(4, h - 4), slice(4, w - 4))
    pos = (max(h, w) - 1) / 2 * 2 * 4 * U  # a few roundings of x and of its normalised form
    tol = LIN_K * U * float(img.max()) + pos * float(img.max())
    good = _kornia_remap(img, mx, my, True)
    np.testing.assert_allclose(good[inner], ref[inner], rtol=0, atol=tol)
    bad = _kornia_remap(img, mx, my, False)
    assert np.abs(bad[inner] - ref[inner]).max() > 0.1  # the pitfall is real


@pytest.mark.parametrize("channels", [1, 2, 3, 4, 5])
@pytest.mark.parametrize("dtype", [np.float32, np.uint8, np.uint16])
def test_every_channel_count_follows_cv2(channels, dtype):
    """OpenCV 5 interpolates 1, 3 and 4 channels at float positions and
    snaps 2 and >= 5 channels to 1/32 px (8-bit: ties rounded up); the torch
    path asks which (snaps_to_32nds) and does the same."""
    img = np.stack([_ramp(dtype=dtype, seed=10 + c) for c in range(channels)], -1)
    h, w = img.shape[:2]
    rng = np.random.default_rng(5)
    mx = rng.uniform(-2, w + 1, (23, 31)).astype(np.float32)
    my = rng.uniform(-2, h + 1, (23, 31)).astype(np.float32)
    ref = _cv(img, mx, my, "linear", "replicate").reshape(23, 31, channels)
    got = remap(img, mx, my, border="replicate", device="torch-cpu").reshape(23, 31, channels)
    if dtype == np.float32:
        np.testing.assert_allclose(got, ref, rtol=0, atol=LIN_K * U * float(img.max()))
    else:
        assert np.abs(got.astype(np.int64) - ref.astype(np.int64)).max() <= 1
