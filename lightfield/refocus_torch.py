"""Refocusing on a torch device: shift-and-add and Fourier slice, the numpy methods ported.

The same two methods as :mod:`lightfield.refocus` (shift-and-add, Ng 2005
eq. 5.9) and :mod:`lightfield.ng2005` (Fourier slice photography, eqs.
5.10-5.11), run through torch on the device :func:`lumigraph.capture.device.resolve_device`
gives (``"cuda"``, or ``"torch-cpu"`` to check the port without a GPU). Same
grid, kernels, borders and normalisation as the numpy code: the results agree
within float32 rounding (``tests/device/test_refocus_torch.py`` states the bound).

**Shift-and-add, batched.** Every view of the light field is shifted at once:
one resampling pass along x, one along y, each a sum over the kernel's taps
of ``index_select`` gathers of whole rows. The tap index of view ``n`` and
output column ``x`` is ``mirror_n(x + floor(dx_n) + first + t)``, the mirror
rule of the numpy code's padding folded into the index (half-sample symmetric,
or the edge where the view's padding would exceed the image), so no padded
copy is made; the weights are the numpy kernels' (:func:`lightfield.refocus._taps`),
the same float32 numbers. A cubic B-spline's prefilter (scipy, float64) runs
once on the host. We do not use ``grid_sample`` here: it offers only bilinear
and a Keys a = -0.75 bicubic, not the Lanczos-3 default nor Keys a = -1/2.

**Fourier slice.** The padded, pre-filtered 4-D spectrum is built as in
:func:`lightfield.ng2005.prepare` (``torch.fft.rfft2`` of every view, then
the two small angular DFT matrices), held on the device; each slice reads
the same Kaiser-Bessel taps (:func:`lightfield.ng2005._axis_terms`) with
gathers and ends in ``torch.fft.irfft2``.

torch is imported inside the functions (the ``gpu`` extra).

Examples
--------
>>> import numpy as np
>>> from lumigraph.lightfield.field import LightField
>>> from lumigraph.lightfield.refocus import shift_and_add
>>> lf = LightField(np.random.default_rng(0).random((3, 3, 10, 12, 1)).astype(np.float32))
>>> a = shift_and_add_stack_torch(lf, [0.4], device="torch-cpu")[0]
>>> float(np.abs(a - shift_and_add(lf, 0.4)).max()) < 1e-5
True
"""

from __future__ import annotations

import math

import numpy as np

from lumigraph.capture.device import resolve_device, to_numpy, to_torch
from lumigraph.lightfield.field import LightField


def _axis_plan(shifts, n: int, pads, small: int, kernel: str):
    """For one axis of every view: the integer shifts ``(N,)``, whether each
    view's padding is the edge rule ``(N,)`` and the float32 tap weights
    ``(T, N)``; :func:`_axis_index` turns the first two into gather indices.

    The numpy code pads each view by its own ``pad`` (half-sample symmetric,
    or the edge where ``pad >= small``, the view's smaller side) and reads
    taps at ``x + floor(d) + first + t``; here that padding is folded into the
    index: the position is reflected (or clamped) instead.
    """
    from lumigraph.lightfield.refocus import _taps

    shifts = np.asarray(shifts, np.float64)
    pads = np.asarray(pads)
    first, w_half = _taps(kernel, 0.5)
    taps = len(w_half)
    base = np.floor(shifts)
    frac = shifts - base
    wts = np.zeros((taps, len(shifts)), np.float32)
    # the weights depend on the fraction only: one evaluation per distinct one
    for f in np.unique(frac):
        sel = frac == f
        if f < 1e-9 and kernel != "bspline3":
            w = np.zeros(taps)
            w[-first] = 1.0     # the numpy code copies an integer shift: one tap of 1
        else:
            _, w = _taps(kernel, float(f))
        wts[:, sel] = np.array([np.float32(x) for x in w], np.float32)[:, None]
    edge = np.asarray(pads) >= small
    return base.astype(np.int64), edge, wts


