"""View-dependent texture mapping: a photograph's own view is a copy of it; a
diffuse surface is reproduced within the bilinear resampling error."""

from __future__ import annotations

import numpy as np
import pytest

from lumigraph.capture.errors import InputError
from lumigraph.capture.raster import pixel_rays, rasterize
from lumigraph.capture.render import render
from lumigraph.capture.scenes.facade import Building
from lumigraph.stereo.debevec1996.vdtm import (
    Photograph,
    fill_holes,
    prepare_photographs,
    render_vdtm,
)

SIZE = (96, 72)


@pytest.fixture(scope="module")
def facade():
    s = render("facade", size=SIZE, seed=5, photos=6, novel=1, supersample=1)
    b = Building(s.gt["parameters"]).mesh()
    mesh = (b.vertices, b.faces)
    photos = prepare_photographs(mesh, [
        Photograph(im.astype(np.float32), np.array(c["K"]), np.array(c["R"]), np.array(c["t"]))
        for im, c in zip(s.images, s.gt["cameras"].values(), strict=True)])
    return s, mesh, photos


@pytest.mark.parametrize("method", ["blend", "view-map"])
def test_own_view_is_a_copy(facade, method):
    s, mesh, photos = facade
    for j in (0, 3):
        p = photos[j]
        out = render_vdtm(mesh, photos, p.K, p.R, p.t, SIZE, method=method)
        m = out.model
        assert m.sum() > 500 and not out.filled[m].any()
        # within 8-bit rounding of the photograph itself
        assert np.abs(np.rint(out.image[m]) - p.image[m]).max() == 0


def _plane_photos(f, cams, V, F):
    """Images of the plane (V, F) whose radiance is ``f(X)``, point-sampled
    at pixel centres (no noise): bilinear interpolation is then the only error."""
    photos = []
    for K, R, t in cams:
        r = rasterize(V, F, K, R, t, SIZE)
        X = r.points(V, F)
        img = np.where(r.hit[..., None], f(np.nan_to_num(X)), 0.0)
        photos.append(Photograph(img.astype(np.float64), K, R, t))
    return photos


