"""The radiance merge of :func:`hdr.merge.merge` on a torch device.

Same weights (variance-optimal or hat), clip margin, deghosting, bounds and
flags as the numpy merge: the per-exposure look-up tables (``w`` and
``w X̂``, per channel and code) are built by the same numpy code on the host
(a few thousand numbers), the per-pixel work (a gather per exposure and two
float32 sums, in exposure order as the numpy code adds them) runs on the
device, and the few pixel-channels no exposure measured are filled on the
host by the numpy code's own :func:`hdr.merge._fill_bounds`. So the radiance
agrees with ``device="cpu"`` within float32 rounding and the flags are the
same (``tests/device/test_hdr_torch.py``).

torch is imported inside the functions (the ``gpu`` extra).

Examples
--------
>>> import numpy as np
>>> from lumigraph.hdr.response import ResponseCurve
>>> from lumigraph.hdr.merge import merge
>>> x = np.array([[[20 / 255], [100 / 255], [5.0]]])
>>> t = [0.5, 2.0]
>>> z = np.stack([np.clip(np.round(x * ti * 255), 0, 255) for ti in t]).astype(np.uint8)
>>> a = merge_torch(z, t, ResponseCurve.linear(8, 1), device="torch-cpu")
>>> b = merge(z, t, ResponseCurve.linear(8, 1))
>>> bool(np.allclose(a.radiance, b.radiance, rtol=1e-6)), a.flags.tolist() == b.flags.tolist()
(True, True)
"""

from __future__ import annotations

import math

import numpy as np

from lumigraph.capture.device import resolve_device, to_numpy
from lumigraph.capture.errors import InputError
from lumigraph.hdr.merge import (
    BLACK,
    CLIPPED,
    GHOST,
    RadianceMap,
    _fill_bounds,
    check_noise,
    variance_weight_table,
)
from lumigraph.hdr.response import ResponseCurve
from lumigraph.hdr.samples import check_stack, hat_weight


