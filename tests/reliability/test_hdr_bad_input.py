"""``lumigraph hdr`` refuses bad options and outputs that would overwrite its
inputs: exit 2, one line naming the flag (or file), nothing written at the
output, the inputs' bytes unchanged. The library refuses the same values,
naming its argument."""

from __future__ import annotations

import math

import numpy as np
import pytest
from reliability._inprocess_cli import assert_refused, cli, snapshot

from lumigraph.capture.errors import InputError


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """A small 3-exposure bracket folder, its true response and a radiance map."""
    from lumigraph.capture.io import write_exr
    from lumigraph.capture.render import render
    from lumigraph.hdr.response import ResponseCurve

    root = tmp_path_factory.mktemp("hdr-bad")
    s = render("bracket", size=(48, 36), exposures=3)
    s.save(root / "bracket")
    ResponseCurve("gt", 8, s.gt_arrays["g"]).save(root / "response.json")
    write_exr(root / "rad.exr", s.gt_arrays["radiance"].astype(np.float32))
    return root


def _refused(capsys, data, tmp_path, where, argv, *fragments):
    """Run ``argv`` (``{B}`` the bracket, ``{R}`` the response, ``{E}`` the
    radiance, ``{O}`` an output under tmp_path) and check the refusal."""
    fill = {"{B}": data / "bracket", "{R}": data / "response.json", "{E}": data / "rad.exr"}
    out = tmp_path / "out"
    args = [fill.get(a, a) for a in argv]
    args = [str(a).replace("{O}", str(out)) for a in args]
    before = snapshot(data)
    r = cli(capsys, *args)
    assert_refused(r, where, *fragments)
    assert snapshot(data) == before  # the inputs' bytes
    assert not any(tmp_path.iterdir()), list(tmp_path.iterdir())  # nothing at the output
    return r


# The list, and each numeric option's edges: refused by the parser.
BAD_OPTIONS = [
    ("--window", ["hdr", "video", "{B}", "--response", "{R}", "--out", "{O}", "--window", "0"]),
    ("--window", ["hdr", "video", "{B}", "--response", "{R}", "--out", "{O}", "--window", "4"]),
    ("--window", ["hdr", "video", "{B}", "--response", "{R}", "--out", "{O}", "--window", "nan"]),
    ("--key", ["hdr", "video", "{B}", "--response", "{R}", "--out", "{O}", "--key", "inf"]),
    ("--consistency-sigma", ["hdr", "video", "{B}", "--response", "{R}", "--out", "{O}",
                             "--consistency-sigma", "0"]),
    ("--temporal", ["hdr", "video", "{B}", "--response", "{R}", "--out", "{O}", "--temporal",
                    "4"]),
    ("--key", ["hdr", "tonemap", "{E}", "--out", "{O}.png", "--key", "0"]),
    ("--key", ["hdr", "tonemap", "{E}", "--out", "{O}.png", "--key", "nan"]),
    ("--key", ["hdr", "tonemap", "{E}", "--out", "{O}.png", "--key=-1"]),
    ("--order", ["hdr", "response", "{B}", "--method", "mitsunaga-nayar", "--out", "{O}.json",
                 "--order", "2.5"]),
    ("--order", ["hdr", "response", "{B}", "--out", "{O}.json", "--order", "0"]),
    ("--order", ["hdr", "response", "{B}", "--out", "{O}.json", "--order", "11"]),
    ("--smoothness", ["hdr", "response", "{B}", "--out", "{O}.json", "--smoothness", "nan"]),
    ("--smoothness", ["hdr", "response", "{B}", "--out", "{O}.json", "--smoothness=-0.5"]),
    ("--smoothness", ["hdr", "response", "{B}", "--out", "{O}.json", "--smoothness", "inf"]),
    ("--samples", ["hdr", "response", "{B}", "--out", "{O}.json", "--samples", "1"]),
    ("--seed", ["hdr", "response", "{B}", "--out", "{O}.json", "--seed=-1"]),
    ("--times", ["hdr", "response", "{B}", "--out", "{O}.json", "--times", "1,nan,4"]),
    ("--noise", ["hdr", "merge", "{B}", "--response", "{R}", "--out", "{O}.exr", "--noise",
                 "10000"]),
    ("--noise", ["hdr", "merge", "{B}", "--response", "{R}", "--out", "{O}.exr", "--noise",
                 "nan,5"]),
    ("--levels", ["hdr", "align", "{B}", "--out", "{O}", "--levels", "0"]),
    ("--reference", ["hdr", "align", "{B}", "--out", "{O}", "--reference=-1"]),
    ("--out", ["hdr", "convert", "{E}", "{O}.jpg"]),
]


@pytest.mark.parametrize("where,argv", BAD_OPTIONS,
                         ids=[f"{a[1]}{a[-2] if a[-2].startswith('--') else ''}={a[-1]}"
                              for _, a in BAD_OPTIONS])
def test_bad_options_are_refused_before_any_work(capsys, data, tmp_path, where, argv):
    # convert's output is positional: its name is the argument's
    _refused(capsys, data, tmp_path, "output" if argv[1] == "convert" else where, argv)


