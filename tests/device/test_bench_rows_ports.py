"""The device bench rows of separation, calib and stereo on the CPU only
(quick inputs): every case has our cpu row, the torch rows say they were not
run, and the peers ran on the same inputs with the same error figure."""

from __future__ import annotations

import importlib
import math

import pytest


@pytest.mark.parametrize("module", ["lumigraph.separation.bench_device",
                                    "lumigraph.calib.bench_device",
                                    "lumigraph.stereo.bench_device"])
def test_rows_on_cpu(module):
    rows = importlib.import_module(module).rows(devices=("cpu",), quick=True)
    cases = {(r.stage, r.case) for r in rows}
    assert cases
    for stage, case in cases:
        mine = [r for r in rows if (r.stage, r.case) == (stage, case)]
        cpu = [r for r in mine if r.device == "cpu"]
        assert len(cpu) == 1 and cpu[0].status == "ok" and cpu[0].max_abs_vs_cpu == 0.0
        assert math.isfinite(cpu[0].error_vs_truth) and cpu[0].time_s > 0
        for r in mine:
            if r.device in ("torch-cpu", "cuda"):
                assert r.status.startswith("skipped")
        peers = [r for r in mine if r.peer]
        assert peers and all(p.status == "ok" and math.isfinite(p.error_vs_truth) for p in peers)
