"""``lumigraph separate`` (and its ``patterns`` verb), ``inspect`` and
``bench``: every option typed, bad values refused before any work with one
line naming the flag, outputs never over the inputs."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest
from reliability._inprocess_cli import assert_refused, cli, snapshot

from lumigraph.capture.commandline import Number, NumberList
from lumigraph.capture.errors import InputError


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """Two linear 16-bit checker captures and their complements' order."""
    from lumigraph.capture import io
    from lumigraph.capture.patterns import checker_set

    d = tmp_path_factory.mktemp("sep-bad") / "caps"
    ps = checker_set((32, 24), square=4, shifts=1)
    for i, im in enumerate(ps.images):
        io.write_image(d / f"c{i}.png", np.round((0.2 + 0.6 * im) * 65535).astype(np.uint16),
                       bit_depth=16)
    return d


SEPARATE_BAD = [("--noise", "nan"), ("--noise", "-1"), ("--saturation", "0"),
                ("--saturation", "inf"), ("--tile", "1"), ("--tile", "2.5"), ("--alpha", "1"),
                ("--b", "1"), ("--b", "nan")]


@pytest.mark.parametrize("flag,value", SEPARATE_BAD)
def test_separate_refuses_bad_options(capsys, captures, tmp_path, flag, value):
    before = snapshot(captures)
    out = tmp_path / "out"
    r = cli(capsys, "separate", *sorted(captures.glob("*.png")), f"{flag}={value}", "--out", out)
    assert_refused(r, flag)
    assert not out.exists() and snapshot(captures) == before


def test_separate_library_refuses_noise_and_saturation_naming_them():
    from lumigraph.separation import separate
    from lumigraph.separation.separate import check_options

    for kw, where in ((dict(noise_sigma=math.nan), "noise_sigma"),
                      (dict(noise_sigma=-1.0), "noise_sigma"),
                      (dict(saturation=0.0), "saturation"), (dict(saturation=math.inf), "saturation"),
                      (dict(tile=2.5), "tile")):
        with pytest.raises(InputError) as e:
            check_options(**kw)
        assert e.value.where == where
    with pytest.raises(InputError) as e:
        separate(np.ones((2, 8, 8, 1), np.float32), noise_sigma=math.nan)
    assert e.value.where == "noise_sigma"


def test_separate_into_its_input_folder_is_refused_before_separating(capsys, captures,
                                                                     monkeypatch):
    import lumigraph.separation as sep

    def never(*a, **k):
        raise AssertionError("separated before the outputs were checked")

    monkeypatch.setattr(sep, "separate", never)
    user = captures / "direct.exr"
    user.write_bytes(b"a user's file, not ours")
    try:
        before = snapshot(captures)
        r = cli(capsys, "separate", *sorted(captures.glob("c*.png")), "--out", captures)
        assert_refused(r, "--out", "direct.exr")
        assert snapshot(captures) == before
    finally:
        user.unlink()


def _typed_actions(parser):
    for a in parser._actions:
        if a.option_strings and a.nargs != 0 and not isinstance(a, argparse._HelpAction):
            yield a


def test_the_patterns_verb_types_every_option_and_refuses_bad_numbers(capsys):
    # the structural test walks build_parser(); 'separate patterns' has a parser of its own
    from lumigraph.separation.cli import build_patterns_parser

    p = build_patterns_parser()
    for a in _typed_actions(p):
        assert a.choices is not None or a.type not in (None, str, int, float), a.dest
        if isinstance(a.type, Number | NumberList):
            flag = next(o for o in a.option_strings if o.startswith("--"))
            for bad in a.type.bad_examples():
                with pytest.raises(SystemExit) as e:
                    p.parse_args(["--out", "x", f"{flag}={bad}"])
                assert e.value.code == 2
                err = capsys.readouterr().err.strip().splitlines()
                assert len(err) == 1 and err[0].startswith(f"error: {flag}:"), err
    with pytest.raises(SystemExit):
        p.parse_args(["--out", "x", "--size", "640by480"])
    assert capsys.readouterr().err.startswith("error: --size: expected WIDTHxHEIGHT")


def test_patterns_refuse_a_bad_size_and_write_nothing(capsys, tmp_path):
    out = tmp_path / "pat"
    assert_refused(cli(capsys, "separate", "patterns", "--size", "4x4", "--out", out), "--size",
                   "impossible size")
    assert_refused(cli(capsys, "separate", "patterns", "--square", "6", "--shifts", "4", "--out",
                       out), "--square")  # the library's rule across two options
    assert not out.exists()


# ---------------------------------------------------------------- inspect, bench
def test_inspect_options_are_typed(capsys, captures, tmp_path):
    png = captures / "c0.png"
    assert_refused(cli(capsys, "inspect", png, "--times", "1/30,nan"), "--times")
    assert_refused(cli(capsys, "inspect", png, "--times", "0"), "--times")
    assert_refused(cli(capsys, "inspect", png, "--out", tmp_path / "s.txt"), "--out")
    (tmp_path / "s.json").mkdir()
    assert_refused(cli(capsys, "inspect", png, "--out", tmp_path / "s.json"), "--out", "folder")
    notes = captures / "notes.json"  # a user's file beside the input
    notes.write_text("{}")
    try:
        before = snapshot(captures)
        assert_refused(cli(capsys, "inspect", png, "--out", notes), "--out", "beside this command's inputs")
        assert snapshot(captures) == before
    finally:
        notes.unlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.json"]


def test_bench_repeats_and_stages_are_checked(capsys, tmp_path):
    from lumigraph.bench import build_parser
    from lumigraph.capture.bench import Stage, check_repeats, run_stage

    out = tmp_path / "b"
    assert_refused(cli(capsys, "bench", "io", "--repeats", "0", "--out", out), "--repeats", ">= 3")
    assert_refused(cli(capsys, "bench", "io", "--repeats", "2", "--out", out), "--repeats")
    assert_refused(cli(capsys, "bench", "nosuch", "--out", out), "STAGE", "unknown bench stage")
    assert not out.exists()
    # no stage named: every stage (an empty list is not checked against choices)
    assert build_parser().parse_args(["--out", "x"]).stages == []
    assert build_parser().parse_args(["hdr", "io", "--out", "x"]).stages == ["hdr", "io"]
    with pytest.raises(InputError) as e:
        check_repeats(1)
    assert e.value.where == "repeats"
    empty = Stage("t", (), (), error=lambda a, b: 0.0, error_name="e")
    with pytest.raises(InputError):
        run_stage(empty, repeats=0)
    assert run_stage(empty) == []
