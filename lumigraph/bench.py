"""``lumigraph bench``: run every method of the chosen stages beside their peers,
on the same ground-truth inputs, and write the speed-against-error report."""

from __future__ import annotations

import argparse
from pathlib import Path

from lumigraph.capture.commandline import make_parser, number, output_dir, run, say
from lumigraph.capture.registry import Method, Registry

# bench stage name -> its stage(*, quick) -> Stage and a one-line summary, in the
# one registry shape (the harness is lumigraph.capture.bench; each stage's bench
# module sits in its own folder). A new bench stage is one line here.
BENCH_STAGES = Registry("bench stage", [
    Method("io", "lumigraph.capture.bench_io:stage",
           "write+read round trips of linear float images (EXR, PFM; OpenCV TIFF, RGBE)"),
    Method("render", "lumigraph.capture.bench_render:stage",
           "render time of every synthetic scene at its default test size"),
    Method("calib", "lumigraph.calib.bench:stage",
           "board detection and calibration, ours beside bare OpenCV"),
    Method("hdr", "lumigraph.hdr.bench:stage",
           "response recovery and merging beside OpenCV, colour-hdri and pfstools"),
    Method("flow", "lumigraph.stereo.bench_flow:stage",
           "optical flow and video matching against exact ground truth"),
    Method("stereo", "lumigraph.stereo.bench_stereo:stage",
           "block matching against OpenCV, triangulation, SfM"),
    Method("facade", "lumigraph.stereo.bench_facade:stage",
           "Façade photogrammetric modelling: block parameters and cameras from marked edges"),
    Method("lightfield", "lumigraph.lightfield.bench:stage",
           "refocusing, lenslet decoding, light-slab rendering, depth"),
    Method("separation", "lumigraph.separation.bench:stage",
           "Nayar 2006 separation against Mitsuba ground truth"),
    Method("gpu", "lumigraph.bench_gpu:stage",
           "the torch/kornia ports on cpu, torch-cpu and cuda beside our CPU code and peers"),
    Method("scale", "lumigraph.bench_scale:stage",
           "batch throughput: in-process, 1 and 2 Dask workers, one command per item"),
    Method("view", "lumigraph.view.bench:stage",
           "lumigraph view: server time of an exposure and a refocus slider move"),
])

EPILOG = """\
examples:
  lumigraph bench --out out/bench              every stage
  lumigraph bench hdr flow --out /tmp/b        two stages
  lumigraph bench io --out /tmp/b --quick      small inputs, for a smoke test
  lumigraph bench gpu --device cuda --out /tmp/b   the GPU rows and their speed targets

Writes DIR/report.md (per stage: the targets with measured and peer figures,
then one table per input case: method, knob value, median wall time, error
against ground truth), DIR/report.json (the same, machine-readable) and
DIR/<stage>.png (error against time, log axes, one line per method; dashed
lines are peers). Each row's time is the median of --repeats runs (>= 3).
"""


def _bench(args) -> int:
    from lumigraph.capture.bench import run_stage, write_report

    names = args.stages or list(BENCH_STAGES)
    stages = {n: load_stage(n, quick=args.quick, device=args.device) for n in names}
    results = {}
    for name, st in stages.items():
        say(args, f"bench {name}: {len(st.cases)} case(s), {len(st.methods)} method(s)")

        def show(row):
            if not args.quiet:
                v = f"{row.knob}={row.value}" if row.knob else ""
                print(f"  {row.case:<22} {row.method:<30} {v:<14} {row.time_s:9.4g} s  "
                      f"err {row.error:.4g}  {row.status if row.status != 'ok' else ''}", flush=True)

        rows = run_stage(st, repeats=args.repeats, on_row=show)
        from lumigraph.capture.bench import Results

        extra_checks = []
        if st.extra:
            extra_rows, extra_checks = st.extra()
            for row in extra_rows:
                show(row)
            rows = [*rows, *extra_rows]
        checks = st.checks(Results(rows), {"quick": args.quick}) if st.checks else []
        checks = [*checks, *extra_checks]
        results[name] = (st, rows, checks)
        for c in checks:
            say(args, f"  [{'pass' if c.passed else 'FAIL'}] {c.target}: {c.measured:.4g}"
                      + (f" (ref {c.reference:.4g})" if c.reference is not None else ""))
    report = write_report(Path(args.out), results,
                          header="quick mode: small inputs" if args.quick else "")
    say(args, f"report: {report}")
    return 0


def load_stage(name: str, *, quick: bool = False, device: str | None = None):
    """The :class:`lumigraph.capture.bench.Stage` of bench stage ``name``;
    ``device`` goes to the stages that take one (``gpu``)."""
    from lumigraph.capture.errors import InputError

    if name not in BENCH_STAGES:
        raise InputError(name, f"unknown bench stage; choose from {', '.join(BENCH_STAGES)}")
    method = BENCH_STAGES[name]
    try:
        stage = method.load()
    except ModuleNotFoundError as e:
        if e.name == method.target.split(":")[0]:
            raise InputError(name, "this stage has no bench yet") from None
        raise
    import inspect

    if device is not None and "device" in inspect.signature(stage).parameters:
        return stage(quick=quick, device=device)
    return stage(quick=quick)


def _stage_name(text: str) -> str:
    """A name of :data:`BENCH_STAGES` (a type, not ``choices``: argparse checks
    an empty ``nargs="*"`` list against ``choices`` and would refuse it)."""
    if text not in BENCH_STAGES:
        raise argparse.ArgumentTypeError(f"unknown bench stage {text!r}; choose from "
                                         f"{', '.join(BENCH_STAGES)}")
    return text


_stage_name.__name__ = "bench stage"


def build_parser(prog: str = "lumigraph bench"):
    """The ``lumigraph bench`` parser."""
    from lumigraph.capture.bench import MIN_REPEATS
    from lumigraph.capture.device import DEVICES

    p = make_parser(prog, "Speed against error: our methods and the peers on the same inputs.",
                    epilog=EPILOG)
    p.add_argument("stages", nargs="*", metavar="STAGE", type=_stage_name,
                   help=f"stages to run (default all): {', '.join(BENCH_STAGES)}")
    p.add_argument("--out", required=True, type=output_dir,
                   help="report folder (report.md, report.json, STAGE.png)")
    p.add_argument("--repeats", type=number(int, lo=MIN_REPEATS), default=MIN_REPEATS,
                   help="timed runs per row, median kept")
    p.add_argument("--quick", action="store_true", help="small inputs (smoke test)")
    p.add_argument("--device", choices=DEVICES, default="auto",
                   help="the gpu stage's devices: auto = cpu and torch-cpu rows, cuda rows when "
                        "torch sees a GPU; cuda = insist on the GPU; torch-cpu = no cuda rows; "
                        "cpu = ours and the peers only (other stages ignore it)")
    p.set_defaults(func=_bench)
    return p


def main(argv=None, prog="lumigraph bench") -> int:
    return run(build_parser(prog), argv)
