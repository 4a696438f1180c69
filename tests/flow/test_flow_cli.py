"""``lumigraph flow`` through the command line: outputs, sidecars, bad input."""

import json

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture import io
from lumigraph.capture.render import render


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    d = tmp_path_factory.mktemp("pair")
    render("flow", size=(96, 72), seed=2).save(d)
    return d


def test_flow_writes_flo_probability_picture_and_meta(pair, tmp_path):
    out = tmp_path / "f.flo"
    r = lumigraph("flow", pair / "frame00.png", pair / "frame01.png", "--out", out,
                  "--viz", tmp_path / "f.png", "-q")
    assert r.returncode == 0, r.stderr
    flow = io.read_flo(out)
    assert flow.shape == (72, 96, 2)
    prob = io.read_exr(tmp_path / "f.prob.exr")
    assert prob.shape == (72, 96) and 0 <= prob.min() and prob.max() <= 1
    meta = json.loads((tmp_path / "f.flo.meta.json").read_text())
    assert meta["model"]["levels"] >= 1 and meta["model"]["level_choice"]["candidates"]
    assert io.read_image(tmp_path / "f.png").shape == (72, 96, 3)


def test_video_matching_method(pair, tmp_path):
    out = tmp_path / "m.flo"
    r = lumigraph("flow", pair / "frame00.png", pair / "frame01.png", "--out", out,
                  "--method", "video-matching", "--levels", "2", "-q")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "m.flo.meta.json").read_text())["model"]["levels"] == 2
    assert (tmp_path / "m.prob.exr").exists()


def _nothing_written(d):
    return not any(p.name.startswith("out") for p in d.iterdir())


def test_different_sizes(pair, tmp_path):
    small = tmp_path / "small.png"
    io.write_image(small, np.zeros((40, 50, 3), np.uint8))
    r = lumigraph("flow", pair / "frame00.png", small, "--out", tmp_path / "out.flo")
    assert_clean_error(r, "small.png", "50x40")
    assert _nothing_written(tmp_path)


def test_empty_image(pair, tmp_path):
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    r = lumigraph("flow", empty, pair / "frame01.png", "--out", tmp_path / "out.flo")
    assert_clean_error(r, "empty.png")
    assert _nothing_written(tmp_path)


def test_missing_file(pair, tmp_path):
    r = lumigraph("flow", pair / "frame00.png", tmp_path / "nope.png", "--out", tmp_path / "out.flo")
    assert_clean_error(r, "nope.png")
    assert _nothing_written(tmp_path)


def test_bad_levels_and_out(pair, tmp_path):
    r = lumigraph("flow", pair / "frame00.png", pair / "frame01.png", "--out",
                  tmp_path / "out.flo", "--levels", "zero")
    assert_clean_error(r, "--levels")
    r = lumigraph("flow", pair / "frame00.png", pair / "frame01.png", "--out", tmp_path / "out.png")
    assert_clean_error(r, "--out")
    assert _nothing_written(tmp_path)


def test_bench_flow_quick(tmp_path):
    r = lumigraph("bench", "flow", "--out", tmp_path, "--quick", "-q")
    assert r.returncode == 0, r.stderr
    js = json.loads((tmp_path / "report.json").read_text())
    rows = js["stages"]["flow"]["rows"]
    methods = {x["method"] for x in rows}
    assert {"pyramid (ours)", "Farneback", "DIS medium", "video matching (ours)"} <= methods
    assert all(x["status"] == "ok" or x["status"].startswith("unavailable") for x in rows)
    assert js["stages"]["flow"]["checks"]
    assert (tmp_path / "flow.png").read_bytes().startswith(b"\x89PNG")


@pytest.mark.parametrize("flags, kw", [(["--median-radius", "5"], dict(median_radius=5)),
                                       (["--finest-level", "1", "--iterations", "1"],
                                        dict(finest_level=1, iterations=1))])
def test_median_radius_and_finest_level_reach_the_method(pair, tmp_path, flags, kw):
    from lumigraph.stereo.pyramid_flow import pyramid_flow

    out = tmp_path / "k.flo"
    r = lumigraph("flow", pair / "frame00.png", pair / "frame01.png", "--out", out, "--method",
                  "pyramid", *flags, "-q")
    assert r.returncode == 0, r.stderr
    params = json.loads((tmp_path / "k.flo.meta.json").read_text())["params"]
    assert all(params[k] == v for k, v in kw.items())
    i0, i1 = io.read_image(pair / "frame00.png"), io.read_image(pair / "frame01.png")
    ref = pyramid_flow(i0, i1, method="local", **kw).flow
    # the file holds the library's answer (float32 .flo, unknown stored as 1e10)
    assert np.array_equal(np.isfinite(io.read_flo(out)), np.isfinite(ref))
    assert np.allclose(io.read_flo(out), ref, equal_nan=True, atol=0)


@pytest.mark.parametrize("flags, fragment", [(["--median-radius", "-1"], "--median-radius"),
                                             (["--median-radius", "65"], "--median-radius"),
                                             (["--finest-level", "3", "--levels", "2"], "--finest-level"),
                                             (["--levels", "13"], "--levels"),
                                             (["--method", "video-matching", "--window", "4"],
                                              "--window"),
                                             (["--iterations", "0"], "--iterations"),
                                             (["--method", "video-matching", "--median-radius", "5"],
                                              "--method"),
                                             (["--median-radius", "5"], "--method"),
                                             (["--method", "pyramid", "--preset", "fast"], "--preset"),
                                             (["--preset", "slow"], "--preset")])