def _axis_index(base, edge, n: int, taps: int, first: int, dev):
    """The gather indices ``(T, N * n)`` of :func:`_axis_plan`'s view shifts,
    built on the device (on the host this index arithmetic alone took longer
    than a GPU refocus)."""
    import torch

    b = torch.from_numpy(base).to(dev)
    e = torch.from_numpy(edge).to(dev)
    nv = b.shape[0]
    p = (torch.arange(n, device=dev)[None, None, :] + b[None, :, None]
         + first + torch.arange(taps, device=dev)[:, None, None])       # (T, N, n)
    mirrored = torch.where(p < 0, -p - 1, torch.where(p >= n, 2 * n - 1 - p, p))
    idx = torch.where(e[None, :, None], p.clamp(0, n - 1), mirrored)
    idx = idx + (torch.arange(nv, device=dev) * n)[None, :, None]
    return idx.reshape(taps, -1)


def shift_and_add_stack_torch(lf: LightField, slopes, *, kernel: str = "lanczos3",
                              device="cuda") -> np.ndarray:
    """:func:`lightfield.refocus.shift_and_add` at each slope on a torch device:
    ``(N, H, W, C)`` float32 (numpy, on the host).

    Parameters
    ----------
    lf : LightField
        Views (U, V, H, W, C) float32 linear.
    slopes : sequence of float
        px per view step.
    kernel : {"linear", "cubic", "lanczos3", "bspline3"}
        As :func:`lightfield.refocus.shift_and_add`.
    device : str or Device
        ``"cuda"``, ``"torch-cpu"`` (or ``"auto"``; ``"cpu"`` is refused here:
        the numpy path is :func:`lightfield.refocus.shift_and_add_stack`).
    """
    import torch

    from lumigraph.lightfield.refocus import KERNELS, _taps, spline_coefficients

    if kernel not in KERNELS:
        raise ValueError(f"kernel: expected one of {', '.join(KERNELS)}, got {kernel!r}")
    dev = resolve_device(device)
    if not dev.uses_torch:
        raise ValueError("device: the torch path needs 'cuda' or 'torch-cpu'")
    u, v = lf.grid
    uc, vc = lf.center
    _, _, h, w, c = lf.data.shape
    n = u * v
    data = lf.data.reshape(n, h, w, c)
    if kernel == "bspline3":
        data = np.stack([spline_coefficients(x) for x in data])
    views = to_torch(data, dev)                                    # (N, H, W, C)
    # x pass reads rows of the (N W, H C) layout: one column of a view a row
    by_col = views.permute(0, 2, 1, 3).contiguous().reshape(n * w, h * c)
    small = min(h, w)
    first = _taps(kernel, 0.5)[0]
    out = np.empty((len(slopes), h, w, c), np.float32)
    ii, jj = np.divmod(np.arange(n), v)
    for k, s in enumerate(slopes):
        dx = -float(s) * (jj - vc)
        dy = -float(s) * (ii - uc)
        pads = [int(math.ceil(max(abs(a), abs(b)))) + 4 for a, b in zip(dx, dy, strict=True)]
        bx, ex, wx = _axis_plan(dx, w, pads, small, kernel)
        by, ey, wy = _axis_plan(dy, h, pads, small, kernel)
        ix_t = _axis_index(bx, ex, w, len(wx), first, dev.torch)
        iy_t = _axis_index(by, ey, h, len(wy), first, dev.torch)
        wx_t = torch.from_numpy(wx).to(dev.torch)[:, :, None, None]      # (T, N, 1, 1)
        wy_t = torch.from_numpy(wy).to(dev.torch)[:, :, None, None]
        acc = None
        for t in range(len(wx)):              # taps in the numpy code's order
            term = by_col.index_select(0, ix_t[t]).view(n, w, h * c) * wx_t[t]
            acc = term if acc is None else acc.add_(term)
        by_row = acc.reshape(n, w, h, c).permute(0, 2, 1, 3).contiguous().reshape(n * h, w * c)
        acc = None
        for t in range(len(wy)):
            term = by_row.index_select(0, iy_t[t]).view(n, h, w * c) * wy_t[t]
            acc = term if acc is None else acc.add_(term)
        img = acc.reshape(n, h, w, c).sum(0) / np.float32(n)
        out[k] = to_numpy(img)
    return out