def _look(C, target):
    fwd = (target - C) / np.linalg.norm(target - C)
    right = np.cross(fwd, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    R = np.stack([right, np.cross(fwd, right), fwd])
    return R, -R @ C


def test_lambertian_within_the_bilinear_bound():
    # a wall x in [-4, 4], z in [0, 5] at y = 0 with a smooth texture
    V = np.array([[-4.0, 0, 0], [4, 0, 0], [4, 0, 5], [-4, 0, 5]])
    F = np.array([[0, 1, 2], [0, 2, 3]])
    K = np.array([[70.0, 0, 47.5], [0, 70.0, 35.5], [0, 0, 1]])

    def f(X):
        return np.stack([100 + 60 * np.sin(0.9 * X[..., 0]) * np.cos(0.7 * X[..., 2]),
                         120 + 50 * np.cos(1.3 * X[..., 0] + 0.4 * X[..., 2]),
                         90 + 40 * np.sin(0.8 * X[..., 2])], -1)

    target = np.array([0.0, 0, 2.5])
    cams = [_look(np.array([12 * np.sin(a), -12 * np.cos(a), 2.5 + 1.5 * np.sin(3 * a)]), target)
            for a in np.radians([-40, -15, 10, 35])]
    photos = prepare_photographs((V, F), [Photograph(p.image, p.K, p.R, p.t)
                                          for p in _plane_photos(f, [(K, R, t) for R, t in cams], V, F)])
    # the bound: linear interpolation along x, then along y, errs by at most
    # (max|g_xx| + max|g_yy|) / 8 at one pixel spacing, g the photograph (its second
    # differences inside the wall); a weighted mean of samples errs by at most the
    # largest photograph's bound
    bound = 0.0
    for p in photos:
        g, inner = p.image, np.isfinite(p.depth)
        gyy = np.abs(g[2:] - 2 * g[1:-1] + g[:-2])[inner[2:] & inner[1:-1] & inner[:-2]]
        gxx = np.abs(g[:, 2:] - 2 * g[:, 1:-1] + g[:, :-2])[inner[:, 2:] & inner[:, 1:-1] & inner[:, :-2]]
        bound = max(bound, (gxx.max() + gyy.max()) / 8)
    for a in np.radians([-27, 22]):
        R, t = _look(np.array([11 * np.sin(a), -11 * np.cos(a), 3.0]), target)
        truth_r = rasterize(V, F, K, R, t, SIZE)
        truth = f(truth_r.points(V, F))
        for method in ("blend", "view-map"):
            out = render_vdtm((V, F), photos, K, R, t, SIZE, method=method)
            m = out.model & ~out.filled
            assert m.sum() > 0.9 * truth_r.hit.sum()
            err = np.abs(out.image[m] - truth[m])
            assert err.max() <= bound, (method, err.max(), bound)


def test_share_seen_by_one_photograph():
    """A wall photographed whole from the front and, from its left, only as
    far as x = 1.4 m: where the second photograph's frame ends, one
    photograph alone sees the wall, and the rendering (either method) says
    how much of the view that is (there its colour cannot follow the view)."""
    V = np.array([[-4.0, 0, 0], [4, 0, 0], [4, 0, 5], [-4, 0, 5]])
    F = np.array([[0, 1, 2], [0, 2, 3]])
    K = np.array([[70.0, 0, 47.5], [0, 70.0, 35.5], [0, 0, 1]])
    whole = _look(np.array([0.0, -12, 2.5]), np.array([0.0, 0, 2.5]))
    left = _look(np.array([-4.0, -8, 2.5]), np.array([-4.0, 0, 2.5]))  # frame ends near x = 1.4

    def f(X):
        return 100 + 20 * np.sin(X[..., :1])

    photos = prepare_photographs((V, F), [Photograph(p.image, p.K, p.R, p.t) for p in
                                          _plane_photos(f, [(K, *whole), (K, *left)], V, F)])
    R, t = _look(np.array([1.0, -11, 3.0]), np.array([0.0, 0, 2.5]))
    out = render_vdtm((V, F), photos, K, R, t, SIZE)
    r = rasterize(V, F, K, R, t, SIZE)
    X = r.points(V, F)[r.hit]
    # each point's place in the left photograph's frame, which ends half a pixel past
    # the last pixel centre: points beyond it are not seen, points a full cell inside
    # are (the wall is continuous there); the whole wall is in the front one's frame,
    # which sees all of it but the pixels on its rim (their cells reach off the wall:
    # the rendering's holes, seen by none)
    x = (X @ left[0].T + left[1]) @ K.T
    u = x[:, 0] / x[:, 2]
    surely_one, maybe_one = np.mean(u > SIZE[0] - 0.5), np.mean(u > SIZE[0] - 1.5)
    assert 0.2 < surely_one  # the fixture puts a fifth of the view or more in one photograph
    assert surely_one - out.info["hole_fraction"] <= out.info["seen_by_one_fraction"] <= maybe_one
    # the view map's three photographs of the wall are both that see it: its count is
    # exact too, whatever the number blended
    for k in (1, 2):
        vm = render_vdtm((V, F), photos, K, R, t, SIZE, method="view-map", neighbours=k)
        assert surely_one - vm.info["hole_fraction"] <= vm.info["seen_by_one_fraction"] <= maybe_one


def test_holes_are_filled_from_neighbours():
    img = np.zeros((8, 8, 1))
    img[:, :4] = 10.0
    img[:, 4:] = 20.0
    known = np.ones((8, 8), bool)
    known[3:5, 3:5] = False
    out = fill_holes(img * known[..., None], known, np.ones((8, 8), bool))
    assert (out[known] == img[known]).all()
    assert (out[~known] >= 10).all() and (out[~known] <= 20).all()


def test_bad_arguments():
    V = np.array([[-1.0, -1, 4], [1, -1, 4], [0, 1, 4]])
    K = np.array([[20.0, 0, 7.5], [0, 20.0, 5.5], [0, 0, 1]])
    p = Photograph(np.zeros((12, 16, 3)), K, np.eye(3), np.zeros(3))
    with pytest.raises(InputError, match="method"):
        render_vdtm((V, [[0, 1, 2]]), [p], K, np.eye(3), np.zeros(3), (16, 12), method="nearest")
    with pytest.raises(InputError, match="photographs"):
        render_vdtm((V, [[0, 1, 2]]), [], K, np.eye(3), np.zeros(3), (16, 12))
    q = Photograph(np.zeros((12, 16)), K, np.eye(3), np.zeros(3))
    with pytest.raises(InputError, match="channels"):
        render_vdtm((V, [[0, 1, 2]]), [p, q], K, np.eye(3), np.zeros(3), (16, 12))
    assert pixel_rays(K, (16, 12)).shape == (12, 16, 3)


def test_weights_taper_at_the_next_nearest():
    from lumigraph.stereo.debevec1996.vdtm import EPS_RAD, _weights

    th = np.array([[0.1], [0.2], [0.4], [np.inf]])  # the fourth photograph does not see
    w = _weights(th, 1.0, 2)[:, 0]
    expect = [(0.1 + EPS_RAD) ** -1 * (1 - 0.1 / 0.4), (0.2 + EPS_RAD) ** -1 * (1 - 0.2 / 0.4), 0, 0]
    np.testing.assert_allclose(w, expect, rtol=1e-12)
    # every photograph (neighbours 0); two seen: no third to taper at
    np.testing.assert_allclose(_weights(th, 1.0, 0)[:3, 0], (th[:3, 0] + EPS_RAD) ** -1)
    np.testing.assert_allclose(_weights(th[[0, 1, 3]], 1.0, 2)[:2, 0], (th[:2, 0] + EPS_RAD) ** -1)
    # equal angles at the threshold would taper everything away: untapered there
    eq = _weights(np.full((3, 1), 0.3), 1.0, 2)[:, 0]
    assert (eq > 0).all() and np.ptp(eq) == 0


@pytest.mark.parametrize("neighbours", [0, 1, 2])
def test_view_map_is_the_blend_with_three_photographs(facade, neighbours):
    # with three photographs every plane's three are all of them: the view map
    # blends the same photographs with the same weights; only its visibility (per
    # plane, precomputed) and its angles (interpolated over the plane) differ, so
    # most pixels agree within half a code and the whole within the 0.5 dB
    s, mesh, _ = facade
    photos = prepare_photographs(mesh, [
        Photograph(im.astype(np.float32), np.array(c["K"]), np.array(c["R"]), np.array(c["t"]))
        for im, c in list(zip(s.images, s.gt["cameras"].values(), strict=True))[1:4]])
    cam = s.gt["novel_cameras"]["view_0"]
    K, R, t = (np.array(cam[x]) for x in ("K", "R", "t"))
    a = render_vdtm(mesh, photos, K, R, t, SIZE, neighbours=neighbours)
    b = render_vdtm(mesh, photos, K, R, t, SIZE, neighbours=neighbours, method="view-map")
    assert a.model.sum() > 500
    both = a.model & ~a.filled & ~b.filled
    assert both.sum() > 0.9 * a.model.sum()
    assert np.median(np.abs(b.image - a.image).max(2)[both]) <= 0.5
    gt, m = s.gt_arrays["novel_0"], s.gt_arrays["novel_model_0"]

    def psnr(x):
        return 10 * np.log10(255.0 ** 2 / np.mean((x.image[m] - gt[m]) ** 2))

    assert abs(psnr(b) - psnr(a)) <= 0.5


def test_push_pull_on_tiles_equals_the_whole_pyramid():
    # the tiles holding holes carry every block a hole's value depends on: the same
    # values as the pyramid over the whole box (the same float operations)
    from lumigraph.stereo.debevec1996.vdtm import _push_pull, _push_pull_full

    rng = np.random.default_rng(3)
    for _ in range(60):
        h, w = rng.integers(1, 70, 2)
        known = rng.random((h, w)) < rng.random() ** 2
        hole = ~known & (rng.random((h, w)) < 0.5)
        if not hole.any() or not known.any():
            continue
        img = rng.random((h, w, 3)).astype(np.float32)
        np.testing.assert_array_equal(_push_pull(img, known, hole), _push_pull_full(img, known, hole))


def test_zbuffer_leaves_out_faces_turned_away_with_the_same_result(facade):
    # the building is a union of closed outward-facing blocks: from outside, the
    # faces turned away never show; from inside a block, or for an open mesh, every
    # face is drawn
    from lumigraph.stereo.debevec1996.vdtm import _outward_solids, _zbuffer

    s, mesh, photos = facade
    v, f = (np.asarray(a) for a in mesh)
    assert _outward_solids(v, f) and not _outward_solids(v, f[1:])
    for p in photos[:3]:
        a = rasterize(v, f, p.K, p.R, p.t, SIZE, bary=False)
        b = _zbuffer(v, f, p.K, np.asarray(p.R), np.asarray(p.t), SIZE, None)
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.face, b.face)
    inside = v[f[:12].ravel()].mean(0)  # the house's centre (its box: the first 12 faces)
    K = photos[0].K
    R = np.eye(3)
    a = rasterize(v, f, K, R, -R @ inside, SIZE, bary=False)
    b = _zbuffer(v, f, K, R, -R @ inside, SIZE, None)
    assert a.hit.any()
    np.testing.assert_array_equal(a.face, b.face)
    # with labels (the view map's planes): each pixel's triangle's label
    labels = np.arange(len(f)) % 5 + 10
    for R_, t_ in ((np.asarray(photos[1].R), np.asarray(photos[1].t)), (R, -R @ inside)):
        a = _zbuffer(v, f, K, R_, t_, SIZE, None)
        b = _zbuffer(v, f, K, R_, t_, SIZE, None, labels=labels)
        np.testing.assert_array_equal(b.face, np.where(a.hit, labels[np.maximum(a.face, 0)], -1))
        np.testing.assert_array_equal(a.covered, b.covered)


