"""Light-field depth (lightfield/wang2015.py against the variance baseline):
bounds from the rendered ground truth, the command line, and HCI antinous."""

import numpy as np
from conftest import assert_clean_error, lumigraph, need_shared

from lumigraph.capture.render import render
from lumigraph.lightfield import refocus, wang2015
from lumigraph.lightfield.field import LightField

SLOPES = np.linspace(-0.5, 2.5, 31)        # step 0.1 px/view
STEP = float(SLOPES[1] - SLOPES[0])


def _scene(grid="5x5", size=(96, 72), seed=3):
    s = render("lightfield-array", size=size, grid=grid, seed=seed, thin_lens=False)
    return LightField(s.gt_arrays["views"], spacing=1.0), s.gt_arrays["disparity"]


def _far_from_edges(gt, reach):
    from scipy.ndimage import maximum_filter, minimum_filter

    edge = (maximum_filter(gt, 3) - minimum_filter(gt, 3)) > 1e-3
    return maximum_filter(edge, 2 * reach + 1) == 0


def test_planes_are_exact_away_from_edges_and_silhouettes_beat_the_baseline():
    lf, gt = _scene()
    est = wang2015.estimate_disparity(lf, SLOPES)
    assert est.disparity.shape == gt.shape and est.confidence.shape == gt.shape
    assert 0 <= est.confidence.min() and est.confidence.max() <= 1
    # noise-free planes on the candidate grid: away from an occlusion edge (by
    # the largest parallax over the aperture, 0.8 px/view x 2 views, plus the
    # guided filter's support, twice its radius) the parabola lands within a
    # quarter step
    reach = int(np.ceil(0.8 * 2)) + 2 * wang2015.RADIUS
    far = _far_from_edges(gt, reach)
    far[:reach], far[-reach:], far[:, :reach], far[:, -reach:] = False, False, False, False
    assert far.mean() > 0.2
    assert np.median(np.abs(est.disparity - gt)[far]) < STEP / 4
    # the target: BadPix(0.07) at most half the variance baseline's
    old = refocus.estimate_disparity(lf, SLOPES)
    bad = lambda d: float((np.abs(d - gt) > 0.07).mean())  # noqa: E731
    assert bad(est.disparity) <= 0.5 * bad(old.disparity)


def test_confidence_is_low_where_there_is_no_parallax_information():
    lf, _ = _scene(size=(48, 40))
    flat = LightField(np.full_like(lf.data, 0.3), spacing=1.0)
    est = wang2015.estimate_disparity(flat, SLOPES, median_radius=0)
    assert est.confidence.max() < 1e-3


def test_cli_writes_disparity_and_confidence_and_keeps_the_old_method(tmp_path):
    from lumigraph.capture.io import read_pfm

    scene_dir = tmp_path / "scene"
    render("lightfield-array", size=(64, 48), grid="3x3", thin_lens=False).save(scene_dir)
    lf = tmp_path / "lf"
    assert lumigraph("lightfield", "import", scene_dir, "--out", lf).returncode == 0
    r = lumigraph("lightfield", "depth", lf, "--slopes=-0.5,2.5,31", "--confidence",
                  tmp_path / "c.pfm", "--out", tmp_path / "d.pfm")
    assert r.returncode == 0, r.stderr
    c = read_pfm(tmp_path / "c.pfm")
    assert c.shape == read_pfm(tmp_path / "d.pfm").shape and 0 <= c.min() and c.max() <= 1
    r = lumigraph("lightfield", "depth", lf, "--slopes=-0.5,2.5,31", "--method", "variance",
                  "--window", "5", "--out", tmp_path / "v.pfm")
    assert r.returncode == 0, r.stderr
    r = lumigraph("lightfield", "depth", lf, "--slopes=-0.5,2.5,31", "--window", "5",
                  "--out", tmp_path / "w.pfm")
    assert_clean_error(r, "--window", "variance")
    assert not (tmp_path / "w.pfm").exists()


