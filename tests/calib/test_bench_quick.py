"""The calib bench runs in quick mode through the command line."""

import json

from conftest import lumigraph


def test_bench_calib_quick(tmp_path):
    r = lumigraph("bench", "calib", "--quick", "--out", tmp_path)
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "report.json").read_text())
    text = json.dumps(rep)
    assert "ours auto" in text and "OpenCV calibrateCamera" in text
    assert (tmp_path / "report.md").exists()
