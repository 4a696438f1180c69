"""The reflection layer of VDTM (stereo/debevec1996/reflection.py): a glossy
plane whose colour is a texture plus a function of the mirror direction,
rendered exactly, photographed from five places and seen from a sixth."""

import numpy as np
import pytest

from lumigraph.capture.errors import InputError
from lumigraph.stereo.debevec1996.reflection import fit_reflection_layer
from lumigraph.stereo.debevec1996.vdtm import Photograph, prepare_photographs, render_vdtm

W, H, F = 64, 48, 50.0
K = np.array([[F, 0, (W - 1) / 2], [0, F, (H - 1) / 2], [0, 0, 1]])
QUAD = (np.array([[-3.0, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]]), np.array([[0, 1, 2], [0, 2, 3]]))
A_TEX, L_TEX_PX = 40.0, 40.0  # texture amplitude (codes) and wavelength in pixels at the photographs
K_TEX = 2 * np.pi / (L_TEX_PX * 6.5 / F)  # rad per metre: 6.5 m from the plane, F px per unit
SX, SY = 60.0, 40.0  # the layer: codes per unit of the mirror direction's x and y


def pose(C):
    """cam_from_world of a camera at ``C`` looking at the origin, y down."""
    C = np.asarray(C, float)
    z = -C / np.linalg.norm(C)
    x = np.cross([0, 1.0, 0], z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return R, -R @ C


def shade(C, glossy=True, patch=0.0):
    """The exact image from ``C``: texture + (glossy) the layer at the hit
    point, except on a matte square ``|X|, |Y| < patch`` (another material)."""
    R, t = pose(C)
    yy, xx = np.mgrid[0:H, 0:W]
    ray = np.stack([(xx - K[0, 2]) / F, (yy - K[1, 2]) / F, np.ones_like(xx, float)], -1) @ R
    lam = -np.asarray(C)[2] / ray[..., 2]
    X = np.asarray(C) + lam[..., None] * ray
    d = ray / np.linalg.norm(ray, axis=-1, keepdims=True)
    img = 100 + A_TEX * np.sin(K_TEX * X[..., 0]) * np.cos(K_TEX * X[..., 1])
    if glossy:  # the mirror direction about z: (dx, dy, -dz); S linear in its x, y
        matte = (np.abs(X[..., 0]) < patch) & (np.abs(X[..., 1]) < patch)
        img = img + np.where(matte, 0.0, SX * d[..., 0] + SY * d[..., 1])
    return img[..., None], X


PHOTOS = [(-3.0, -2.0, 6.0), (-1.5, -2.5, 6.0), (0.0, -2.0, 6.5), (1.5, -2.5, 6.0), (3.0, -2.0, 6.0)]
NEW = (4.5, -1.0, 6.0)  # beyond the last photograph: a blend can only copy its neighbours


def photographs(glossy=True, patch=0.0):
    return prepare_photographs(QUAD, [Photograph(shade(C, glossy, patch)[0], K, *pose(C))
                                      for C in PHOTOS])


def test_the_layer_moves_each_sample_to_the_new_view():
    photos = photographs()
    layer = fit_reflection_layer(QUAD, photos, grid=16)
    (g,) = layer.groups
    assert g.used and g.scores["none"] > min(v for k, v in g.scores.items() if k != "none")
    truth, X = shade(NEW)
    R, t = pose(NEW)
    plain = render_vdtm(QUAD, photos, K, R, t, (W, H))
    moved = render_vdtm(QUAD, photos, K, R, t, (W, H), reflection=layer)
    assert moved.info["reflection"] and not plain.info["reflection"]
    # away from the plane's rim, where every photograph sees the point
    inner = (np.abs(X[..., 0]) < 2.5) & (np.abs(X[..., 1]) < 2.5)
    err = np.sqrt(np.mean((moved.image[inner] - truth[inner]) ** 2))
    err_plain = np.sqrt(np.mean((plain.image[inner] - truth[inner]) ** 2))
    # the layer is linear in the mirror direction, which the bilinear grid holds
    # exactly and the Laplacian does not penalise: what remains is the bilinear
    # sampling of the texture, at most A (π / L)² / 2 a sample, in each of the
    # blend's samples and in the two samples of each difference the fit used
    eps = A_TEX * (np.pi / L_TEX_PX) ** 2 / 2
    assert err <= 3 * eps, (err, eps)
    # and the plain blend misses the view's change: its error is the layer's change
    # between the photographs and the new view (tens of codes), not the sampling
    assert err_plain > 10 * eps


def test_a_matte_patch_on_a_glossy_plane_keeps_the_blend_there(monkeypatch):
    import lumigraph.stereo.debevec1996.reflection as reflection

    patch = 1.2  # metres: a 2.4 m square of another material, about 12 texels across
    photos = photographs(patch=patch)
    truth, X = shade(NEW, patch=patch)
    R, t = pose(NEW)
    eps = A_TEX * (np.pi / L_TEX_PX) ** 2 / 2
    inner = (np.abs(X[..., 0]) < 2.5) & (np.abs(X[..., 1]) < 2.5)
    edge = np.maximum(np.abs(X[..., 0]), np.abs(X[..., 1]))
    # the gate decides over 5 x 5 texels (0.2 m each): 0.6 m from the patch's edge
    # is beyond every neighbourhood that holds both materials
    matte, glossy = edge < patch - 0.6, inner & (edge > patch + 0.6)

    def rms(img, at):
        return float(np.sqrt(np.mean((img[at] - truth[at]) ** 2)))

    layer = fit_reflection_layer(QUAD, photos, grid=16)
    (g,) = layer.groups
    assert g.used and g.gate
    # the gate is off on the patch, give or take its window (2 texels) at the edges:
    # between the patch shrunk and grown by that, as shares of the 6 x 6 m plane
    off, win = layer.summary()[0]["gated_off_fraction"], 2 * layer.texel
    assert (2 * (patch - win)) ** 2 / 36 <= off <= (2 * (patch + win)) ** 2 / 36, off
    moved = render_vdtm(QUAD, photos, K, R, t, (W, H), reflection=layer).image
    # on the matte patch the samples are not moved: the blend of a matte texture,
    # exact but for the bilinear sampling; on the glossy rest, moved as before
    assert rms(moved, matte) <= 3 * eps, rms(moved, matte)
    assert rms(moved, glossy) <= 3 * eps, rms(moved, glossy)
    # without the gate the layer moves the patch's samples too, by the glossy
    # material's change between the photographs and the new view
    monkeypatch.setattr(reflection, "GATE", False)
    ungated = fit_reflection_layer(QUAD, photos, grid=16)
    assert not ungated.groups[0].gate
    wrong = render_vdtm(QUAD, photos, K, R, t, (W, H), reflection=ungated).image
    assert rms(wrong, matte) > 10 * eps


def test_a_matte_plane_keeps_the_blend_and_says_so():
    layer = fit_reflection_layer(QUAD, photographs(glossy=False), grid=16)
    (g,) = layer.groups
    assert not g.used and g.held_out > 0
    assert set(g.scores) == {"none"} | {f"{b} lambda={x:g}" for b in ("fading", "linear")
                                        for x in (1, 3, 10, 30, 100, 300)}
    assert layer.summary()[0]["used"] is False
    R, t = pose(NEW)
    photos = photographs(glossy=False)
    a = render_vdtm(QUAD, photos, K, R, t, (W, H)).image
    b = render_vdtm(QUAD, photos, K, R, t, (W, H), reflection=layer).image
    assert np.array_equal(a, b)


def test_bad_arguments_name_themselves():
    photos = photographs()
    with pytest.raises(InputError, match="lambdas"):
        fit_reflection_layer(QUAD, photos, lambdas=(1.0, -2.0))
    with pytest.raises(InputError, match="grid"):
        fit_reflection_layer(QUAD, photos, grid=2)
    with pytest.raises(InputError, match="photographs"):
        fit_reflection_layer(QUAD, [])
    layer = fit_reflection_layer(QUAD, photos, grid=8)
    R, t = pose(NEW)
    with pytest.raises(InputError, match="reflection"):
        render_vdtm(QUAD, photos, K, R, t, (W, H), method="view-map", reflection=layer)


def test_the_fit_solves_the_centred_least_squares_problem():
    """The fit's normal equations are built from the plain bilinear design and
    each texel's mean row, never from the centred design; against a dense
    solve of the centred problem written out, the layer agrees to round-off
    (the system is well conditioned here: λ = 1 on a 6 × 6 grid)."""
    from lumigraph.stereo.debevec1996.reflection import _Centred, _design, _laplacian, _solve

    rng = np.random.default_rng(3)
    T, grid = 40, 6
    tex = np.repeat(np.arange(T), rng.integers(1, 5, T))      # 1–4 samples a texel
    crd = rng.uniform(-1, 1, (len(tex), 2))
    obs = rng.normal(100, 20, (len(tex), 3))
    weight = rng.uniform(0.2, 1.0, T)
    B = _design(crd, grid)
    lap2 = (lambda L: (L.T @ L).tocsr())(_laplacian(grid, "fading"))
    S, res, cnt, res_none = _solve(_Centred(B, obs, tex, T), lap2, 1.0, weight)

    rows = np.flatnonzero(np.bincount(tex, minlength=T)[tex] >= 2)
    Bd = B.toarray()
    mean_B = np.array([Bd[tex == t].mean(0) for t in range(T)])
    mean_o = np.array([obs[tex == t].mean(0) for t in range(T)])
    Ac = Bd[rows] - mean_B[tex[rows]]
    rc = obs[rows] - mean_o[tex[rows]]
    w = weight[tex[rows]]
    G = grid * grid
    A = Ac.T @ (w[:, None] * Ac) + 1.0 * w.sum() / G * lap2.toarray() + 1e-6 * np.eye(G)
    want = np.linalg.solve(A, Ac.T @ (w[:, None] * rc))
    np.testing.assert_allclose(S, want, rtol=0, atol=1e-9 * np.abs(want).max())
    r = rc - Ac @ want
    np.testing.assert_allclose(res, np.bincount(tex[rows], (r ** 2).sum(1), minlength=T),
                               rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(cnt, np.bincount(tex, minlength=T))
    np.testing.assert_allclose(res_none, np.bincount(tex[rows], (rc ** 2).sum(1), minlength=T),
                               rtol=1e-12)


def test_the_gate_is_one_where_no_texel_near_was_seen_twice():
    """The gate's neighbourhood sums come from a running-sum filter, which
    leaves round-off (~1e-16 of the sums nearby) where every term is 0. A
    test on that residue made the gate of a held-out fold random on the
    texels only the left-out photograph and one other saw: its scores moved
    by a third when the photographs moved by 1e-3 codes. Where no texel in
    the window has a difference to explain, the gate is exactly 1; elsewhere
    it is the rule on the window's exact sums."""
    from lumigraph.stereo.debevec1996.reflection import GATE_RADIUS, _gate

    rng = np.random.default_rng(0)
    rows, cols, seen_cols = 30, 40, 17  # texels seen twice in the first 17 columns only
    index = np.arange(rows * cols).reshape(rows, cols)
    index[:, -1] = -1  # cells off the polygon
    T = rows * cols
    res, res_none = np.zeros(T), np.zeros(T)
    data = index[:, :seen_cols].ravel()
    res_none[data] = rng.uniform(0, 1e3, len(data))
    res[data] = res_none[data] * rng.uniform(0.2, 1.8, len(data))  # the layer better or worse
    g, ((k, _, _, grid),) = _gate(res, res_none, [(0, 0.0, 0.0, index)], GATE_RADIUS)
    assert k == 0 and grid.shape == index.shape
    r = GATE_RADIUS
    far = np.zeros(index.shape, bool)
    far[:, seen_cols + r:] = True
    inside = index >= 0
    assert np.all(g[index[far & inside]] == 1.0)
    # the rule on the exact window sums, where they are not tied to round-off
    A = np.zeros(index.shape)
    B = np.zeros(index.shape)
    A[inside], B[inside] = res[index[inside]], res_none[index[inside]]
    for y, x in zip(*np.nonzero(~far & inside), strict=True):
        a = A[max(y - r, 0):y + r + 1, max(x - r, 0):x + r + 1].sum()
        b = B[max(y - r, 0):y + r + 1, max(x - r, 0):x + r + 1].sum()
        if abs(a - b) > 1e-9 * b:
            assert g[index[y, x]] == float(a < b), (y, x)
