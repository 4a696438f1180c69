"""Lenslet decoding and light-slab rendering against ground truth."""

import numpy as np
import pytest

from lumigraph.capture.errors import EstimationError
from lumigraph.capture.render import render
from lumigraph.lightfield.field import LightField
from lumigraph.lightfield.lenslet import decode, estimate_grid
from lumigraph.lightfield.levoy1996 import render_view


def _psnr(a, b):
    return 10 * np.log10(float(b.max()) ** 2 / np.mean((a.astype(np.float64) - b) ** 2))


@pytest.mark.parametrize("name", ["lightfield-lenslet", "lightfield-lenslet-hex"])
def test_decode_recovers_grid_and_views(name):
    s = render(name, size=(24, 20))
    d = decode(*s.images, views=5)
    g = d.grid
    assert g.lattice == s.gt["lattice"]
    err = np.linalg.norm(g.centers() - s.gt_arrays["centers"], axis=-1)
    assert 0 < err.max() < 0.1                 # the bound on every centre
    assert abs(g.rotation_deg - s.gt["rotation_deg"]) < 0.05
    truth = s.gt_arrays.get("views_rect", s.gt_arrays["views"])
    assert d.lightfield.data.shape == truth.shape
    # Square: exact but for 12-bit quantisation (PSNR >> 35 dB); hex: plus
    # cubic resampling of half-lenslet offsets onto the square grid.
    assert 35 < _psnr(d.lightfield.data, truth) < 100


def test_black_white_image_is_refused():
    with pytest.raises(EstimationError, match="black"):
        estimate_grid(np.zeros((50, 50)))


@pytest.fixture(scope="module")
def array():
    s = render("lightfield-array", size=(64, 64), grid="5x5", thin_lens=False,
               disparity_near=0.6, disparity_far=0.1)
    return s, LightField(s.gt_arrays["views"], spacing=1.0, focal_px=s.gt["focal_px"])


def test_novel_view_between_cameras(array):
    s, lf = array
    out = render_view(lf, s.gt["novel_position"])
    assert out.valid.all()
    # Disparities <= 0.6 px/view: half a view step away from the cameras the
    # blended rays are at most 0.3 px apart.
    assert 30 < _psnr(out.image, s.gt_arrays["novel_view"]) < 90
    fast = render_view(lf, s.gt["novel_position"], interpolation="uv-bilinear")
    assert _psnr(fast.image, s.gt_arrays["novel_view"]) > 30


def test_camera_positions_reproduce_views_and_rays_outside_are_invalid(array):
    _, lf = array
    out = render_view(lf, (1.0, -1.0, 0.0), focus_slope=0.3)
    np.testing.assert_allclose(out.image[out.valid], lf.data[1, 3][out.valid], atol=1e-6)
    assert out.valid.all()
    sheared = render_view(lf, (0.5, 0.0, 0.0), focus_slope=0.8)  # samples x +- 0.4 px
    assert not sheared.valid.all() and sheared.valid[:, 1:-1].all()
    far = render_view(lf, (5.0, 0.0, 0.0))
    assert not far.valid.any() and (far.image == 0).all()
    with pytest.raises(ValueError, match="interpolation"):
        render_view(lf, (0, 0, 0), interpolation="cubic")
