"""Score SGM settings on the tuning set of docs/decisions/stereo-sgm.md.

The tuning set: the rendered ``pair`` and ``pair-hard`` of the stereo bench
and the Middlebury 2001/2003 pairs (tsukuba, venus, teddy, cones). The 2005
scenes and KITTI are not read here: they are the bench's reported-on set.

Usage (each argument a JSON object of ``hirschmuller2008.match`` options;
none = the defaults)::

    OPENBLAS_NUM_THREADS=1 python docs/decisions/stereo_sgm_tuning.py '{}' '{"lr_tolerance": 1}'

Prints, per setting, bad-2.0 on non-occluded / all GT pixels per pair and
the mean over the pairs.
"""

import json
import sys

import numpy as np

from lumigraph.stereo import bench_stereo as b
from lumigraph.stereo.hirschmuller2008 import match

CASES = {"pair": lambda: b._pair((320, 240)),
         "pair-hard": lambda: b._pair((320, 240), textureless=True, occluders=2),
         **{n: (lambda n=n: b._real(n)) for n in b.REAL}}


def main(argv):
    data = {n: f() for n, f in CASES.items()}
    for text in argv or ["{}"]:
        opts = json.loads(text)
        row, nonocc = [], []
        for n, d in data.items():
            e = b._error(d, match(d["left"], d["right"], max_disp=d["max_disp"], **opts).disparity)
            row.append(f"{n} {e['bad2_nonocc']:.3f}/{e['bad2_all']:.3f}")
            nonocc.append(e["bad2_nonocc"])
        print(f"{text}: mean {np.mean(nonocc):.4f} | " + "  ".join(row), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
