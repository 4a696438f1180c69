"""Model-based stereo (stereo/debevec1996/model_stereo.py) on the model-stereo facade: exact
ground truth, the warped offset image of Fig. 5.12c, and the CLI verb."""

import json

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph
from scipy import ndimage

from lumigraph.capture import io
from lumigraph.capture.render import render
from lumigraph.capture.rig import Rig
from lumigraph.stereo.debevec1996 import (
    ModelStereo,
    model_in_offset_view,
    model_stereo,
    warp_offset,
)

MAX_OFFSET = 0.35  # m; the relief is 0.18-0.27 m deep along the key rays


def rig_of(s):
    g = s.gt["rig"]
    return Rig.from_dict(g)


def interior(s, radius):
    """Pixels farther than ``radius`` px from any depth edge (a window of that
    half-size sees one surface only)."""
    Z = np.nan_to_num(s.gt_arrays["depth"], nan=99.0)
    edge = (ndimage.maximum_filter(Z, 3) - ndimage.minimum_filter(Z, 3)) > 0.02
    return ndimage.distance_transform_edt(~edge) > radius


@pytest.fixture(scope="module")
def facade():
    s = render("model-stereo")
    res = model_stereo(s.images[0], s.images[1], s.gt_arrays["model_depth"], rig_of(s),
                       max_offset=MAX_OFFSET, window=9)
    return s, res


def test_relief_is_recovered(facade):
    s, res = facade
    g = s.gt_arrays
    seen = np.isfinite(g["offset_xy"][..., 0])
    relief = seen & interior(s, 5) & (np.abs(g["relief"]) > 0.1)
    assert relief.sum() > 5000
    err = np.abs(res.depth - g["depth"])[relief]
    step = res.info["step"]
    # One delta step moves the offset sample by one pixel (at most). With
    # 1-code noise on an 81-pixel window of texture (window std >> sigma), the
    # parabola's sub-step error is a small fraction of a step, its bias
    # (bilinear resampling) under a quarter step: median < step / 4. Bounded
    # below too: exactly zero error would mean ground truth leaked in.
    assert 0 < np.nanmedian(err) < step / 4
    # The detail IS recovered: the median error is a small fraction of the
    # relief depth (0.18 m pillars, 0.25 m recesses), and the model alone
    # (delta = 0) is off by the full relief there.
    assert np.nanmedian(err) < 0.05 * 0.18
    model_err = np.abs(g["model_depth"] - g["depth"])[relief]
    assert np.median(model_err) > 0.15
    # dense and rarely off by more than a step on the relief interiors
    assert np.isfinite(err).mean() > 0.85
    assert np.mean(err <= step) > 0.85
    # recovered offsets have the relief's sign: pillars in front, recesses behind
    assert np.nanmedian(res.offset[relief & (g["relief"] < 0)]) < -0.15
    assert np.nanmedian(res.offset[relief & (g["relief"] > 0)]) > 0.2


def test_wall_where_the_model_is_exact(facade):
    s, res = facade
    g = s.gt_arrays
    wall = np.isfinite(g["offset_xy"][..., 0]) & interior(s, 5) & (np.abs(g["relief"]) < 1e-9)
    err = np.abs(res.depth - g["depth"])[wall]
    assert np.isfinite(err).mean() > 0.95
    assert 0 < np.nanmedian(err) < res.info["step"] / 4
    assert np.nanmedian(np.abs(res.offset[wall])) < res.info["step"] / 4


def test_result_is_consistent(facade):
    s, res = facade
    assert isinstance(res, ModelStereo)
    assert res.depth.dtype == np.float32 and res.depth.shape == s.images[0].shape[:2]
    assert np.array_equal(res.valid, np.isfinite(res.depth))
    ok = res.valid
    np.testing.assert_allclose(res.depth[ok], (s.gt_arrays["model_depth"] + res.offset)[ok], rtol=1e-5)
    assert res.info["delta_range"] == [-MAX_OFFSET, MAX_OFFSET]
    assert res.info["steps"] == 2 * round(MAX_OFFSET / res.info["step"]) + 1


