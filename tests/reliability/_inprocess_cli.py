"""In-process command runs for the bad-input tests: the same ``main`` the
``lumigraph`` script calls, without a fresh interpreter per case (so a
parametrised list of bad values stays cheap)."""

from __future__ import annotations

import os
from pathlib import Path
from types import SimpleNamespace


def cli(capsys, *args) -> SimpleNamespace:
    """Run ``lumigraph ARGS`` in this process; its exit status and output."""
    from lumigraph.command import main

    capsys.readouterr()
    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    return SimpleNamespace(returncode=rc, stdout=out.out, stderr=out.err)


def snapshot(*roots) -> dict[str, bytes]:
    """Every file under ``roots`` (a file or a folder) with its bytes."""
    files = {}
    for root in map(Path, roots):
        if root.is_file():
            files[str(root)] = root.read_bytes()
        elif root.is_dir():
            for dirpath, _, names in os.walk(root):
                for n in names:
                    p = Path(dirpath) / n
                    files[str(p)] = p.read_bytes()
    return files


def assert_refused(proc, where: str, *fragments: str) -> None:
    """Exit 2 and exactly one stderr line, ``error: WHERE: ...``."""
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"error: {where}:"), (where, lines[0])
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    assert "Traceback" not in proc.stderr
