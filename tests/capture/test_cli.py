"""The command-line conventions (DESIGN §5): version, help, exit codes, one-line
errors naming the file, nothing half-written; and the artifact sidecars (§4)."""

import json

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture import io
from lumigraph.capture.artifact import atomic_path, make_meta, meta_path, write_artifact


def test_version_and_help():
    v = lumigraph("--version")
    assert v.returncode == 0 and v.stdout.startswith("lumigraph ")
    h = lumigraph("--help")
    assert h.returncode == 0
    for stage in ("render", "calib", "hdr", "flow", "stereo", "lightfield", "separate", "bench"):
        assert f"  {stage}" in h.stdout


def test_unknown_stage_exits_2_with_one_line():
    assert_clean_error(lumigraph("frobnicate"), "unknown stage")


def test_render_sample_writes_stack_gt_and_meta(tmp_path):
    out = tmp_path / "s"
    r = lumigraph("render", "sample", "--out", out, "--size", "40x20", "--seed", "3",
                  "--noise", "3", "--quiet")
    assert r.returncode == 0, r.stderr
    st = io.read_stack([out])
    assert st.images.shape == (1, 20, 40, 3) and st.bit_depth == 12 and st.linear
    gt = json.loads((out / "gt.json").read_text())
    assert gt["params"]["seed"] == 3 and gt["params"]["noise"] == 3.0
    radiance = np.load(out / "gt" / "radiance.npy")
    # codes = radiance * 4095 + N(0, 3): the residual's spread is the injected noise
    resid = st.images[0].astype(float) - radiance * 4095
    assert 2.5 < resid.std() < 3.5
    meta = json.loads((out / "stack.json.meta.json").read_text())
    assert meta["schema"] == "lumigraph.render" and "numpy" in meta["versions"]


def test_render_is_deterministic(tmp_path):
    for d in ("a", "b"):
        assert lumigraph("render", "sample", "--out", tmp_path / d, "--noise", "2",
                         "--no-cache", "-q").returncode == 0
    assert (tmp_path / "a" / "ramp.png").read_bytes() == (tmp_path / "b" / "ramp.png").read_bytes()


def test_render_bad_options(tmp_path):
    assert_clean_error(lumigraph("render", "nosuch", "--out", tmp_path / "x"), "unknown scene")
    assert_clean_error(lumigraph("render", "sample", "--out", tmp_path / "x", "--size", "3x2"),
                       "--size", "impossible size")
    assert_clean_error(lumigraph("render", "sample", "--out", tmp_path / "x", "--bit-depth", "7"),
                       "--bit-depth", "out of range")
    assert_clean_error(lumigraph("render", "sample", "--out", tmp_path / "x", "--colour", "red"),
                       "--colour", "no such option")
    # issue 3's list, on the scenes they concern
    assert_clean_error(lumigraph("render", "bracket", "--out", tmp_path / "x", "--bit-depth", "7"),
                       "--bit-depth")
    assert_clean_error(lumigraph("render", "bracket", "--out", tmp_path / "x", "--min-time", "-0.01"),
                       "--min-time", "out of range")
    # validated late (after the options parse), still one line
    assert_clean_error(lumigraph("render", "sample", "--out", tmp_path / "x", "--size", "10x10"),
                       "--size", "impossible size")
    assert not (tmp_path / "x").exists()


def test_render_checks_live_in_the_library_and_the_cli_names_flags(tmp_path):
    # the scene validates its size and options, naming the argument ...
    from lumigraph.capture.errors import InputError
    from lumigraph.capture.render import get_scene, render

    with pytest.raises(InputError, match="^bit_depth: 7 is out of range"):
        render("sample", bit_depth=7, cache=False)
    with pytest.raises(InputError, match="^size: impossible size 3x2 for scene 'sample'"):
        get_scene("sample").check_size((3, 2))
    with pytest.raises(InputError, match="^size: impossible size 12x12"):
        render("sample", size=(12, 12), cache=False)
    # ... and the command line reports the flag that set it
    r = lumigraph("render", "sample", "--out", tmp_path / "x", "--size", "3x2")
    assert_clean_error(r, "error: --size: impossible size 3x2 for scene 'sample' (at least 16x16)")
    assert_clean_error(lumigraph("render", "sample", "--out", tmp_path / "x", "--size", "3by2"),
                       "error: --size: expected WIDTHxHEIGHT")
    assert_clean_error(lumigraph("render", "sample", "--out", tmp_path / "x", "--bit-depth", "7"),
                       "error: --bit-depth: 7 is out of range")
    assert not (tmp_path / "x").exists()


