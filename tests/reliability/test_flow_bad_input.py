"""``lumigraph flow``: bad options and outputs over inputs are refused before
any work (exit 2, one line naming the flag or file, nothing written)."""

import numpy as np
import pytest
from reliability._refusal import assert_refused

from lumigraph.capture import io
from lumigraph.capture.render import render
from lumigraph.stereo.flow_cli import main


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    d = tmp_path_factory.mktemp("flowpair")
    render("flow", size=(96, 72), seed=2).save(d)
    return d


@pytest.mark.parametrize("flags, where", [
    (("--iterations", "0"), "--iterations"),
    (("--levels", "13"), "--levels"),
    (("--levels", "0"), "--levels"),
    (("--finest-level", "-1"), "--finest-level"),
    (("--window", "4"), "--window"),
    (("--median-radius", "65"), "--median-radius"),
])
def test_out_of_range_knobs_are_refused_by_the_parser(pair, tmp_path, capsys, flags, where):
    out = tmp_path / "f.flo"
    assert_refused(main, [pair / "frame00.png", pair / "frame01.png", *flags, "--out", out],
                   where, capsys, outputs=[out, tmp_path / "f.prob.exr"], inputs=[pair])


def test_viz_over_an_input_image_is_refused(pair, tmp_path, capsys):
    out = tmp_path / "f.flo"
    assert_refused(main, [pair / "frame00.png", pair / "frame01.png", "--out", out,
                          "--viz", pair / "frame00.png"],
                   "--viz", capsys, outputs=[out], inputs=[pair], fragments=["inputs"])


def test_the_probability_image_beside_out_is_declared(pair, tmp_path, capsys):
    # f.prob.exr is written beside f.flo: a file of that name in an input folder,
    # not flow's, is refused before any flow is computed
    d = tmp_path / "frames"
    d.mkdir()
    for n in ("frame00.png", "frame01.png"):
        (d / n).write_bytes((pair / n).read_bytes())
    io.write_exr(d / "f.prob.exr", np.zeros((4, 4), np.float32))
    assert_refused(main, [d / "frame00.png", d / "frame01.png", "--out", d / "f.flo"],
                   "--out", capsys, outputs=[d / "f.flo"], inputs=[d], fragments=["f.prob.exr"])


def test_a_picture_folder_for_two_images_is_named_viz(pair, tmp_path, capsys):
    out = tmp_path / "f.flo"
    assert_refused(main, [pair / "frame00.png", pair / "frame01.png", "--out", out,
                          "--viz", tmp_path / "pics"], "--viz", capsys,
                   outputs=[out, tmp_path / "pics"], inputs=[pair], fragments=[".png"])
