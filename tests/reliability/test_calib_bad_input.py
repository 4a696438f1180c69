"""``lumigraph calib``: outputs over the photographs, a rig of the same images
on both sides and bad options are refused before any work (exit 2, one line
naming the flag or file, nothing written, the inputs unchanged)."""

import pytest
from reliability._refusal import assert_refused

from lumigraph.calib.cli import main
from lumigraph.capture.camera import Camera
from lumigraph.capture.errors import EstimationError
from lumigraph.capture.render import render


@pytest.fixture(scope="module")
def boards(tmp_path_factory):
    d = tmp_path_factory.mktemp("boards")
    s = render("boards", size=(320, 240), seed=7, views=6)
    s.save(d)
    return d, s


@pytest.fixture
def camera(boards, tmp_path):
    path = tmp_path / "cam" / "camera.json"
    Camera.from_dict(boards[1].gt["camera"]).save(path)
    return path


def test_undistort_into_the_photographs_folder_is_refused_before_work(boards, camera, capsys):
    d, _ = boards
    photos = sorted(d.glob("view_*.png"))
    for images in (photos, [d]):  # the files, or the folder with its stack.json
        assert_refused(main, ["undistort", "--camera", camera, *images, "--out", d], "--out",
                       capsys, inputs=[d, camera], fragments=["view_00.png"])
    assert not (d / "camera.json").exists() and not (d / "undistorted.json").exists()


def test_calibrate_never_replaces_the_stack_it_reads(boards, tmp_path, capsys):
    d, _ = boards
    assert_refused(main, ["calibrate", d, "--out", d / "stack.json"], "--out", capsys, inputs=[d])
    # the extra exports are declared outputs too, checked before the work: a
    # cameras.txt beside the photographs that calib did not write is kept
    e = tmp_path / "shots"
    e.mkdir()
    for k in range(3):
        (e / f"view_0{k}.png").write_bytes((d / f"view_0{k}.png").read_bytes())
    (e / "cameras.txt").write_text("# the user's own notes\n")
    assert_refused(main, ["calibrate", *sorted(e.glob("*.png")), "--board", "checker:10x7:30",
                          "--out", tmp_path / "c.json", "--yaml", e / "camera.yml",
                          "--colmap", e / "cameras.txt"], "--colmap", capsys,
                   outputs=[tmp_path / "c.json", e / "camera.yml"], inputs=[e],
                   fragments=["cameras.txt"])


def test_the_same_images_on_both_sides_are_no_rig(boards, tmp_path, capsys):
    d, _ = boards
    photos = sorted(d.glob("view_*.png"))[:3]
    out = tmp_path / "rig.json"
    assert_refused(main, ["stereo", "--left", *photos, "--right", *photos, "--board",
                          "checker:10x7:30", "--out", out], "--right", capsys, outputs=[out],
                   inputs=[d], fragments=["also the left image of pair 0"])


def test_identical_views_on_both_sides_give_no_baseline(boards):
    # copies of the left photographs as the right ones: the library finds the
    # rig of zero baseline (1e-9 of the board) and refuses it, naming right
    from lumigraph.calib.calibrate import calibrate_stereo
    from lumigraph.calib.detect import BoardSpec, detect

    _, s = boards
    board = BoardSpec.parse(s.stack["board"])
    dets = [detect(im, board) for im in s.images]
    cam = Camera.from_dict(s.gt["camera"])
    with pytest.raises(EstimationError, match="^right: the right camera sits where the left"):
        calibrate_stereo(dets, list(dets), left_camera=cam, right_camera=cam)


def test_rectify_the_same_file_twice_is_refused(boards, tmp_path, capsys):
    d, _ = boards
    out = tmp_path / "rect"
    assert_refused(main, ["rectify", "--rig", tmp_path / "rig.json", d / "view_00.png",
                          d / "view_00.png", "--out", out], d / "view_00.png", capsys,
                   outputs=[out], inputs=[d])


@pytest.mark.parametrize("flags, where", [(("--alpha", "1.5"), "--alpha"),
                                          (("--alpha", "nan"), "--alpha")])
def test_rectify_alpha_range(boards, tmp_path, capsys, flags, where):
    d, _ = boards
    out = tmp_path / "rect"
    assert_refused(main, ["rectify", "--rig", tmp_path / "rig.json", d / "view_00.png",
                          d / "view_01.png", *flags, "--out", out], where, capsys, outputs=[out],
                   inputs=[d])
