"""Device rows of ``lumigraph bench gpu``: one ported call on every device, beside its CPU peer.

Each stage with a torch port has a module ``<stage>/bench_device.py`` exposing::

    def rows(*, devices: tuple[str, ...], quick: bool) -> list[DeviceRow]

``devices`` is a subset of ``("cpu", "torch-cpu", "cuda")`` in that order
(``"cpu"`` is always first: it is the reference every other row is compared
with; ``"cuda"`` is present only when torch sees a GPU). ``quick`` asks for
small inputs (a smoke test that runs on a CPU-only machine in seconds).

For each ported call and input case the module returns one :class:`DeviceRow`
per device and one per CPU peer (OpenCV, ...), built with :func:`measure`:

- ``stage``: the command it ports, e.g. ``"lightfield refocus"``;
- ``case``: the input, with its size, e.g. ``"9x9x512x512 RGB, 100 depths"``;
- ``device``: ``"cpu"`` (ours, numpy/OpenCV), ``"torch-cpu"``, ``"cuda"``, or
  the peer's name (``"opencv"``) with ``peer`` set to the library;
- ``time_s``: the minimum over the repeats (a GPU call is synchronised);
- ``max_abs_vs_cpu``: max abs difference of the output against our ``cpu``
  row's output on the same inputs (0 for the cpu row itself);
- ``error_vs_truth``: the case's error against ground truth where it has one
  (``nan`` otherwise), the same metric on every row of the case;
- ``target``: for a device row with a speed target of the issue, the bound
  on ``time_s / cpu time_s`` (``0.05`` = 20x faster); the gatherer turns it
  into a :class:`lumigraph.capture.bench.Check`;
- ``status``: ``"ok"``, ``"skipped: <why>"`` or ``"failed: <why>"``.

A device the machine lacks is a row from :func:`skipped` (so the report says
the cuda rows were not run instead of silently leaving them out).

>>> import numpy as np
>>> ref = np.arange(6.0)
>>> row, out = measure("toy", "6 values", "cpu", lambda: ref * 2, reference=None, repeats=3)
>>> row.status, row.max_abs_vs_cpu
('ok', 0.0)
>>> row2, _ = measure("toy", "6 values", "torch-cpu", lambda: ref * 2 + 1e-7,
...                   reference=out, repeats=3)
>>> bool(row2.max_abs_vs_cpu < 1e-6)
True
>>> skipped("toy", "6 values", "cuda", "torch sees no CUDA GPU").status
'skipped: torch sees no CUDA GPU'
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

#: the order of the device rows; peers follow
DEVICE_ORDER = ("cpu", "torch-cpu", "cuda")


@dataclass(frozen=True)
class DeviceRow:
    """One (ported call, input case, device or peer) measurement; see the module docstring."""

    stage: str
    case: str
    device: str
    time_s: float
    max_abs_vs_cpu: float
    error_vs_truth: float = math.nan
    peer: str | None = None
    target: float | None = None
    status: str = "ok"
    note: str = ""
    extra: dict = field(default_factory=dict)


def _sync(device: str) -> None:
    # a CUDA call returns before the kernel ends: time to the end of the work
    if device == "cuda":
        import torch

        torch.cuda.synchronize()


def _as_numpy(out):
    import numpy as np

    if hasattr(out, "detach"):          # a torch tensor
        out = out.detach().to("cpu").numpy()
    return np.asarray(out, dtype=np.float64)


def measure(stage: str, case: str, device: str, call: Callable[[], Any], *,
            reference=None, truth: Callable[[Any], float] | None = None,
            repeats: int = 3, peer: str | None = None, target: float | None = None,
            note: str = "", warmup: bool | None = None) -> tuple[DeviceRow, Any]:
    """Time ``call()`` (min of ``repeats``; synchronised on cuda) and compare
    its output with ``reference`` (our cpu output; ``None`` for the cpu row
    itself) and, through ``truth(output)``, with ground truth.

    A first untimed call is made on torch devices (``warmup`` default): kernel
    selection and allocator growth are a one-time cost, not the call's.
    Returns the row and the output (the cpu row's output is the next rows'
    ``reference``). Never raises for the call's failure: the row says it.
    """
    import numpy as np

    out = None
    try:
        if warmup if warmup is not None else device in ("torch-cpu", "cuda"):
            call()
            _sync(device)
        times = []
        for _ in range(max(1, repeats)):
            _sync(device)
            t0 = time.perf_counter()
            out = call()
            _sync(device)
            times.append(time.perf_counter() - t0)
        a = _as_numpy(out)
        diff = 0.0 if reference is None else float(np.max(np.abs(a - _as_numpy(reference))))
        err = float(truth(a)) if truth is not None else math.nan
        row = DeviceRow(stage, case, device, min(times), diff, err, peer, target, "ok", note,
                        {"times_s": tuple(times)})
    except Exception as e:  # a port or a peer may fail on an input: record it
        msg = str(e).splitlines()[0][:160] if str(e) else ""
        row = DeviceRow(stage, case, device, math.nan, math.nan, math.nan, peer, target,
                        f"failed: {type(e).__name__}: {msg}", note,
                        {"traceback": traceback.format_exc(limit=3)})
    return row, out


def skipped(stage: str, case: str, device: str, why: str, *, target: float | None = None,
            peer: str | None = None) -> DeviceRow:
    """The row of a device (or peer) that was not run here, saying why."""
    return DeviceRow(stage, case, device, math.nan, math.nan, math.nan, peer, target,
                     f"skipped: {why}")


def not_run(stage, name, dev, devices, quick):
    """The skipped row of a device not run here, or None: a device not asked
    or absent, and torch-cpu at full size (minutes on torch's CPU device;
    ``--quick`` and ``tests/device`` check the port there)."""
    if dev not in devices:
        why = "torch sees no CUDA GPU" if dev == "cuda" else "not asked (--device)"
        return skipped(stage, name, dev, why)
    if dev == "torch-cpu" and not quick:
        return skipped(stage, name, dev, "full size: minutes on torch's CPU device; --quick "
                                         "and tests/device check the port")
    return None


def repeats_for(dev: str, quick: bool) -> int:
    """Repeats of a timing (min taken): the full-size CPU rows take seconds each."""
    return 3 if quick else (5 if dev == "cuda" else 2)


def device_rows(out_rows: list, stage: str, case: str, devices, call: Callable[[str], Any], *,
                truth, quick: bool, note: str = "", warmup: bool | None = None):
    """The cpu, torch-cpu and cuda rows of ``call(device)``: a :func:`not_run`
    row for each device not run here, the others :func:`measure`d against the
    cpu row's output, appended to ``out_rows``. Returns the cpu output (the
    peers' ``reference``; None when cpu was not run)."""
    ref = None
    for dev in ("cpu", "torch-cpu", "cuda"):
        skip = not_run(stage, case, dev, devices, quick)
        if skip is not None:
            out_rows.append(skip)
            continue
        row, out = measure(stage, case, dev, lambda dev=dev: call(dev), reference=ref,
                           truth=truth, repeats=repeats_for(dev, quick), note=note,
                           warmup=warmup)
        out_rows.append(row)
        if dev == "cpu":
            ref = out
    return ref


def single_thread():
    """Context: cv2 and torch at one thread (restored after): the bench compares
    single-threaded library calls."""
    import contextlib

    @contextlib.contextmanager
    def ctx():
        import cv2

        prev = cv2.getNumThreads()
        cv2.setNumThreads(1)
        tprev = None
        try:
            import torch

            tprev = torch.get_num_threads()
            torch.set_num_threads(1)
        except ImportError:
            pass
        try:
            yield
        finally:
            cv2.setNumThreads(prev)
            if tprev is not None:
                import torch

                torch.set_num_threads(tprev)

    return ctx()
