"""Independent checks of the light-field scenes' ground truth (capture issue, family 4)."""

import numpy as np

from lumigraph.capture.render import render
from lumigraph.capture.scenes.lightfield import (
    build_scene,
    synthetic_aperture,
    thin_lens_image,
    view_offsets,
)
from lumigraph.lightfield.lenslet import LensletGrid, devignette, slice_views


def _scene(disparities, size=48):
    return build_scene(np.random.default_rng(3), width=size, height=size, f=float(size),
                       spacing=1.0, disparities=np.asarray(disparities), texel_px=1.5, reach=4.0)


def test_views_of_one_plane_are_integer_shifts_of_each_other():
    # One plane at disparity exactly 2 px/view: view (u, v) is the centre view
    # moved by (-2 (v - vc), -2 (u - uc)) px, exactly (a different camera, a
    # different footprint of the same texture: an independent check of the
    # projection and of the disparity sign convention).
    sc = _scene([2.0])
    xs = np.arange(48.0)
    centre = sc.render(0.0, xs, 0.0, xs)
    right_below = sc.render(1.0, xs, 1.0, xs)          # view (uc + 1, vc + 1)
    np.testing.assert_allclose(right_below[5:-5, 5:-5], centre[7:-3, 7:-3], atol=1e-9)


def test_synthetic_aperture_is_the_average_of_shifted_renders():
    sc = _scene([1.0, 0.6, 0.2])
    s = 0.43
    literal = np.mean([sc.render(ov, np.arange(48.0) - s * ov, ou, np.arange(48.0) - s * ou)
                       for ou in view_offsets(3) for ov in view_offsets(4)], 0)
    fast = synthetic_aperture(sc, 3, 4, 1.0, s, 48, 48)
    np.testing.assert_allclose(fast, literal, atol=1e-12)


def test_thin_lens_sharp_at_its_focus_and_close_to_the_array_average():
    sc = _scene([0.5])
    xs = np.arange(48.0)
    centre = sc.render(0.0, xs, 0.0, xs)
    tl = thin_lens_image(sc, 5, 5, 1.0, 0.5, 48, 48)
    np.testing.assert_allclose(tl, centre, atol=1e-9)   # in focus: the pinhole image
    tl0 = thin_lens_image(sc, 5, 5, 1.0, 0.0, 48, 48)    # defocused by 0.5 px/view
    sa0 = synthetic_aperture(sc, 5, 5, 1.0, 0.0, 48, 48)
    # Midpoint rule of the same aperture integral: close but not equal.
    d = np.abs(tl0 - sa0)[6:-6, 6:-6]
    assert 0 < d.max() < 0.02


def test_array_scene_depth_matches_planes_and_rendering_is_deterministic():
    a = render("lightfield-array", size=(40, 32), grid="3x3", thin_lens=False, cache=False)
    b = render("lightfield-array", size=(40, 32), grid="3x3", thin_lens=False, cache=False)
    assert all(np.array_equal(x, y) for x, y in zip(a.images, b.images, strict=True))
    depths = np.array([p["depth"] for p in a.gt["planes"]])
    found = np.unique(a.gt_arrays["depth"])
    assert len(found) == len(depths)             # every plane is seen somewhere
    np.testing.assert_allclose(np.sort(found), np.sort(depths), rtol=1e-6)
    np.testing.assert_allclose(a.gt_arrays["disparity"] * a.gt_arrays["depth"],
                               a.gt["focal_px"] * a.gt["spacing"], rtol=1e-6)


def _gt_grid(s):
    g = s.gt
    th = np.radians(g["rotation_deg"])
    rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    basis = g["pitch_px"] * rot @ np.diag([1.0, np.sqrt(3) / 2 if g["lattice"] == "hex" else 1.0])
    n = g["views"][0]
    return LensletGrid(np.array(g["origin_px"]), basis, g["lattice"], g["hex_odd_shift"],
                       g["rows"], g["cols"], n * g["view_step_px"], 0.0)


def test_lenslet_raw_resliced_with_the_gt_grid_reproduces_the_views():
    for name in ("lightfield-lenslet", "lightfield-lenslet-hex"):
        s = render(name, size=(14, 12))
        grid = _gt_grid(s)
        np.testing.assert_allclose(grid.centers(), s.gt_arrays["centers"], atol=1e-9)
        views = slice_views(devignette(*s.images), grid, s.gt["views"][0])
        truth = s.gt_arrays["views"]
        # 12-bit quantisation of raw and white: |err| <= (1/2)/(w 3890) per
        # code, with w >= 0.45 (vignetting x falloff): < 6e-4 relative, plus the
        # ratio's own rounding.
        err = np.abs(views - truth) / np.maximum(truth, 1e-3)
        assert 0 < err.max() < 2e-3, name
