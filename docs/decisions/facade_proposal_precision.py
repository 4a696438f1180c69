"""Automatic marking's proposals, how far each lies from its true edge, by where it came from
and what kind of edge it marks (session 47; the crease proposals' own noise, a lead of
session 46, tested before building on it).

For each rendered seed (draw 0 of the bench's noise draws, the given start ``of`` one
factor off or ``bf`` the ``blocks.json`` rough model), ``automark`` runs as the bench runs
it; every final mark's two endpoints are measured (px, signed) from its true projected edge
line. Sources: ``hand``; ``line`` a detected line's proposal; ``search`` an edge searched
for along its projection (``_search_edge``); ``crease`` the crease scan's (``_crease``).
Edge classes at the true model: ``crease`` the edge's middle lies inside another block's
face (not on that block's edges: a wing's end against the house's wall), ``shared`` it lies
on another block's edge (the house's eaves under the roof's), ``free`` neither.

usage: python docs/decisions/facade_proposal_precision.py of,bf SEED...

2026-12-07 (session 47's code, ef72a2d), tuning seeds 4-11, both starts (16 runs), endpoints
(px; "into" the mean signed offset towards the mark's own block):

=======  ======  ====  =====  ==========  =====  =====  ======
source   class   n     RMS    median |d|  p90    max    into
=======  ======  ====  =====  ==========  =====  =====  ======
hand     free     444  0.55   0.38        0.90   1.85   -0.04
hand     shared    68  0.50   0.34        0.83   1.25   -0.04
line     free    1080  0.20   0.06        0.26   2.57   +0.03
line     shared   277  0.33   0.13        0.39   2.25   +0.03
line     crease    70  0.19   0.08        0.26   0.84   -0.02
search   free      20  0.30   0.11        0.69   0.81   -0.17
search   shared    21  0.28   0.21        0.45   0.51   +0.04
search   crease     3  0.06   0.04        0.09   0.09   +0.04
crease   crease    22  0.27   0.15        0.40   0.91   +0.12
=======  ======  ====  =====  ==========  =====  =====  ======

(n: marks.) The crease scan's proposals are a little less precise than the detected lines'
(RMS 0.27 against 0.20 px, against the hand marks' 0.55), and a detected line on a crease edge
is no worse than elsewhere: no evidence for weighing crease proposals as the hand marks.
They sit 0.12 px into their own block on average (ends placed short), small beside their
spread. All proposals are heavy-tailed (median |d| a third or less of the RMS, a tail past 2 px).
"""

import sys

import numpy as np

import lumigraph.stereo.debevec1996.automark as am
from lumigraph.stereo import bench_facade as BF
from lumigraph.stereo.debevec1996.solve import project_model_edges


def edge_classes(model) -> dict:
    """``{edge name: "free" | "shared" | "crease"}`` (see the module's text)."""
    mesh = model.mesh()
    tris = mesh.vertices[mesh.faces]
    E = model.edges()
    out = {}
    for name, (p, q) in E.items():
        own, mid, cls = name.split("/")[0], 0.5 * (p + q), "free"
        for T, blk in zip(tris, mesh.face_block, strict=True):
            if blk == own:
                continue
            a, b, c = T
            n = np.cross(b - a, c - a)
            n /= np.linalg.norm(n)
            if abs((mid - a) @ n) > 1e-6:
                continue
            # barycentric: inside the triangle or on its rim
            v0, v1, v2 = b - a, c - a, mid - a
            d00, d01, d11, d20, d21 = v0 @ v0, v0 @ v1, v1 @ v1, v2 @ v0, v2 @ v1
            den = d00 * d11 - d01 * d01
            s, t = (d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den
            if s < -1e-9 or t < -1e-9 or s + t > 1 + 1e-9:
                continue
            on_edge = any(np.linalg.norm(np.cross(mid - P, Q - P)) / np.linalg.norm(Q - P) < 1e-6
                          for nm, (P, Q) in E.items() if nm.split("/")[0] == blk)
            cls = "shared" if on_edge else "crease"
            if cls == "crease":
                break
        out[name] = cls
    return out


def offsets(seed: int, start: str) -> list:
    """``[(source, class, d0, d1, inward)]`` for every final mark of one run, ``inward``
    the sign that turns ``d`` into the offset towards the mark's own block."""
    c = BF.rendered_case(seed)
    D = BF.rendered_draws(seed, draws=1)
    truth = c["model"].with_values(c["truth"])
    classes = edge_classes(truth)
    found = {"search": set(), "crease": set()}
    search, crease = am._search_edge, am._crease

    def rec_search(*a, **kw):
        o = search(*a, **kw)
        if o is not None:
            found["search"].add(tuple(np.round(o, 6)))
        return o

    def rec_crease(*a, **kw):
        o = crease(*a, **kw)
        found["crease"] |= {tuple(np.round(m.segment, 6)) for m in o}
        return o

    am._search_edge, am._crease = rec_search, rec_crease
    try:
        res = am.automark(c["start"] if start == "of" else D.rough, D[0][1], c["images"],
                          c["K"], noise_px=0.5, rough_rotations=c["rotations"])
    finally:
        am._search_edge, am._crease = search, crease
    out = []
    for m in res.marks.marks:
        cam = c["cameras"][m.photo]
        a, b = (np.asarray(x, float) for x in project_model_edges(
            truth, np.array(cam["K"]), np.array(cam["R"]), np.array(cam["t"]).ravel())[m.edge])
        u = (b - a) / np.linalg.norm(b - a)
        n = np.array([-u[1], u[0]])
        key = tuple(np.round(m.segment, 6))
        src = ("hand" if not m.proposed else "crease" if key in found["crease"]
               else "search" if key in found["search"] else "line")
        d = [float((p - a) @ n) for p in np.asarray(m.segment).reshape(2, 2)]
        # signed into the mark's own block: towards the block's centre across the line
        P, Q = truth.edges()[m.edge]
        mid = 0.5 * (P + Q)
        own = np.array([X for nm, (X, _) in truth.edges().items()
                        if nm.split("/")[0] == m.edge.split("/")[0]]).mean(axis=0)
        step = 1e-3 * (own - mid) / np.linalg.norm(own - mid)
        K, R, t = (np.array(cam[k], float) for k in ("K", "R", "t"))
        x0, x1 = (K @ (R @ X + t.ravel()) for X in (mid, mid + step))
        inward = float(np.sign((x1[:2] / x1[2] - x0[:2] / x0[2]) @ n))
        out.append((src, classes[m.edge], *d, inward))
    return out


if __name__ == "__main__":
    rows = []
    for start in sys.argv[1].split(","):
        for s in map(int, sys.argv[2:]):
            rows += offsets(s, start)
            print(f"{start} seed {s}: {len(rows)} marks so far", flush=True)
    for src in ("hand", "line", "search", "crease"):
        for cls in ("free", "shared", "crease"):
            d = np.array([x for r in rows if r[0] == src and r[1] == cls for x in r[2:4]])
            inward = np.array([r[4] * x for r in rows if r[0] == src and r[1] == cls
                               for x in r[2:4]])
            if d.size:
                print(f"{src:7s} {cls:7s} n={d.size // 2:5d} RMS {np.sqrt(np.mean(d ** 2)):.2f} "
                      f"median |d| {np.median(np.abs(d)):.2f} p90 {np.percentile(np.abs(d), 90):.2f}"
                      f" max {np.abs(d).max():.2f} mean into its block {inward.mean():+.2f}")
