"""Harness of docs/decisions/charuco-marker-removal.md: the ``calib`` bench
(``lumigraph bench calib``) restricted to its family cases and the ChArUco
speed rows, run by the bench's own runner and checks (the 1280 px clean /
strong / fronto cases and the real photos, which this change does not touch,
are left out to save their ~10 minutes).

Usage::

    OPENBLAS_NUM_THREADS=1 python docs/decisions/calib_family_bench.py [repeats]

Prints every check (PASS/FAIL, measured, reference, detail).
"""

import dataclasses
import sys


def main(argv):
    from lumigraph.calib import bench as B
    from lumigraph.capture.bench import Results, run_stage

    st = B.stage()
    keep = {f[0] for f in B.FAMILY} | set(B.CHARUCO_SPEED)
    st = dataclasses.replace(st, cases=tuple(c for c in st.cases if c.name in keep))
    rows = run_stage(st, repeats=int(argv[0]) if argv else None)
    for c in st.checks(Results(rows), {"quick": False}):
        print(f"{'PASS' if c.passed else 'FAIL'} {c.target}: {c.measured:.4g} (ref {c.reference}) {c.detail}",
              flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
