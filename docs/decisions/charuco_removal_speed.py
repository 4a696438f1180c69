"""Harness of docs/decisions/charuco-marker-removal.md, "Cost, batched":
detection + ``calibrate(auto)`` with the per-marker removal (the reference
kept in tests/calib/_charuco_removal_reference.py) and with the batched one,
and bare OpenCV (``CharucoDetector.detectBoard`` + ``calibrateCamera`` with
the model auto chose), interleaved in one process, OpenCV on one thread,
min of the repeats.

Usage (names of the bench's FAMILY sets)::

    OPENBLAS_NUM_THREADS=1 python docs/decisions/charuco_removal_speed.py 5 "charuco 320 blur0.6 s13" "charuco 960 blur1.0"
"""

import importlib.util
import sys
import time
from pathlib import Path

import numpy as np


def main(argv):
    from lumigraph.calib import bench as B
    from lumigraph.calib import detect as D
    from lumigraph.calib.zhang2000 import _one_opencv_thread

    path = Path(__file__).resolve().parents[2] / "tests" / "calib" / "_charuco_removal_reference.py"
    spec = importlib.util.spec_from_file_location("_charuco_removal_reference", path)
    R = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(R)
    new = (D._paint_out_markers, D._refine_without_markers)
    old = (R._paint_out_markers, R._refine_without_markers)
    reps = int(argv[0])
    for name in argv[1:]:
        fam = next(f for f in B.FAMILY if f[0] == name)
        data = B._family(*fam[1:6])()
        model = B._ours("auto")(data, None)["model"]

        def ours(fs, data=data):
            D._paint_out_markers, D._refine_without_markers = fs
            try:
                return B._ours("auto")(data, None)
            finally:
                D._paint_out_markers, D._refine_without_markers = new

        runs = {"before": lambda: ours(old), "after": lambda: ours(new),
                "opencv": lambda data=data, model=model: B._opencv(data, model)}
        t = {k: [] for k in runs}
        with _one_opencv_thread():
            for r in range(reps):
                for k in list(runs)[r % 3:] + list(runs)[:r % 3]:
                    t0 = time.perf_counter()
                    runs[k]()
                    t[k].append(time.perf_counter() - t0)
        m = {k: min(v) for k, v in t.items()}
        print(f"{name}: min of {reps}: before {m['before']:.3f} s ({m['before'] / m['opencv']:.2f}x), "
              f"after {m['after']:.3f} s ({m['after'] / m['opencv']:.2f}x), OpenCV {m['opencv']:.3f} s; "
              f"medians {np.median(t['before']):.3f}/{np.median(t['after']):.3f}/{np.median(t['opencv']):.3f}",
              flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
