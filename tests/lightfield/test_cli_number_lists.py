"""``lumigraph lightfield``: one syntax for number lists, and import without --spacing (issue 16)."""

import json

import numpy as np
import pytest

from lumigraph.capture.io import read_exr, write_image
from lumigraph.lightfield.cli import build_parser, join_number_lists, main


@pytest.mark.parametrize("argv", [
    ["--slope", "-2", "-1", "0"], ["--slope=-2", "-1", "0"], ["--slope=-2,-1,0"],
    ["--slope", "-2,-1,0"], ["--slope", "-2,-1", "0"], ["--slope", "-2", "-1,0"]])
def test_every_spelling_of_a_slope_list_is_the_same(argv):
    a = build_parser().parse_args(join_number_lists(["refocus", "lf", *argv, "--out", "o"]))
    assert [v for g in a.slope for v in g] == [-2.0, -1.0, 0.0]


@pytest.mark.parametrize("argv", [["--slopes", "-1,1,41"], ["--slopes=-1,1,41"],
                                  ["--slopes", "-1", "1", "41"], ["--slopes=-1", "1,41"]])
def test_depth_slopes_spellings(argv):
    a = build_parser().parse_args(join_number_lists(["depth", "lf", *argv, "--out", "d.pfm"]))
    assert a.slopes == (-1.0, 1.0, 41)


def test_alpha_and_depth_lists_and_bad_values(capsys):
    a = build_parser().parse_args(join_number_lists(["refocus", "lf", "--alpha", "0.9,1.1", "1.2",
                                                     "--out", "o"]))
    assert [v for g in a.alpha for v in g] == [0.9, 1.1, 1.2]
    # a negative depth is still out of range, reported under the flag (exit 2)
    assert main(["refocus", "lf", "--depth", "-2,3", "--out", "o"]) == 2
    assert "--depth" in capsys.readouterr().err
    # a bad word among the values is reported under the flag, as argparse would
    assert main(["refocus", "lf", "--slope", "-1", "inf", "--out", "o"]) == 2
    assert "--slope" in capsys.readouterr().err
    # '--slopes' takes one value: a positional after it stays a positional
    assert join_number_lists(["depth", "--slopes", "-1,1,9", "lf"]) == ["depth",
                                                                      "--slopes=-1,1,9", "lf"]


def test_import_without_spacing_refocuses_by_slope_refuses_depth(tmp_path, capsys):
    files = []
    for k in range(4):
        files.append(tmp_path / f"v{k}.png")
        write_image(files[-1], np.full((8, 10, 3), 40 * k + 20, np.uint8))
    lf = tmp_path / "lf"
    assert main(["import", *map(str, files), "--grid", "2x2", "--focal-px", "100", "--out",
                 str(lf), "-q"]) == 0
    meta = json.loads((lf / "lightfield.json").read_text())
    assert "spacing_unknown" in meta["info"]
    out = tmp_path / "s"
    assert main(["refocus", str(lf), "--slope", "-1", "0", "1", "--out", str(out), "-q"]) == 0
    assert read_exr(out / "refocus-001.exr").shape == (8, 10, 3)
    capsys.readouterr()
    assert main(["refocus", str(lf), "--depth", "2", "--out", str(tmp_path / "d.exr")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "lightfield.json" in err and "--spacing" in err
    assert main(["render", str(lf), "--position", "0", "0", "0", "--focus-depth", "2",
                 "--out", str(tmp_path / "v.exr")]) == 2
    assert "--spacing" in capsys.readouterr().err
    assert not (tmp_path / "d.exr").exists() and not (tmp_path / "v.exr").exists()
