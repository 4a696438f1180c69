"""The torch path of SSD block matching's scan: the cost volume, its box
aggregation and the winner-take-all bookkeeping of
:func:`lumigraph.stereo.block_matching._scan_numpy`, for all disparities of a
band of rows at once, on torch's CPU device or CUDA.

The cost of left pixel ``(x, y)`` at disparity ``d`` is the window sum of
``Σ_c (L_c(x, y) − R_c(x − d, y))²`` (reference ch. 5, eq. 5.1; Scharstein and
Szeliski, IJCV 47, 2002, doi:10.1023/A:1014573219977), encoded as
``(cost << nb) | d`` in int32 exactly as the numpy path encodes it
(:class:`lumigraph.stereo.block_matching._Costs`): integer images are summed
exactly in int64, as the C kernel ``stereo/_ssd.c`` sums them, float images are squared and summed as OpenCV does (float64 window sums
rounded to float32, float32 scaling, truncation), with OpenCV's
``BORDER_REFLECT`` at the band's edges. The decision (sub-pixel parabola,
uniqueness, left–right check, texture test) stays on numpy
(:func:`lumigraph.stereo.block_matching._decide`): it reads five ``(H, W)``
arrays and is cheap.

Semi-global matching's aggregation has its own port
(:mod:`lumigraph.stereo.hirschmuller2008_torch`).

Examples
--------
>>> import numpy as np
>>> from lumigraph.stereo.block_matching import match
>>> rng = np.random.default_rng(0)
>>> right = rng.integers(0, 255, (30, 60)).astype(np.uint8)
>>> left = np.roll(right, 4, axis=1)
>>> a = match(left, right, max_disp=8, window=5)
>>> b = match(left, right, max_disp=8, window=5, device="torch-cpu")
>>> bool(np.array_equal(a.disparity, b.disparity, equal_nan=True)), b.info["engine"]
(True, 'torch-cpu')
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.device import to_numpy, torch_modules

INT_MAX = np.iinfo(np.int32).max
# bytes of one band's working set on a GPU (the volume, its squares and sums)
CUDA_BAND_BYTES = 1 << 30
CPU_BAND_ROWS = 64  # as the numpy path: a band stays in the CPU's cache


def _reflect(n: int, r: int, device):
    """Indices of ``range(-r, n + r)`` under OpenCV's BORDER_REFLECT
    (``fedcba|abcdef|fedcba``), for any ``r``."""
    torch, _ = torch_modules()
    i = np.arange(-r, n + r) % (2 * n)
    i = np.where(i >= n, 2 * n - 1 - i, i)
    return torch.as_tensor(i, dtype=torch.int64, device=device)


def _box_sum(x, k: int):
    """Window sums (unnormalised) of side ``k`` over the last two axes, with
    BORDER_REFLECT; ``x`` int64 or float64, the result in the same dtype
    (exact for integers; float64 roundings only)."""
    torch, _ = torch_modules()
    r = k // 2
    h, w = x.shape[-2:]
    xp = x.index_select(-2, _reflect(h, r, x.device)).index_select(-1, _reflect(w, r, x.device))
    zero_w = torch.zeros((*xp.shape[:-1], 1), dtype=x.dtype, device=x.device)
    c = torch.cat([zero_w, xp.cumsum(-1)], -1)
    s = c[..., k:] - c[..., :-k]
    zero_h = torch.zeros((*s.shape[:-2], 1, s.shape[-1]), dtype=x.dtype, device=x.device)
    c = torch.cat([zero_h, s.cumsum(-2)], -2)
    return c[..., k:, :] - c[..., :-k, :]


def _costs_volume(L, Rv, *, costs, cwin):
    """The ``(D, h, wp)`` int32 costs (not yet encoded) of one band:
    ``L`` ``(C, h, wp)``, ``Rv`` ``(C, D, h, wp)`` the right image's view
    at every disparity, ``cwin`` ``(h, wp)`` the window index per pixel."""
    torch, _ = torch_modules()
    wins = costs.wins
    if costs.integer:
        diff = (L[:, None].to(torch.int32) - Rv.to(torch.int32)).abs()
        sq = (diff * diff).sum(0).to(torch.int64)  # (D, h, wp), exact
        # exact int64 window sums, as the C kernel's (OpenCV's int32 box
        # filter of the numpy path wraps past 2^31: windows of 47+ px of
        # quarter-code luma can get there)
        if len(wins) == 1:
            v = _box_sum(sq, wins[0])
            return (v >> costs.rshift if costs.rshift else v).to(torch.int32)
        out = None
        for k, win in enumerate(wins):
            mk = _box_sum(sq, win).to(torch.float64) * costs.scale[k]
            mk = mk.to(torch.int32)  # truncation, as numpy's astype and the C kernel
            out = mk if out is None else torch.where(cwin == k, mk, out)
        return out
    diff = (L[:, None] - Rv).abs()  # float32, one rounding as cv2.absdiff
    nch = diff.shape[0]
    if len(wins) == 1:
        n = wins[0] ** 2
        if nch == 1:  # cv2.sqrBoxFilter squares in float64
            d64 = diff[0].to(torch.float64)
            s = _box_sum(d64 * d64, wins[0]).to(torch.float32)
        else:  # float32 squares summed over the planes, then a float64 box sum
            sq = diff[0] * diff[0]
            for c in range(1, nch):
                sq = sq + diff[c] * diff[c]
            s = _box_sum(sq.to(torch.float64), wins[0]).to(torch.float32)
        return (s * np.float32(costs.unit / n)).to(torch.int32)
    sq = diff[0] * diff[0]
    for c in range(1, nch):
        sq = sq + diff[c] * diff[c]
    sq64 = sq.to(torch.float64)
    out = None
    for k, win in enumerate(wins):
        mk = (_box_sum(sq64, win) * (1.0 / win ** 2)).to(torch.float32)  # normalised boxFilter
        out = mk if out is None else torch.where(cwin == k, mk, out)
    return (out * np.float32(costs.unit)).to(torch.int32)


def _scan_band(Lp, Rp, y0, y1, *, D, costs, cwin_full):
    """Rows ``y0:y1`` (tensors ``Lp`` ``(C, H, W + D)``, ``Rp``
    ``(C, H, W + 2D − 1)``): best, em, ep, second, best_r as int32 tensors
    ``(y1 − y0, W)``, the numpy path's encoding."""
    torch, _ = torch_modules()
    margin = max(costs.wins) // 2
    H = Lp.shape[1]
    a0, a1 = max(0, y0 - margin), min(H, y1 + margin)
    L, R = Lp[:, a0:a1], Rp[:, a0:a1]
    nch, h, wp = L.shape
    w = wp - D
    # view j of the unfolded right image starts at column j = D - 1 - d
    Rv = R.unfold(2, wp, 1).flip(2).permute(0, 2, 1, 3)  # (C, D, h, wp)
    cwin = None
    if cwin_full is not None:
        cwin = torch.nn.functional.pad(cwin_full[a0:a1], (0, D))
    vol = _costs_volume(L, Rv, costs=costs, cwin=cwin)
    nb = costs.nb
    d = torch.arange(D, dtype=torch.int32, device=vol.device)[:, None, None]
    vol = (vol << nb) | d
    x = torch.arange(wp, device=vol.device)
    vol = torch.where((x[None, None, :] < d) | (x[None, None, :] >= w), INT_MAX, vol)
    best = vol.amin(0)
    # the right pixel x - d sees the cost of left pixel x at disparity d
    xi = x[None, :] + torch.arange(D, device=vol.device)[:, None]  # (D, wp)
    shifted = vol.gather(2, xi.clamp(max=wp - 1)[:, None, :].expand(D, h, wp))
    best_r = torch.where((xi < wp)[:, None, :], shifted, INT_MAX).amin(0)
    best = best[:, :w]
    dbest = (best & ((1 << nb) - 1)).to(torch.int64)
    em = vol.gather(0, (dbest - 1).clamp(min=0)[None]).squeeze(0)
    ep = vol.gather(0, (dbest + 1).clamp(max=D - 1)[None]).squeeze(0)
    v = vol[:, :, :w].clone()
    for off in (-1, 0, 1):
        v.scatter_(0, (dbest + off).clamp(0, D - 1)[None], INT_MAX)
    second = v.amin(0)
    s = slice(y0 - a0, y1 - a0)
    return best[s], em[s], ep[s], second[s], best_r[s, :w]


