"""``lumigraph stereo`` end to end: files in, files out, clean errors."""

import json

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture import io
from lumigraph.capture.render import render


@pytest.fixture(scope="module")
def pairs(tmp_path_factory):
    root = tmp_path_factory.mktemp("pairs")
    out = {}
    for layout in ("rectified", "unrectified"):
        s = render("stereo-pair", size=(200, 150), layout=layout)
        out[layout] = (s.save(root / layout), s)
    return out



def _relative_depth_error(pts, scene):
    """(|Z - Z_true| / Z_true, fraction in view) of left-camera-frame points,
    each looked up at the true depth of the pixel it projects to (points
    outside the image dropped)."""
    K = np.array(scene.gt["rig"]["left"]["K"])
    uv = pts @ K.T
    uv = np.round(uv[:, :2] / uv[:, 2:]).astype(int)
    h, w = scene.gt_arrays["depth"].shape
    ok = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    Z = scene.gt_arrays["depth"][uv[ok, 1], uv[ok, 0]]
    return np.abs(pts[ok, 2] - Z) / Z, float(ok.mean())

def test_match_rectified_and_depth(pairs, tmp_path):
    folder, s = pairs["rectified"]
    d = tmp_path / "d.pfm"
    r = lumigraph("stereo", "match", folder / "left.png", folder / "right.png", "--max-disp", "40",
                  "--out", d, "-q")
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "d.pfm.meta.json").read_text())
    assert meta["model"]["sgm"]["method"] == "sgm" and meta["params"]["method"] == "sgm"  # the default
    disp = io.read_pfm(d)
    gt = s.gt_arrays["disparity"]
    e = np.abs(disp - gt)[np.isfinite(gt)]
    assert 0 < np.nanmedian(e) < 0.3
    ply = tmp_path / "p.ply"
    r = lumigraph("stereo", "depth", d, "--rig", folder / "gt.json", "--image", folder / "left.png",
                  "--out", ply, "-q")
    assert r.returncode == 0, r.stderr
    pts, cols = io.read_ply(ply)
    assert cols is not None and len(pts) == (disp > 0).sum()  # d = 0 is at infinity


def test_unrectified_needs_rig_then_depth_matches_gt(pairs, tmp_path):
    folder, s = pairs["unrectified"]
    d = tmp_path / "d.pfm"
    r = lumigraph("stereo", "match", folder / "left.png", folder / "right.png", "--max-disp", "40",
                  "--out", d)
    assert_clean_error(r, "right.png", "not rectified", "--rig")
    assert not d.exists()
    r = lumigraph("stereo", "match", folder / "left.png", folder / "right.png", "--rig",
                  folder / "gt.json", "--max-disp", "40", "--out", d, "-q")
    assert r.returncode == 0, r.stderr
    ply = tmp_path / "p.ply"
    r = lumigraph("stereo", "depth", d, "--rig", folder / "gt.json", "--out", ply, "-q")
    assert r.returncode == 0, r.stderr
    pts, _ = io.read_ply(ply)
    # points are in the original left camera frame: project and compare depth
    rel, _ = _relative_depth_error(pts, s)
    # disparity error ~0.2 px at d ~ 10-30 px -> ~1 % depth error; rounding
    # the pixel adds up to half a pixel of position along slanted surfaces
    assert 0 < np.nanmedian(rel) < 0.02


