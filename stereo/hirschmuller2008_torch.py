"""The torch path of semi-global matching's aggregation (Hirschmüller 2008,
eqs. 13–14): ``S(p, d) = Σ_r L_r(p, d)`` over 8 (or 4) paths, on torch's CPU
device or CUDA.

H. Hirschmüller, "Stereo processing by semiglobal matching and mutual
information", IEEE TPAMI 30(2), 2008, doi:10.1109/TPAMI.2007.1166. Each path
recursion is sequential along its direction, so the port steps column by
column (horizontal paths, every row and disparity at once) and row by row
(vertical and diagonal paths, every column and disparity at once), as the
numpy twin :func:`lumigraph.stereo.hirschmuller2008.aggregate` does: one
step is a handful of device operations on an ``(N, D)`` block. The
arithmetic is integers (int32, the ``P2`` adaptation by floor division, the
sum wrapped to uint16 as the C kernel's), so ``S`` equals the C kernel's and
the numpy twin's exactly. The census, the matching cost, the winner search
and the checks stay on the CPU (the C kernel): the cost volume travels to
the device and ``S`` back.

Examples
--------
>>> import numpy as np
>>> c = np.zeros((3, 4, 5), np.uint16); c[..., [0, 1, 3, 4]] = 9
>>> int(aggregate(c, np.zeros((3, 4), np.uint8), p1=1, p2=4, edge=0, device="torch-cpu")[1, 1].argmin())
2
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.device import resolve_device, to_numpy, torch_modules


def _step(torch, C, prev, P1, P2):
    """One step of eq. 13 for ``N`` pixels: ``C``, ``prev`` (N, D) int32, ``P2`` (N,)."""
    m = prev.amin(1, keepdim=True)
    v = prev.clone()
    v[:, 1:] = torch.minimum(v[:, 1:], prev[:, :-1] + P1)
    v[:, :-1] = torch.minimum(v[:, :-1], prev[:, 1:] + P1)
    v = torch.minimum(v, m + P2[:, None])
    return C + v - m


def _penalty2(torch, P1, P2, edge, a, b):
    if edge <= 0:
        return torch.full(a.shape, P2, dtype=torch.int32, device=a.device)
    q = torch.div(P2 * edge, edge + (a - b).abs(), rounding_mode="floor")
    return q.clamp(min=P1).to(torch.int32)


def aggregate(cost: np.ndarray, guide: np.ndarray, *, p1: int, p2: int, edge: int,
              paths: int = 8, device="torch-cpu") -> np.ndarray:
    """:func:`lumigraph.stereo.hirschmuller2008.aggregate` on ``device``:
    ``cost`` (H, W, D) uint16, ``guide`` (H, W) uint8; returns (H, W, D)
    uint16 (numpy)."""
    torch, _ = torch_modules()
    dev = resolve_device(device)
    C = torch.from_numpy(np.ascontiguousarray(cost, dtype=np.uint16).astype(np.int32)).to(dev.torch)
    g = torch.from_numpy(np.ascontiguousarray(guide, dtype=np.uint8).astype(np.int32)).to(dev.torch)
    h, w, D = C.shape
    S = torch.zeros((h, w, D), dtype=torch.int32, device=C.device)
    Ct = C.permute(1, 0, 2).contiguous()  # (W, H, D): a column is one contiguous block
    gt = g.t().contiguous()
    St = torch.zeros((w, h, D), dtype=torch.int32, device=C.device)
    xs = torch.arange(w, device=C.device)
    for sgn in (1, -1):
        cols = range(w) if sgn > 0 else range(w - 1, -1, -1)
        rows = range(h) if sgn > 0 else range(h - 1, -1, -1)
        # horizontal: from (x - sgn, y), every row at once
        prev = None
        for x in cols:
            if prev is None:
                cur = Ct[x]
            else:
                cur = _step(torch, Ct[x], prev, p1, _penalty2(torch, p1, p2, edge, gt[x], gt[x - sgn]))
            St[x] += cur
            prev = cur
        # from the previous row: (x - sgn·dx, y - sgn)
        for dx in ((-1, 0, 1) if paths == 8 else (0,)):
            xp = xs - sgn * dx
            ok = (xp >= 0) & (xp < w)
            okx, xpo = xs[ok], xp[ok]
            prev = None
            for y in rows:
                cur = C[y].clone()
                if prev is not None:
                    cur[okx] = _step(torch, C[y][okx], prev[xpo], p1,
                                     _penalty2(torch, p1, p2, edge, g[y][okx], g[y - sgn][xpo]))
                S[y] += cur
                prev = cur
    S += St.permute(1, 0, 2)
    return to_numpy(S & 0xFFFF).astype(np.uint16)
