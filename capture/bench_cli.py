"""``lumigraph bench``: run every method of the chosen stages beside their peers,
on the same ground-truth inputs, and write the speed-against-error report."""

from __future__ import annotations

from pathlib import Path

from capture.command import make_parser, run, say

EPILOG = """\
examples:
  lumigraph bench --out out/bench              every stage
  lumigraph bench hdr flow --out /tmp/b        two stages
  lumigraph bench io --out /tmp/b --quick      small inputs, for a smoke test

Writes DIR/report.md (per stage: the targets with measured and peer figures,
then one table per input case: method, knob value, median wall time, error
against ground truth), DIR/report.json (the same, machine-readable) and
DIR/<stage>.png (error against time, log axes, one line per method; dashed
lines are peers). Each row's time is the median of --repeats runs (>= 3).
"""


def _bench(args) -> int:
    from capture.bench import BENCH_STAGES, load_stage, run_stage, write_report

    names = args.stages or list(BENCH_STAGES)
    stages = {n: load_stage(n, quick=args.quick) for n in names}
    results = {}
    for name, st in stages.items():
        say(args, f"bench {name}: {len(st.cases)} case(s), {len(st.methods)} method(s)")

        def show(row):
            if not args.quiet:
                v = f"{row.knob}={row.value}" if row.knob else ""
                print(f"  {row.case:<22} {row.method:<30} {v:<14} {row.time_s:9.4g} s  "
                      f"err {row.error:.4g}  {row.status if row.status != 'ok' else ''}", flush=True)

        rows = run_stage(st, repeats=args.repeats, on_row=show)
        from capture.bench import Results

        checks = st.checks(Results(rows), {"quick": args.quick}) if st.checks else []
        results[name] = (st, rows, checks)
        for c in checks:
            say(args, f"  [{'pass' if c.passed else 'FAIL'}] {c.target}: {c.measured:.4g}"
                      + (f" (ref {c.reference:.4g})" if c.reference is not None else ""))
    report = write_report(Path(args.out), results,
                          header="quick mode: small inputs" if args.quick else "")
    say(args, f"report: {report}")
    return 0


def main(argv=None, prog="lumigraph bench") -> int:
    from capture.bench import BENCH_STAGES

    p = make_parser(prog, "Speed against error: our methods and the peers on the same inputs.",
                    epilog=EPILOG)
    p.add_argument("stages", nargs="*", metavar="STAGE",
                   help=f"stages to run (default all): {', '.join(BENCH_STAGES)}")
    p.add_argument("--out", required=True, help="report folder")
    p.add_argument("--repeats", type=int, default=3, help="timed runs per row, median kept (>= 3)")
    p.add_argument("--quick", action="store_true", help="small inputs (smoke test)")
    p.set_defaults(func=_bench)
    return run(p, argv)
