"""SIGKILL at random points of commands that write several files leaves the
previous complete result set or the new one, never a mix; a rerun completes.

Each command alternates between two option sets (A and B) whose results
differ, so "old" and "new" are told apart by their bytes. A trial starts the
command, kills it with SIGKILL at a random moment of its run (uniform over the
time a complete run takes, start-up included), and reads the output files:
they must equal the old set or the new set byte for byte. A kill after the
commit point leaves a journal instead; the next run into the folder completes
it, so the trial runs the recovery and then demands the new set. A random
kill rarely lands inside the commit itself (microseconds between renames), so
failpoint trials (``LUMIGRAPH_FAILPOINT=commit:N``) also kill before each
rename in turn. After every trial a rerun must complete with no temporary
file left behind.
"""

from __future__ import annotations

import hashlib
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lumigraph.capture.artifact import JOURNAL_PREFIX, _journal_file, recover_commits

ROOT = Path(__file__).resolve().parents[2]
FIX = ROOT / "fixtures"
TRIALS = 20


def _cmd(*args) -> list[str]:
    return [sys.executable, "-m", "lumigraph", *map(str, args), "--quiet"]


def _env(**extra) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    env.update(extra)
    return env


def _snapshot(paths) -> dict:
    out = {}
    for p in paths:
        p = Path(p)
        files = sorted(f for f in p.rglob("*") if f.is_file()) if p.is_dir() else [p]
        for f in files:  # temporaries (hidden, never a result) are not part of the set
            if f.exists() and not f.name.startswith("."):
                out[str(f)] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


def _strays(folder: Path) -> list[str]:
    return [f.name for f in folder.rglob(".*") if f.is_file()]


def _set_of(snapshot: dict) -> dict:
    # sidecars record the time and command line: they differ on every run
    return {k: v for k, v in snapshot.items() if not k.endswith(".meta.json")}


def _case_merge(tmp: Path):
    b = tmp / "bracket"
    shutil.copytree(FIX / "bracket-8bit", b)
    subprocess.run(_cmd("hdr", "response", b, "--out", tmp / "r.json"), check=True, env=_env())
    out = tmp / "out"
    return ([_cmd("hdr", "merge", b, "--response", tmp / "r.json", "--out", out / "radiance.exr",
                  "--weights", w) for w in ("hat", "variance")], [out])


def _case_lightfield_depth(tmp: Path):
    lf = tmp / "lf"
    shutil.copytree(FIX / "lightfield", lf)
    out = tmp / "out"
    return ([_cmd("lightfield", "depth", lf, "--method", "variance", "--window", str(w),
                  "--all-in-focus", out / "all-in-focus.exr", "--out", out / "disparity.pfm") for w in (5, 9)], [out])


def _case_refocus_sweep(tmp: Path):
    lf = tmp / "lf"
    shutil.copytree(FIX / "lightfield", lf)
    out = tmp / "sweep"
    return ([_cmd("lightfield", "refocus", lf, f"--slope={s}", "--method", "shift-add", "--out", out)
             for s in ("0,0.5,1", "-1,0.25,0.75")], [out])


def _case_calibrate(tmp: Path):
    boards = tmp / "boards"
    subprocess.run(_cmd("render", "boards", "--out", boards, "--size", "320x240", "--views", "6",
                        "--seed", "2"), check=True, env=_env())
    out = tmp / "cal"
    return ([_cmd("calib", "calibrate", boards, "--model", m, "--out", out / "camera.json",
                  "--yaml", out / "camera.yml", "--colmap", out / "cameras.txt")
             for m in ("k1", "k1k2")], [out])


CASES = {"hdr-merge": _case_merge, "lightfield-depth-all-in-focus": _case_lightfield_depth,
         "refocus-sweep": _case_refocus_sweep, "calib-calibrate-yaml-colmap": _case_calibrate}


def _complete(cmd, env=None) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env or _env())
    assert r.returncode == 0, r.stderr
    return time.perf_counter() - t0


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_sigkill_leaves_old_or_new_set(case, tmp_path):
    cmds, outs = CASES[case](tmp_path)
    folder = outs[0]
    # the two complete sets, made once in full
    sets, took = [], []
    for c in cmds:
        took.append(_complete(c))
        sets.append(_set_of(_snapshot(outs)))
    assert sets[0] != sets[1], "the two option sets must give different results"
    assert set(sets[0]) == set(sets[1]), "both runs write the same file names"
    n_files = len(_snapshot(outs))  # every file the commit renames, sidecars included
    rng = random.Random(f"kill-{case}")
    # random moments, then one failpoint trial before each rename of the commit
    # and one just after the journal's file is opened, before it is locked (a
    # window of microseconds that a random kill once hit in CI)
    trials = ([("random", None)] * TRIALS + [("commit", k) for k in range(n_files + 1)]
              + [("journal", 0)])
    current = 1  # the last complete run was cmds[1]
    kinds = {"old": 0, "new": 0, "recovered": 0}
    fd, jtmp = _journal_file(folder)  # whether this file system gives unnamed journals
    os.close(fd)
    unnamed_journal = jtmp is None
    if jtmp is not None:
        os.unlink(jtmp)
    for kind, k in trials:
        new = 1 - current
        env = _env() if kind == "random" else _env(LUMIGRAPH_FAILPOINT=f"{kind}:{k}")
        proc = subprocess.Popen(cmds[new], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                env=env)
        if kind == "random":
            time.sleep(rng.uniform(0.0, max(took)))
            proc.send_signal(signal.SIGKILL)
        proc.wait()
        after = _set_of(_snapshot(outs))
        journals = [f for f in folder.rglob(JOURNAL_PREFIX + "*.json")]  # past the commit point
        if journals:
            assert recover_commits(folder) >= 1
            after = _set_of(_snapshot(outs))
            assert after == sets[new], f"{kind} {k}: a recovered commit must be the new set"
            kinds["recovered"] += 1
        elif kind == "journal":
            assert after == sets[current], "a kill before the commit point must leave the old set"
            kinds["old"] += 1
            if unnamed_journal:  # no journal file is visible, before any rerun
                left = [f.name for f in folder.rglob(JOURNAL_PREFIX + "*")]
                assert not left, left
        elif after == sets[new]:
            kinds["new"] += 1
        else:
            assert after == sets[current], f"{kind} {k}: a mixed or partial set after SIGKILL"
            kinds["old"] += 1
        # the rerun completes and cleans what the kill left
        _complete(cmds[new])
        assert _set_of(_snapshot(outs)) == sets[new]
        assert not _strays(folder), _strays(folder)
        current = new
    # every failpoint landed inside a commit, and each was completed
    assert kinds["recovered"] >= n_files + 1, kinds