def test_warped_offset_image_reproduces_key_where_model_exact():
    s = render("model-stereo", noise=0.0)
    g = s.gt_arrays
    rig = rig_of(s)
    wall = np.isfinite(g["offset_xy"][..., 0]) & interior(s, 6) & (np.abs(g["relief"]) < 1e-9)
    key = s.images[0].astype(np.float32)
    w0 = warp_offset(s.images[1], g["model_depth"], rig)
    diff0 = np.abs(w0 - key)[wall]
    # Noise-free: only 8-bit rounding of both views (<= 0.5 code each) and
    # bilinear resampling of the offset view (it sees the wall 18 deg off its
    # normal, the key 12 deg, and its focal is 3 % longer: its pixels cover a
    # slightly different patch of wall, a different box filter) remain: mean
    # |difference| under 2 codes.
    assert np.all(np.isfinite(diff0))
    assert np.mean(diff0) < 2.0
    # ...and misregistering by one step (one offset pixel) is much worse: the
    # agreement is geometric, not a smooth image agreeing with anything.
    step = model_stereo(s.images[0], s.images[1], g["model_depth"], rig, max_offset=MAX_OFFSET).info["step"]
    for d in (-step, step):
        w1 = warp_offset(s.images[1], g["model_depth"], rig, delta=d)
        assert np.nanmean(np.abs(w1 - key)[wall]) > 2.5 * np.mean(diff0)
    # on the relief the model is wrong and the warped image disagrees
    rel = np.isfinite(g["offset_xy"][..., 0]) & interior(s, 6) & (np.abs(g["relief"]) > 0.1)
    assert np.nanmean(np.abs(w0 - key)[rel]) > 3 * np.mean(diff0)


def test_model_absent_is_unknown_and_inputs_untouched(facade):
    s, _ = facade
    zm = s.gt_arrays["model_depth"].copy()
    zm[:, :100] = np.nan
    key, off = s.images[0].copy(), s.images[1].copy()
    zm_before = zm.copy()
    res = model_stereo(key, off, zm, rig_of(s), max_offset=MAX_OFFSET, window=5)
    assert np.isnan(res.depth[:, :100]).all() and np.isnan(res.warped[:, :100]).all()
    assert res.info["rejected"]["no_model"] == 100 * zm.shape[0]
    np.testing.assert_array_equal(zm, zm_before)
    np.testing.assert_array_equal(key, s.images[0])
    np.testing.assert_array_equal(off, s.images[1])


def test_bad_arguments(facade):
    s, _ = facade
    rig = rig_of(s)
    zm = s.gt_arrays["model_depth"]
    a, b = s.images
    with pytest.raises(ValueError, match="model_depth"):
        model_stereo(a, b, zm[:-1], rig, max_offset=0.3)
    with pytest.raises(ValueError, match="model_depth"):
        model_stereo(a, b, np.full_like(zm, np.nan), rig, max_offset=0.3)
    with pytest.raises(ValueError, match="max_offset"):
        model_stereo(a, b, zm, rig, max_offset=0.0)
    with pytest.raises(ValueError, match="window"):
        model_stereo(a, b, zm, rig, max_offset=0.3, window=8)
    with pytest.raises(ValueError, match="offset"):
        model_stereo(a, b[:-2], zm, rig, max_offset=0.3)
    with pytest.raises(TypeError, match="rig"):
        model_stereo(a, b, zm, s.gt["rig"], max_offset=0.3)
    with pytest.raises(ValueError, match="left_right"):
        model_stereo(a, b, zm, rig, max_offset=0.3, left_right=0.0)


