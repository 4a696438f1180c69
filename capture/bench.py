"""Speed against error: our methods beside the peers, on the same inputs, in one run.

Each stage contributes a :class:`Stage` from a module listed in
:data:`lumigraph.bench.BENCH_STAGES` (a function ``stage(*, quick: bool) -> Stage``):

- **cases**: inputs with exact ground truth (built once per run);
- **methods**: ours and the peers' (OpenCV, colour-hdri, pfstools, …), each
  with a knob swept over a few values;
- **error**: a metric of an output against the case's ground truth;
- **checks**: the issue's targets, each a ratio to a peer measured in this run.

:func:`run_stages` times every (case, method, knob value) as the median of
``repeats`` runs (interleaved across the case's methods), and
:func:`write_report` writes ``report.md``,
``report.json`` and one ``<stage>.png`` (error against time, log axes, one
line per method).

Examples
--------
>>> import numpy as np
>>> st = Stage("toy", cases=(Case("c", lambda: np.arange(10.0)),),
...            methods=(Method("sum", lambda d, k: d.sum()),),
...            error=lambda d, out: abs(out - 45.0), error_name="abs error")
>>> rows = run_stage(st, repeats=3)
>>> rows[0].error, rows[0].status
(0.0, 'ok')
"""

from __future__ import annotations

import math
import statistics
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from lumigraph.capture.errors import InputError


def shared_data(*parts: str) -> Path:
    """A path in the shared real-data folder: ``$LUMIGRAPH_SHARED`` or the
    ``shared/`` folder beside this checkout (DESIGN §7), e.g.
    ``shared_data("data", "stereo-real", "teddy")``. It may not exist: pair it
    with :func:`missing_shared` as a case's ``unavailable``."""
    import os

    root = os.environ.get("LUMIGRAPH_SHARED", Path(__file__).resolve().parents[2] / "shared")
    return Path(root).joinpath(*parts)


def missing_shared(*parts: str) -> Callable[[], str | None]:
    """An ``unavailable`` callback: the reason when a shared data path is absent."""

    def reason() -> str | None:
        p = shared_data(*parts)
        return None if p.exists() else f"real data not found: {p}"

    return reason


@dataclass(frozen=True)
class Case:
    """Inputs with ground truth. ``load()`` is called once per run; its result is
    passed to every method and to the error metric. ``unavailable()`` returns a
    reason when the case cannot be built here (real data not present); its rows
    then say so instead of failing the run."""

    name: str
    load: Callable[[], Any]
    note: str = ""
    unavailable: Callable[[], str | None] | None = None


@dataclass(frozen=True)
class Method:
    """One method (ours, or a peer's when ``peer`` names the library).

    ``run(data, value)`` is timed; ``value`` is the knob's value. ``prepare``
    (optional, untimed) builds per-case state passed as ``data`` instead (for
    example a one-time FFT timed separately by a check). ``unavailable()``
    returns a reason when the method cannot run here (a missing tool).
    ``cases`` restricts it to some cases; ``None`` means all.
    """

    name: str
    run: Callable[[Any, Any], Any]
    knob: str = ""
    values: tuple = (None,)
    peer: str | None = None
    unavailable: Callable[[], str | None] | None = None
    cases: tuple[str, ...] | None = None
    prepare: Callable[[Any], Any] | None = None


@dataclass(frozen=True)
class Row:
    stage: str
    case: str
    method: str
    peer: str | None
    knob: str
    value: Any
    time_s: float
    times_s: tuple[float, ...]
    error: float
    status: str
    extra: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Check:
    """One target from an issue, measured: ``measured`` against ``reference``
    (the peer's figure from the same run, or the bound)."""

    target: str
    measured: float
    reference: float | None
    passed: bool
    detail: str = ""


class Results:
    """Lookups over a stage's rows, for writing checks."""

    def __init__(self, rows: Sequence[Row]):
        self.rows = list(rows)

    def get(self, case: str, method: str, value: Any = None) -> Row:
        for r in self.rows:
            if r.case == case and r.method == method and (value is None or r.value == value):
                return r
        raise KeyError(f"no bench row for case={case!r} method={method!r} value={value!r}")

    def of(self, case: str, method: str) -> list[Row]:
        return [r for r in self.rows if r.case == case and r.method == method and r.status == "ok"]

    def best(self, case: str, method: str) -> Row:
        """The method's lowest-error row on ``case``."""
        rows = self.of(case, method)
        if not rows:
            raise KeyError(f"no successful rows for case={case!r} method={method!r}")
        return min(rows, key=lambda r: r.error)

    def fastest_within(self, case: str, method: str, error: float) -> Row | None:
        """The method's fastest row whose error is at most ``error``."""
        ok = [r for r in self.of(case, method) if r.error <= error]
        return min(ok, key=lambda r: r.time_s) if ok else None


