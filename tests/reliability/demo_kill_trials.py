"""SIGKILL ``make demo`` at random moments; every result set must stay whole.

    python tests/reliability/demo_kill_trials.py [--trials 20] [--out DIR] [--seed 0]

Not part of ``make test`` (each trial rebuilds part of the demo: minutes); the
figures go into the closing note of the reliability issue. A trial removes
the outputs of 1-3 random demo stages, starts ``make demo OUT=DIR``, kills its
whole process group with SIGKILL at a random moment of the rebuild, and then
checks every artifact under DIR:

* a primary file and its ``.meta.json`` agree (the sidecar records the
  primary's SHA-256): an old primary beside a new sidecar, or the reverse, is
  a mixed set;
* (only trials whose kill landed while make was running count towards
  ``--trials``)
* the files of each grouped Makefile step (``a b &: ...``) are all present or
  all absent, unless a commit journal in their folder says a commit was cut
  short, which the next run completes.

Then ``make demo`` runs again and must finish (exit 0) with every artifact
consistent and no temporary file left. Exit status 1 if any trial failed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
STAGES = ["calib", "hdr", "flow", "stereo", "lightfield", "separation", "sample"]
GROUPS = [("calib/camera.json", "calib/camera.yml", "calib/cameras.txt"),
          ("calib/rig.json", "calib/rig.yml"),
          ("hdr/response.json", "hdr/curve.png"),
          ("hdr/radiance.exr", "hdr/radiance.mask.png"),
          ("lightfield/disparity.pfm", "lightfield/all-in-focus.exr"),
          ("stereo/facade_depth.pfm", "stereo/facade_warped.png"),
          ("flow/flow.flo", "flow/flow.png"),
          ("flow/video-match.flo", "flow/video-match.png")]


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def check(out: Path) -> list[str]:
    """Problems with the artifacts under ``out`` (empty: every set whole)."""
    problems = []
    journals = {p.parent for p in out.rglob(".lumigraph-commit.*.json")}
    for side in out.rglob("*.meta.json"):
        primary = side.with_name(side.name[: -len(".meta.json")])
        if primary.parent in journals:
            continue
        try:
            meta = json.loads(side.read_text())
        except ValueError:
            problems.append(f"{side}: not JSON")
            continue
        want = (meta.get("output") or {}).get("sha256")
        if want is None or primary.name.endswith(".json") and "output" not in meta:
            continue
        if not primary.exists():
            problems.append(f"{primary}: sidecar without its file")
        elif _sha(primary) != want:
            problems.append(f"{primary}: does not match its sidecar (a mixed set)")
    for group in GROUPS:
        have = [(out / g).exists() for g in group]
        if any(have) and not all(have) and (out / group[0]).parent not in journals:
            problems.append(f"group {group}: only {sum(have)} of {len(group)} present")
    return problems


def strays(out: Path) -> list[Path]:
    return [p for p in out.rglob(".*") if p.is_file() and ".tmp" in p.name
            or p.name.startswith(".lumigraph-commit.")]


def make_demo(out: Path, **kw) -> subprocess.Popen:
    return subprocess.Popen(["make", "demo", f"OUT={out}"], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True, **kw)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--out", default="/tmp/lumigraph-demo-kill")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    out = Path(a.out)
    rng = random.Random(a.seed)
    p = make_demo(out)
    _, err = p.communicate()
    if p.returncode != 0:
        sys.stderr.write(err.decode())
        return 1
    failed = trial = kills = 0
    while kills < a.trials and trial < 3 * a.trials:
        trial += 1
        for stage in rng.sample(STAGES, rng.randint(1, 3)):
            shutil.rmtree(out / stage, ignore_errors=True)
        t0 = time.perf_counter()
        p = make_demo(out)
        time.sleep(rng.uniform(0.2, 12.0))
        still = p.poll() is None
        kills += still  # a trial whose make had already finished killed nothing
        if still:
            os.killpg(p.pid, signal.SIGKILL)
        p.wait()
        killed_after = time.perf_counter() - t0
        during = check(out)
        p = make_demo(out)
        _, err = p.communicate()
        after = check(out) + [f"left behind: {s}" for s in strays(out)]
        ok = p.returncode == 0 and not during and not after
        failed += not ok
        print(f"trial {trial:2d}: killed at {killed_after:5.1f} s"
              f"{'' if still else ' (make had finished)'}: "
              f"{'ok' if ok else 'FAILED'}; rerun exit {p.returncode}", flush=True)
        for line in during + after:
            print("   ", line)
        if p.returncode != 0:
            print("   ", err.decode().strip().splitlines()[-3:])
    print(f"{kills} kills during make demo in {trial} trials; {trial - failed} of {trial} trials "
          "kept every set whole and the rerun completed")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
