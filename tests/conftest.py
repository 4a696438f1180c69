"""Shared test set-up.

Rendered scenes are cached under .pytest_cache/lumigraph-scenes (shared by the
xdist workers; every cache write is atomic), so each scene renders once per
machine. SHARED points at ../shared (the real data sets).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("LUMIGRAPH_SHARED", ROOT.parent / "shared"))
os.environ.setdefault("LUMIGRAPH_CACHE", str(ROOT / ".pytest_cache" / "lumigraph-cache"))


def need_tool(name: str, package: str) -> str:
    """Path of a system tool; on CI a missing tool fails the test (CI must
    install it), elsewhere it skips with the package to install."""
    path = shutil.which(name)
    if path is None:
        msg = f"{name} not found: install the Debian package {package} (make sysdeps)"
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)
    return path


def need_shared(*parts: str) -> Path:
    p = SHARED.joinpath(*parts)
    if not p.exists():
        msg = f"shared data missing: {p}"
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)
    return p


def lumigraph(*args: str, cwd=None, timeout=600) -> subprocess.CompletedProcess:
    """Run the command line as a user would (a fresh process)."""
    return subprocess.run([sys.executable, "-m", "lumigraph", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=timeout)


def assert_clean_error(proc: subprocess.CompletedProcess, *fragments: str) -> None:
    """Exit 2, exactly one line on stderr starting 'error:', naming what is given."""
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    assert "Traceback" not in proc.stderr


@pytest.fixture
def run_cli():
    return lumigraph


def pytest_collection_modifyitems(config, items):
    """Run the tests marked ``slow`` first. The xdist workers take tests in
    collection order; a minute-long end-to-end test collected last leaves
    the other worker idle for that minute, while short tests at the end
    fill the workers evenly. Stable: the order within each group is kept."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
