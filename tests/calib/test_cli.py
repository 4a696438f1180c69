"""``lumigraph calib``: the happy path through files, and every bad input of
issue 4 exiting 2 with one line naming the file/option and writing nothing."""

import json

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture import io
from lumigraph.capture.render import render


@pytest.fixture(scope="module")
def boards(tmp_path_factory):
    d = tmp_path_factory.mktemp("boards")
    render("boards", size=(320, 240), seed=7, views=6).save(d)
    return d


def _nothing_written(out):
    assert not out.exists() and not out.with_name(out.name + ".meta.json").exists()


def test_calibrate_undistort_through_files(boards, tmp_path):
    out = tmp_path / "camera.json"
    r = lumigraph("calib", "calibrate", boards, "--out", out, "--yaml", tmp_path / "c.yml",
                  "--colmap", tmp_path / "cameras.txt", "--quiet")
    assert r.returncode == 0, r.stderr
    cam = json.loads(out.read_text())
    assert cam["image_size"] == [320, 240] and len(cam["candidates"]) == 6
    meta = json.loads((tmp_path / "camera.json.meta.json").read_text())
    assert meta["model"]["chosen"] == cam["model"] and meta["quality"]["rms_px"] == cam["rms_px"]
    assert (tmp_path / "cameras.txt").read_text().count("\n1 ") == 1
    und = tmp_path / "und"
    r = lumigraph("calib", "undistort", "--camera", out, boards / "view_00.png", "--out", und, "--quiet")
    assert r.returncode == 0, r.stderr
    assert io.read_image(und / "view_00.png").shape == (240, 320)
    assert json.loads((und / "camera.json").read_text())["model"] == "none"


def test_no_board_in_any_image(tmp_path):
    blank = tmp_path / "blank.png"
    io.write_image(blank, np.full((120, 160), 128, np.uint8))
    out = tmp_path / "camera.json"
    assert_clean_error(lumigraph("calib", "calibrate", blank, blank, blank, "--board", "checker:10x7:25",
                                 "--out", out), "no checker:10x7:25 board found")
    _nothing_written(out)


def test_fewer_than_three_usable_views(boards, tmp_path):
    out = tmp_path / "camera.json"
    assert_clean_error(lumigraph("calib", "calibrate", boards / "view_00.png", boards / "view_01.png",
                                 "--board", "checker:10x7:30", "--out", out), "at least 3")
    _nothing_written(out)


def test_mixed_image_sizes(boards, tmp_path):
    small = tmp_path / "small.png"
    io.write_image(small, np.zeros((100, 120), np.uint8))
    out = tmp_path / "camera.json"
    assert_clean_error(lumigraph("calib", "calibrate", boards / "view_00.png", small, "--board",
                                 "checker:10x7:30", "--out", out), "small.png", "one image size")
    _nothing_written(out)


@pytest.mark.parametrize("spec, fragment", [("chess:10x7", "cannot parse"),
                                             ("checker:10x7:-3", "--board"),
                                             ("charuco:5x5:30:40:DICT_4X4_50", "marker")])
def test_unparsable_board(boards, tmp_path, spec, fragment):
    out = tmp_path / "camera.json"
    assert_clean_error(lumigraph("calib", "calibrate", boards, "--board", spec, "--out", out), fragment)
    _nothing_written(out)


def test_board_that_does_not_match_the_photos(boards, tmp_path):
    out = tmp_path / "camera.json"
    assert_clean_error(lumigraph("calib", "calibrate", boards, "--board", "checker:9x6:30", "--out", out),
                       "no checker:9x6:30 board found", "counts squares")
    _nothing_written(out)


def test_undistort_with_camera_of_another_size(boards, tmp_path):
    from lumigraph.capture.camera import Camera

    cam = tmp_path / "camera.json"
    Camera(np.array([[300.0, 0, 160], [0, 300, 120], [0, 0, 1]]), np.zeros(5), (640, 480)).save(cam)
    out = tmp_path / "und"
    assert_clean_error(lumigraph("calib", "undistort", "--camera", cam, boards / "view_00.png", "--out", out),
                       "view_00.png", "640x480")
    assert not out.exists()


def test_stereo_and_rectify_through_files(tmp_path):
    s = tmp_path / "s"
    render("boards-stereo", size=(320, 240), seed=8, views=6).save(s)
    rig = tmp_path / "rig.json"
    left = sorted(s.glob("left_*.png"))
    right = sorted(s.glob("right_*.png"))
    r = lumigraph("calib", "stereo", "--left", *left, "--right", *right, "--board", "checker:10x7:30",
                  "--model", "k1k2p1p2k3", "--out", rig, "--yaml", tmp_path / "rig.yml", "--quiet")
    assert r.returncode == 0, r.stderr
    d = json.loads(rig.read_text())
    assert abs(d["baseline"] / 120.0 - 1) < 0.02
    out = tmp_path / "rect"
    r = lumigraph("calib", "rectify", "--rig", rig, left[0], right[0], "--out", out, "--quiet")
    assert r.returncode == 0, r.stderr
    assert io.read_image(out / "left.png").shape == (240, 320)
    assert np.load(out / "maps_left.npy").shape == (240, 320, 2)
    assert json.loads((out / "rectification.json").read_text())["focal_px"] > 0


def test_option_checks_live_in_the_library_and_the_cli_names_flags(boards, tmp_path):
    # the library checks its own arguments, naming them ...
    from lumigraph.calib.calibrate import calibrate_stereo, check_stereo_pairs
    from lumigraph.calib.rectify import check_rectify_options
    from lumigraph.capture.errors import InputError

    with pytest.raises(InputError, match=r"^alpha: expected a value in \[0, 1\], got 1.5"):
        check_rectify_options(alpha=1.5)
    with pytest.raises(InputError, match="^right: expected as many right images as left"):
        check_stereo_pairs(["a", "b"], ["c"])
    with pytest.raises(InputError, match="^right: expected as many"):
        calibrate_stereo([None, None], [None])
    # ... and the command line reports the flag, before reading any file
    gone = tmp_path / "gone.png"
    for alpha in ("1.5", "-0.1", "nan"):
        r = lumigraph("calib", "rectify", "--rig", tmp_path / "no-rig.json", gone, gone, "--alpha", alpha,
                      "--out", tmp_path / "rect")
        assert_clean_error(r, "error: --alpha: expected a number >= 0 and <= 1")
    r = lumigraph("calib", "stereo", "--left", boards / "view_00.png", boards / "view_01.png",
                  "--right", boards / "view_00.png", "--board", "checker:10x7:30", "--out", tmp_path / "rig.json")
    assert_clean_error(r, "error: --right: expected as many right images as left (2), got 1")
    r = lumigraph("calib", "calibrate", boards, "--model", "k9", "--out", tmp_path / "c.json")
    assert r.returncode == 2 and "--model" in r.stderr
    assert not (tmp_path / "rect").exists() and not (tmp_path / "rig.json").exists()