def test_hci_antinous_beats_the_baseline():
    """Real-data check (held out: nothing was tuned on it). Centre 160x160 crop
    to keep the test short; the issue's targets on the whole view are in the
    bench (BadPix 0.07 <= 20 % and MSE x 100 <= 5, both met since round 6:
    docs/decisions/lightfield-depth.md), so here only the comparison with the
    baseline on the same input is asserted."""
    from lumigraph.capture.io import read_image, read_pfm
    from lumigraph.lightfield.field import from_images

    root = need_shared("data", "lightfield-real", "hci_antinous_5x5")
    crop = (slice(176, 336), slice(176, 336))
    names = [root / f"input_Cam{9 * r + c:03d}.png" for r in range(2, 7) for c in range(2, 7)]
    lf = from_images([read_image(n)[crop] for n in names], grid=(5, 5), spacing=1.0)
    gt = read_pfm(root / "gt_disp_lowres.pfm")[crop]
    slopes = np.linspace(-3.3, 2.9, 63)
    new = wang2015.estimate_disparity(lf, slopes).disparity
    old = refocus.estimate_disparity(lf, slopes).disparity
    b = 15   # the HCI evaluation's boundary offset
    err = lambda d: (d - gt)[b:-b, b:-b]  # noqa: E731
    assert (np.abs(err(new)) > 0.07).mean() < (np.abs(err(old)) > 0.07).mean()


def test_coarse_to_fine_matches_the_full_sweep_on_planes():
    """Every 2nd candidate then per-pixel fine samples: on noise-free planes,
    away from occlusion edges, within a quarter candidate step of the truth,
    as the sweep over every candidate is; a stride below 1 is refused."""
    import pytest

    from lumigraph.capture.errors import InputError

    lf, gt = _scene(size=(64, 48))
    reach = int(np.ceil(0.8 * 2)) + 2 * wang2015.RADIUS + 2
    far = _far_from_edges(gt, reach)
    far[:reach], far[-reach:], far[:, :reach], far[:, -reach:] = False, False, False, False
    for stride in (1, 2):
        est = wang2015.estimate_disparity(lf, SLOPES, stride=stride, median_radius=0)
        assert np.median(np.abs(est.disparity - gt)[far]) < STEP / 4
    with pytest.raises(InputError, match="stride"):
        wang2015.estimate_disparity(lf, SLOPES, stride=0)


def test_unfatten_gives_the_dark_background_back_and_keeps_the_foreground():
    from lumigraph.lightfield.bench import dark_background_scene

    # the bench's dark-background kind (its failure mode is HCI antinous's);
    # seed 7 is neither a tuning nor a reported seed
    lf, gt = dark_background_scene(7, size=(96, 72))
    on = wang2015.estimate_disparity(lf, SLOPES).disparity
    off = wang2015.estimate_disparity(lf, SLOPES, halo_radius=0).disparity
    # fattened: a background pixel given a nearer plane's disparity (the planes
    # are >= 0.7 px/view apart, so half of that separates the two)
    fat = lambda d: int(((d - gt) > 0.35).sum())  # noqa: E731
    assert fat(off) > 0 and fat(on) < fat(off)
    # and what it moves to the far side is, on the whole, background: fewer
    # bad pixels (HCI BadPix(0.07)) than without it
    bad = lambda d: int((np.abs(d - gt) > 0.07).sum())  # noqa: E731
    assert bad(on) < bad(off)



def test_differences_within_half_a_code_are_no_evidence():
    # 8-bit input (the reference's gamma-encoded values on a grid of codes):
    # a view that differs from it by less than half a code everywhere matches
    # it exactly (up to float32 rounding of values ~1: a few 1e-7); by more
    # than half a code it does not (0.1 code left, ~4e-4)
    rng = np.random.default_rng(0)
    codes = rng.integers(40, 200, (32, 40, 3)) / 255.0        # gamma-encoded (sqrt) values
    step = 1 / 255
    for frac, zero in ((0.4, True), (0.6, False)):
        views = np.stack([codes + frac * step, codes, codes - frac * step])[None] ** 2  # linear
        lf = LightField(views.astype(np.float32), spacing=1.0)
        assert abs(wang2015.quantisation_step(np.sqrt(lf.data[0, 1])) - step) < 1e-6
        cost, _ = wang2015._matcher(lf)
        assert (float(cost(0.0, filtered=False).max()) < 1e-6) == zero


