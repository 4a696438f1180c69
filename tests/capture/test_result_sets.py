"""The write plumbing every command shares: result sets, the output guard,
output locks, writability before work, and foreign messages kept back."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from lumigraph.capture import artifact
from lumigraph.capture.artifact import (
    JOURNAL_PREFIX,
    guard,
    make_meta,
    recover_commits,
    result_set,
    write_artifact,
    write_json,
)
from lumigraph.capture.commandline import (
    _Lock,
    check_writable,
    make_parser,
    output_dir,
    output_file,
    run,
)
from lumigraph.capture.errors import InputError


def _files(d: Path) -> list[str]:
    return sorted(f.name for f in d.iterdir())


def test_a_set_is_invisible_until_it_commits(tmp_path):
    with result_set([(tmp_path, "dir")]):
        write_json(tmp_path / "a.json", {"a": 1})
        write_artifact(tmp_path / "b.txt", lambda p: p.write_text("b"), meta=make_meta("t"))
        assert not (tmp_path / "a.json").exists() and not (tmp_path / "b.txt").exists()
    assert _files(tmp_path) == ["a.json", "b.txt", "b.txt.meta.json"]


def test_a_failed_set_leaves_nothing(tmp_path):
    (tmp_path / "a.json").write_text("old")
    with pytest.raises(RuntimeError), result_set([(tmp_path, "dir")]):
        write_json(tmp_path / "a.json", {"a": 1})
        write_json(tmp_path / "c.json", {"c": 1})
        raise RuntimeError("the command failed")
    assert _files(tmp_path) == ["a.json"] and (tmp_path / "a.json").read_text() == "old"


def test_writes_outside_the_declared_outputs_are_immediate(tmp_path):
    scratch = tmp_path / "scratch.json"
    with result_set([(tmp_path / "out", "dir")]):
        write_json(scratch, {"x": 1})
        assert scratch.exists()  # read back within the command (a bench's round trip)


def test_the_primary_goes_into_place_last(tmp_path, monkeypatch):
    order = []
    real = os.replace
    monkeypatch.setattr(artifact.os, "replace", lambda a, b: (order.append(Path(b).name),
                                                                 real(a, b)))
    with result_set([(tmp_path / "r.exr", "file"), (tmp_path / "r.mask.png", "file")]):
        write_artifact(tmp_path / "r.exr", lambda p: p.write_text("r"), meta=make_meta("t"))
        write_artifact(tmp_path / "r.mask.png", lambda p: p.write_text("m"), meta=make_meta("t"))
    finals = [n for n in order if not n.startswith(".")]
    assert finals == ["r.mask.png.meta.json", "r.mask.png", "r.exr.meta.json", "r.exr"]


def test_an_interrupted_commit_is_completed_from_anywhere(tmp_path):
    """A run killed after its commit point (failpoint) leaves a journal with
    absolute paths: recovery works from any working directory."""
    script = textwrap.dedent("""
        import os
        from lumigraph.capture.artifact import result_set, write_json
        with result_set([("out", "dir")]):
            write_json("out/a.json", {"a": 1})
            write_json("out/b.json", {"b": 2})
    """)
    env = dict(os.environ, LUMIGRAPH_FAILPOINT="commit:1")
    r = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env)
    assert r.returncode == -9
    out = tmp_path / "out"
    assert [n for n in _files(out) if n.startswith(JOURNAL_PREFIX)]
    assert recover_commits(out) == 1
    assert [n for n in _files(out) if not n.startswith(".")] == ["a.json", "b.json"]
    assert not [n for n in _files(out) if n.startswith(".")]


def test_the_guard_protects_inputs_and_what_lies_beside_them(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    (src / "photo.png").write_bytes(b"photo")
    (src / "notes.txt").write_text("user's")
    with guard([src / "photo.png"], producer="lumigraph t"):
        with pytest.raises(InputError, match="one of this command's inputs"):
            write_json(src / "photo.png", {})
        with pytest.raises(InputError, match="not written by this command"):
            write_json(src / "notes.txt", {})
        write_artifact(src / "mine.json", lambda p: p.write_text("1"), meta=make_meta("t"))
    assert (src / "photo.png").read_bytes() == b"photo" and (src / "notes.txt").read_text() == "user's"
    with guard([src / "photo.png"], producer="lumigraph t"):  # our own earlier output: replaced
        write_artifact(src / "mine.json", lambda p: p.write_text("2"), meta=make_meta("t"))
    with guard([src / "photo.png"], producer="lumigraph other"):  # another command's: --force
        with pytest.raises(InputError, match="--force"):
            write_json(src / "mine.json", {})
    with guard([src / "photo.png"], producer="lumigraph other", force=True):
        write_artifact(src / "notes.txt", lambda p: p.write_text("forced"), meta=make_meta("t"))
        with pytest.raises(InputError, match="inputs"):
            write_json(src / "photo.png", {})  # --force never replaces an input
    assert (src / "mine.json").read_text() == "2" and (src / "notes.txt").read_text() == "forced"
    assert (src / "photo.png").read_bytes() == b"photo"


def test_unwritable_outputs_are_refused_before_work(tmp_path):
    a_file = tmp_path / "f"
    a_file.write_text("x")
    with pytest.raises(InputError, match="is a file, not a folder"):
        check_writable(a_file / "out.exr", where="--out")
    with pytest.raises(InputError, match="is a folder"):
        check_writable(tmp_path, where="--out")
    with pytest.raises(InputError, match="not a folder"):
        check_writable(a_file, where="--out", kind="dir")
    if os.getuid() != 0:  # root writes anywhere; the probe is a real write
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o555)
        with pytest.raises(InputError, match="cannot write"):
            check_writable(ro / "x.exr", where="--out")


def _toy_parser(tmp_path, work):
    p = make_parser("toy", "a toy command")
    p.add_argument("src")
    p.add_argument("--out", type=output_file(".json"), required=True)
    p.add_argument("--dir", type=output_dir)
    p.set_defaults(func=work)
    return p


def test_run_refuses_an_output_that_is_an_input(tmp_path, capsys):
    src = tmp_path / "in.json"
    src.write_text("{}")
    called = []
    rc = run(_toy_parser(tmp_path, lambda a: called.append(1)), [str(src), "--out", str(src)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and not called and src.read_text() == "{}"
    assert len(err) == 1 and err[0].startswith("error: --out:") and "inputs" in err[0]


def test_a_second_writer_of_the_same_output_is_refused(tmp_path, capsys):
    out = tmp_path / "o.json"
    held = _Lock(out, "--out")  # another run holds it
    try:
        rc = run(_toy_parser(tmp_path, lambda a: write_json(a.out, {})),
                 [str(tmp_path), "--out", str(out)])
    finally:
        held.release()
    err = capsys.readouterr().err
    assert rc == 2 and "another lumigraph run" in err and f"pid {os.getpid()}" in err
    assert not out.exists()
    assert run(_toy_parser(tmp_path, lambda a: write_json(a.out, {})),
               [str(tmp_path), "--out", str(out)]) == 0 and out.exists()


def test_foreign_messages_are_kept_back(tmp_path):
    """What a C library prints on descriptor 2 is not shown (only with --debug)."""
    script = textwrap.dedent("""
        import os, sys
        from lumigraph.capture.commandline import make_parser, run
        from lumigraph.capture.errors import InputError
        def work(args):
            os.write(2, b"libpng warning: iCCP: known incorrect sRGB profile\\n")
            raise InputError("a.png", "not an image")
        p = make_parser("toy", "t")
        p.set_defaults(func=work)
        sys.exit(run(p, sys.argv[1:]))
    """)
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr == "error: a.png: not an image\n"
    r = subprocess.run([sys.executable, "-c", script, "--debug"], capture_output=True, text=True)
    assert "libpng warning" in r.stderr


def test_an_unusable_result_is_exit_3_one_line_and_held_warnings_dropped(tmp_path, capsys):
    """Exit 3 (DESIGN §5): the work ran, its result is not usable; the one line
    is the last word, warnings held during the run are not shown."""
    from lumigraph.capture.commandline import warn
    from lumigraph.capture.errors import UnusableResult

    def work(args):
        warn("only 1 of 4 views matched")
        raise UnusableResult(tmp_path, "registered 1 of 4 views; nothing written")

    rc = run(_toy_parser(tmp_path, work), [str(tmp_path), "--out", str(tmp_path / "o.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 3 and err == [f"error: {tmp_path}: registered 1 of 4 views; nothing written"]