# ------------------------------------------------------------- Fourier slice
class _Spectrum:
    """The 4-D spectrum on the device and the geometry of
    :class:`lightfield.ng2005.FourierLightField`."""

    def __init__(self, spectrum, grid, size, pad, shape_p, kernel_width, beta, max_slope):
        self.spectrum, self.grid, self.size, self.pad = spectrum, grid, size, pad
        self.shape_p, self.kernel_width, self.beta = shape_p, kernel_width, beta
        self.max_slope = max_slope


def prepare_torch(lf: LightField, *, max_slope: float = 1.5, oversample: float = 1.5,
                  kernel_width: int = 5, device="cuda") -> _Spectrum:
    """:func:`lightfield.ng2005.prepare` on a torch device (all channels at once)."""
    import torch

    from lumigraph.lightfield.ng2005 import _geometry, _kb_hat

    dev = resolve_device(device)
    pad, hp, wp, nu, nv = _geometry(lf, max_slope, oversample, kernel_width)
    u, v = lf.grid
    _, _, h, w, c = lf.data.shape
    osr = min(nu / u, nv / v)
    beta = math.pi * math.sqrt(max((kernel_width / osr) ** 2 * (osr - 0.5) ** 2 - 0.8, 1.0))
    pu, pv = np.arange(u) - (u - 1) / 2, np.arange(v) - (v - 1) / 2
    weight = (1.0 / (_kb_hat(pu / nu, kernel_width, beta)[:, None]
                     * _kb_hat(pv / nv, kernel_width, beta)[None, :])).astype(np.float32)
    mode = "symmetric" if pad < min(h, w) else "edge"
    iy = torch.from_numpy(np.pad(np.arange(h), (pad, hp - h - pad), mode=mode)).to(dev.torch)
    ix = torch.from_numpy(np.pad(np.arange(w), (pad, wp - w - pad), mode=mode)).to(dev.torch)
    x = to_torch(lf.data, dev) * to_torch(weight, dev)[:, :, None, None, None]
    x = x.index_select(2, iy).index_select(3, ix)                 # (U, V, Hp, Wp, C)
    s = torch.fft.rfft2(x, dim=(2, 3))                            # (U, V, Hp, Wr, C)
    del x
    wr = wp // 2 + 1
    s = s.permute(2, 0, 1, 3, 4).reshape(hp, u, v * wr * c)
    fu = np.exp(-2j * np.pi * np.outer(np.arange(nu) - nu // 2, pu) / nu).astype(np.complex64)
    fv = np.exp(-2j * np.pi * np.outer(np.arange(nv) - nv // 2, pv) / nv).astype(np.complex64)
    half = torch.matmul(to_torch(fu, dev, dtype=torch.complex64), s)   # (Hp, Nu, V Wr C)
    del s
    half = half.reshape(hp * nu, v, wr * c)
    spec = torch.matmul(to_torch(fv, dev, dtype=torch.complex64), half)  # (Hp Nu, Nv, Wr C)
    spec = spec.reshape(hp, nu, nv, wr, c)
    return _Spectrum(spec, (u, v), (w, h), (pad, pad), (hp, wp), kernel_width, float(beta),
                     float(abs(max_slope)))


def refocus_torch(spec: _Spectrum, slope: float, *, interpolation: str = "lanczos3"):
    """:func:`lightfield.ng2005.refocus` from a spectrum of :func:`prepare_torch`:
    a torch tensor ``(H, W, C)`` float32 on the spectrum's device."""
    import torch

    from lumigraph.lightfield.ng2005 import INTERPOLATIONS, _axis_terms

    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation: expected one of {', '.join(INTERPOLATIONS)}, "
                         f"got {interpolation!r}")
    if abs(slope) > spec.max_slope + 1e-9:
        raise ValueError(f"slope: {slope} exceeds the max_slope {spec.max_slope} the spectrum "
                         "was padded for")
    sp = spec.spectrum
    dev = sp.device
    hp, nu, nv, wr, c = sp.shape
    hp_, wp = spec.shape_p
    u, v = spec.grid
    k = spec.kernel_width
    ky = (np.arange(hp) - hp // 2) / hp
    kx = np.fft.rfftfreq(wp)
    # u: acc[y, n, x] = sum_a wu[y, a] S[y, i(y, a), n, x]  (rows in centred order)
    acc = torch.zeros((hp, nv, wr, c), dtype=sp.dtype, device=dev)
    for lo, hi, idx, wt in _axis_terms(ky, slope, nu, u, k, spec.beta, interpolation):
        rows = torch.from_numpy((np.arange(lo, hi) - hp // 2) % hp).to(dev)
        iu = torch.from_numpy(idx).to(dev)
        wu = torch.from_numpy(wt.astype(np.float32)).to(dev)
        for a in range(k):
            acc.index_add_(0, rows, sp[rows, iu[:, a]] * wu[:, a, None, None, None])
    # v: out[y, x] = sum_b wv[x, b] acc[y, j(x, b), x]
    out = torch.zeros((hp, wr, c), dtype=sp.dtype, device=dev)
    for lo, hi, idx, wt in _axis_terms(kx, slope, nv, v, k, spec.beta, interpolation):
        cols = torch.arange(lo, hi, device=dev)
        iv = torch.from_numpy(idx).to(dev)
        wv = torch.from_numpy(wt.astype(np.float32)).to(dev)
        for b in range(k):
            out[:, lo:hi] += acc[:, iv[:, b], cols] * wv[None, :, b, None]
    img = torch.fft.irfft2(out, s=(hp_, wp), dim=(0, 1))
    w, h = spec.size
    py, px = spec.pad
    return img[py:py + h, px:px + w] / np.float32(u * v)


def refocus_stack_torch(lf: LightField, slopes, *, max_slope: float | None = None,
                        oversample: float = 1.5, kernel_width: int = 5,
                        interpolation: str = "lanczos3", device="cuda") -> np.ndarray:
    """:func:`lightfield.ng2005.refocus_stack` on a torch device: one 4-D FFT
    for all slopes, ``(N, H, W, C)`` float32 (numpy, on the host)."""
    from lumigraph.lightfield.ng2005 import INTERPOLATIONS

    slopes = [float(s) for s in slopes]
    if not slopes:
        raise ValueError("slopes: expected at least one slope, got none")
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation: expected one of {', '.join(INTERPOLATIONS)}, "
                         f"got {interpolation!r}")
    dev = resolve_device(device)
    if not dev.uses_torch:
        raise ValueError("device: the torch path needs 'cuda' or 'torch-cpu'")
    top = max(abs(s) for s in slopes) if max_slope is None else max_slope
    if max(abs(s) for s in slopes) > top + 1e-9:
        raise ValueError(f"slope: {max(slopes, key=abs)} exceeds max_slope {top}")
    spec = prepare_torch(lf, max_slope=top, oversample=oversample, kernel_width=kernel_width,
                         device=dev)
    _, _, h, w, c = lf.data.shape
    out = np.empty((len(slopes), h, w, c), np.float32)
    for n, s in enumerate(slopes):
        out[n] = to_numpy(refocus_torch(spec, s, interpolation=interpolation))
    return out