def merge_torch(images: np.ndarray, exposure_times_s, response: ResponseCurve, *,
                weights: str = "variance", full_well_e: float | None = None,
                read_noise_e: float | None = None, clip_margin: float = 0.02,
                deghost: bool = False, deghost_sigma: float = 4.0,
                reference: int | None = None, device="cuda") -> RadianceMap:
    """:func:`hdr.merge.merge` on a torch device (same parameters, less the
    CPU's ``block_rows``/``workers``); returns the same :class:`RadianceMap`
    (numpy arrays on the host).

    ``images`` may be a numpy array or a torch tensor already on the device
    (a GPU pipeline then skips the upload).
    """
    import torch

    dev = resolve_device(device)
    if not dev.uses_torch:
        raise ValueError("device: the torch path needs 'cuda' or 'torch-cpu'")
    on_device = hasattr(images, "detach")
    z_host = to_numpy(images) if on_device else images
    z, t, bd = check_stack(z_host, exposure_times_s, bit_depth=response.bit_depth)
    full_well_e, read_noise_e = check_noise(weights, full_well_e, read_noise_e)
    p, h, w, c = z.shape
    if response.channels not in (1, c):
        raise InputError("response", f"curve has {response.channels} channels, images have {c}")
    # The tables exactly as hdr.merge.merge builds them (float64, then float32).
    x_tab = response.exposure_table()
    if response.channels == 1:
        x_tab = np.repeat(x_tab, c, axis=0)
    zmax = response.code_max
    codes = np.arange(zmax + 1)
    if weights == "variance":
        w_tab = variance_weight_table(x_tab, full_well_e=full_well_e, read_noise_e=read_noise_e,
                                      clip_margin=clip_margin)
        var_tab = np.where(w_tab > 0, 1.0 / np.maximum(w_tab, 1e-300), np.inf)
    else:
        w_tab = np.tile(hat_weight(codes, bd), (c, 1))
        w_tab[:, (codes < clip_margin * zmax) | (codes > (1 - clip_margin) * zmax)] = 0.0
        var_tab = None
    wl = np.empty((p, c, zmax + 1), np.float32)
    wxl = np.empty((p, c, zmax + 1), np.float32)
    xl = np.empty((p, c, zmax + 1), np.float32)
    for j in range(p):
        wj = w_tab * (t[j] ** 2 if weights == "variance" else 1.0)
        xl[j] = x_tab / t[j]
        wl[j] = wj
        wxl[j] = wj * x_tab / t[j]
    lo_code = int(math.ceil(clip_margin * zmax))
    hi_code = int(math.floor((1 - clip_margin) * zmax))
    j_long = int(np.argmax(t))
    bound_lo = (x_tab[:, max(lo_code, 0)] / t[j_long]).astype(np.float32)
    if deghost:
        if reference is None:
            good = [np.count_nonzero((z[j] > lo_code) & (z[j] < hi_code)) for j in range(p)]
            reference = int(np.argmax(good))
        if not 0 <= reference < p:
            raise ValueError(f"reference: expected 0..{p - 1}, got {reference}")
        if var_tab is None:
            var_tab = np.where(w_tab > 0, 1.0, np.inf)
        vl = np.stack([(var_tab / (t[j] ** 2 if weights == "variance" else 1.0))
                       .astype(np.float32) for j in range(p)])

    d = dev.torch
    n_codes = zmax + 1
    # channel-interleaved tables: index = code + channel * 2**bit_depth
    ch_off = torch.arange(c, device=d, dtype=torch.int64) * n_codes
    wl_t = torch.from_numpy(wl.reshape(p, -1)).to(d)
    wxl_t = torch.from_numpy(wxl.reshape(p, -1)).to(d)
    zt = images if on_device else torch.from_numpy(np.ascontiguousarray(z))
    zt = zt.to(d)

    def index(j):
        return zt[j].to(torch.int64) + ch_off

    num = torch.zeros((h, w, c), dtype=torch.float32, device=d)
    den = torch.zeros((h, w, c), dtype=torch.float32, device=d)
    ghost = None
    if not deghost:
        for j in range(p):
            ij = index(j)
            num += wxl_t[j][ij]
            den += wl_t[j][ij]
    else:
        xl_t = torch.from_numpy(xl.reshape(p, -1)).to(d)
        vl_t = torch.from_numpy(vl.reshape(p, -1)).to(d)
        ir = index(reference)
        xr, vr = xl_t[reference][ir], vl_t[reference][ir]
        ref_ok = torch.isfinite(vr)
        ghost = torch.zeros((h, w, c), dtype=torch.bool, device=d)
        s2 = np.float32(deghost_sigma ** 2)
        for j in range(p):
            ij = index(j)
            wj = wl_t[j][ij]
            wx = wxl_t[j][ij]
            if j != reference:
                d2 = (xl_t[j][ij] - xr) ** 2
                bad = ref_ok & (wj > 0) & (d2 > s2 * (vl_t[j][ij] + vr))
                wj = torch.where(bad, 0.0, wj)
                wx = torch.where(bad, 0.0, wx)
                ghost |= bad
            num += wx
            den += wj
    out_t = num / torch.clamp(den, min=np.float32(1e-30))
    out = to_numpy(out_t).astype(np.float32, copy=False)
    flags = np.zeros((h, w, c), np.uint8)
    if ghost is not None:
        flags[to_numpy(ghost)] |= GHOST
    no_weight = den <= 0
    if bool(no_weight.any()):          # rare: fetch the mask only then
        empty = to_numpy(no_weight)
        # the numpy fill, once over the whole image: its cost is per unmeasured pixel
        _fill_bounds(out, empty, z, t, x_tab, hi_code, bound_lo, flags)
    warnings = []
    n_clip = int(np.count_nonzero(flags & CLIPPED))
    n_black = int(np.count_nonzero(flags & BLACK))
    if n_clip:
        warnings.append(f"{n_clip} pixel-channels are clipped in every exposure: set to the lower "
                        "bound from the shortest saturated exposure and flagged (add a shorter exposure)")
    if n_black:
        warnings.append(f"{n_black} pixel-channels are black in every exposure: set to the upper "
                        "bound from the longest exposure, one grey per pixel, and flagged (add a "
                        "longer exposure)")
    stats = {"clipped_everywhere": n_clip, "black_everywhere": n_black,
             "black_everywhere_pixels": int(np.count_nonzero((flags & BLACK).any(axis=2))),
             "clipped_everywhere_pixels": int(np.count_nonzero((flags & CLIPPED).any(axis=2))),
             "fill": "one colour per pixel: min/max(bound, measured channels' mean), else one "
                     "grey within every channel's bound",
             "ghost": int(np.count_nonzero(flags & GHOST)) if deghost else 0,
             "reference": reference, "device": dev.name}
    return RadianceMap(out, flags, tuple(float(x) for x in t), weights, tuple(warnings), stats)