def test_the_library_refuses_the_same_values_naming_its_arguments():
    from lumigraph.hdr.debevec1997 import check_smoothness
    from lumigraph.hdr.kang2003 import check_video_options, tonemap_video
    from lumigraph.hdr.mitsunaga1999 import check_order
    from lumigraph.hdr.reinhard2002 import tonemap
    from lumigraph.hdr.ward2003 import align, check_align_options

    rad = np.ones((8, 8, 3), np.float32)
    cases = [
        (lambda: tonemap(rad, key=0.0), "key"),
        (lambda: tonemap(rad, key=math.nan), "key"),
        (lambda: tonemap(rad, key=-1.0), "key"),
        (lambda: tonemap_video(rad[None].repeat(2, 0), key=math.inf), "key"),
        (lambda: check_order(2.5), "order"),
        (lambda: check_order(0), "order"),
        (lambda: check_order(True), "order"),
        (lambda: check_smoothness(math.nan), "smoothness"),
        (lambda: check_smoothness(-1.0), "smoothness"),
        (lambda: check_video_options(window=0), "window"),
        (lambda: check_video_options(window=4), "window"),
        (lambda: check_video_options(consistency_sigma=math.nan), "consistency_sigma"),
        (lambda: check_align_options(levels=0), "levels"),
        (lambda: align(np.zeros((3, 16, 16), np.uint8), reference=3), "reference"),
    ]
    for call, where in cases:
        with pytest.raises(InputError) as e:
            call()
        assert e.value.where == where
    assert check_order("auto") == "auto" and check_smoothness(0.0) == 0.0


def test_align_into_its_input_folder_is_refused_before_aligning(capsys, data, tmp_path,
                                                                monkeypatch):
    import lumigraph.hdr.ward2003 as ward

    def never(*a, **k):
        raise AssertionError("aligned before the outputs were checked")

    monkeypatch.setattr(ward, "align", never)
    d = data / "bracket"
    before = snapshot(data)
    r = cli(capsys, "hdr", "align", d, "--out", d)
    assert_refused(r, "--out", "exposure_00.png", "input")
    assert snapshot(data) == before
    # an index past the images is the library's refusal, under the flag
    _refused(capsys, data, tmp_path, "--reference",
             ["hdr", "align", "{B}", "--out", "{O}", "--reference", "3"])


def test_video_into_its_input_folder_is_refused_before_the_video(capsys, data, tmp_path,
                                                                 monkeypatch):
    # a rendered video's frames are frame_NNN.png: --tonemap would write over them
    import lumigraph.hdr.kang2003 as kang
    from lumigraph.capture.render import render

    def never(*a, consistency_sigma=6.0, **k):  # (--help shows the real default)
        raise AssertionError("computed before the outputs were checked")

    monkeypatch.setattr(kang, "hdr_video", never)
    d = tmp_path / "video"
    render("bracket_video", size=(32, 24), frames=2).save(d)
    before = snapshot(d)
    r = cli(capsys, "hdr", "video", d, "--response", data / "response.json", "--tonemap",
            "--out", d)
    assert_refused(r, "--out", "frame_000.png")
    assert snapshot(d) == before


def test_response_into_its_input_folder_is_refused(capsys, data, tmp_path):
    d = data / "bracket"
    before = snapshot(data)
    assert_refused(cli(capsys, "hdr", "response", d, "--out", d / "stack.json"), "--out",
                   "stack.json")
    assert_refused(cli(capsys, "hdr", "response", d, "--out", d / "new.json", "--plot",
                       d / "exposure_00.png"), "--plot", "exposure_00.png")
    assert snapshot(data) == before
    assert not (d / "new.json").exists()


def test_an_output_file_that_is_a_folder_is_refused_and_leaves_no_sidecar(capsys, data,
                                                                         tmp_path):
    for verb, argv, name in (
            ("merge", ["{B}", "--response", "{R}"], "rad.exr"),
            ("tonemap", ["{E}"], "t.png"),
            ("response", ["{B}"], "r.json")):
        folder = tmp_path / name
        folder.mkdir()
        fill = {"{B}": data / "bracket", "{R}": data / "response.json", "{E}": data / "rad.exr"}
        r = cli(capsys, "hdr", verb, *[fill.get(a, a) for a in argv], "--out", folder)
        assert_refused(r, "--out", "folder")
        assert list(folder.iterdir()) == [] and sorted(p.name for p in tmp_path.iterdir()) == [name]
        folder.rmdir()


def test_the_plot_is_reported_under_its_own_flag(capsys, data, tmp_path):
    for plot in (tmp_path / "curve.jpg", tmp_path / "dir.png"):
        if plot.suffix == ".png":
            plot.mkdir()
        r = cli(capsys, "hdr", "response", data / "bracket", "--out", tmp_path / "r.json",
                "--plot", plot)
        assert_refused(r, "--plot")
        assert not (tmp_path / "r.json").exists()
