"""``lumigraph bench gpu``'s gatherer: device selection, the rows' shape in
the report and the speed checks (on made-up rows: the real ones take minutes)."""

from __future__ import annotations

import math

import pytest

from lumigraph.bench_gpu import _to_row, checks_for, devices_for
from lumigraph.capture.bench_device import DeviceRow, measure, skipped


def test_cpu_device_runs_ours_and_the_peers_only():
    devices, note = devices_for("cpu")
    assert devices == ("cpu",) and "not run" in note


def test_auto_says_when_the_cuda_rows_are_not_run():
    torch = pytest.importorskip("torch")
    devices, note = devices_for("auto")
    if torch.cuda.is_available():
        assert devices[-1] == "cuda"
    else:
        assert devices == ("cpu", "torch-cpu") and "cuda rows not run" in note


def test_checks_compare_cuda_with_our_cpu_row_of_the_same_case():
    rows = [DeviceRow("hdr merge", "9 x 12 MP", "cpu", 2.0, 0.0),
            DeviceRow("hdr merge", "9 x 12 MP", "cuda", 0.1, 1e-7, target=0.1),
            DeviceRow("hdr tonemap local", "12 MP", "cpu", 1.0, 0.0),
            DeviceRow("hdr tonemap local", "12 MP", "cuda", 0.5, 0.0, target=0.1),
            skipped("lightfield refocus", "9x9", "cuda", "torch sees no CUDA GPU", target=0.05)]
    checks = checks_for(rows)
    assert [c.passed for c in checks] == [True, False]        # the skipped row has no check
    assert checks[0].measured == pytest.approx(0.05) and checks[0].reference == 0.1


def test_rows_carry_input_truth_and_status_into_the_report():
    row, out = measure("toy", "3 values", "cpu", lambda: [1.0, 2.0, 3.0], repeats=3,
                       truth=lambda a: abs(a.sum() - 6.0))
    r = _to_row("toy", row)
    assert r.stage == "gpu" and r.method == "toy: cpu" and r.status == "ok"
    assert r.extra["input"] == "3 values" and r.extra["vs_truth"] == 0.0
    assert len(r.times_s) == 3 and r.time_s == min(r.times_s)
    bad, _ = measure("toy", "3 values", "cuda", lambda: 1 / 0, repeats=3)
    assert bad.status.startswith("failed: ZeroDivisionError") and math.isnan(bad.time_s)
