"""Hard cases for lightfield/: out-of-range refocus, degenerate and non-square
grids, rotated hexagonal lenslets, bad input."""

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture.errors import InputError
from lumigraph.capture.render import render
from lumigraph.lightfield import ng2005
from lumigraph.lightfield.field import LightField
from lumigraph.lightfield.lenslet import decode
from lumigraph.lightfield.refocus import check_refocus_range, shift_and_add


def _psnr(a, b):
    return 10 * np.log10(1.0 / np.mean((a.astype(np.float64) - b) ** 2))


def _sinc_shift_and_add(lf, slope, pad, shape):
    """Shift-and-add with exact Fourier (sinc) shifts of mirror-padded views:
    what the Fourier slice theorem says the Fourier method computes."""
    import scipy.fft as sfft

    u, v = lf.grid
    uc, vc = lf.center
    acc = 0.0
    for i in range(u):
        for j in range(v):
            h, w = lf.data.shape[2:4]
            img = np.pad(lf.data[i, j].astype(np.float64),
                         ((pad, shape[0] - h - pad), (pad, shape[1] - w - pad), (0, 0)),
                         mode="symmetric")
            f = sfft.fft2(img, axes=(0, 1))
            ky, kx = sfft.fftfreq(img.shape[0]), sfft.fftfreq(img.shape[1])
            ph = np.exp(-2j * np.pi * slope * (ky[:, None] * (i - uc) + kx[None, :] * (j - vc)))
            acc = acc + sfft.ifft2(f * ph[..., None], axes=(0, 1)).real[pad:pad + h, pad:pad + w]
    return acc / (u * v)


@pytest.mark.parametrize("grid", ["2x2", "1x5", "3x1", "2x5"])
def test_small_and_non_square_grids_refocus_to_truth(grid):
    s = render("lightfield-array", size=(48, 40), grid=grid, thin_lens=False, focus=(0.3, 0.9))
    lf = LightField(s.gt_arrays["views"], spacing=1.0, focal_px=48.0)
    spec = ng2005.prepare(lf, max_slope=0.9)
    for k, slope in enumerate((0.3, 0.9)):
        gt = s.gt_arrays["synthetic_aperture"][k]
        sa, base = shift_and_add(lf, slope), shift_and_add(lf, slope, kernel="linear")
        # Even grids have half-integer offsets (2x2: shifts of +-slope/2), so
        # every view is interpolated; the same bounds as the 5x5 case hold.
        assert _psnr(sa, gt) > max(_psnr(base, gt), 38), grid
        # The Fourier slice equals sinc-interpolated shift-and-add up to its
        # kernel's aliasing (< 1e-3 of full scale at oversampling 1.5, 4 taps)
        # for even, odd and one-view axes alike. (Sinc interpolation rings at
        # occlusion edges: on views this small it can fall below bilinear,
        # while at 512x512 it beats Lanczos; see the bench.)
        ref = _sinc_shift_and_add(lf, slope, spec.pad[0], spec.shape_p)
        assert np.abs(ng2005.refocus(spec, slope, interpolation="sinc") - ref).max() < 2e-3, grid


def test_alpha_outside_refocusable_range_warns_with_the_bound():
    lf = LightField(np.zeros((9, 9, 4, 4, 1)), spacing=1.0, focal_px=4.0)
    assert check_refocus_range(lf, [lf.slope_from_alpha(1.1)]) == []
    (w,) = check_refocus_range(lf, [lf.slope_from_alpha(0.5)])
    assert "alpha 0.5" in w and "|1 - 1/alpha| <= dx/du = 0.1111" in w


def test_rotated_hexagonal_lenslets_meet_the_bounds():
    s = render("lightfield-lenslet-hex", size=(24, 24), rotation_deg=-7.0, pitch=25.3,
               view_step_px=3.2)
    d = decode(*s.images, views=5)
    err = np.linalg.norm(d.grid.centers() - s.gt_arrays["centers"], axis=-1)
    assert d.grid.lattice == "hex" and err.max() < 0.1
    truth = s.gt_arrays["views_rect"]
    assert 35 < 10 * np.log10(truth.max() ** 2 / np.mean((d.lightfield.data - truth) ** 2))


def test_impossible_grids_and_options_are_refused(tmp_path):
    # the library names the scene's argument; the command line its flag
    with pytest.raises(InputError, match="^grid: "):
        render("lightfield-array", grid="1x1", cache=False)
    with pytest.raises(InputError, match="^view_step_px: "):
        render("lightfield-lenslet", size=(10, 10), view_step_px=5.0, cache=False)
    r = lumigraph("render", "lightfield-array", "--out", tmp_path / "x", "--grid", "0x3", "-q")
    assert_clean_error(r, "--grid")
    assert not (tmp_path / "x" / "stack.json").exists()
    r = lumigraph("render", "lightfield-lenslet", "--out", tmp_path / "y", "--size", "16x16",
                  "--view-step-px", "5", "-q")
    assert_clean_error(r, "--view-step-px", "do not fit")


