"""The README's Python examples run, in order, in a fresh interpreter: the
README cannot drift from the library's API. Its first screen shows the two
set-up commands (DESIGN §6)."""

import re
import subprocess
import sys
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_first_screen_shows_the_two_commands():
    head = "\n".join(README.read_text().splitlines()[:40])
    assert "make demo" in head and "make test" in head


def test_python_examples_run(tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)
    assert len(blocks) >= 6
    code = "\n\n".join(blocks)
    # in a scratch folder: the examples write files, as a user's would
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                       cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
