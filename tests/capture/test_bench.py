"""The bench harness: timing, errors, peers, checks and the report files."""

import json
import math

import numpy as np
from conftest import lumigraph

from lumigraph.capture.bench import Case, Method, Results, Stage, run_stage


def test_failures_and_unavailable_peers_are_rows_not_crashes():
    st = Stage("toy", (Case("c", lambda: np.arange(4.0)),),
               (Method("ok", lambda d, k: d.sum() * k, "k", (1.0, 2.0)),
                Method("boom", lambda d, k: 1 / 0),
                Method("missing", lambda d, k: 0, peer="nowhere", unavailable=lambda: "no tool")),
               error=lambda d, out: abs(out - 6.0), error_name="abs")
    rows = run_stage(st, repeats=3)
    res = Results(rows)
    assert res.get("c", "ok", 1.0).error == 0.0 and res.get("c", "ok", 2.0).error == 6.0
    assert len(res.get("c", "ok", 1.0).times_s) == 3
    assert res.get("c", "boom").status.startswith("failed: ZeroDivisionError")
    assert res.get("c", "missing").status == "unavailable: no tool"
    assert math.isnan(res.get("c", "missing").error)


def test_bench_io_writes_report_and_plot(tmp_path):
    r = lumigraph("bench", "io", "--out", tmp_path, "--quick", "-q")
    assert r.returncode == 0, r.stderr
    md = (tmp_path / "report.md").read_text()
    assert "exr float32 (ours)" in md and "float TIFF (OpenCV)" in md
    png = (tmp_path / "io.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 5000
    js = json.loads((tmp_path / "report.json").read_text())
    rows = js["stages"]["io"]["rows"]
    exr = [r for r in rows if r["method"] == "exr float32 (ours)"]
    half = [r for r in rows if r["method"] == "exr half (ours)"]
    rgbe = [r for r in rows if r["method"] == "RGBE .hdr (OpenCV)"]
    assert all(r["error"] == 0.0 for r in exr)
    assert all(0 < r["error"] <= 2.0 ** -11 for r in half)      # half: 11-bit mantissa
    assert all(2.0 ** -11 < r["error"] <= 2.0 ** -7 for r in rgbe)  # RGBE: 8-bit mantissa
    assert all(r["time_s"] > 0 for r in rows)


def test_unknown_bench_stage():
    r = lumigraph("bench", "nosuch", "--out", "/tmp/never-written")
    assert r.returncode == 2 and "unknown bench stage" in r.stderr


def test_bench_render_times_every_scene_cold(tmp_path):
    r = lumigraph("bench", "render", "--out", tmp_path, "--quick", "-q")
    assert r.returncode == 0, r.stderr
    js = json.loads((tmp_path / "report.json").read_text())["stages"]["render"]
    assert {row["method"] for row in js["rows"]} == {"sample", "bracket", "stereo-pair", "flow"}
    assert all(row["status"] == "ok" and row["time_s"] > 0 for row in js["rows"])
    assert len(js["checks"]) == 4 and all("<= 5 s" in c["target"] for c in js["checks"])