def test_rectification_json_gives_the_same_disparity_and_points_as_the_rig(pairs, tmp_path):
    """``calib rectify`` writes rectification.json; stereo uses it as saved, and on
    the same inputs the outputs are byte-identical to rectifying from the rig."""
    folder, _ = pairs["unrectified"]
    L, R, rig = folder / "left.png", folder / "right.png", folder / "gt.json"
    r = lumigraph("calib", "rectify", "--rig", rig, L, R, "--out", tmp_path / "rect", "-q")
    assert r.returncode == 0, r.stderr
    rect = tmp_path / "rect" / "rectification.json"
    outs = {}
    for how, src in (("rig", rig), ("rectification", rect)):
        d, ply = tmp_path / f"d_{how}.pfm", tmp_path / f"p_{how}.ply"
        r = lumigraph("stereo", "match", L, R, f"--{how}", src, "--max-disp", "40", "--out", d, "-q")
        assert r.returncode == 0, r.stderr
        r = lumigraph("stereo", "depth", d, f"--{how}", src, "--image", L, "--out", ply, "-q")
        assert r.returncode == 0, r.stderr
        meta = json.loads((tmp_path / f"d_{how}.pfm.meta.json").read_text())
        assert str(src) in json.dumps(meta["inputs"])
        outs[how] = (d.read_bytes(), ply.read_bytes())
    assert outs["rig"][0] == outs["rectification"][0]
    assert outs["rig"][1] == outs["rectification"][1]
    # the rectified pair calib wrote is the pair match rectified: matching it unrectified agrees
    d = tmp_path / "d_pre.pfm"
    r = lumigraph("stereo", "match", tmp_path / "rect" / "left.png", tmp_path / "rect" / "right.png",
                  "--max-disp", "40", "--out", d, "-q")
    assert r.returncode == 0, r.stderr
    assert d.read_bytes() == outs["rig"][0]


def test_calibrated_rig_chain_through_files(tmp_path):
    """Boards -> calib stereo -> rig.json -> calib rectify -> stereo match -> stereo
    depth on the files a user would have: no ground truth goes in, and the depth
    of the pair (rendered with the rig the boards were) is close to the truth."""
    boards, pair = tmp_path / "boards", tmp_path / "pair"
    render("boards-stereo", size=(320, 240), rig="stereo-pair-unrectified", distortion="none",
           square=0.06, baseline=0.18).save(boards)
    s = render("stereo-pair", size=(320, 240), layout="unrectified", baseline=0.18)
    s.save(pair)
    rig = tmp_path / "rig.json"
    r = lumigraph("calib", "stereo", "--left", *sorted(boards.glob("left_*.png")), "--right",
                  *sorted(boards.glob("right_*.png")), "--board", "checker:10x7:0.06", "--out", rig, "-q")
    assert r.returncode == 0, r.stderr
    r = lumigraph("calib", "rectify", "--rig", rig, pair / "left.png", pair / "right.png", "--out",
                  tmp_path / "rect", "-q")
    assert r.returncode == 0, r.stderr
    rect = tmp_path / "rect" / "rectification.json"
    d, ply = tmp_path / "d.pfm", tmp_path / "p.ply"
    r = lumigraph("stereo", "match", pair / "left.png", pair / "right.png", "--rectification", rect,
                  "--max-disp", "47", "--out", d, "-q")
    assert r.returncode == 0, r.stderr
    r = lumigraph("stereo", "depth", d, "--rectification", rect, "--out", ply, "-q")
    assert r.returncode == 0, r.stderr
    pts, _ = io.read_ply(ply)
    rel, in_view = _relative_depth_error(pts, s)
    # as with the true rig (~1 % from ~0.2 px of disparity error), plus the
    # calibration's own error (0.05 px RMS, baseline within ~0.3 %)
    assert in_view > 0.9 and 0 < np.nanmedian(rel) < 0.02