@dataclass(frozen=True)
class Stage:
    name: str
    cases: tuple[Case, ...]
    methods: tuple[Method, ...]
    error: Callable[[Any, Any], float | dict]
    error_name: str
    checks: Callable[[Results, dict], list[Check]] | None = None
    description: str = ""
    repeats: int = 3
    # Rows and checks measured by the stage's own protocol (seed sweeps,
    # interleaved timings of one call against its peer) that do not fit the
    # case x method grid; run after the grid, before ``checks``.
    extra: Callable[[], tuple[list[Row], list[Check]]] | None = None
    # More columns of the report's tables: (heading, key of a row's ``extra``).
    columns: tuple[tuple[str, str], ...] = ()
    # ``plot(path, stage, rows)`` draws ``<stage>.png`` when error against time
    # is not the stage's picture (throughput against workers)
    plot: Callable[[Path, Stage, list[Row]], None] | None = None


def _is_number(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


MIN_REPEATS = 3  # timed runs per row: the median of fewer is not a median of anything


def check_repeats(repeats: int) -> int:
    """Timed runs per row: an integer >= :data:`MIN_REPEATS`.

    Raises
    ------
    InputError
        Naming ``repeats``.

    Examples
    --------
    >>> check_repeats(5)
    5
    >>> try:
    ...     check_repeats(0)
    ... except InputError as e:
    ...     print(e)
    repeats: expected an integer >= 3 (the median of the timed runs), got 0
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < MIN_REPEATS:
        raise InputError("repeats", f"expected an integer >= {MIN_REPEATS} (the median of the "
                                    f"timed runs), got {repeats!r}")
    return repeats


def run_stage(stage: Stage, *, repeats: int | None = None,
              on_row: Callable[[Row], None] | None = None) -> list[Row]:
    """Run every (case, method, knob value) of ``stage``; never raises for a
    method's failure (the row's status says what went wrong). ``repeats``
    (default the stage's, at least :data:`MIN_REPEATS`) is checked by
    :func:`check_repeats`."""
    repeats = max(MIN_REPEATS, stage.repeats) if repeats is None else check_repeats(repeats)
    rows: list[Row] = []

    def emit(row: Row) -> None:
        rows.append(row)
        if on_row:
            on_row(row)

    def unavailable(case: Case, m: Method, reason: str) -> None:
        emit(Row(stage.name, case.name, m.name, m.peer, m.knob, None, math.nan, (), math.nan,
                 f"unavailable: {reason}"))

    for case in stage.cases:
        methods = [m for m in stage.methods if m.cases is None or case.name in m.cases]
        reason = case.unavailable() if case.unavailable else None
        if reason:
            for m in methods:
                unavailable(case, m, reason)
            continue
        data = case.load()
        jobs = []
        for m in methods:
            reason = m.unavailable() if m.unavailable else None
            if reason:
                unavailable(case, m, reason)
                continue
            state = m.prepare(data) if m.prepare else data
            jobs += [{"m": m, "value": v, "state": state, "times": [], "status": "ok",
                      "err": math.nan, "extra": {}} for v in m.values]
        # Interleaved: repeat r runs every (method, value) once, in an order that
        # rotates with r, so a burst of machine load falls on all of them alike
        # and the medians compare like with like. The error is taken from the
        # last run's output (methods that accumulate state across runs report it
        # there), and each output is dropped at once: one in memory at a time.
        for r in range(repeats):
            k = r % len(jobs) if jobs else 0
            for j in jobs[k:] + jobs[:k]:
                if j["status"] != "ok":
                    continue
                try:
                    t0 = time.perf_counter()
                    out = j["m"].run(j["state"], j["value"])
                    j["times"].append(time.perf_counter() - t0)
                    if len(j["times"]) == repeats:
                        err = stage.error(data, out)
                        if isinstance(err, dict):
                            j["extra"] = {key: v for key, v in err.items() if key != "error"}
                            err = err["error"]
                        j["err"] = float(err)
                    del out
                except Exception as e:  # a peer may refuse an input: record it
                    j["status"] = (f"failed: {type(e).__name__}: "
                                   f"{str(e).splitlines()[0][:160] if str(e) else ''}")
                    j["err"] = math.nan
                    j["extra"] = {"traceback": traceback.format_exc(limit=3)}
        for j in jobs:
            m, times = j["m"], j["times"]
            emit(Row(stage.name, case.name, m.name, m.peer, m.knob, j["value"],
                     statistics.median(times) if times else math.nan, tuple(times), j["err"],
                     j["status"], j["extra"]))
    return rows


def _fmt(x: Any, digits: int = 4) -> str:
    if x is None:
        return "—"
    if _is_number(x):
        if isinstance(x, float) and math.isnan(x):
            return "—"
        return f"{x:.{digits}g}"
    return str(x)


def write_report(out_dir: str | Path, results: dict[str, tuple[Stage, list[Row], list[Check]]],
                 *, header: str = "") -> Path:
    """Write ``report.md``, ``report.json`` and ``<stage>.png`` into ``out_dir``."""
    from lumigraph.capture.artifact import atomic_path, library_versions, write_json

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    md = ["# lumigraph bench: speed against error", ""]
    if header:
        md += [header, ""]
    md += ["Wall time is the median of the repeats; error is against exact ground truth. "
           "Targets are ratios to a peer measured in this same run.", ""]
    js = {"versions": library_versions(), "stages": {}}
    for name, (stage, rows, checks) in results.items():
        md += [f"## {name}", ""]
        if stage.description:
            md += [stage.description, ""]
        if checks:
            md += ["| target | measured | reference | pass | detail |", "|---|---|---|---|---|"]
            for c in checks:
                md.append(f"| {c.target} | {_fmt(c.measured)} | {_fmt(c.reference)} | "
                          f"{'yes' if c.passed else '**NO**'} | {c.detail} |")
            md.append("")
        for case in stage.cases:
            crow = [r for r in rows if r.case == case.name]
            if not crow:
                continue
            md += [f"### {name} / {case.name}", ""]
            if case.note:
                md += [case.note, ""]
            more = "".join(f" {head} |" for head, _ in stage.columns)
            md += [f"| method | peer | knob | time (s) | {stage.error_name} |{more} status |",
                   "|---|---|---|---|---|" + "---|" * len(stage.columns) + "---|"]
            for r in crow:
                knob = f"{r.knob}={_fmt(r.value)}" if r.knob else ""
                cells = "".join(f" {_fmt(r.extra.get(key))} |" for _, key in stage.columns)
                md.append(f"| {r.method} | {r.peer or 'ours'} | {knob} | {_fmt(r.time_s)} | "
                          f"{_fmt(r.error)} |{cells} {r.status} |")
            md.append("")
        md += [f"![{name}]({name}.png)", ""]
        (stage.plot or _plot)(out / f"{name}.png", stage, rows)
        js["stages"][name] = {"error_name": stage.error_name,
                              "rows": [asdict(r) for r in rows],
                              "checks": [asdict(c) for c in checks]}
    with atomic_path(out / "report.md") as tmp:
        tmp.write_text("\n".join(md) + "\n")
    write_json(out / "report.json", js)
    return out / "report.md"


def _plot(path: Path, stage: Stage, rows: list[Row]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lumigraph.capture.artifact import atomic_path

    cases = [c.name for c in stage.cases if any(r.case == c.name for r in rows)] or ["-"]
    # a grid at most three wide, so a stage with many cases stays legible
    ncols = min(3, len(cases))
    nrows = -(-len(cases) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.6 * ncols, 4.4 * nrows), squeeze=False)
    for ax in axes.flat[len(cases):]:
        ax.set_visible(False)
    for ax, case in zip(axes.flat, cases, strict=False):
        methods = dict.fromkeys(r.method for r in rows if r.case == case)
        for m in methods:
            pts = [(r.time_s, r.error, r.value) for r in rows
                   if r.case == case and r.method == m and r.status == "ok"
                   and r.time_s is not None and r.error is not None
                   and r.time_s > 0 and r.error > 0 and math.isfinite(r.error)]
            if not pts:
                continue
            pts.sort()
            peer = next(r.peer for r in rows if r.method == m)
            # peers: squares and dashes, ours: circles and solid lines (colours repeat)
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "--s" if peer else "-o",
                    label=m + (f" ({peer})" if peer else ""), ms=4)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time (s, median)")
        ax.set_ylabel(stage.error_name)
        ax.set_title(f"{stage.name} / {case}")
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
