"""``lumigraph stereo``: bad options, images blamed on the wrong file, outputs
over inputs (exit 2), and an SfM that registered too few views (exit 3)."""

import json
from pathlib import Path

import numpy as np
import pytest
from reliability._refusal import assert_refused

from lumigraph.capture import io
from lumigraph.capture.errors import EstimationError
from lumigraph.capture.render import render
from lumigraph.stereo.cli import main


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    d = tmp_path_factory.mktemp("pair")
    s = render("stereo-pair", size=(200, 150), layout="rectified")
    s.save(d)
    # a disparity of 10 px everywhere: depth f B / d = 200 * 0.18 / 10 = 3.6 rig units
    io.write_pfm(d / "d.pfm", np.full((150, 200), 10.0, np.float32))
    return d


def test_a_left_image_of_the_wrong_size_is_blamed_not_the_right(pair, tmp_path, capsys):
    small = tmp_path / "small.png"
    io.write_image(small, io.read_image(pair / "left.png")[:100, :150])
    out = tmp_path / "d.pfm"
    assert_refused(main, ["match", small, pair / "right.png", "--rig", pair / "gt.json",
                          "--max-disp", "16", "--out", out], small, capsys, outputs=[out],
                   inputs=[pair], fragments=["150x100", "200x150"])


def test_the_same_file_as_both_views_is_refused(pair, tmp_path, capsys):
    out = tmp_path / "d.pfm"
    assert_refused(main, ["match", pair / "left.png", pair / "left.png", "--max-disp", "16",
                          "--out", out], pair / "left.png", capsys, outputs=[out], inputs=[pair],
                   fragments=["also the left image"])


@pytest.mark.parametrize("value", ["0", "-1", "nan"])
def test_max_depth_must_be_positive(pair, tmp_path, capsys, value):
    out = tmp_path / "p.ply"
    assert_refused(main, ["depth", pair / "d.pfm", "--rig", pair / "gt.json",
                          f"--max-depth={value}", "--out", out], "--max-depth", capsys,
                   outputs=[out], inputs=[pair])


def test_a_max_depth_that_keeps_no_point_is_named(pair, tmp_path, capsys):
    out = tmp_path / "p.ply"
    assert_refused(main, ["depth", pair / "d.pfm", "--rig", pair / "gt.json",
                          "--max-depth", "1", "--out", out], "--max-depth", capsys,
                   outputs=[out], inputs=[pair], fragments=["no point is nearer than 1"])
    # above the 3.6 of every point: all are kept
    assert main(["depth", str(pair / "d.pfm"), "--rig", str(pair / "gt.json"), "--max-depth", "4",
                 "--out", str(out), "-q"]) == 0
    assert len(io.read_ply(out)[0]) == 150 * 200


@pytest.mark.parametrize("value", ["0", "-1", "inf"])
def test_triangulate_pixel_sigma_must_be_positive(pair, tmp_path, capsys, value):
    tracks = tmp_path / "t.json"
    tracks.write_text(json.dumps({"views": [], "tracks": []}))
    out = tmp_path / "p.json"
    assert_refused(main, ["triangulate", tracks, f"--pixel-sigma={value}", "--out", out],
                   "--pixel-sigma", capsys, outputs=[out], inputs=[tracks])


def test_model_based_warped_image_never_replaces_the_key(pair, tmp_path, capsys):
    model = tmp_path / "model.npy"
    np.save(model, np.full((150, 200), 3.0))
    out = tmp_path / "z.pfm"
    assert_refused(main, ["model-based", pair / "left.png", pair / "right.png", "--rig",
                          pair / "gt.json", "--model", model, "--max-offset", "0.3",
                          "--warped", pair / "left.png", "--out", out], "--warped", capsys,
                   outputs=[out], inputs=[pair, model], fragments=["inputs"])


@pytest.fixture
def views(tmp_path):
    rng = np.random.default_rng(0)
    files = []
    for k in range(4):
        files.append(tmp_path / f"v{k}.png")
        io.write_image(files[-1], rng.integers(0, 255, (40, 50), dtype=np.uint8))
    return files


@pytest.mark.parametrize("registered, fragment", [(1, "registered 1 of 4 views"),
                                                  (None, "fewer than 2 of 4 views")])
def test_sfm_registering_too_few_views_is_unusable(views, tmp_path, capsys, monkeypatch,
                                                   registered, fragment):
    import lumigraph.stereo.sfm as sfm
    from lumigraph.capture.camera import Camera

    def fake(images, names, **kw):  # what COLMAP would report, without running it
        if registered is None:
            raise EstimationError("images", "fewer than two views could be registered")
        n = len(names)
        reg = np.arange(n) < registered
        cam = Camera(np.diag([60.0, 60.0, 1.0]), [0, 0, 0, 0, 0], (50, 40), "k1", {})
        return sfm.Reconstruction(tuple(Path(x).name for x in names), reg,
                                  np.repeat(np.eye(3)[None], n, 0), np.zeros((n, 3)), cam,
                                  np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros(0, int),
                                  {"registered": registered, "fixed_intrinsics": True})

    monkeypatch.setattr(sfm, "reconstruct", fake)
    out = tmp_path / "sfm"
    folder = str(Path(views[0]).resolve().parent)  # the one line names the views' folder
    assert_refused(main, ["sfm", *views, "--out", out], folder, capsys, code=3, outputs=[out],
                   inputs=views, fragments=[fragment, "nothing written"])


def test_sfm_min_registered_is_a_fraction(views, tmp_path, capsys):
    assert_refused(main, ["sfm", *views, "--min-registered", "1.5", "--out", tmp_path / "s"],
                   "--min-registered", capsys, outputs=[tmp_path / "s"], inputs=views)