def test_view_map_planes_chosen_for_the_view_and_background(facade):
    # choosing the three for a subset of the planes gives those planes' rows of the
    # whole choice; off the model and at unfilled holes the view map leaves the
    # background, elsewhere the same values whatever the background
    s, mesh, photos = facade
    from lumigraph.stereo.debevec1996.vdtm import prepare_view_maps

    maps = prepare_view_maps(mesh, photos)
    cam = s.gt["novel_cameras"]["view_0"]
    K, R, t = (np.array(cam[x]) for x in ("K", "R", "t"))
    C = -R.T @ t
    every = maps.choose_planes(C)
    some = np.arange(0, len(maps.planes), 2)
    part = maps.choose_planes(C, planes=some)
    np.testing.assert_array_equal(part[some], every[some])
    assert (np.delete(part, some, 0) == -1).all()
    a = render_vdtm(mesh, photos, K, R, t, SIZE, method="view-map", maps=maps, fill=False)
    b = render_vdtm(mesh, photos, K, R, t, SIZE, method="view-map", maps=maps, fill=False,
                    background=7.0)
    holes = render_vdtm(mesh, photos, K, R, t, SIZE, method="view-map", maps=maps).filled
    seen = a.model & ~holes  # (fill=False reports no holes)
    assert seen.sum() > 500 and holes.any()
    np.testing.assert_array_equal(a.image[seen], b.image[seen])
    assert (b.image[~seen] == 7.0).all() and (a.image[~seen] == 0.0).all()


