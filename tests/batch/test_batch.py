"""The batch layer in this process (no cluster): items, failures, exit
status, resume. The real engine is tests/batch/test_distributed.py."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from cli_catalog import run_cli  # noqa: E402

SIZE = (48, 36)


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    from lumigraph.capture.render import render

    d = tmp_path_factory.mktemp("shots")
    for seed in range(3):
        render("bracket", size=SIZE, seed=seed).save(d / "shots" / f"b{seed}")
    rc, _, err = run_cli(["hdr", "response", d / "shots" / "b0", "--out", d / "response.json", "-q"])
    assert rc == 0, err
    return d


def _copy(shots: Path, tmp_path: Path) -> Path:
    shutil.copytree(shots / "shots", tmp_path / "shots")
    return tmp_path / "shots"


def _merge(shots: Path, folder: Path, out: Path, *extra) -> tuple[int, str]:
    rc, _, err = run_cli(["hdr", "merge", folder, "--response", shots / "response.json",
                          "--out", out, "-q", *extra])
    return rc, err


def _status(out: Path) -> dict[str, str]:
    return {i["name"]: i["status"] for i in json.loads((out / "index.json").read_text())["items"]}


def test_a_failed_item_is_named_and_the_others_are_written(shots, tmp_path):
    folder = _copy(shots, tmp_path)
    bad = folder / "b1" / "exposure_03.png"
    bad.write_bytes(bad.read_bytes()[:100])  # truncated
    rc, err = _merge(shots, folder, tmp_path / "out")
    assert rc == 4, err
    errors = [ln for ln in err.splitlines() if ln.startswith("error: ")]
    assert len(errors) == 1 and errors[0].startswith("error: b1: ") and "exposure_03.png" in errors[0]
    assert _status(tmp_path / "out") == {"b0": "done", "b1": "failed", "b2": "done"}
    assert sorted(p.name for p in (tmp_path / "out").glob("*.exr")) == ["b0.exr", "b2.exr"]
    # the input repaired, a rerun does the failed item only
    shutil.copy(shots / "shots" / "b1" / "exposure_03.png", bad)
    rc, err = _merge(shots, folder, tmp_path / "out")
    assert rc == 0, err
    assert _status(tmp_path / "out") == {"b0": "skipped", "b1": "done", "b2": "skipped"}


def test_a_rerun_redoes_what_changed(shots, tmp_path):
    folder = _copy(shots, tmp_path)
    out = tmp_path / "out"
    assert _merge(shots, folder, out)[0] == 0
    first = {p.name: p.read_bytes() for p in out.glob("*.exr")}
    assert _merge(shots, folder, out)[0] == 0
    assert set(_status(out).values()) == {"skipped"}
    # an input's bytes: that item only
    (folder / "b2" / "stack.json").write_text((folder / "b2" / "stack.json").read_text() + "\n")
    assert _merge(shots, folder, out)[0] == 0
    assert _status(out) == {"b0": "skipped", "b1": "skipped", "b2": "done"}
    # an option: every item
    assert _merge(shots, folder, out, "--weights", "hat")[0] == 0
    assert set(_status(out).values()) == {"done"}
    assert {p.name: p.read_bytes() for p in out.glob("*.exr")} != first
    # a half-written item (its primary gone): done again
    (out / "b0.exr").unlink()
    assert _merge(shots, folder, out, "--weights", "hat")[0] == 0
    assert _status(out)["b0"] == "done"


def test_the_batch_is_the_single_command_item_by_item(shots, tmp_path):
    out = tmp_path / "out"
    rc, _, err = run_cli(["hdr", "merge", shots / "shots" / "b0", shots / "shots" / "b1",
                          "--response", shots / "response.json", "--out", out, "-q"])
    assert rc == 0, err
    for b in ("b0", "b1"):
        rc, _, err = run_cli(["hdr", "merge", shots / "shots" / b, "--response",
                              shots / "response.json", "--out", tmp_path / f"{b}.exr", "-q"])
        assert rc == 0, err
        assert (tmp_path / f"{b}.exr").read_bytes() == (out / f"{b}.exr").read_bytes()
        assert (tmp_path / f"{b}.mask.png").read_bytes() == (out / f"{b}.mask.png").read_bytes()
    meta = json.loads((out / "b0.exr.meta.json").read_text())
    assert meta["batch"]["item"] == "b0" and meta["command"][:3] == ["lumigraph", "hdr", "merge"]


@pytest.mark.parametrize("extra,fragment", [
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "not both"),
    (["--scheduler", "nonsense"], "scheduler address"),
])
def test_bad_batch_options_are_refused_before_any_work(shots, tmp_path, extra, fragment):
    rc, err = _merge(shots, shots / "shots", tmp_path / "out", *extra)
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --") and fragment in lines[0], lines
    assert not (tmp_path / "out" / "b0.exr").exists()


@pytest.mark.parametrize("answer", [None, b"HTTP/1.1 400 Bad Request\r\n\r\n" * 4])
def test_an_unreachable_scheduler_is_refused_within_the_connect_timeout(shots, tmp_path,
                                                                         monkeypatch, answer):
    """A port that accepts and stays silent, or answers bytes that are not
    Dask's: exit 2, one line naming the address, nothing written, after the
    connect timeout (not Dask's default 30 s)."""
    import contextlib
    import socket
    import threading
    import time

    from lumigraph.capture import batch

    monkeypatch.setattr(batch, "CONNECT_TIMEOUT", "1s")
    server = socket.create_server(("127.0.0.1", 0))
    address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
    held = []

    def serve():
        with contextlib.suppress(OSError):
            while True:
                conn, _ = server.accept()
                held.append(conn)
                if answer:
                    conn.sendall(answer)

    threading.Thread(target=serve, daemon=True).start()
    try:
        t0 = time.monotonic()
        rc, err = _merge(shots, shots / "shots", tmp_path / "out", "--scheduler", address)
        took = time.monotonic() - t0
    finally:
        server.close()
        for c in held:
            c.close()
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and address in lines[0], err
    assert lines[0].startswith("error: --scheduler: "), lines
    # the 1 s timeout plus the batch's own set-up; Dask's default would be 30 s
    assert took < 10, took
    assert not (tmp_path / "out").exists()


def test_many_brackets_need_an_output_folder(shots, tmp_path):
    rc, err = _merge(shots, shots / "shots", tmp_path / "one.exr")
    assert rc == 2 and "name a folder" in err, err


def test_a_journal_being_created_is_not_taken_for_a_dead_one(tmp_path):
    """Workers commit into one folder at once: a journal temporary that another
    writer has just created, not yet locked (empty), is left alone; an old
    empty one is a writer's killed in that window, removed."""
    import os
    import time

    from lumigraph.capture.artifact import JOURNAL_PREFIX, STALE_EMPTY_JOURNAL_S, recover_commits

    fresh = tmp_path / f"{JOURNAL_PREFIX}fresh123.json.tmp"
    old = tmp_path / f"{JOURNAL_PREFIX}old12345.json.tmp"
    fresh.touch()
    old.touch()
    t = time.time() - 2 * STALE_EMPTY_JOURNAL_S
    os.utime(old, (t, t))
    recover_commits(tmp_path)
    assert fresh.exists() and not old.exists()


def test_separate_over_many_stacks_is_the_single_command_per_stack(tmp_path):
    """(Not in the catalog: its inputs are a folder of stacks, whose damage
    is one item's failure, exit 4, not the corpus's exit 2.)"""
    root = Path(__file__).resolve().parents[2]
    for p in ("p0", "p1"):
        shutil.copytree(root / "fixtures" / "projector", tmp_path / "stacks" / p)
    rc, _, err = run_cli(["separate", tmp_path / "stacks", "--out", tmp_path / "sep", "-q"])
    assert rc == 0, err
    rc, _, err = run_cli(["separate", tmp_path / "stacks" / "p1", "--out", tmp_path / "one", "-q"])
    assert rc == 0, err
    for f in ("direct.exr", "global.exr", "mask.png"):
        assert (tmp_path / "sep" / "p1" / f).read_bytes() == (tmp_path / "one" / f).read_bytes()
    assert _status(tmp_path / "sep") == {"p0": "done", "p1": "done"}


def test_refocus_over_several_light_fields_is_the_single_command_per_light_field(tmp_path):
    """Each light field one item (one value: NAME.exr; several: the folder
    NAME/ with its index.json), the same bytes as the one-light-field command;
    a rerun does nothing."""
    from lumigraph.capture.render import render

    for k in range(2):
        render("lightfield-array", size=(24, 20), grid="3x3", thin_lens=False,
               seed=k).save(tmp_path / "scenes" / f"s{k}")
        rc, _, err = run_cli(["lightfield", "import", tmp_path / "scenes" / f"s{k}", "--out",
                              tmp_path / "fields" / f"lf{k}", "-q"])
        assert rc == 0, err
    fields = tmp_path / "fields"
    rc, _, err = run_cli(["lightfield", "refocus", fields, "--slope", "0.5", "--out",
                          tmp_path / "one", "-q"])
    assert rc == 0, err
    rc, _, err = run_cli(["lightfield", "refocus", fields / "lf0", fields / "lf1", "--slope", "0",
                          "0.5", "--out", tmp_path / "many", "-q"])
    assert rc == 0, err
    assert _status(tmp_path / "one") == _status(tmp_path / "many") == {"lf0": "done", "lf1": "done"}
    for k in range(2):
        rc, _, err = run_cli(["lightfield", "refocus", fields / f"lf{k}", "--slope", "0.5", "--out",
                              tmp_path / f"single{k}.exr", "-q"])
        assert rc == 0, err
        assert (tmp_path / "one" / f"lf{k}.exr").read_bytes() == \
            (tmp_path / f"single{k}.exr").read_bytes()
        rc, _, err = run_cli(["lightfield", "refocus", fields / f"lf{k}", "--slope", "0", "0.5",
                              "--out", tmp_path / f"stack{k}", "-q"])
        assert rc == 0, err
        for name in ("refocus-000.exr", "refocus-001.exr"):
            assert (tmp_path / "many" / f"lf{k}" / name).read_bytes() == \
                (tmp_path / f"stack{k}" / name).read_bytes()
    rc, _, err = run_cli(["lightfield", "refocus", fields, "--slope", "0.5", "--out",
                          tmp_path / "one", "-q"])
    assert rc == 0 and _status(tmp_path / "one") == {"lf0": "skipped", "lf1": "skipped"}, err