def test_rectification_for_another_image_size_is_refused(pairs, tmp_path):
    folder, _ = pairs["unrectified"]
    r = lumigraph("calib", "rectify", "--rig", folder / "gt.json", folder / "left.png",
                  folder / "right.png", "--out", tmp_path / "rect", "-q")
    assert r.returncode == 0, r.stderr
    rect = tmp_path / "rect" / "rectification.json"
    small = [tmp_path / "l.png", tmp_path / "r.png"]
    for f in small:
        io.write_image(f, np.zeros((50, 60, 3), np.uint8))
    out = tmp_path / "d.pfm"
    r = lumigraph("stereo", "match", *small, "--rectification", rect, "--max-disp", "16", "--out", out)
    assert_clean_error(r, "rectification.json", "rectification is for 200x150 images, the pair is 60x50")
    assert not out.exists()
    io.write_pfm(tmp_path / "small.pfm", np.ones((50, 60), np.float32))
    r = lumigraph("stereo", "depth", tmp_path / "small.pfm", "--rectification", rect, "--out",
                  tmp_path / "p.ply")
    assert_clean_error(r, "small.pfm", "differs from the rectified size")
    r = lumigraph("stereo", "match", *small, "--rig", folder / "gt.json", "--rectification", rect,
                  "--max-disp", "16", "--out", out)
    assert_clean_error(r, "--rectification", "not allowed with")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"schema": "lumigraph.rectification"}))
    r = lumigraph("stereo", "depth", tmp_path / "small.pfm", "--rectification", bad, "--out",
                  tmp_path / "p.ply")
    assert_clean_error(r, "bad.json", "missing keys 'rig'")


def test_match_bad_input(pairs, tmp_path):
    folder, _ = pairs["rectified"]
    small = tmp_path / "small.png"
    io.write_image(small, np.zeros((50, 60, 3), np.uint8))
    out = tmp_path / "d.pfm"
    assert_clean_error(lumigraph("stereo", "match", folder / "left.png", small, "--max-disp", "16",
                                 "--out", out), "small.png", "differs")
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    assert_clean_error(lumigraph("stereo", "match", empty, folder / "right.png", "--max-disp", "16",
                                 "--out", out), "empty.png")
    assert_clean_error(lumigraph("stereo", "match", folder / "left.png", folder / "right.png",
                                 "--max-disp", "16", "--window", "4", "--out", out), "--window")
    assert not out.exists()


def test_triangulate_json_and_text(pairs, tmp_path):
    folder, s = pairs["unrectified"]
    rig = s.gt["rig"]
    P = s.gt_arrays["points"]
    xy = s.gt_arrays["right_xy"]
    ys, xs = np.mgrid[0:150, 0:200]
    ok = np.isfinite(xy).all(axis=2)
    idx = np.flatnonzero(ok.ravel())[::500]
    left = np.column_stack([xs.ravel()[idx], ys.ravel()[idx]]).astype(float)
    right = xy.reshape(-1, 2)[idx]
    txt = tmp_path / "m.txt"
    np.savetxt(txt, np.hstack([left, right]), header="x_left y_left x_right y_right")
    out = tmp_path / "pts.ply"
    r = lumigraph("stereo", "triangulate", txt, "--rig", folder / "gt.json", "--out", out, "-q")
    assert r.returncode == 0, r.stderr
    pts, _ = io.read_ply(out)
    assert np.allclose(pts, P.reshape(-1, 3)[idx], rtol=1e-6)
    tracks = {"views": [{"camera": rig["left"]},
                        {"camera": rig["right"], "cam_from_world": {"R": rig["R"], "t": rig["T"]}}],
              "tracks": [[l.tolist(), r_.tolist()] for l, r_ in zip(left, right, strict=True)]}
    js = tmp_path / "t.json"
    js.write_text(json.dumps(tracks))
    r = lumigraph("stereo", "triangulate", js, "--out", tmp_path / "t_out.json", "-q")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "t_out.json").read_text())
    assert np.allclose([p["xyz"] for p in doc["points"]], P.reshape(-1, 3)[idx], rtol=1e-6)
    assert all(p["sigma"] > 0 for p in doc["points"])
    assert_clean_error(lumigraph("stereo", "triangulate", txt, "--out", tmp_path / "x.ply"), "--rig")


