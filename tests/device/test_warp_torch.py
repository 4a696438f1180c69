"""The torch resampling (kornia remap) against cv2.remap: identity and known
shifts on asymmetric images, every border, so the align_corners and
pixel-centre conventions are checked, not assumed."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("kornia")
cv2 = pytest.importorskip("cv2")

from lumigraph.capture.device import resolve_device  # noqa: E402
from lumigraph.capture.warp_torch import remap, remap_hwc  # noqa: E402

U32 = 2.0 ** -24  # unit roundoff of float32
CV_BORDER = {"constant": cv2.BORDER_CONSTANT, "replicate": cv2.BORDER_REPLICATE,
             "reflect101": cv2.BORDER_REFLECT_101}


def _image(h=23, w=37, c=3):
    """Asymmetric in every way: H != W, a ramp along x and a different one
    along y (a left-right or up-down flip, or a half-pixel slip, shows), noise."""
    rng = np.random.default_rng(7)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    base = (0.02 * xs + 0.05 * ys ** 1.3)[..., None] + rng.random((h, w, c), dtype=np.float32)
    return base.astype(np.float32)


def _bound(img, w_max):
    """|torch - cv2| for maps whose fractions are multiples of 1/32 (cv2's
    INTER_TAB_SIZE: it then uses the exact weights). kornia normalises a
    pixel coordinate x to 2 x / (W - 1) - 1 and grid_sample maps it back:
    about five float32 roundings of numbers up to W - 1, so the sample
    position moves by at most 8 u (W - 1) px (u = 2^-24), which moves the
    value by that times the largest difference between adjacent samples
    (G, per axis); each side's bilinear sum of 4 products adds 4 u M."""
    g = max(np.abs(np.diff(img, axis=0)).max(), np.abs(np.diff(img, axis=1)).max())
    m = np.abs(img).max()
    return 2 * 8 * U32 * (w_max - 1) * g + 2 * 4 * U32 * m + 2 * 4 * U32 * m


@pytest.mark.parametrize("border", sorted(CV_BORDER))
@pytest.mark.parametrize("shift", [(0.0, 0.0), (1.0, 0.0), (0.0, -2.0), (3.0, 5.0),
                                   (0.25, 0.0), (0.0, 0.375), (-1.25, 0.75), (0.5, -0.5)])
def test_remap_matches_cv2(border, shift):
    img = _image()
    h, w = img.shape[:2]
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    mx, my = xs + np.float32(shift[0]), ys + np.float32(shift[1])
    want = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=CV_BORDER[border], borderValue=0)
    m = np.stack([mx, my], axis=-1)
    got = remap_hwc(img, m, resolve_device("torch-cpu"), border=border).numpy()
    assert got.shape == want.shape
    assert np.abs(got - want).max() <= _bound(img, max(h, w))


def test_identity_is_exact_where_the_pitfall_would_shift():
    """With kornia's default align_corners (False) an identity map resamples
    the image (kornia #4504); ours returns it unchanged, to rounding."""
    img = _image(11, 17, 1)
    h, w = img.shape[:2]
    t = torch.from_numpy(img).permute(2, 0, 1)[None]
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32),
                            torch.arange(w, dtype=torch.float32), indexing="ij")
    got = remap(t, xs, ys)[0, 0].numpy()
    assert np.abs(got - img[..., 0]).max() <= _bound(img, max(h, w))


def test_remap_rejects_unknown_border():
    t = torch.zeros(1, 1, 2, 2)
    with pytest.raises(ValueError, match="border"):
        remap(t, t[:, 0], t[:, 0], border="wrap")