# ------------------------------------------------------------------ depth
def _depth_scene(grid):
    s = render("lightfield-array", size=(80, 60), grid=grid, seed=5, thin_lens=False)
    return LightField(s.gt_arrays["views"], spacing=1.0), s.gt_arrays["disparity"]


@pytest.mark.parametrize("grid,cross", [("5x5", False), ("9x9", False), ("9x9", True)])
def test_depth_on_5x5_9x9_and_cross_shaped_sets(grid, cross):
    """Depth (wang2015) on a 5x5 and a 9x9 grid and on the central row and
    column of a 9x9 grid: within a quarter candidate step of the planes away
    from occlusion edges (largest parallax over the aperture plus the guided
    filter's support), BadPix(0.07) at most half the variance baseline's."""
    from scipy.ndimage import maximum_filter, minimum_filter

    from lumigraph.lightfield import refocus, wang2015

    lf, gt = _depth_scene(grid)
    slopes = np.linspace(-0.5, 2.5, 31)
    u, v = lf.grid
    views = None
    if cross:
        views = np.zeros((u, v), bool)
        views[u // 2], views[:, v // 2] = True, True
    est = wang2015.estimate_disparity(lf, slopes, views=views)
    reach = int(np.ceil(0.8 * (max(u, v) - 1) / 2)) + 2 * wang2015.RADIUS
    edge = (maximum_filter(gt, 3) - minimum_filter(gt, 3)) > 1e-3
    far = maximum_filter(edge, 2 * reach + 1) == 0
    far[:reach], far[-reach:], far[:, :reach], far[:, -reach:] = False, False, False, False
    err = np.abs(est.disparity - gt)
    assert np.median(err[far]) < 0.1 / 4
    old = refocus.estimate_disparity(lf, slopes)
    assert (err > 0.07).mean() <= 0.5 * (np.abs(old.disparity - gt) > 0.07).mean()


def test_cross_shaped_import_is_refused_and_masks_are_checked(tmp_path):
    from lumigraph.capture.io import write_image
    from lumigraph.lightfield import wang2015

    # a cross (9 of a 5x5 grid's views) is not a light-field folder: refused
    files = []
    for k in range(9):
        files.append(tmp_path / f"v{k}.png")
        write_image(files[-1], np.full((8, 10, 3), 20 * k, np.uint8))
    r = lumigraph("lightfield", "import", *files, "--grid", "5x5", "--spacing", "1",
                  "--out", tmp_path / "lf")
    assert_clean_error(r, "--grid", "needs 25 images, got 9")
    lf = LightField(np.zeros((3, 3, 8, 8, 3)), spacing=1.0)
    with pytest.raises(InputError, match="^views: "):
        wang2015.estimate_disparity(lf, [0, 1, 2], views=np.ones((2, 3), bool))
    no_centre = np.ones((3, 3), bool)
    no_centre[1, 1] = False
    with pytest.raises(InputError, match="^views: .*central"):
        wang2015.estimate_disparity(lf, [0, 1, 2], views=no_centre)


def test_a_light_field_with_one_missing_view_is_refused(tmp_path):
    """Hard case: one view of the array missing, as files given to `import`
    or as a light-field folder that lost one: exit 2, one line, naming it."""
    import shutil
    from pathlib import Path

    src = Path(__file__).resolve().parents[2] / "fixtures" / "lightfield"
    views = sorted(src.glob("view-*.exr"))
    r = lumigraph("lightfield", "import", *views[:-1], "--grid", "3x3", "--out", tmp_path / "a",
                  "-q")
    assert_clean_error(r, "--grid", "needs 9 images, got 8")
    assert not (tmp_path / "a").exists()
    lf = tmp_path / "lf"
    shutil.copytree(src, lf)
    (lf / "view-01-02.exr").unlink()
    r = lumigraph("lightfield", "refocus", lf, "--slope", "0.5", "--out", tmp_path / "r.exr", "-q")
    assert_clean_error(r, "lightfield.json", "view-01-02.exr")
    assert not (tmp_path / "r.exr").exists()


def test_refocus_beyond_the_depth_of_field_says_so(tmp_path):
    """Hard case: a slope outside the range the aperture's sampling refocuses
    exactly is done, with a warning on stderr naming the bound."""
    import shutil
    from pathlib import Path

    lf = tmp_path / "lf"
    shutil.copytree(Path(__file__).resolve().parents[2] / "fixtures" / "lightfield", lf)
    r = lumigraph("lightfield", "refocus", lf, "--alpha", "0.5", "--out", tmp_path / "r.exr")
    assert r.returncode == 0, r.stderr
    assert "warning:" in r.stderr and "alpha 0.5" in r.stderr and (tmp_path / "r.exr").exists()
