"""Artifacts get the mode the umask gives (0o666 & ~umask), not mkstemp's 0600.

Each case runs in a fresh interpreter: setting the umask here would leak into
every other test of this process (and the umask is process-wide, not per thread).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

WRITE_ALL = r"""
import json, os, stat, sys
from pathlib import Path
import numpy as np

os.umask(int(sys.argv[2], 8))
from lumigraph.capture import io
from lumigraph.capture.artifact import make_meta, meta_path, save_json_artifact, write_artifact
from lumigraph.capture.render import render

d = Path(sys.argv[1])
a = write_artifact(d / "a.txt", lambda p: p.write_text("x"), meta=make_meta("test.umask"))
io.write_image(d / "img.png", np.zeros((3, 4), np.uint8))
io.write_exr(d / "img.exr", np.zeros((3, 4), np.float32))
save_json_artifact(d / "camera.json", {"k": 1}, meta=make_meta("test.umask"))
render("sample", size=(16, 16), cache=False).save(d / "scene")
files = [a, meta_path(a), d / "img.png", d / "img.exr", d / "camera.json",
         meta_path(d / "camera.json"), d / "scene" / "ramp.png", d / "scene" / "stack.json",
         d / "scene" / "gt.json", d / "scene" / "gt" / "radiance.npy"]
print(json.dumps({str(p.relative_to(d)): stat.S_IMODE(p.stat().st_mode) for p in files}))
"""


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_artifacts_get_the_mode_the_umask_gives(tmp_path, umask, mode):
    r = subprocess.run([sys.executable, "-c", WRITE_ALL, str(tmp_path), f"{umask:o}"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    modes = json.loads(r.stdout)
    assert len(modes) == 10
    wrong = {name: oct(m) for name, m in modes.items() if m != mode}
    assert not wrong, f"expected {oct(mode)} under umask {umask:03o}: {wrong}"


@pytest.mark.parametrize("proc", [True, False], ids=["proc-status", "umask-swap"])
def test_reading_the_umask_does_not_change_it(proc):
    # without /proc (macOS, BSD) the fallback swaps the umask under a lock and restores it
    hide = "" if proc else "a.open = lambda *args, **kw: (_ for _ in ()).throw(OSError())\n"
    code = ("import os; os.umask(0o027)\n"
            "import lumigraph.capture.artifact as a\n" + hide +
            "print(oct(a.current_umask()), oct(a.file_mode()), oct(os.umask(0)))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["0o27", "0o640", "0o27"]