def test_model_seen_from_the_offset_camera(facade):
    s, _ = facade
    rig = rig_of(s)
    zm = s.gt_arrays["model_depth"]
    h, w = zm.shape
    zo = model_in_offset_view(zm, rig)
    # the model is the wall plane n.X = d (key frame): three of its points fix it
    X = [rig.left.unproject(np.array([[x, y]], float))[0] * zm[y, x]
         for x, y in ((10, 10), (w - 10, 10), (w // 2, h - 10))]
    n = np.cross(X[1] - X[0], X[2] - X[0])
    # offset frame: X_o = R X + T, so (R n).X_o = d + (R n).T
    n_o = rig.R @ n
    d_o = n @ X[0] + n_o @ rig.T
    ys, xs = np.mgrid[0:h, 0:w]
    ro = rig.right.unproject(np.stack([xs.ravel(), ys.ravel()], 1).astype(float)).reshape(h, w, 3)
    exact = d_o / (ro @ n_o)  # unit-z rays: the ray parameter is z
    # where that plane point lies on the model (inside the key frame, model known)
    Xk = (ro * exact[..., None] - rig.T) @ rig.R
    pk = rig.left.project(Xk.reshape(-1, 3)).reshape(h, w, 2)
    on = ((pk[..., 0] > 2) & (pk[..., 0] < w - 3) & (pk[..., 1] > 2) & (pk[..., 1] < h - 3))
    assert on.sum() > 0.5 * h * w
    assert np.isfinite(zo[on]).all()
    # Each offset pixel takes the depth of a model sample within sqrt(2)/2 px
    # of its centre (samples <= 0.5 px apart), so it is off by at most
    # 0.71 px times the depth gradient; bilinear depth between key pixels
    # adds a second-order error (1/z, not z, is affine on a plane), < 1e-4 m.
    grad = np.hypot(*np.gradient(exact))
    err = np.abs(zo - exact)[on]
    assert np.all(err <= 0.71 * grad[on] + 1e-4)
    assert np.median(err) > 0  # a splat, not the exact plane


# ------------------------------------------------------------------- CLI
@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("facade")
    s = render("model-stereo", size=(200, 150))
    folder = s.save(root / "scene")
    io.write_pfm(root / "model.pfm", s.gt_arrays["model_depth"])
    return folder, root / "model.pfm", s


def test_cli_model_based(scene_dir, tmp_path):
    folder, model, s = scene_dir
    out, warped = tmp_path / "depth.pfm", tmp_path / "warped.png"
    r = lumigraph("stereo", "model-based", folder / "key.png", folder / "offset.png", "--rig",
                  folder / "gt.json", "--model", model, "--max-offset", "0.35", "--window", "9",
                  "--out", out, "--warped", warped, "-q")
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "depth.pfm.meta.json").read_text())
    assert meta["params"]["max_offset"] == 0.35 and meta["params"]["window"] == 9
    assert meta["delta_range"] == [-0.35, 0.35] and meta["delta_step"] > 0
    z = io.read_pfm(out)
    assert abs(meta["quality"]["valid_fraction"] - np.isfinite(z).mean()) < 1e-9
    gt = s.gt_arrays["depth"]
    seen = np.isfinite(s.gt_arrays["offset_xy"][..., 0])
    e = np.abs(z - gt)[seen]
    assert 0 < np.nanmedian(e) < 0.02
    w = io.read_image(warped)
    assert w.shape == s.images[1].shape and w.dtype == np.uint8
    # the .npy model of a rendered scene works as well
    out2 = tmp_path / "d2.pfm"
    r = lumigraph("stereo", "model-based", folder / "key.png", folder / "offset.png", "--rig",
                  folder / "gt.json", "--model", folder / "gt" / "model_depth.npy", "--max-offset",
                  "0.35", "--out", out2, "-q")
    assert r.returncode == 0, r.stderr
    z2 = io.read_pfm(out2)
    # the PFM holds the model rounded to float32 (~4e-7 m at 6 m), the .npy float64;
    # the census cost of the default cost="sgm" is an integer, so that rounding may
    # flip a code and move a winner, by no more than one δ step
    assert meta["params"]["cost"] == "sgm"
    both = np.isfinite(z) & np.isfinite(z2)
    assert np.mean(np.isfinite(z) == np.isfinite(z2)) > 0.999
    d = np.abs(z2[both] - z[both])
    assert np.mean(d <= 1e-4) > 0.999 and d.max() <= meta["delta_step"]


def _run(folder, model, out, *extra, key="key.png", offset="offset.png", rig=None):
    return lumigraph("stereo", "model-based", folder / key, folder / offset, "--rig",
                     rig or folder / "gt.json", "--model", model, "--out", out, *extra)


def test_cli_bad_inputs(scene_dir, tmp_path):
    folder, model, s = scene_dir
    out = tmp_path / "d.pfm"
    small = tmp_path / "small.png"
    io.write_image(small, s.images[1][:-10])
    r = lumigraph("stereo", "model-based", folder / "key.png", small, "--rig", folder / "gt.json",
                  "--model", model, "--max-offset", "0.3", "--out", out)
    assert_clean_error(r, "small.png", "differs")
    bad_model = tmp_path / "m_small.pfm"
    io.write_pfm(bad_model, s.gt_arrays["model_depth"][:-4])
    assert_clean_error(_run(folder, bad_model, out, "--max-offset", "0.3"), "m_small.pfm", "differs")
    nan_model = tmp_path / "m_nan.pfm"
    io.write_pfm(nan_model, np.full(s.images[0].shape[:2], np.nan, np.float32))
    assert_clean_error(_run(folder, nan_model, out, "--max-offset", "0.3"), "m_nan.pfm", "absent")
    rig = json.loads((folder / "gt.json").read_text())["rig"]
    rig["left"]["image_size"] = [100, 75]
    rig["right"]["image_size"] = [100, 75]
    rig_path = tmp_path / "rig.json"
    rig_path.write_text(json.dumps(rig))
    assert_clean_error(_run(folder, model, out, "--max-offset", "0.3", rig=rig_path), "rig.json",
                       "100x75")
    for bad in ("0", "-1", "nan"):
        assert_clean_error(_run(folder, model, out, "--max-offset", bad), "--max-offset")
    assert_clean_error(_run(folder, model, out, "--max-offset", "0.3", "--window", "8"), "--window")
    for bad in ("-1", "nan", "inf"):
        assert_clean_error(_run(folder, model, out, "--max-offset", "0.3", "--left-right", bad),
                           "--left-right")
    assert not out.exists() and not (tmp_path / "d.pfm.meta.json").exists()


def test_cli_left_right_flag(scene_dir, tmp_path):
    # the flag reaches the library: 0 turns the check off (same as left_right=None),
    # and the default refuses at least what the check-free run keeps out
    folder, model, s = scene_dir
    runs = {}
    for flag in ("0", "1.25"):
        out = tmp_path / f"lr{flag}.pfm"
        r = _run(folder, model, out, "--max-offset", "0.35", "--left-right", flag, "-q")
        assert r.returncode == 0, r.stderr
        meta = json.loads(out.with_name(out.name + ".meta.json").read_text())
        runs[flag] = (io.read_pfm(out), meta)
    off, on = runs["0"], runs["1.25"]
    assert off[1]["params"]["left_right"] is None and on[1]["params"]["left_right"] == 1.25
    assert off[1]["model"]["model_based_stereo"]["rejected"]["left_right"] == 0
    assert on[1]["model"]["model_based_stereo"]["rejected"]["left_right"] > 0
    assert np.isfinite(on[0]).sum() < np.isfinite(off[0]).sum()


def test_options_are_checked_by_the_library_before_any_file_is_read(scene_dir, tmp_path):
    from lumigraph.capture.errors import InputError
    from lumigraph.stereo.debevec1996 import check_model_stereo_options

    assert check_model_stereo_options(max_offset=1) == 1.0
    for kwargs, name in ((dict(max_offset=float("inf")), "max_offset"),
                         (dict(max_offset=0.3, window=65), "window"),
                         (dict(max_offset=0.3, step=0.5), "step"),
                         (dict(max_offset=0.3, max_cost=float("nan")), "max_cost"),
                         (dict(max_offset=0.3, uniqueness=-1), "uniqueness"),
                         (dict(max_offset=0.3, left_right=-1.0), "left_right")):
        with pytest.raises(InputError, match=f"^{name}: expected"):
            check_model_stereo_options(**kwargs)
    folder, model, s = scene_dir
    zm = s.gt_arrays["model_depth"]
    with pytest.raises(InputError, match=r"^model_depth: no finite positive depth"):
        model_stereo(s.images[0], s.images[1], np.zeros_like(zm), rig_of(s), max_offset=0.3)
    # the command line names the flag, checked before the (missing) files are read
    gone = tmp_path / "gone"
    out = tmp_path / "d.pfm"
    for extra, flag in ((("--max-offset", "0.3", "--step", "0.5"), "--step"),
                        (("--max-offset", "0.3", "--max-cost", "-1"), "--max-cost"),
                        (("--max-offset", "0.3", "--texture-snr", "nan"), "--texture-snr"),
                        (("--max-offset", "0.3", "--window", "2"), "--window"),
                        (("--max-offset", "0", "--left-right", "0"), "--max-offset")):
        r = lumigraph("stereo", "model-based", gone / "k.png", gone / "o.png", "--rig", gone / "r.json",
                      "--model", gone / "m.pfm", "--out", out, *extra)
        assert_clean_error(r, f"error: {flag}: expected")
    assert not out.exists()
