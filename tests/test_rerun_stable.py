"""Byte-stable reruns: every command of ``lumigraph``, run twice on the same
inputs, writes byte-identical primary artifacts (``tests/cli_catalog.py``
holds one invocation of each; sidecars, which record time and paths, are not
compared, nor the bench's wall-time reports, which the catalog names with
the reason).

Twice in one process, with OpenCV's global generator drawn from in between
(a result must depend on its inputs and options, not on what ran before);
and, for the commands whose results once depended on threads or process
history (calibration, stereo calibration, SfM, flow), twice in two fresh
processes as a user runs them.
"""

from __future__ import annotations

import pytest
from cli_catalog import ENTRIES, command_words, materialise, run_cli, run_cli_process


def _written(m) -> set:
    """Primary files under the output folder (sidecars left out)."""
    out = m.names["out"]
    return {p for p in out.rglob("*") if p.is_file() and not p.name.endswith(".meta.json")}


def _check_run(m, result) -> None:
    rc, _, err = result
    assert rc == 0, f"{' '.join(m.argv)}\n{err}"
    # the catalog lists exactly what the command writes (its users rely on it)
    assert _written(m) == set(m.outputs), sorted(str(p) for p in _written(m) ^ set(m.outputs))


def _assert_identical(first, second) -> None:
    differ = [a.relative_to(first.names["out"]).as_posix()
              for a, b in zip(first.stable_outputs, second.stable_outputs, strict=True)
              if a.read_bytes() != b.read_bytes()]
    assert not differ, f"differ between two runs on the same inputs: {differ}"


def _disturb_process_state() -> None:
    """Use up some of OpenCV's global random stream, as any earlier OpenCV
    call that draws from it would."""
    import cv2
    import numpy as np

    cv2.randu(np.empty((7, 5), np.float32), 0.0, 1.0)


def test_catalog_covers_every_command_and_verb():
    covered = {e.name.split(" (")[0] for e in ENTRIES}
    words = command_words()
    assert words - covered == set(), "commands without a catalog entry"
    assert covered - words == set(), "catalog entries for commands that do not exist"


def test_catalog_entries_are_consistent():
    for e in ENTRIES:
        assert all("{out}" in o for o in e.outputs), e.name
        assert all("{in}" in i for i in e.inputs), e.name
        assert len(set(e.outputs)) == len(e.outputs), e.name
    # exclusions stay the exception: only the bench's timing reports
    assert {e.name for e in ENTRIES if e.unstable} == {"bench"}


@pytest.mark.parametrize("entry", ENTRIES, ids=lambda e: e.name)
def test_rerun_in_one_process_is_byte_identical(entry, tmp_path):
    first = materialise(entry, tmp_path, out=tmp_path / "first")
    _check_run(first, run_cli(first.argv))
    if not first.stable_outputs:  # the bench: written, nothing to compare
        return
    second = materialise(entry, tmp_path, out=tmp_path / "second", prepared=first.names)
    _disturb_process_state()
    _check_run(second, run_cli(second.argv))
    _assert_identical(first, second)


@pytest.mark.parametrize("entry", [e for e in ENTRIES if e.fresh_process], ids=lambda e: e.name)
def test_rerun_in_two_processes_is_byte_identical(entry, tmp_path):
    first = materialise(entry, tmp_path, out=tmp_path / "first")
    second = materialise(entry, tmp_path, out=tmp_path / "second", prepared=first.names)
    _check_run(first, run_cli_process(first.argv))
    _check_run(second, run_cli_process(second.argv))
    _assert_identical(first, second)
