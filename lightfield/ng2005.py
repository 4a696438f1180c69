"""Fourier slice digital refocusing (Ng 2005), reference eqs. 5.10-5.11.

R. Ng, "Fourier Slice Photography", ACM SIGGRAPH 2005, doi:10.1145/1073204.1073256.

Refocusing is an integral projection (eq. 5.10) of the light field after the
shear of eq. 5.11; by the Fourier slice photography theorem its 2-D spectrum is
a 2-D slice of the light field's 4-D spectrum. We compute the 4-D FFT once;
each refocus is then a slice plus one inverse 2-D FFT. On the centre view's
grid (no 1/alpha magnification, as in :mod:`lightfield.refocus`) the slice at
spatial frequency ``(ky, kx)`` lies at angular frequency ``(s ky, s kx)``
(cycles per view step) — on the grid in ``(ky, kx)``, off it in ``(fu, fv)``:

    E_s^(ky, kx) = 1/(UV) sum_{u,v} L^(u, v, ky, kx) exp(-2 pi i s (ky (u - uc) + kx (v - vc))).

The angular axes are zero-padded by ``oversample`` (1.5) and the slice interpolated
with a Kaiser-Bessel kernel of ``kernel_width`` (4) taps (relative error < 1e-3); the views are first
divided by the kernel's Fourier transform (Ng's pre-multiplication /
roll-off correction), so the only residual is the kernel's aliasing, far below
the shift-and-add interpolation error. The spatial axes are mirror-padded by
the largest shift so the FFT's wrap-around never reaches the image (the same
border rule as shift-and-add). Memory: complex64, real FFT along x:
``ceil(oU) ceil(oV) Hp (Wp/2 + 1) C`` x 8 bytes.

Examples
--------
>>> import numpy as np
>>> from lumigraph.lightfield.field import LightField
>>> from lumigraph.lightfield.refocus import shift_and_add
>>> rng = np.random.default_rng(1)
>>> lf = LightField(rng.random((3, 3, 16, 20, 1)).astype(np.float32))
>>> spec = prepare(lf, max_slope=1.0)
>>> a, b = refocus(spec, 0.0), lf.data.mean((0, 1))
>>> float(np.abs(a - b).max()) < 1e-3      # slope 0: the plain average (kernel aliasing ~5e-4)
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lumigraph.lightfield.field import LightField

# scipy.fft threads for the 2-D FFTs (-1: all cores).
WORKERS = -1


def _kb(t: np.ndarray, width: int, beta: float) -> np.ndarray:
    x = 1.0 - (2.0 * t / width) ** 2
    return np.where(x >= 0, np.i0(beta * np.sqrt(np.maximum(x, 0))) / np.i0(beta), 0.0)


def _kb_hat(nu: np.ndarray, width: int, beta: float) -> np.ndarray:
    """Fourier transform of the Kaiser-Bessel kernel at ``nu`` (cycles/bin), by quadrature."""
    t = np.linspace(-width / 2, width / 2, 4001)
    k = _kb(t, width, beta)
    wq = np.full(t.shape, t[1] - t[0])
    wq[0] = wq[-1] = wq[0] / 2
    return (k[None, :] * np.cos(2 * np.pi * np.asarray(nu)[:, None] * t[None, :])) @ wq


@dataclass(frozen=True)
class FourierLightField:
    """The padded, pre-filtered 4-D spectrum of a light field, ready to slice.

    Attributes
    ----------
    spectrum : ndarray, (Nu, Nv, Hp, Wp//2 + 1, C) complex64
        FFT over (y, x) (real along x) and over the zero-padded angular axes;
        the angular axes in centred order (index m is frequency m - N//2).
    grid : (U, V); size : (W, H) of the views; pad : (py, px) spatial padding.
    shape_p : (Hp, Wp) padded spatial size.
    kernel_width : int; beta : float (Kaiser-Bessel parameters).
    delta : (du, dv) grid-centre offset not representable on the integer grid.
    """

    spectrum: np.ndarray
    grid: tuple[int, int]
    size: tuple[int, int]
    pad: tuple[int, int]
    shape_p: tuple[int, int]
    kernel_width: int
    beta: float
    delta: tuple[float, float]
    max_slope: float

    @property
    def nbytes(self) -> int:
        return int(self.spectrum.nbytes)


def prepare(lf: LightField, *, max_slope: float = 1.5, oversample: float = 1.5,
            kernel_width: int = 4) -> FourierLightField:
    """The one-time 4-D FFT (after padding and the kernel pre-filter).

    Parameters
    ----------
    lf : LightField
    max_slope : float
        Largest |slope| that will be requested (sets the spatial padding).
    oversample : float
        Angular zero-padding factor (>= 1.25).
    kernel_width : int
        Kaiser-Bessel taps per angular axis (2..8).
    """
    import scipy.fft as sfft

    if not oversample >= 1.25:
        raise ValueError(f"oversample: expected >= 1.25, got {oversample}")
    if not 2 <= kernel_width <= 8:
        raise ValueError(f"kernel_width: expected 2..8, got {kernel_width}")
    u, v = lf.grid
    _, _, h, w, c = lf.data.shape
    reach = abs(max_slope) * max((u - 1) / 2, (v - 1) / 2)
    pad = int(math.ceil(reach)) + 2
    hp, wp = _odd_fast_len(h + 2 * pad), _odd_fast_len(w + 2 * pad)
    py, px = pad, pad
    # Small grids (2 views) need more than 1.5x: the kernel's passband must
    # cover the occupied bins with margin, so at least 4 empty bins per axis.
    nu = max(int(math.ceil(oversample * u)), u + 4)
    nv = max(int(math.ceil(oversample * v)), v + 4)
    # Beatty et al. (2005) choice of beta for a given width and oversampling.
    osr = min(nu / u, nv / v)
    beta = math.pi * math.sqrt(max((kernel_width / osr) ** 2 * (osr - 0.5) ** 2 - 0.8, 1.0))
    cu, cv = u // 2, v // 2
    pu, pv = np.arange(u) - cu, np.arange(v) - cv
    rolloff_u = _kb_hat(pu / nu, kernel_width, beta)
    rolloff_v = _kb_hat(pv / nv, kernel_width, beta)
    weight = (1.0 / (rolloff_u[:, None] * rolloff_v[None, :])).astype(np.float32)

    views = _prefaulted((u, v, hp, wp // 2 + 1, c), np.complex64)
    for i in range(u):
        for j in range(v):
            padded = np.pad(lf.data[i, j], ((py, hp - h - py), (px, wp - w - px), (0, 0)),
                            mode="symmetric" if pad < min(h, w) else "edge")
            views[i, j] = sfft.rfft2(padded * weight[i, j], axes=(0, 1), workers=WORKERS)
    # The angular transform of the zero-padded grid has only U x V non-zero
    # inputs: two small DFT matrices (BLAS) instead of an FFT over mostly
    # zeros, and the result comes out with the angular axes outermost, the
    # layout whose slices stream through memory (see refocus()).
    # Angular frequencies stored centred (row m is frequency m - n//2): the
    # taps of the low spatial frequencies, where slices cross zero angular
    # frequency, then never wrap around the periodic axis (see refocus()).
    fu = np.exp(-2j * np.pi * np.outer(np.arange(nu) - nu // 2, pu) / nu).astype(np.complex64)
    fv = np.exp(-2j * np.pi * np.outer(np.arange(nv) - nv // 2, pv) / nv).astype(np.complex64)
    rest = hp * (wp // 2 + 1) * c
    views = views.reshape(u, v, rest)
    spec = _prefaulted((nu, nv, rest), np.complex64)
    # In column chunks through reused buffers: a full-size intermediate
    # would be another ~0.4 GB of fresh pages, whose faults cost more than
    # the arithmetic.
    ck = min(rest, 1 << 14)
    for c0 in range(0, rest, ck):
        n = min(ck, rest - c0)
        blk = np.ascontiguousarray(views[:, :, c0:c0 + n]).reshape(u, v * n)
        half = (fu @ blk).reshape(nu, v, n)
        spec[:, :, c0:c0 + n] = fv @ half
    del views
    spec = spec.reshape(nu, nv, hp, wp // 2 + 1, c)
    return FourierLightField(spec, (u, v), (w, h), (py, px),
                             (hp, wp), kernel_width, float(beta),
                             ((u - 1) / 2 - cu, (v - 1) / 2 - cv), float(abs(max_slope)))


def _prefaulted(shape: tuple[int, ...], dtype) -> np.ndarray:
    """A zeroed array whose pages are mapped in one call (``MAP_POPULATE``).

    The spectrum is ~0.7 GB for 9x9 views of 512x512x3; on virtual machines
    a first-touch page fault costs ~30 us per 4 KiB page, seconds in all,
    more than the FFTs themselves. Falls back to ``np.zeros`` where the flag
    does not exist.
    """
    import mmap

    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape)) * dtype.itemsize
    flag = getattr(mmap, "MAP_POPULATE", None)
    if flag is None or nbytes < (1 << 25):
        return np.zeros(shape, dtype)
    buf = mmap.mmap(-1, nbytes, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | flag)
    return np.frombuffer(buf, dtype).reshape(shape)


def _odd_fast_len(n: int) -> int:
    """Smallest odd FFT-friendly length >= n. Odd lengths have no Nyquist bin,
    whose phase a fractional shift leaves ambiguous (a +-1 alternating error)."""
    import scipy.fft as sfft

    m = n
    # pocketfft is fast for any 11-smooth length; the 5-smooth odd ones alone
    # are sparse (522 -> 625, +43 % area over 525 = 3 5^2 7).
    while m % 2 == 0 or sfft.next_fast_len(m, real=False) != m:
        m += 1
    return m


def _axis_taps(freq: np.ndarray, slope: float, n: int, width: int, beta: float):
    """Stored-bin indices (centred order, ``(width,)`` per frequency) and weights."""
    mu = slope * freq * n                                  # fractional angular bin
    first = np.floor(mu - width / 2).astype(np.int64) + 1
    idx = first[:, None] + np.arange(width)
    w = _kb(mu[:, None] - idx, width, beta)
    return (idx + n // 2) % n, w


def _runs(first: np.ndarray) -> list[tuple[int, int, int]]:
    """Maximal runs ``(start, stop, value)`` of equal consecutive entries."""
    cut = np.flatnonzero(np.diff(first)) + 1
    starts, stops = np.r_[0, cut], np.r_[cut, len(first)]
    return list(zip(starts.tolist(), stops.tolist(), first[starts].tolist(), strict=True))


def refocus(spec: FourierLightField, slope: float) -> np.ndarray:
    """One refocused photograph from the prepared spectrum: a 2-D slice of the
    4-D spectrum (Fourier slice photography theorem) and an inverse 2-D FFT.

    The slice reads the spectrum at angular bins ``(s ky nu, s kx nv)``: the
    Kaiser-Bessel taps along u depend on ``ky`` only and those along v on
    ``kx`` only, so the slice is separable, and the taps' integer start is
    constant over runs of rows and columns. Over each such block (a few
    dozen per slope) the 4 x 4 taps are one strided view of the spectrum:
    a batched matmul contracts u with one weight row per ``ky``, then v is
    contracted with one weight per ``kx``, as real float32 arithmetic on the
    (re, im) pairs (the weights are real), instead of 16 scattered gathers.

    Returns
    -------
    ndarray, (H, W, C) float32
        Same grid and normalisation as :func:`lightfield.refocus.shift_and_add`.
    """
    import scipy.fft as sfft

    if abs(slope) > spec.max_slope + 1e-9:
        raise ValueError(f"slope: {slope} exceeds the max_slope {spec.max_slope} the spectrum "
                         "was padded for; prepare() again with a larger max_slope")
    nu, nv, hp, wr, c = spec.spectrum.shape
    c2 = 2 * c
    hp_, wp = spec.shape_p
    ky = sfft.fftfreq(hp_)
    kx = sfft.rfftfreq(wp)
    k = spec.kernel_width
    iu, wu = _axis_taps(ky, slope, nu, k, spec.beta)
    iv, wv = _axis_taps(kx, slope, nv, k, spec.beta)
    wu = wu.astype(np.float32)
    # v weights repeated over the (re, im) x channel floats of each column, so
    # every multiply below streams a contiguous row segment.
    wvx = np.repeat(wv.astype(np.float32).T, c2, axis=1)             # (k, wr * 2C)
    flat = spec.spectrum.view(np.float32).reshape(nu, nv, hp, wr * c2)
    out = np.zeros((hp, wr * c2), np.float32)
    tmp = np.empty_like(out)
    part = np.empty_like(out)
    wu_rows = wu[:, None, None, :]
    for x0, x1, j0 in _runs(iv[:, 0]):
        cols = slice(x0 * c2, x1 * c2)
        for y0, y1, i0 in _runs(iu[:, 0]):
            o = out[y0:y1, cols]
            if i0 + k <= nu and j0 + k <= nv:
                # (rows, v taps, u taps, cols) strided view: one batched
                # matmul contracts u, a second small contraction v.
                block = flat[i0:i0 + k, j0:j0 + k, y0:y1, cols].transpose(2, 1, 0, 3)
                np.einsum("ybx,bx->yx", np.matmul(wu_rows[y0:y1], block)[:, :, 0],
                          wvx[:, cols], out=o)
                continue
            # Taps wrapping around the periodic angular axis (|slope ky| near
            # the angular Nyquist rate): tap by tap.
            t, p = tmp[y0:y1, cols], part[y0:y1, cols]
            for b in range(k):
                jb = (j0 + b) % nv
                np.multiply(flat[i0, jb, y0:y1, cols], wu[y0:y1, 0:1], out=p)
                for a in range(1, k):
                    np.multiply(flat[(i0 + a) % nu, jb, y0:y1, cols], wu[y0:y1, a:a + 1], out=t)
                    p += t
                np.multiply(p, wvx[b, cols], out=t)
                o += t
    spec2 = out.view(np.complex64).reshape(hp, wr, c)
    if spec.delta != (0.0, 0.0):
        phase_u = np.exp(2j * np.pi * slope * ky * spec.delta[0])
        phase_v = np.exp(2j * np.pi * slope * kx * spec.delta[1])
        spec2 *= (phase_u[:, None] * phase_v[None, :]).astype(np.complex64)[..., None]
    img = sfft.irfft2(spec2, s=(hp_, wp), axes=(0, 1), workers=WORKERS)
    u, v = spec.grid
    w, h = spec.size
    py, px = spec.pad
    return np.ascontiguousarray(img[py:py + h, px:px + w] / (u * v), dtype=np.float32)


def refocus_lightfield(lf: LightField, slope: float, **options) -> np.ndarray:
    """Prepare and refocus once (convenience; prefer :func:`prepare` for many slopes)."""
    spec = prepare(lf, max_slope=max(abs(slope), 1e-3), **options)
    return refocus(spec, slope)


def refocus_stack(lf: LightField, slopes, *, max_slope: float | None = None,
                  **options) -> np.ndarray:
    """Refocus at every slope from one prepared spectrum: ``(N, H, W, C)`` float32.

    ``max_slope`` (default: the largest ``|slope|``) and ``options`` go to
    :func:`prepare`; the one 4-D FFT is shared by all slopes. This is the
    ``fourier`` entry of :data:`lightfield.methods.REFOCUS_METHODS`.

    >>> rng = np.random.default_rng(2)
    >>> lf = LightField(rng.random((3, 3, 12, 14, 1)).astype(np.float32))
    >>> refocus_stack(lf, [0.0, 0.5]).shape
    (2, 12, 14, 1)
    """
    slopes = [float(s) for s in slopes]
    if not slopes:
        raise ValueError("slopes: expected at least one slope, got none")
    spec = prepare(lf, max_slope=max(abs(s) for s in slopes) if max_slope is None else max_slope,
                   **options)
    return np.stack([refocus(spec, s) for s in slopes])
