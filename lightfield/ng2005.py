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

**The spatial reconstruction filter.** Read literally, the slice shifts every
view by band-limited (sinc) interpolation. The views are point samples of a
scene that is not band-limited (texture beyond Nyquist, occlusion edges), and
there sinc interpolation rings: on rendered scenes it loses up to 1.1 dB to
Lanczos-3 shift-and-add (docs/decisions/fourier-refocus.md). Ng's theorem holds
for any reconstruction of the continuous light field: with a spatial filter of
response ``H(f)`` the shift of a view by ``d`` px has the discrete response
``sum_p H(k + p) exp(2 pi i (k + p) d)`` (Poisson summation), so the slice reads
the 4-D spectrum at angular frequency ``s (k + p)`` for each alias ``p`` where
``H(k + p) != 0``. ``interpolation="lanczos3"`` (default) uses the trapezoid
``H`` (flat to 1/3 cycle/px, zero from 2/3) of ``sinc(x) sinc(x / 3)``, the
band-limited form of the Lanczos-3 kernel of shift-and-add: at most one alias
per axis, for ``|k| > 1/3``; ``"sinc"`` is the ideal low-pass (Ng's slice).

**The angular resampling** (Ng 2005 §5.3, after Jackson et al. 1991): the
angular axes are zero-padded by ``oversample`` (1.5) and the slice interpolated
with a Kaiser-Bessel kernel of ``kernel_width`` taps; the views are first
divided by the kernel's Fourier transform (the roll-off correction). The
angular spectrum of views at offsets ``u - uc`` is periodic in frequency
(period 1 cycle/view) for odd grids and anti-periodic for even ones (half-integer
offsets), so any slope and alias is reachable by wrapping the taps with their
sign. The spatial axes are mirror-padded by the largest shift so the FFT's
wrap-around never reaches the image (the border rule of shift-and-add).

**Memory.** complex64, real FFT along x, ``ceil(oU) ceil(oV) Hp (Wp/2 + 1) C``
x 8 bytes: the per-view FFTs are written into the first ``U V`` slots of each
row of the spectrum's own buffer and the angular transform runs in place, row
block by row block, writing each column block of the stored layout
(:class:`FourierLightField`) straight into its place, so no second full-size
array exists. :func:`refocus_stack`
prepares colour channels one at a time when the whole spectrum would exceed the
light field's own size.

Examples
--------
>>> import numpy as np
>>> from lumigraph.lightfield.field import LightField
>>> rng = np.random.default_rng(1)
>>> lf = LightField(rng.random((3, 3, 16, 20, 1)).astype(np.float32))
>>> spec = prepare(lf, max_slope=1.0)
>>> a, b = refocus(spec, 0.0), lf.data.mean((0, 1))
>>> float(np.abs(a - b).max()) < 1e-4      # slope 0: the plain average
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lumigraph.lightfield.field import LightField

# scipy.fft threads for the 2-D FFTs (-1: all cores; the bench sets 1).
WORKERS = -1

# Half-width of the trapezoid's roll-off around 1/2 cycle/px, per spatial
# reconstruction filter: sinc(x) sinc(2 r x) has the response 1 for
# |f| <= 1/2 - r, 0 from 1/2 + r, linear between (r = 1/6: Lanczos-3's sinc(x/3)).
INTERPOLATIONS = {"lanczos3": 1.0 / 6.0, "sinc": 0.0}

# Spatial rows per block of the slice: fewer Python-level steps per slice,
# the block's products stay in cache (16-64 rows x 32-64 columns within the
# noise of each other at 9x9x512²; docs/decisions/fourier-refocus.md).
ROWS = 32

# Spatial columns per block of the stored spectrum (FourierLightField.cols):
# a slice reads each block's few v-bins as one piece per row and u-bin
# (64 columns x 5-8 bins x 3 channels: 8-12 KB).
COLS = 64


def _kb(t: np.ndarray, width: int, beta: float) -> np.ndarray:
    from scipy.special import i0

    x = 1.0 - (2.0 * t / width) ** 2
    return np.where(x >= 0, i0(beta * np.sqrt(np.maximum(x, 0))) / i0(beta), 0.0)


def _kb_hat(nu: np.ndarray, width: int, beta: float) -> np.ndarray:
    """Fourier transform of the Kaiser-Bessel kernel at ``nu`` (cycles/bin), by quadrature."""
    t = np.linspace(-width / 2, width / 2, 4001)
    k = _kb(t, width, beta)
    wq = np.full(t.shape, t[1] - t[0])
    wq[0] = wq[-1] = wq[0] / 2
    return (k[None, :] * np.cos(2 * np.pi * np.asarray(nu)[:, None] * t[None, :])) @ wq


def spatial_response(f: np.ndarray, interpolation: str = "lanczos3") -> np.ndarray:
    """Response ``H(f)`` of the spatial reconstruction filter (``f`` in cycles/px).

    The trapezoids sum to 1 over the aliases ``f + p`` (the filter
    interpolates: ``h(n) = 0`` at every non-zero integer ``n``).

    >>> spatial_response(np.array([0.0, 0.4, 0.5, 0.6, 0.7])).round(3).tolist()
    [1.0, 0.8, 0.5, 0.2, 0.0]
    """
    r = INTERPOLATIONS[interpolation]
    a = np.abs(np.asarray(f, np.float64))
    if r == 0:
        return np.where(a < 0.5, 1.0, np.where(a == 0.5, 0.5, 0.0))
    return np.clip((0.5 + r - a) / (2 * r), 0.0, 1.0)


@dataclass(frozen=True)
class FourierLightField:
    """The padded, pre-filtered 4-D spectrum of a light field, ready to slice.

    Attributes
    ----------
    spectrum : ndarray, (Hp, Nu, Nv * Wr * C) complex64, Wr = Wp//2 + 1
        FFT over (y, x) (real along x) and over the zero-padded angular axes;
        the angular axes in centred order (index m is frequency (m - N//2)/N
        cycles per view step), about the grid centre ``(U - 1)/2``. Stored in
        column blocks: for each row and u-bin, the columns ``cols[b]:cols[b+1]``
        are one ``(Nv, cols[b+1] - cols[b], C)`` block, so that the few
        v-bins a slice reads for a block are one contiguous piece
        (:meth:`block`; :meth:`angular` gives the plain (Hp, Nu, Nv, Wr, C)).
    grid : (U, V); size : (W, H) of the views; pad : (py, px) spatial padding.
    shape_p : (Hp, Wp) padded spatial size.
    kernel_width : int; beta : float (Kaiser-Bessel parameters).
    max_slope : float; channels : the light field's channels held, in order.
    shape : (Hp, Nu, Nv, Wr, C), the spectrum's logical shape.
    cols : column-block bounds, ``0 = cols[0] < ... < cols[-1] = Wr``.
    """

    spectrum: np.ndarray
    grid: tuple[int, int]
    size: tuple[int, int]
    pad: tuple[int, int]
    shape_p: tuple[int, int]
    kernel_width: int
    beta: float
    max_slope: float
    channels: tuple[int, ...] = (0,)
    shape: tuple[int, ...] = ()
    cols: tuple[int, ...] = ()
    # Scratch buffers of refocus(), reused from slice to slice (not thread-safe:
    # one spectrum, one thread at a time).
    workspace: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def nbytes(self) -> int:
        return int(self.spectrum.nbytes)

    def block(self, b: int) -> np.ndarray:
        """Column block ``b``: a view ``(Hp, Nu, Nv, cols[b+1] - cols[b], C)``."""
        hp, nu, nv, _, c = self.shape
        x0, x1 = self.cols[b], self.cols[b + 1]
        return self.spectrum[:, :, nv * c * x0:nv * c * x1].reshape(hp, nu, nv, x1 - x0, c)

    def angular(self) -> np.ndarray:
        """The spectrum as one (Hp, Nu, Nv, Wr, C) array (a copy)."""
        return np.concatenate([self.block(b) for b in range(len(self.cols) - 1)], axis=3)


def _column_blocks(wr: int) -> tuple[int, ...]:
    """Bounds of the column blocks: about :data:`COLS` columns each, as even as
    the width allows (no padding: the spectrum keeps its size)."""
    nb = max(1, round(wr / COLS))
    return tuple(int(round(b * wr / nb)) for b in range(nb + 1))


def _geometry(lf: LightField, max_slope: float, oversample: float, kernel_width: int):
    if not oversample >= 1.25:
        raise ValueError(f"oversample: expected >= 1.25, got {oversample}")
    if not 2 <= kernel_width <= 8:
        raise ValueError(f"kernel_width: expected 2..8, got {kernel_width}")
    u, v = lf.grid
    h, w = lf.data.shape[2:4]
    reach = abs(max_slope) * max((u - 1) / 2, (v - 1) / 2)
    pad = int(math.ceil(reach)) + 2
    hp, wp = _odd_fast_len(h + 2 * pad), _odd_fast_len(w + 2 * pad)
    # Small grids (2 views) need more than 1.5x: the kernel's passband must
    # cover the occupied bins with margin, so at least 4 empty bins per axis.
    nu = max(int(math.ceil(oversample * u)), u + 4)
    nv = max(int(math.ceil(oversample * v)), v + 4)
    return pad, hp, wp, nu, nv


def spectrum_nbytes(lf: LightField, *, max_slope: float = 1.5, oversample: float = 1.5,
                    kernel_width: int = 5, channels: int | None = None) -> int:
    """Bytes of the spectrum :func:`prepare` would hold for ``channels``
    channels (default: all)."""
    _, hp, wp, nu, nv = _geometry(lf, max_slope, oversample, kernel_width)
    c = lf.data.shape[4] if channels is None else channels
    return nu * nv * hp * (wp // 2 + 1) * c * 8


def prepare(lf: LightField, *, max_slope: float = 1.5, oversample: float = 1.5,
            kernel_width: int = 5, channels=None) -> FourierLightField:
    """The one-time 4-D FFT (after padding and the kernel pre-filter).

    Parameters
    ----------
    lf : LightField
    max_slope : float
        Largest |slope| that will be requested (sets the spatial padding).
    oversample : float
        Angular zero-padding factor (>= 1.25).
    kernel_width : int
        Kaiser-Bessel taps per angular axis (2..8); 5 keeps the resampling
        error below 1e-4 RMS of full scale on white-noise views (6: 1e-5;
        4: 3e-4, which costs up to 0.3 dB on a 62 dB refocus). Each tap
        more reads 1/Nu more of the spectrum per slice.
    channels : sequence of int, optional
        The colour channels to transform (default: all); one at a time keeps
        the spectrum a third of the size.
    """
    return _prepare(lf, max_slope, oversample, kernel_width, channels, None)


def _prepare(lf, max_slope, oversample, kernel_width, channels, buffer) -> FourierLightField:
    """:func:`prepare` into ``buffer`` (a complex64 array at least the
    spectrum's size, wholly overwritten) when given."""
    import scipy.fft as sfft

    pad, hp, wp, nu, nv = _geometry(lf, max_slope, oversample, kernel_width)
    u, v = lf.grid
    _, _, h, w, c = lf.data.shape
    chans = tuple(range(c)) if channels is None else tuple(int(k) for k in channels)
    nc = len(chans)
    # Beatty et al. (2005) choice of beta for a given width and oversampling.
    osr = min(nu / u, nv / v)
    beta = math.pi * math.sqrt(max((kernel_width / osr) ** 2 * (osr - 0.5) ** 2 - 0.8, 1.0))
    # View offsets from the grid centre (half-integers on even grids).
    pu, pv = np.arange(u) - (u - 1) / 2, np.arange(v) - (v - 1) / 2
    weight = (1.0 / (_kb_hat(pu / nu, kernel_width, beta)[:, None]
                     * _kb_hat(pv / nv, kernel_width, beta)[None, :])).astype(np.float32)
    wr = wp // 2 + 1
    row = wr * nc
    cols = _column_blocks(wr)
    # Layout: per row y and u-bin, column blocks of (Nv, columns, C): a
    # slice reads k v-bins of a column block as one contiguous piece.
    size = hp * nu * nv * row
    if buffer is not None and buffer.dtype == np.complex64 and buffer.size >= size:
        spec = buffer.reshape(-1)[:size].reshape(hp, nu * nv * row)
    else:
        spec = _prefaulted((hp, nu * nv * row), np.complex64)
    # The per-view FFTs go into the first U V (row-long) slots of every row;
    # the angular transform below then runs in place, row block by row block.
    views = spec.reshape(hp, nu * nv, row)
    mode = "symmetric" if pad < min(h, w) else "edge"
    sel = list(chans)
    for i in range(u):
        for j in range(v):
            view = lf.data[i, j][..., sel] if nc != c else lf.data[i, j]
            padded = np.pad(view * weight[i, j], ((pad, hp - h - pad), (pad, wp - w - pad), (0, 0)),
                            mode=mode)
            views[:, i * v + j] = sfft.rfft2(padded, axes=(0, 1), workers=WORKERS).reshape(hp, row)
    # The angular transform of the zero-padded grid has only U x V non-zero
    # inputs: two small DFT matrices (BLAS) instead of an FFT over mostly
    # zeros. Frequencies stored centred (bin m is frequency m - n//2): the
    # taps of the low spatial frequencies, where slices cross zero angular
    # frequency, never wrap around.
    fu = np.exp(-2j * np.pi * np.outer(np.arange(nu) - nu // 2, pu) / nu).astype(np.complex64)
    fv = np.exp(-2j * np.pi * np.outer(np.arange(nv) - nv // 2, pv) / nv).astype(np.complex64)
    # Rows y0:y1 are read into `half` before they are overwritten, and no
    # other row is touched: in place, with a few MB of temporaries. The v
    # transform writes each column block straight into its place.
    rb = max(1, (1 << 19) // (u * v * row))
    for y0 in range(0, hp, rb):
        y1 = min(hp, y0 + rb)
        blk = views[y0:y1, :u * v].reshape(y1 - y0, u, v * row)
        half = np.matmul(fu, blk).reshape((y1 - y0) * nu, v, row)
        out = spec[y0:y1].reshape((y1 - y0) * nu, nv * row)
        for x0, x1 in zip(cols[:-1], cols[1:], strict=True):
            np.matmul(fv, half[..., x0 * nc:x1 * nc],
                      out=out[:, nv * nc * x0:nv * nc * x1].reshape(-1, nv, (x1 - x0) * nc))
    return FourierLightField(spec.reshape(hp, nu, nv * row), (u, v), (w, h), (pad, pad),
                             (hp, wp), kernel_width, float(beta), float(abs(max_slope)), chans,
                             (hp, nu, nv, wr, nc), cols)


def _prefaulted(shape: tuple[int, ...], dtype) -> np.ndarray:
    """A zeroed array whose pages are mapped in one call (``MAP_POPULATE``).

    The spectrum is ~0.2 GB per channel for 9x9 views of 512x512; on virtual
    machines a first-touch page fault costs ~30 us per 4 KiB page, seconds in
    all, more than the FFTs themselves. Falls back to ``np.zeros`` where the
    flag does not exist, and while tracemalloc traces (the mapping would
    hide from it).
    """
    import mmap
    import tracemalloc

    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape)) * dtype.itemsize
    flag = getattr(mmap, "MAP_POPULATE", None)
    # Under tracemalloc a plain (traced) allocation, so measured peaks see it.
    if flag is None or nbytes < (1 << 25) or tracemalloc.is_tracing():
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


def _axis_terms(freq: np.ndarray, slope: float, n: int, views: int, width: int, beta: float,
                interpolation: str):
    """Per alias ``p`` of one axis: ``(lo, hi, idx, w)``: the rows ``lo:hi`` of
    the increasing ``freq`` where ``H(freq + p) > 0``, their stored angular
    bins ``(hi - lo, width)`` and real weights (KB tap x ``H`` x the sign of
    the taps' wrap)."""
    out = []
    for p in (0, -1, 1):
        f = freq + p
        hf = spatial_response(f, interpolation)
        rows = np.flatnonzero(hf > 0)
        if rows.size == 0:
            continue
        lo, hi = int(rows[0]), int(rows[-1]) + 1
        mu = slope * f[lo:hi] * n                          # fractional angular bin
        first = np.floor(mu - width / 2).astype(np.int64) + 1
        idx = first[:, None] + np.arange(width)
        w = _kb(mu[:, None] - idx, width, beta) * hf[lo:hi, None]
        q, stored = np.divmod(idx + n // 2, n)
        if views % 2 == 0:       # half-integer offsets: anti-periodic spectrum
            w = w * np.where(q % 2 == 0, 1.0, -1.0)
        out.append((lo, hi, stored, w))
    return out


def _runs(first: np.ndarray) -> list[tuple[int, int, int]]:
    """Maximal runs ``(start, stop, value)`` of equal consecutive entries."""
    cut = np.flatnonzero(np.diff(first)) + 1
    starts, stops = np.r_[0, cut], np.r_[cut, len(first)]
    return list(zip(starts.tolist(), stops.tolist(), first[starts].tolist(), strict=True))


def refocus(spec: FourierLightField, slope: float, *,
            interpolation: str = "lanczos3") -> np.ndarray:
    """One refocused photograph from the prepared spectrum: a 2-D slice of the
    4-D spectrum (Fourier slice photography theorem) and an inverse 2-D FFT.

    The slice reads the spectrum at angular bins ``(s (ky + p) Nu, s (kx + q) Nv)``
    for the spatial filter's aliases ``p, q`` (module docstring). The
    Kaiser-Bessel taps along u depend on ``ky`` only and those along v on
    ``kx`` only, so the slice is separable. Each row reads a cyclic range of
    u-bins (its k taps, or one range holding its alias terms' taps too
    where that is no longer than reading them apart), constant over runs of
    rows; each stored column block (:data:`COLS` columns) likewise a range of
    v-bins for all its columns (a bin more where the taps' start changes
    inside the block). Per (up to :data:`ROWS` rows of) one row run x one
    column block, one batched BLAS product contracts the u-taps over the
    block's v-bins, one contiguous piece per row and u-bin, then an einsum the
    v-taps, on the (re, im) float pairs (the weights are real). The slice
    thus reads about ``k^2 / (Nu Nv)`` of the spectrum (x 1.8 for the alias
    terms); it is memory-bound.

    Parameters
    ----------
    spec : FourierLightField
    slope : float
        px per view step, ``|slope| <= spec.max_slope``.
    interpolation : {"lanczos3", "sinc"}
        Spatial reconstruction filter (module docstring).

    Returns
    -------
    ndarray, (H, W, C) float32
        Same grid and normalisation as :func:`lightfield.refocus.shift_and_add`.
    """

    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation: expected one of {', '.join(INTERPOLATIONS)}, "
                         f"got {interpolation!r}")
    if abs(slope) > spec.max_slope + 1e-9:
        raise ValueError(f"slope: {slope} exceeds the max_slope {spec.max_slope} the spectrum "
                         "was padded for; prepare() again with a larger max_slope")
    return _refocus(spec, _plan(spec, slope, interpolation))


def _arc(need: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row of the boolean ``(rows, n)``: the shortest cyclic range of bins
    ``start, start + 1, ... start + m - 1`` (mod n) that holds every needed bin."""
    n = need.shape[1]
    # rows repeat (runs of one tap start): solve each distinct row once (as
    # bit masks where they fit in 62 bits: faster than unique rows)
    if n <= 62:
        keys, inv = np.unique(need.astype(np.int64) @ (1 << np.arange(n, dtype=np.int64)),
                              return_inverse=True)
        uniq = (keys[:, None] >> np.arange(n)) & 1 > 0
    else:
        uniq, inv = np.unique(need, axis=0, return_inverse=True)
    d = (np.arange(n)[None, :] - np.arange(n)[:, None]) % n          # (start, bin)
    length = np.where(uniq[:, None, :], d[None], -1).max(axis=2) + 1  # (rows, start)
    start = length.argmin(axis=1)
    return start[inv.ravel()], length[np.arange(len(uniq)), start][inv.ravel()]


def _dense(freq, slope, n, views, width, beta, interpolation):
    """Per alias term of one axis: the tap weights scattered into a dense
    ``(len(freq), n)`` matrix over the stored bins, and which bins they use."""
    out = []
    for lo, hi, idx, w in _axis_terms(freq, slope, n, views, width, beta, interpolation):
        m = np.zeros((freq.size, n))
        rows = np.arange(lo, hi)[:, None]
        np.add.at(m, (rows, idx), w)
        need = np.zeros((freq.size, n), bool)
        need[rows, idx] = True
        out.append((m, need))
    return out


def _windows(terms):
    """The stored bins each row reads, from its alias terms ``(weights, need)``
    (:func:`_dense`): the union of the terms' taps as one cyclic range where
    that is no longer than the terms' ranges apart, else each term's own.
    Returns per slot ``(start, m, weights (rows, max m))``: slot 0 holds the
    union (or term 0), slot t term t where not merged; ``m = 0``: nothing."""
    rows, n = terms[0][0].shape
    start, m = _arc(np.logical_or.reduce([nd for _, nd in terms]))
    own = [_arc(nd) for _, nd in terms]
    merged = m <= sum(mt for _, mt in own)
    total = sum(w for w, _ in terms)
    slots = []
    for t, ((w, _), (st, mt)) in enumerate(zip(terms, own, strict=True)):
        s_ = np.where(merged, start if t == 0 else 0, st)
        m_ = np.where(merged, m if t == 0 else 0, mt)
        if not m_.any():
            continue
        mx = int(m_.max())
        pos = (s_[:, None] + np.arange(mx)) % n
        wt = np.take_along_axis(w, pos, axis=1)
        if t == 0:
            wt = np.where(merged[:, None], np.take_along_axis(total, pos, axis=1), wt)
        slots.append((s_, m_, np.where(np.arange(mx) < m_[:, None], wt, 0.0)))
    return slots


def _plan(spec: FourierLightField, slope: float, interpolation: str):
    """The slice's taps for ``slope`` (independent of the channels held).

    u: per slot, the runs of stored rows ``(r0, r1, start, m)`` that read the
    same ``m`` stored u-bins from ``start`` (cyclic), and the weights
    ``(Hp, 1, max m)``. v: per column block and slot, the block, its columns
    ``[xa, xb)`` read, the first stored v-bin and the weights ``(m, xb - xa)``.
    A row's (or block's) alias terms share one read where their taps'
    union is no longer than the terms apart (:func:`_windows`)."""
    hp, nu, nv = spec.shape[:3]
    u, v = spec.grid
    k = spec.kernel_width
    # Rows in centred order, then rolled to storage order (centred row r is
    # stored at r - hp//2).
    ky = (np.arange(hp) - hp // 2) / hp
    kx = np.fft.rfftfreq(spec.shape_p[1])
    tu = [(np.roll(w, -(hp // 2), axis=0), np.roll(nd, -(hp // 2), axis=0))
          for w, nd in _dense(ky, slope, nu, u, k, spec.beta, interpolation)]
    terms_u = []
    for st, m, wt in _windows(tu):
        key = st * (nu + 1) + m
        runs = [(r0, r1, int(st[r0]), int(m[r0])) for r0, r1, _ in _runs(key) if m[r0] > 0]
        # the mean's 1/(U V) rides on the u weights (no pass over the image)
        terms_u.append((runs, (wt / (u * v)).astype(np.float32)[:, None, :]))
    # v: the same per column block, over all its columns
    tv = _dense(kx, slope, nv, v, k, spec.beta, interpolation)
    starts = np.asarray(spec.cols[:-1])
    col = np.arange(spec.cols[-1])
    # per term: the bins each block needs, their arc, its first and last column
    need = [np.logical_or.reduceat(nd, starts, axis=0) for _, nd in tv]       # (B, Nv)
    arcs = [[a.tolist() for a in _arc(nd)] for nd in need]
    ust, um = (a.tolist() for a in _arc(np.logical_or.reduce(need)))
    spans = [(np.minimum.reduceat(np.where(nd.any(axis=1), col, col.size), starts).tolist(),
              np.maximum.reduceat(np.where(nd.any(axis=1), col, -1), starts).tolist())
             for _, nd in tv]
    total = sum(w for w, _ in tv)
    terms_v = []
    for b, (x0, x1) in enumerate(zip(spec.cols[:-1], spec.cols[1:], strict=True)):
        parts = [(first[b] - x0, last[b] + 1 - x0, st[b], m[b], w)
                 for (w, _), (st, m), (first, last) in zip(tv, arcs, spans, strict=True) if m[b]]
        if len(parts) > 1 and um[b] * (x1 - x0) <= sum(mt * (xb - xa) for xa, xb, _, mt, _ in parts):
            parts = [(0, x1 - x0, ust[b], um[b], total)]
        for xa, xb, st, m, w in parts:
            pos = (st + np.arange(m)) % nv
            terms_v.append((b, xa, xb, st,
                            np.ascontiguousarray(w[x0 + xa:x0 + xb, pos].T, dtype=np.float32)))
    return terms_u, terms_v


def _refocus(spec: FourierLightField, plan) -> np.ndarray:
    import scipy.fft as sfft

    hp, nu, nv, wr, c = spec.shape
    c2 = 2 * c
    wp = spec.shape_p[1]
    terms_u, terms_v = plan
    blocks = [spec.block(b).view(np.float32).reshape(hp, nu, nv, -1)
              for b in range(len(spec.cols) - 1)]
    work = spec.workspace
    out = _scratch(work, "out", (hp, wr * c2))
    out[...] = 0.0
    # one flat scratch each for every block's products (fresh arrays per
    # block would page-fault their pages anew each time)
    nbmax = max(x1 - x0 for x0, x1 in zip(spec.cols[:-1], spec.cols[1:], strict=True)) * c2
    tmp = _scratch(work, "blk", (ROWS * nv * nbmax,))
    ein = _scratch(work, "ein", (ROWS * nbmax,))
    # The slice reads k x k angular bins per spatial frequency, k/Nu * k/Nv of
    # the spectrum: per block (a run of rows reading the same u-bins) x (a
    # column block), one batched BLAS product contracts the u-taps for the
    # block's m (~k) v-bins only, one contiguous piece per row and u-bin
    # (the stored layout), then the v-taps are a small einsum. (Contracting u
    # over all Nv bins first read Nv/k times more memory: the slice is
    # memory-bound.) Weights are real: they act on (re, im) floats.
    vblocks, done = [], set()
    for b, xa, xb, j0, wv in terms_v:
        m = wv.shape[0]
        m1 = min(m, nv - j0)
        full = xa == 0 and xb == spec.cols[b + 1] - spec.cols[b]
        # the first slot's first read of a whole block writes its columns
        # (the rest add to them)
        first = full and b not in done
        done.add(b)
        vblocks.append((blocks[b], slice(xa * c2, xb * c2), full, first,
                        slice((spec.cols[b] + xa) * c2, (spec.cols[b] + xb) * c2),
                        np.repeat(wv, c2, axis=1),
                        [(0, m1, j0)] + ([(m1, m, 0)] if m1 < m else [])))
    for slot, (runs, wrow) in enumerate(terms_u):                  # wrow: (Hp, 1, max m)
        for r0, r1, i0, mu in runs:
            n1 = min(mu, nu - i0)
            # a few rows at a time, all column blocks: the rows' pages stay
            # cached (and mapped) while every block reads its part
            for q0 in range(r0, r1, ROWS):
                q1 = min(q0 + ROWS, r1)
                nq = q1 - q0
                wt = wrow[q0:q1]                                   # (nq, 1, max m)
                pieces = [(wt[..., :n1], i0, i0 + n1)]
                if n1 < mu:
                    pieces.append((wt[..., n1:mu], 0, mu - n1))
                for sb, cols, full, first, ocols, wc, jpieces in vblocks:
                    nb = cols.stop - cols.start
                    m = wc.shape[0]
                    t = tmp[:nq * m * nb].reshape(nq, m, nb)
                    for n, (wp_, a0, a1) in enumerate(pieces):
                        for b0, b1, jj in jpieces:
                            src = sb[q0:q1, a0:a1, jj:jj + b1 - b0]
                            if full:      # (nq, ka, (b1 - b0) nb): contiguous rows
                                dst, wq = t[:, b0:b1].reshape(nq, 1, -1), wp_
                                src = src.reshape(nq, a1 - a0, -1)
                            else:         # part of the block: per v-bin
                                dst, wq = t[:, b0:b1, None], wp_[:, :, None]
                                src = src[..., cols].transpose(0, 2, 1, 3)
                            if n == 0:
                                np.matmul(wq, src, out=dst)
                            else:
                                dst += np.matmul(wq, src)
                    if first and slot == 0:
                        np.einsum("ybx,bx->yx", t, wc, out=out[q0:q1, ocols])
                    else:
                        e = ein[:nq * nb].reshape(nq, nb)
                        np.einsum("ybx,bx->yx", t, wc, out=e)
                        out[q0:q1, ocols] += e
    # Inverse FFT: along y in place in the scratch, then the real transform
    # along x of the image's rows only.
    spec2 = out.view(np.complex64).reshape(hp, wr, c)
    cy = sfft.ifft(spec2, axis=0, overwrite_x=True, workers=WORKERS)
    w, h = spec.size
    py, px = spec.pad
    img = sfft.irfft(cy[py:py + h], n=wp, axis=1, workers=WORKERS)
    return np.ascontiguousarray(img[:, px:px + w], dtype=np.float32)


def _scratch(work: dict, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """A float32 scratch array kept in ``work`` between slices: allocating the
    ~100 MB of a 9x9x512² slice's buffers afresh page-faults every page each
    time, which cost as much as the slice's arithmetic."""
    a = work.get(name)
    if a is None or a.shape != shape:
        a = work[name] = np.empty(shape, np.float32)
    return a


def refocus_lightfield(lf: LightField, slope: float, **options) -> np.ndarray:
    """Prepare and refocus once (convenience; prefer :func:`prepare` for many slopes)."""
    interpolation = options.pop("interpolation", "lanczos3")
    spec = prepare(lf, max_slope=max(abs(slope), 1e-3), **options)
    return refocus(spec, slope, interpolation=interpolation)


def refocus_stack(lf: LightField, slopes, *, max_slope: float | None = None,
                  oversample: float = 1.5, kernel_width: int = 5,
                  interpolation: str = "lanczos3") -> np.ndarray:
    """Refocus at every slope from one prepared spectrum: ``(N, H, W, C)`` float32.

    ``max_slope`` (default: the largest ``|slope|``), ``oversample`` and
    ``kernel_width`` go to :func:`prepare`, ``interpolation`` to
    :func:`refocus`; the one 4-D FFT is shared by all slopes. Colour channels
    are transformed together when their spectrum fits in the light field's
    own size, else one at a time through one reused buffer, so the peak stays
    near the light field's size. This is the
    ``fourier`` entry of :data:`lightfield.methods.REFOCUS_METHODS`.

    >>> rng = np.random.default_rng(2)
    >>> lf = LightField(rng.random((3, 3, 12, 14, 1)).astype(np.float32))
    >>> refocus_stack(lf, [0.0, 0.5]).shape
    (2, 12, 14, 1)
    """
    slopes = [float(s) for s in slopes]
    if not slopes:
        raise ValueError("slopes: expected at least one slope, got none")
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation: expected one of {', '.join(INTERPOLATIONS)}, "
                         f"got {interpolation!r}")
    top = max(abs(s) for s in slopes) if max_slope is None else max_slope
    if max(abs(s) for s in slopes) > top + 1e-9:
        raise ValueError(f"slope: {max(slopes, key=abs)} exceeds max_slope {top}")
    _, _, h, w, c = lf.data.shape
    whole = spectrum_nbytes(lf, max_slope=top, oversample=oversample, kernel_width=kernel_width)
    groups = [None] if whole <= max(lf.data.nbytes, 1 << 26) else [[k] for k in range(c)]
    out = _prefaulted((len(slopes), h, w, c), np.float32)
    buf, plans = None, {}
    for chans in groups:
        # one spectrum buffer for all the channels: its pages are mapped once
        spec = _prepare(lf, top, oversample, kernel_width, chans, buf)
        buf = spec.spectrum
        sel = slice(None) if chans is None else slice(chans[0], chans[0] + 1)
        for n, s in enumerate(slopes):
            if s not in plans:
                plans[s] = _plan(spec, s, interpolation)
            out[n, ..., sel] = _refocus(spec, plans[s])
        del spec
    return out