def test_render_list_documents_options():
    r = lumigraph("render", "--list")
    assert r.returncode == 0 and "sample" in r.stdout and "--bit-depth" in r.stdout


# ---------------------------------------------------------- bad input through a command
def _img(path, shape=(8, 10, 3)):
    io.write_image(path, np.zeros(shape, np.uint8))


def test_missing_file(tmp_path):
    assert_clean_error(lumigraph("inspect", tmp_path / "gone.png"), "gone.png", "not found")


def test_truncated_image(tmp_path):
    p = tmp_path / "cut.png"
    io.write_image(p, np.random.default_rng(0).integers(0, 255, (40, 40, 3), dtype=np.uint8))
    p.write_bytes(p.read_bytes()[:300])
    assert_clean_error(lumigraph("inspect", p), "cut.png")


def test_wrong_extension(tmp_path):
    p = tmp_path / "data.xyz"
    p.write_text("nothing")
    assert_clean_error(lumigraph("inspect", p), "data.xyz", "unsupported image extension")


def test_mismatched_sizes_in_stack_and_nothing_written(tmp_path):
    _img(tmp_path / "a.png")
    _img(tmp_path / "b.png", (8, 12, 3))
    out = tmp_path / "summary.json"
    assert_clean_error(lumigraph("inspect", tmp_path / "a.png", tmp_path / "b.png", "--out", out),
                       "b.png", "one size")
    assert not out.exists() and not meta_path(out).exists()
    assert not list(tmp_path.glob(".*tmp*"))


def test_missing_exif_exposure(tmp_path):
    _img(tmp_path / "a.png")
    _img(tmp_path / "b.png")
    assert_clean_error(lumigraph("inspect", tmp_path / "a.png", tmp_path / "b.png", "--need-times"),
                       "a.png", "no EXIF exposure time")


def test_nan_in_float_input(tmp_path):
    img = np.ones((4, 4, 3), np.float32)
    img[0, 0, 1] = np.inf
    io.write_exr(tmp_path / "bad.exr", img)
    assert_clean_error(lumigraph("inspect", tmp_path / "bad.exr"), "bad.exr", "NaN/inf")


def test_bad_times_value(tmp_path):
    _img(tmp_path / "a.png")
    assert_clean_error(lumigraph("inspect", tmp_path / "a.png", "--times", "fast"), "--times")


def test_inspect_success_writes_summary_and_sidecar(tmp_path):
    _img(tmp_path / "a.png")
    _img(tmp_path / "b.png")
    out = tmp_path / "s.json"
    r = lumigraph("inspect", tmp_path / "a.png", tmp_path / "b.png", "--times", "1/30,1/8",
                  "--out", out)
    assert r.returncode == 0, r.stderr
    s = json.loads(out.read_text())
    assert s["count"] == 2 and s["exposure_times_s"][0] == 1 / 30
    meta = json.loads(meta_path(out).read_text())
    assert [i["path"] for i in meta["inputs"]] == [str(tmp_path / "a.png"), str(tmp_path / "b.png")]
    assert all(len(i["sha256"]) == 64 for i in meta["inputs"])


# --------------------------------------------------------------------- atomic writes
def test_failed_write_leaves_previous_artifact_intact(tmp_path):
    target = tmp_path / "r.txt"
    write_artifact(target, lambda p: p.write_text("good"), meta=make_meta("t"))

    def broken(p):
        p.write_text("half")
        raise RuntimeError("disk on fire")

    try:
        write_artifact(target, broken, meta=make_meta("t"))
    except RuntimeError:
        pass
    assert target.read_text() == "good"
    assert sorted(f.name for f in tmp_path.iterdir()) == ["r.txt", "r.txt.meta.json"]


def test_atomic_path_keeps_suffix(tmp_path):
    with atomic_path(tmp_path / "x.png") as tmp:
        assert tmp.suffix == ".png" and tmp.parent == tmp_path
        tmp.write_bytes(b"1")
    assert (tmp_path / "x.png").read_bytes() == b"1"


def test_internal_fault_is_exit_1(tmp_path, monkeypatch):
    from lumigraph.capture import commandline as command

    p = command.make_parser("t", "t")
    p.set_defaults(func=lambda a: 1 / 0)
    assert command.run(p, []) == 1