def test_view_map_any_number_of_channels(facade):
    # the warps take at most four channels a call: five channels are the three
    # and two more, blended alike; one channel (a 2-D image) is the first
    s, mesh, photos = facade
    cam = s.gt["novel_cameras"]["view_0"]
    K, R, t = (np.array(cam[x]) for x in ("K", "R", "t"))
    five = prepare_photographs(mesh, [
        Photograph(np.concatenate([p.image, p.image[..., :2] * 0.5], 2), p.K, p.R, p.t)
        for p in photos])
    grey = prepare_photographs(mesh, [Photograph(p.image[..., 0], p.K, p.R, p.t) for p in photos])
    a = render_vdtm(mesh, photos, K, R, t, SIZE, method="view-map")
    b = render_vdtm(mesh, five, K, R, t, SIZE, method="view-map")
    c = render_vdtm(mesh, grey, K, R, t, SIZE, method="view-map")
    assert b.image.shape[2] == 5 and c.image.shape[2] == 1
    np.testing.assert_allclose(b.image[..., :3], a.image, rtol=1e-5, atol=1e-3)
    np.testing.assert_allclose(b.image[..., 3:], 0.5 * a.image[..., :2], rtol=1e-5, atol=1e-3)
    np.testing.assert_allclose(c.image[..., 0], a.image[..., 0], rtol=1e-5, atol=1e-3)
