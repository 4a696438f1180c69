"""``lumigraph lightfield``: bad options, non-finite views and outputs over
inputs are refused before any work (exit 2, one line naming the flag or
file, nothing written, the inputs unchanged)."""

import shutil
import time

import numpy as np
import pytest
from reliability._refusal import assert_refused

from lumigraph.capture.io import read_exr, write_exr
from lumigraph.capture.render import render
from lumigraph.lightfield.cli import main


@pytest.fixture(scope="module")
def lf(tmp_path_factory):
    scene = tmp_path_factory.mktemp("lfscene")
    render("lightfield-array", size=(48, 40), grid="3x3", thin_lens=False).save(scene)
    out = tmp_path_factory.mktemp("lf") / "lf"
    assert main(["import", str(scene), "--out", str(out), "-q"]) == 0
    return out


@pytest.fixture(scope="module")
def lenslet(tmp_path_factory):
    d = tmp_path_factory.mktemp("lenslet")
    render("lightfield-lenslet", size=(12, 10)).save(d)  # 22.4 px lenslet pitch
    return d


@pytest.mark.parametrize("views", ["0", "1", "1000"])
def test_decode_views_bounded_before_any_view_is_sliced(lenslet, tmp_path, capsys, views):
    out = tmp_path / "dec"
    t0 = time.perf_counter()
    line = assert_refused(main, ["decode", lenslet / "raw.png", "--white", lenslet / "white.png",
                                 "--views", views, "--out", out],
                          "--views", capsys, outputs=[out], inputs=[lenslet])
    if views == "1000":  # refused from the white image's pitch, not after 1000² views
        assert "at most 15" in line and "pitch 22.4 px" in line, line
        assert time.perf_counter() - t0 < 10


@pytest.mark.parametrize("slopes", ["0,1", "1,0,5", "0,1,2", "0,1,4.5", "0,nan,5", "0,1,5,7"])
def test_depth_slopes_are_min_max_n(lf, tmp_path, capsys, slopes):
    out = tmp_path / "d.pfm"
    assert_refused(main, ["depth", lf, f"--slopes={slopes}", "--out", out], "--slopes", capsys,
                   outputs=[out], inputs=[lf])


@pytest.mark.parametrize("flags, where", [
    (("--slope", "nan"), "--slope"),
    (("--slope", "0.5", "inf"), "--slope"),
    (("--alpha", "0"), "--alpha"),
    (("--depth", "-3"), "--depth"),
])
def test_refocus_values_are_finite_and_in_range(lf, tmp_path, capsys, flags, where):
    out = tmp_path / "r.exr"
    assert_refused(main, ["refocus", lf, *flags, "--out", out], where, capsys, outputs=[out],
                   inputs=[lf])


def test_several_refocus_values_need_a_folder(lf, tmp_path, capsys):
    out = tmp_path / "r.exr"
    assert_refused(main, ["refocus", lf, "--slope", "0,1", "--out", out], "--out", capsys,
                   outputs=[out], inputs=[lf], fragments=["name a folder"])
    assert not out.exists()  # no folder named r.exr either
    # one value into a folder: refused as before (one value writes one .exr)
    assert_refused(main, ["refocus", lf, "--slope", "0.5", "--out", tmp_path / "sweep"], "--out",
                   capsys, outputs=[tmp_path / "sweep"], inputs=[lf])


def test_all_in_focus_is_an_exr_output_and_never_an_input(lf, tmp_path, capsys):
    assert_refused(main, ["depth", lf, "--all-in-focus", tmp_path / "a.png", "--out",
                          tmp_path / "d.pfm"], "--all-in-focus", capsys,
                   outputs=[tmp_path / "a.png", tmp_path / "d.pfm"], inputs=[lf])
    assert_refused(main, ["depth", lf, "--all-in-focus", lf / "view-00-00.exr", "--out",
                          tmp_path / "d.pfm"], "--all-in-focus", capsys,
                   outputs=[tmp_path / "d.pfm"], inputs=[lf])


def test_import_into_the_views_folder_replaces_no_view(lf, tmp_path, capsys):
    d = tmp_path / "views"
    shutil.copytree(lf, d)
    views = sorted(d.glob("view-*.exr"))
    assert_refused(main, ["import", *views, "--grid", "3x3", "--spacing", "1", "--out", d],
                   "--out", capsys, inputs=[d], fragments=["view-00-00.exr"])


def test_a_non_finite_view_is_refused_naming_its_file(lf, tmp_path, capsys):
    d = tmp_path / "nan-lf"
    shutil.copytree(lf, d)
    bad = d / "view-01-02.exr"
    img = read_exr(bad)
    img[3, 4] = np.nan
    write_exr(bad, img)
    assert_refused(main, ["refocus", d, "--slope", "0.5", "--out", tmp_path / "r.exr"], bad,
                   capsys, outputs=[tmp_path / "r.exr"], inputs=[d], fragments=["not finite"])
    views = sorted(d.glob("view-*.exr"))
    assert_refused(main, ["import", *views, "--grid", "3x3", "--spacing", "1", "--out",
                          tmp_path / "lf2"], bad, capsys, outputs=[tmp_path / "lf2"], inputs=[d])
