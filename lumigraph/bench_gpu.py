"""Bench stage ``gpu``: every ported dense call on each device, beside its CPU peer.

Gathers the rows of the stages' ``bench_device`` modules
(:mod:`lumigraph.capture.bench_device` describes the interface and the row):
light fields (refocusing), HDR (merge, tone mapping) and, where those modules
exist, separation, calibration (undistort, rectify) and stereo (cost volume,
flow warping). A stage without one is left out silently (it has no port yet).

Devices: ``--device auto`` (default) runs ``cpu`` and ``torch-cpu`` rows, and
``cuda`` rows when torch sees a GPU (else each cuda row says it was not run);
``--device cuda`` insists on the GPU (exit 2 without one); ``--device
torch-cpu`` leaves the cuda rows out; ``--device cpu`` runs ours and the
peers only. The issue's speed targets (refocus 100 depths of 9x9x512x512 RGB
<= 0.05x, merge 9 x 12 MP <= 0.1x, local tone mapping 12 MP <= 0.1x our
CPU time) are checks on the cuda rows, each against our cpu row of the same
run; they are measured only where a GPU is present. ``--quick`` runs small
inputs (a smoke test, seconds on a CPU).
"""

from __future__ import annotations

import importlib
import math

from lumigraph.capture.bench import Case, Check, Row, Stage

#: the stages' device-row modules, in report order (a missing one is skipped)
MODULES = (
    ("lightfield", "lumigraph.lightfield.bench_device"),
    ("hdr", "lumigraph.hdr.bench_device"),
    ("separation", "lumigraph.separation.bench_device"),
    ("calib", "lumigraph.calib.bench_device"),
    ("stereo", "lumigraph.stereo.bench_device"),
)


def _present() -> list[tuple[str, object]]:
    out = []
    for key, name in MODULES:
        try:
            out.append((key, importlib.import_module(name)))
        except ModuleNotFoundError as e:
            if e.name != name:
                raise
    return out


def devices_for(device: str) -> tuple[tuple[str, ...], str]:
    """``(devices to run, note)`` for the bench's ``--device``."""
    from lumigraph.capture.device import resolve_device, torch_available

    if device == "cpu":
        return ("cpu",), "cuda and torch-cpu rows not run: --device cpu"
    if device == "auto":
        if not torch_available():
            return ("cpu",), ("torch rows not run: torch/kornia are not installed "
                              "(pip install 'lumigraph[gpu]')")
        import torch

        if torch.cuda.is_available():
            return ("cpu", "torch-cpu", "cuda"), f"cuda: {torch.cuda.get_device_name(0)}"
        return ("cpu", "torch-cpu"), "cuda rows not run: torch sees no CUDA GPU"
    dev = resolve_device(device)          # InputError: no GPU / no extra
    if dev.name == "cuda":
        import torch

        return ("cpu", "torch-cpu", "cuda"), f"cuda: {torch.cuda.get_device_name(0)}"
    return ("cpu", "torch-cpu"), "cuda rows not run: --device torch-cpu"


def _to_row(key: str, r) -> Row:
    times = tuple(r.extra.get("times_s", ()))
    return Row("gpu", key, f"{r.stage}: {r.device}", r.peer, "", None, r.time_s, times,
               r.max_abs_vs_cpu, r.status,
               {"input": r.case, "vs_truth": r.error_vs_truth, "target": r.target,
                "note": r.note, **{k: v for k, v in r.extra.items() if k != "times_s"}})


def checks_for(device_rows) -> list[Check]:
    """The speed targets of the cuda rows that ran, each against our cpu row."""
    out = []
    for r in device_rows:
        if r.target is None or r.device != "cuda" or r.status != "ok":
            continue
        cpu = next((c for c in device_rows if c.stage == r.stage and c.case == r.case
                    and c.device == "cpu" and c.status == "ok"), None)
        if cpu is None or not math.isfinite(cpu.time_s) or cpu.time_s <= 0:
            continue
        ratio = r.time_s / cpu.time_s
        out.append(Check(f"{r.stage} ({r.case}): cuda time <= {r.target:g}x our cpu time",
                         ratio, r.target, ratio <= r.target,
                         f"cuda {r.time_s:.4g} s, cpu {cpu.time_s:.4g} s, "
                         f"max |cuda - cpu| {r.max_abs_vs_cpu:.3g}"))
    return out


def stage(*, quick: bool = False, device: str = "auto") -> Stage:
    """The ``gpu`` bench stage (module docstring)."""
    devices, note = devices_for(device)
    if "cuda" not in devices and not quick:
        # the full sizes exist for the GPU's targets; without one they only cost minutes
        quick = True
        note += "; no GPU: small inputs, as --quick"
    present = _present()

    def extra():
        rows, device_rows = [], []
        threads = None
        if "torch-cpu" in devices:
            import torch

            # single thread, as every CPU row (the rules of the bench)
            threads = torch.get_num_threads()
            torch.set_num_threads(1)
        try:
            for key, mod in present:
                got = mod.rows(devices=devices, quick=quick)
                device_rows += got
                rows += [_to_row(key, r) for r in got]
        finally:
            if threads is not None:
                torch.set_num_threads(threads)
        return rows, checks_for(device_rows)

    desc = ("Each ported call on every device, and its CPU peer, on the same inputs in one "
            "process. Error: max |output - our cpu output| (0 for the cpu row; a peer's is its "
            "method's difference, not rounding); 'vs truth' where the case has ground truth. "
            "Time: min of the repeats, cuda synchronised; torch-cpu on one thread. Nothing was tuned on these inputs. "
            + note + ".")
    return Stage("gpu", tuple(Case(key, lambda: None) for key, _ in present), (),
                 error=lambda d, out: math.nan, error_name="max abs diff vs cpu",
                 description=desc, extra=extra,
                 columns=(("input", "input"), ("vs truth", "vs_truth"), ("target", "target"),
                          ("note", "note")))