def test_refill_keeps_a_slanted_plane_and_still_removes_an_outlier():
    # a weighted median is biased on a slope (its colour weights pick values
    # from other rows); where the window holds no depth edge, step 6 fits a
    # plane instead, and a plane is its fixed point (up to float32 rounding
    # of values ~2: 1e-6), whatever the colours; an isolated outlier (a 3 x 3
    # median removes it) does not stop the fit and is replaced by the plane
    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:60, 0:80]
    plane = (0.2 + 0.055 * y - 0.01 * x).astype(np.float32)   # antinous's floor slope
    guide = rng.random((60, 80, 3)).astype(np.float32)
    conf = rng.random((60, 80)).astype(np.float32)
    noisy = plane.copy()
    noisy[30, 40] += 1.0
    out = wang2015.refill(noisy, conf, guide)
    assert np.abs(out - plane).max() < 1e-5
    med = wang2015.refill(plane, conf, guide, plane_jump=0)     # the median alone
    assert np.abs(med - plane).max() > 0.055                   # at least one row off


def test_slanted_floor_scene_beats_the_baseline():
    from lumigraph.lightfield.bench import slanted_floor_scene

    # the bench's kind S (a shaded ellipse before a dark wall and a floor
    # slanting 0.055 px/view per row, supersampled silhouettes); seed 7 is
    # neither a tuning nor a reported seed: the target, BadPix(0.07)
    # at most half the variance baseline's
    lf, gt = slanted_floor_scene(7, size=(96, 72))
    new = wang2015.estimate_disparity(lf, SLOPES).disparity
    old = refocus.estimate_disparity(lf, SLOPES).disparity
    bad = lambda d: float((np.abs(d - gt) > 0.07)[15:-15, 15:-15].mean())  # noqa: E731
    assert bad(new) <= 0.5 * bad(old)


def test_despeckle_replaces_isolated_errors_and_keeps_slopes_and_edges():
    # step 7b: on a slanted plane (antinous's floor slope) with a straight
    # depth edge, isolated gross errors (1 and 2 px) go back onto the plane
    # and nothing else moves. The bound is the plane's own: with n of the 25
    # window values wrong (a k x k speck: n = k^2), the median lies within n
    # ranks of the clean window's median, i.e. within the spread of its
    # middle 2n + 1 values, widened by the noise's full range (0.2).
    y, x = np.mgrid[0:40, 0:60]
    plane = (0.2 + 0.055 * y - 0.01 * x).astype(np.float32)
    truth = np.where(x >= 40, np.float32(2.5), plane)
    noise = np.random.default_rng(3).uniform(-0.1, 0.1, truth.shape).astype(np.float32)
    d = truth + noise                                  # small errors: below the edge step
    specks = [(10, 10, 1), (20, 20, 2), (30, 12, 1)]   # (row, column, size)
    for r, c, k in specks:
        d[r:r + k, c:c + k] = -2.0 if k == 1 else 2.4
    out = wang2015.despeckle(d)
    clean = np.sort((0.055 * np.arange(-2, 3)[:, None] - 0.01 * np.arange(-2, 3)).ravel())
    for r, c, k in specks:
        spread = clean[12 + k * k] - clean[12 - k * k] + 0.2     # + the noise's full range
        assert np.abs(out[r:r + k, c:c + k] - plane[r:r + k, c:c + k]).max() <= spread
    speck = np.zeros(d.shape, bool)
    for r, c, k in specks:
        speck[r:r + k, c:c + k] = True
    # everything else within the noise: the slope, the edge, the small errors
    assert np.array_equal(out[~speck], d[~speck])


def test_despeckle_removes_gross_floor_errors_of_the_dim_floor_scene(monkeypatch):
    from lumigraph.lightfield.bench import dim_floor_scene

    # the bench's kind F (dim, partly texture-less 8-bit floor with sensor
    # noise: flat cost curves leave isolated gross errors); seed 7 is neither
    # a tuning nor a reported seed. Gross = off by more than the depth-edge
    # step (0.3 px/view) away from the silhouette, on the floor and wall
    lf, gt = dim_floor_scene(7, size=(96, 72))
    with_7b = wang2015.estimate_disparity(lf, SLOPES).disparity
    monkeypatch.setattr(wang2015, "SPECKLE", 0)
    without = wang2015.estimate_disparity(lf, SLOPES).disparity
    import cv2
    edge = (cv2.dilate(gt, np.ones((5, 5))) - cv2.erode(gt, np.ones((5, 5)))) > 0.3
    region = ~edge
    region[:15], region[-15:], region[:, :15], region[:, -15:] = False, False, False, False

    def gross(d):
        return int((np.abs(d - gt)[region] > 0.3).sum())

    def mse(d):
        return float(((d - gt)[15:-15, 15:-15] ** 2).mean())

    assert gross(with_7b) < gross(without)
    assert mse(with_7b) < mse(without)
