"""The crease refinement's precision (session 43, sets ``CREASE_PLACED_PX``): at the true
model and cameras of rendered tuning seeds, the wing's right end scanned (``_crease``,
σ 0.05 m) and each proposal's endpoints' distance (px) from the true projected edge line.

usage: python docs/decisions/facade_crease_precision.py 4 5 6 7 8 9 10 11
(2026-12-06: 25 proposals, RMS 0.30 px, median |d| 0.17 px; seed 6 proposed none).
"""

import sys

import numpy as np

import lumigraph.stereo.debevec1996.automark as am
from lumigraph.stereo import bench_facade as BF


def distances(seed: int) -> list:
    c = BF.rendered_case(seed)
    m = c["model"]
    cams = {p: {"K": np.array(v["K"]), "R": np.array(v["R"]), "t": np.array(v["t"]),
                "image_size": list(c["images"][p].shape[1::-1])}
            for p, v in c["cameras"].items()}
    greys = {p: am._grey(c["images"][p]) for p in c["images"]}
    names = [n for n in m.parameter_names if n.startswith("wing/")]
    # the right end: width and offset together, the left end still
    vr = np.array([{"wing/width": 1.0, "wing/offset_x": 0.5}.get(n, 0.0) for n in names])
    vr /= np.linalg.norm(vr)
    out = am._crease(m, names, vr, cams, greys, rough=m, trust=0.3, sigma=0.05)
    C0, C1 = m.edge_matrices()
    index = {n: i for i, n in enumerate(m.edge_names)}
    ds = []
    for mk in out:
        cam, i = cams[mk.photo], index[mk.edge]
        X = np.stack([C0[i] @ m.values, C1[i] @ m.values])
        x = cam["K"] @ (cam["R"] @ X.T + cam["t"][:, None])
        x = (x[:2] / x[2]).T
        line = np.cross(np.r_[x[0], 1.0], np.r_[x[1], 1.0])
        line /= np.hypot(*line[:2])
        d = [float(line @ np.r_[mk.segment[:2], 1.0]), float(line @ np.r_[mk.segment[2:], 1.0])]
        print(seed, mk.photo, mk.edge, np.round(d, 2))
        ds += d
    return ds


if __name__ == "__main__":
    every = []
    for s in map(int, sys.argv[1:]):
        d = distances(s)
        print(f"seed {s}: {len(d) // 2} proposals"
              + (f", RMS {np.sqrt(np.mean(np.square(d))):.2f} px" if d else ""), flush=True)
        every += d
    print(f"all: {len(every) // 2} proposals, RMS {np.sqrt(np.mean(np.square(every))):.2f} px, "
          f"median |d| {np.median(np.abs(every)):.2f} px")