def scan(Lp: np.ndarray, Rp: np.ndarray, *, D: int, costs, device) -> list[np.ndarray]:
    """The five ``(H, W)`` int32 arrays :func:`block_matching._decide` reads,
    computed on ``device`` (a resolved torch :class:`Device`); equal to
    :func:`block_matching._scan_numpy_bands`' (see the module docstring and
    ``tests/device/test_stereo_torch.py`` for where float inputs may differ)."""
    torch, _ = torch_modules()
    dt = torch.int32 if costs.integer else torch.float32
    L = torch.from_numpy(np.ascontiguousarray(Lp).astype(np.int32 if costs.integer else np.float32,
                                                         copy=False)).to(device.torch).to(dt)
    R = torch.from_numpy(np.ascontiguousarray(Rp).astype(np.int32 if costs.integer else np.float32,
                                                         copy=False)).to(device.torch).to(dt)
    cwin = None
    if costs.cwin is not None:
        cwin = torch.from_numpy(costs.cwin.astype(np.int64)).to(device.torch)
    nch, H, wp = L.shape
    if device.torch == "cuda":
        per_row = D * wp * (nch * 4 + 8 * 4)  # the volume, the squares and the sums, bytes
        rows = max(8, int(CUDA_BAND_BYTES // max(per_row, 1)))
    else:
        rows = CPU_BAND_ROWS
    n_bands = max(1, round(H / rows))
    edges = np.linspace(0, H, n_bands + 1).astype(int)
    parts = [_scan_band(L, R, int(edges[i]), int(edges[i + 1]), D=D, costs=costs, cwin_full=cwin)
             for i in range(n_bands)]
    return [to_numpy(torch.cat([p[j] for p in parts])) for j in range(5)]