def test_sfm_cli_recovers_camera_centres(tmp_path):
    from lumigraph.stereo.sfm import align_similarity

    s = render("stereo-views")
    folder = s.save(tmp_path / "views")
    out = tmp_path / "sfm"
    r = lumigraph("stereo", "sfm", *[folder / n for n in s.image_names], "--camera", folder / "gt.json",
                  "--out", out, "-q")
    assert r.returncode == 0, r.stderr
    cams = json.loads((out / "cameras.json").read_text())
    assert all(v["registered"] for v in cams["views"])
    C = np.array([-np.array(v["cam_from_world"]["R"]).T @ v["cam_from_world"]["t"] for v in cams["views"]])
    gt = np.array(s.gt["centres"])
    sc, R, t = align_similarity(C, gt)
    err = np.linalg.norm(sc * C @ R.T + t - gt, axis=1).max() / s.gt["scene_size_m"]
    # issue target: within 1 % of the scene size; > 0 since SIFT positions are noisy
    assert 0 < err < 0.01
    pts, cols = io.read_ply(out / "points.ply")
    assert len(pts) > 100 and cols is not None


def test_bench_quick_through_cli(tmp_path):
    r = lumigraph("bench", "stereo", "--quick", "--out", tmp_path / "b", "-q")
    assert r.returncode == 0, r.stderr
    rep = (tmp_path / "b" / "report.md").read_text()
    assert "StereoBM" in rep and "triangulation" in rep


def test_match_channels_and_prefilter_flags(pairs, tmp_path):
    # the options reach the matcher and its record; both still match the pair
    folder, s = pairs["rectified"]
    gt = s.gt_arrays["disparity"]
    for flags, channels, prefilter in ((["--channels", "color", "--prefilter", "none"], "rgb", "none"),
                                       (["--prefilter", "local-mean"], "luma", "local-mean")):
        d = tmp_path / f"{channels}-{prefilter}.pfm"
        r = lumigraph("stereo", "match", folder / "left.png", folder / "right.png", "--max-disp", "40",
                      "--method", "ssd", "--window", "9", *flags, "--out", d, "-q")
        assert r.returncode == 0, r.stderr
        info = json.loads(d.with_name(d.name + ".meta.json").read_text())["model"]["block_matching"]
        assert (info["channels"], info["prefilter"]) == (channels, prefilter)
        e = np.abs(io.read_pfm(d) - gt)[np.isfinite(gt)]
        assert 0 < np.nanmedian(e) < 0.3
    assert_clean_error(lumigraph("stereo", "match", folder / "left.png", folder / "right.png",
                                 "--max-disp", "40", "--channels", "hsv", "--out", tmp_path / "x.pfm"),
                       "--channels")
    assert not (tmp_path / "x.pfm").exists()