def test_bad_flow_knobs(pair, tmp_path, flags, fragment):
    assert_clean_error(lumigraph("flow", pair / "frame00.png", pair / "frame01.png", "--out",
                                 tmp_path / "out.flo", *flags), fragment)
    assert _nothing_written(tmp_path)


@pytest.mark.parametrize("kw, where", [(dict(levels=13), "levels"), (dict(levels=0), "levels"),
                                       (dict(window=4), "window"), (dict(iterations=0), "iterations"),
                                       (dict(median_radius=65), "median_radius"),
                                       (dict(median_radius=-1), "median_radius"),
                                       (dict(finest_level=-1), "finest_level"),
                                       (dict(levels=2, finest_level=2), "finest_level")])
def test_the_library_checks_the_flow_options_naming_the_argument(kw, where):
    # the ranges the command line enforces are the library's own (validation once)
    from lumigraph.capture.errors import InputError
    from lumigraph.stereo.flow_methods import check_options
    from lumigraph.stereo.pyramid_flow import pyramid_flow
    from lumigraph.stereo.sand2004 import video_matching

    a = np.zeros((16, 16), np.float32)
    for call in (lambda: pyramid_flow(a, a, **kw), lambda: check_options("pyramid", **kw)):
        with pytest.raises(InputError) as e:
            call()
        assert e.value.where == where and not e.value.problem.startswith("--")
    if set(kw) == {"levels"}:
        with pytest.raises(InputError) as e:
            video_matching(a, a, **kw)
        assert e.value.where == "levels"
    with pytest.raises(InputError) as e:
        check_options("video-matching", finest_level=1)
    assert e.value.where == "method"
    assert check_options("video-matching", levels=3, window=9, finest_level=0) == {"levels": 3}


def test_sequence_writes_one_flow_per_consecutive_pair(tmp_path):
    d = tmp_path / "seq"
    s = render("flow-sequence", size=(96, 72), frames=4, seed=3)
    s.save(d)
    frames = [d / n for n in s.image_names]
    out, viz = tmp_path / "flows", tmp_path / "pictures"
    r = lumigraph("flow", *frames, "--out", out, "--viz", viz, "-q")
    assert r.returncode == 0, r.stderr
    index = json.loads((out / "index.json").read_text())
    assert [p["flow"] for p in index["pairs"]] == ["flow_000.flo", "flow_001.flo", "flow_002.flo"]
    for i in range(3):
        flow = io.read_flo(out / f"flow_{i:03d}.flo")
        assert (out / f"flow_{i:03d}.prob.exr").exists() and (viz / f"flow_{i:03d}.png").exists()
        meta = json.loads((out / f"flow_{i:03d}.flo.meta.json").read_text())
        assert [x["path"] for x in meta["inputs"]] == [str(frames[i]), str(frames[i + 1])]
        # each file is that pair's flow: against the pair's ground truth, not another pair's
        gt, occ = s.gt_arrays["flows"][i], s.gt_arrays["occlusions"][i]
        ok = np.isfinite(flow[..., 0]) & ~occ
        epe = np.median(np.linalg.norm(flow[ok] - gt[ok], axis=1))
        assert 0 < epe < 0.5, (i, epe)


def test_sequence_bad_outputs(tmp_path):
    d = tmp_path / "seq"
    s = render("flow-sequence", size=(96, 72), frames=3, seed=3)
    s.save(d)
    frames = [d / n for n in s.image_names]
    assert_clean_error(lumigraph("flow", *frames, "--out", tmp_path / "out.flo"), "--out", "folder")
    assert_clean_error(lumigraph("flow", *frames, "--out", tmp_path / "outdir", "--viz",
                                 tmp_path / "out.png"), "--viz")
    assert_clean_error(lumigraph("flow", frames[0], "--out", tmp_path / "out.flo"), "two images")
    assert _nothing_written(tmp_path)


def test_method_choices_and_help_come_from_the_registry():
    from lumigraph.stereo.flow_methods import FLOW_METHODS

    r = lumigraph("flow", "--help")
    assert r.returncode == 0 and FLOW_METHODS.help_text() in r.stdout
    r = lumigraph("flow", "a.png", "b.png", "--out", "x.flo", "--method", "nope")
    assert r.returncode == 2 and all(n in r.stderr for n in FLOW_METHODS.names)


@pytest.mark.parametrize("preset", ["fast", "accurate"])
def test_preset_reaches_the_default_method(pair, tmp_path, preset):
    from lumigraph.stereo.kroeger2016 import dense_inverse_search

    out = tmp_path / "p.flo"
    r = lumigraph("flow", pair / "frame00.png", pair / "frame01.png", "--out", out,
                  "--preset", preset, "-q")
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "p.flo.meta.json").read_text())
    assert meta["params"]["method"] == "dis" and meta["params"]["preset"] == preset
    i0, i1 = io.read_image(pair / "frame00.png"), io.read_image(pair / "frame01.png")
    ref = dense_inverse_search(i0, i1, preset=preset).flow
    assert np.array_equal(io.read_flo(out), ref)  # the file holds the library's answer