def test_match_option_checks_live_in_the_library(pairs, tmp_path):
    # block_matching checks its own arguments and names them ...
    from lumigraph.capture.errors import InputError
    from lumigraph.stereo.block_matching import check_match_options, check_rectified, match

    with pytest.raises(InputError, match=r"^max_disp: expected an integer in \[1, 199\]"):
        check_match_options((150, 200), max_disp=200)
    with pytest.raises(InputError, match="^window: expected 'auto' or an odd integer"):
        check_match_options((150, 200), max_disp=16, window=4)
    with pytest.raises(InputError, match="^texture_snr: expected a value >= 0"):
        check_match_options((150, 200), max_disp=16, texture_snr=-1.0)
    with pytest.raises(InputError, match="^left: image 10x8 is smaller than the window 15"):
        check_match_options((8, 10), max_disp=4)
    a = np.zeros((20, 30), np.float32)
    with pytest.raises(InputError, match="^max_disp"):
        match(a, a, max_disp=0)
    folder, s = pairs["unrectified"]
    with pytest.raises(InputError, match="^right: the pair is not rectified.*; do this"):
        check_rectified(io.read_image(folder / "left.png"), io.read_image(folder / "right.png"),
                        remedy="do this")
    # ... and the command line reports the flag (or the image's file), writing nothing
    folder, _ = pairs["rectified"]
    out = tmp_path / "d.pfm"

    def run(*extra, left=folder / "left.png", right=folder / "right.png"):
        return lumigraph("stereo", "match", left, right, "--method", "ssd", "--out", out, *extra)

    # the ranges known without the images: the parser, with the library's bounds
    assert_clean_error(run("--max-disp", "0"), "error: --max-disp: expected an integer >= 1, got '0'")
    assert_clean_error(run("--max-disp", "16", "--window", "65"),
                       "error: --window: expected an odd integer >= 3 and <= 63 or auto, got '65'")
    assert_clean_error(run("--max-disp", "16", "--window", "wide"), "error: --window:")
    assert_clean_error(run("--max-disp", "16", "--uniqueness", "-0.5"),
                       "error: --uniqueness: expected a number >= 0")
    # the bound that needs the image: the library
    assert_clean_error(run("--max-disp", "200"), "error: --max-disp: expected an integer in [1, 199]")
    tiny, tiny2 = tmp_path / "tiny.png", tmp_path / "tiny2.png"
    io.write_image(tiny, np.zeros((8, 10), np.uint8))
    io.write_image(tiny2, np.zeros((8, 10), np.uint8))
    assert_clean_error(run("--max-disp", "4", left=tiny, right=tiny2),
                       f"error: {tiny}: image 10x8 is smaller than the window 15")
    # checked before rectifying: a bad option wins over a rig that does not fit
    unrect, _ = pairs["unrectified"]
    assert_clean_error(run("--max-disp", "0", "--rig", tmp_path / "missing.json"), "error: --max-disp:")
    assert_clean_error(run("--max-disp", "16", left=unrect / "left.png", right=unrect / "right.png"),
                       f"error: {unrect / 'right.png'}: the pair is not rectified", "--rig rig.json")
    assert not out.exists()


def test_triangulate_pixel_sigma_is_checked_by_the_library(pairs, tmp_path):
    from lumigraph.capture.errors import InputError
    from lumigraph.stereo.triangulate import triangulate

    folder, s = pairs["unrectified"]
    g = s.gt["rig"]
    from lumigraph.capture.rig import Rig

    rig = Rig.from_dict(g)
    px = np.array([[[50.0, 60.0]], [[40.0, 61.0]]])
    poses = [(np.eye(3), np.zeros(3)), (rig.R, rig.T)]
    with pytest.raises(InputError, match="^pixel_sigma: expected > 0, got -1"):
        triangulate(px, [rig.left, rig.right], poses, pixel_sigma=-1.0)
    tracks = {"views": [{"camera": g["left"]},
                        {"camera": g["right"], "cam_from_world": {"R": g["R"], "t": g["T"]}}],
              "tracks": [px[:, 0].tolist()], "pixel_sigma": -2}
    js = tmp_path / "t.json"
    js.write_text(json.dumps(tracks))
    out = tmp_path / "p.json"
    # from the flag: the flag is named; from the tracks file: the file is
    assert_clean_error(lumigraph("stereo", "triangulate", js, "--pixel-sigma", "-1", "--out", out),
                       "error: --pixel-sigma: expected a number > 0, got '-1'")
    assert_clean_error(lumigraph("stereo", "triangulate", js, "--out", out),
                       f"error: {js}: expected > 0, got -2")
    # 0 is refused like any value the library refuses (it no longer falls back to the default)
    assert_clean_error(lumigraph("stereo", "triangulate", js, "--pixel-sigma", "0", "--out", out),
                       "error: --pixel-sigma: expected a number > 0, got '0'")
    tracks["pixel_sigma"] = 0
    js.write_text(json.dumps(tracks))
    assert_clean_error(lumigraph("stereo", "triangulate", js, "--out", out), f"error: {js}: expected > 0, got 0")
    assert not out.exists()
