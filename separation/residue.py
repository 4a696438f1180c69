"""High-frequency residue: does the projected pattern survive into the global image?

Nayar's separation assumes global transport blurs the pattern away (eq. 8.12).
A mirror-like surface reflects the pattern sharply onto other surfaces, and a
pattern too coarse for the scene's transport is not averaged either; then the
"global" light still carries the pattern and the split is wrong (reference
§8.3.3, Fig. 8.45). Two checks, both relative to the noise:

- :func:`pair_residue` (checker stacks): every complementary pair gives its own
  global estimate; if the assumption holds they agree, if the pattern survives
  in the global light they differ by the pattern's contribution.
- :func:`spatial_residue` (any method): the global image's local contrast at
  pattern scale, compared with that of the pattern-free mean image (object
  edges show in both, a surviving pattern only in the global image).

Examples
--------
>>> import numpy as np
>>> g = np.ones((32, 32, 1), np.float32)
>>> frac, _ = spatial_residue(g, g, window=5)
>>> frac
0.0
"""

from __future__ import annotations

import numpy as np


def pair_residue(images, complement_of, *, b: float, alpha: float, sigma: np.ndarray,
                 valid: np.ndarray, keep: float = 0.75, rel: float = 0.5) -> tuple[float, np.ndarray]:
    """Fraction of valid pixels whose per-pair global estimates disagree.

    Parameters
    ----------
    images : ndarray, ``(N, H, W, C)`` float32
    complement_of : sequence of int
    b, alpha : float
        Black level and lit fraction (for the per-pair solve).
    sigma : ndarray, ``(H, W, C)``
        Noise standard deviation of one capture.
    valid : ndarray, ``(H, W)`` bool
    rel : float
        A pixel is flagged when the spread of the per-pair global estimates
        exceeds ``rel`` of the global estimate and 6 noise standard deviations.

    Returns
    -------
    fraction : float
    flagged : ndarray, ``(H, W)`` bool
    """
    from lumigraph.separation.nayar2006 import _coefficients

    a = np.asarray(images, np.float32)
    pairs = sorted({(min(i, j), max(i, j)) for i, j in enumerate(complement_of) if j >= 0 and j != i})
    if len(pairs) < 2:
        return 0.0, np.zeros(a.shape[1:3], bool)
    hi = np.maximum(a[[p[0] for p in pairs]], a[[p[1] for p in pairs]])
    lo = np.minimum(a[[p[0] for p in pairs]], a[[p[1] for p in pairs]])
    c = hi - lo
    top = np.sort(c, axis=0)[len(pairs) // 2:].mean(axis=0)
    use = c >= keep * top
    _, _, det = _coefficients(alpha, 1.0 - alpha, b)
    g = (lo - b * hi) / det
    gmax = np.where(use, g, -np.inf).max(axis=0)
    gmin = np.where(use, g, np.inf).min(axis=0)
    spread = np.where(use.sum(axis=0) >= 2, gmax - gmin, 0.0)
    gmean = (g * use).sum(axis=0) / np.maximum(use.sum(axis=0), 1)
    sig_g = np.sqrt(2.0) * sigma * (1.0 + b) / det
    flag = (spread > rel * np.abs(gmean)) & (spread > 6.0 * sig_g)
    flagged = flag.any(axis=-1) & valid
    n = max(int(valid.sum()), 1)
    return float(flagged.sum() / n), flagged


REF_FRACTION = 0.02  # of the 99th percentile of the blurred image: the contrast's floor
REF_PERCENTILE = 99.0
REF_STRIDE = 4  # the percentile looks at every 4th row and column (cheap at 1 MP)
# what a Percentile holds at most: the high bits' histogram, two bins' low bits' and
# one bincount's temporary (int64, 2^16 bins each), whatever the image
PERCENTILE_BYTES = 4 * 8 * (1 << 16)


def spatial_residue(global_, mean_image, *, window: int = 9, rel: float = 0.3,
                    valid: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """Fraction of pixels where the global image has pattern-scale contrast that
    the pattern-free mean image lacks.

    ``r(x) = |x − box(x)| / max(|box(x)|, ref)`` over a ``window``-pixel box
    (about one pattern period; :func:`box_mean`, reflected at the edges) with
    ``ref`` 2 % of the 99th percentile of ``|box(x)|`` on every 4th row and
    column (:func:`strided_percentile`); a pixel is flagged when
    ``r(global) > rel`` and ``r(global) > 3·r(mean)``. Every step is exact by
    bands of rows (:mod:`separation.tiled` computes the same flags band by band).
    """
    sg, sm = box_mean(global_, window), box_mean(mean_image, window)
    ref_g, ref_m = (REF_FRACTION * strided_percentile(x) for x in (sg, sm))
    flag = residue_flags(global_, sg, ref_g, mean_image, sm, ref_m, rel=rel)
    if valid is not None:
        flag &= valid
        n = max(int(valid.sum()), 1)
    else:
        n = flag.size
    return float(flag.sum() / n), flag


def residue_flags(x, sx, ref_x, m, sm, ref_m, *, rel: float = 0.3) -> np.ndarray:
    """:func:`spatial_residue`'s per-pixel flags ``(H, W)`` from the images
    ``x`` (global) and ``m`` (mean), their box means and floors."""
    def contrast(v, s, ref):
        return np.abs(v - s) / np.maximum(np.abs(s), np.float32(1e-6 + ref))

    rg = contrast(np.asarray(x, np.float32), sx, ref_x)
    rm = contrast(np.asarray(m, np.float32), sm, ref_m)
    return ((rg > rel) & (rg > 3.0 * rm)).any(axis=-1)


def box_mean(x, window: int, *, top: bool = True, bottom: bool = True) -> np.ndarray:
    """Mean over a ``window × window`` box, ``(n, W, C)`` float32 rows in, float32 out.

    Reflected at the left and right edges and, where ``top``/``bottom`` say
    the rows given start/end at the image's edge, there (``fedcba|abcdef``,
    OpenCV's ``BORDER_REFLECT``); a side that is not the image's edge gives
    ``window // 2`` fewer rows (those rows are a halo). Each output value is a
    float64 sum, over the window's rows in a fixed order (a binary tree), of
    each row's own window sum (from that row's prefix sums), so a band of rows
    read with a halo of ``window // 2`` gives the whole image's values to the
    bit (a running column sum would not: its rounding depends on where the
    run starts).

    >>> x = np.arange(30, dtype=np.float32).reshape(6, 5, 1)
    >>> whole = box_mean(x, 3)
    >>> part = box_mean(x[1:5], 3, top=False, bottom=False)  # rows 2..3, from 1..4
    >>> bool((part == whole[2:4]).all())
    True
    """
    a = np.asarray(x, np.float32)
    a = a[..., None] if a.ndim == 2 else a
    r = window // 2
    a = np.pad(a, ((r if top else 0, r if bottom else 0), (r, r), (0, 0)), mode="symmetric")
    c = np.zeros((a.shape[0], a.shape[1] + 1, a.shape[2]), np.float64)
    np.cumsum(a, axis=1, dtype=np.float64, out=c[:, 1:])
    rows = c[:, window:] - c[:, :-window]  # each row's own window sums
    n = rows.shape[0] - 2 * r
    # the window's rows summed by binary decomposition (sums of 1, 2, 4, ... rows, each
    # the sum of two halves): about log2(window) passes, each output row the same fixed
    # expression of its own rows wherever the band starts
    acc = None
    part, size, offset, left = rows, 1, 0, window
    while left:
        if left & 1:
            acc = part[offset:offset + n].copy() if acc is None else acc + part[offset:offset + n]
            offset += size
        left >>= 1
        if left:
            part = part[:-size] + part[size:]
            size *= 2
    out = (acc / float(window * window)).astype(np.float32)
    return out[..., 0] if np.ndim(x) == 2 else out


def strided_percentile(x, q: float = REF_PERCENTILE, *, y0: int = 0, stride: int = REF_STRIDE,
                       absolute: bool = True) -> float:
    """The ``q``-th percentile (linear between the order statistics at ``q/100·(n−1)``)
    of ``|x|`` (``absolute``; else ``x``, which must be >= 0) on every
    ``stride``-th row and column, as float64. The order statistics are exact
    values, so :class:`Percentile` over bands of rows gives the same number
    (and numpy's ``percentile`` within a float32 rounding)."""
    p = Percentile(q, stride=stride, absolute=absolute)
    keys = p.keys(x, y0=y0)
    p.total = keys.size
    if keys.size == 0:
        return 0.0
    k0, k1 = p.ranks()
    part = np.partition(keys, sorted({k0, k1}))
    return p.value(float(part[k0:k0 + 1].view(np.float32)[0]),
                   float(part[k1:k1 + 1].view(np.float32)[0]))


class Percentile:
    """:func:`strided_percentile` of an image seen in bands of rows, exact:
    ``|x|`` as float32 bits (for non-negative floats the unsigned integers
    sort the same), a histogram of the high 16 bits in a first pass
    (:meth:`add_high`) picks the bins holding the two order statistics, one of
    the low 16 bits within them (:meth:`add_low`) pins them to the bit. Memory:
    :data:`PERCENTILE_BYTES` at most, whatever the image."""

    def __init__(self, q: float = REF_PERCENTILE, *, stride: int = REF_STRIDE,
                 absolute: bool = True):
        self.q = q
        self.stride = stride
        self.absolute = absolute
        self.total = 0
        self.high = np.zeros(1 << 16, np.int64)
        self.low: dict[int, np.ndarray] = {}

    def keys(self, x, *, y0: int = 0) -> np.ndarray:
        """The sample's keys: rows of ``x`` whose image row (``y0`` + index) is a
        multiple of the stride, every stride-th column."""
        a = np.asarray(x, np.float32)
        first = (-y0) % self.stride
        v = a[first::self.stride, ::self.stride]
        v = np.abs(v) if self.absolute else v + np.float32(0)  # (-0.0 + 0 is +0.0)
        return np.ascontiguousarray(v).view(np.uint32).ravel()

    def ranks(self) -> tuple[int, int]:
        pos = self.q / 100.0 * (self.total - 1)
        k0 = int(np.floor(pos))
        return k0, min(k0 + 1, self.total - 1)

    def value(self, lo: float, hi: float) -> float:
        pos = self.q / 100.0 * (self.total - 1)
        g = pos - np.floor(pos)
        return float(lo + (hi - lo) * g)

    def add_high(self, x, *, y0: int) -> None:
        k = self.keys(x, y0=y0)
        self.total += k.size
        self.high += np.bincount(k >> 16, minlength=1 << 16)

    def _bin_of(self, rank: int) -> tuple[int, int]:
        cum = np.cumsum(self.high)
        b = int(np.searchsorted(cum, rank, side="right"))
        return b, rank - (int(cum[b - 1]) if b else 0)

    def bins(self) -> set[int]:
        """The high-bit bins the second pass looks into."""
        return {self._bin_of(k)[0] for k in self.ranks()}

    def add_low(self, x, *, y0: int) -> None:
        k = self.keys(x, y0=y0)
        hi = k >> 16
        for b in self.bins():
            h = np.bincount(k[hi == b] & 0xFFFF, minlength=1 << 16)
            self.low[b] = self.low.get(b, 0) + h

    def result(self) -> float:
        if self.total == 0:
            return 0.0
        vals = []
        for rank in self.ranks():
            b, r = self._bin_of(rank)
            low = int(np.searchsorted(np.cumsum(self.low[b]), r, side="right"))
            vals.append(float(np.array([(b << 16) | low], np.uint32).view(np.float32)[0]))
        return self.value(*vals)


def float_keys(x) -> np.ndarray:
    """float32/float64 values as unsigned integers of the same width that sort
    as the values do (negatives flipped, positives offset by the sign bit)."""
    a = np.ascontiguousarray(x)
    bits = 8 * a.dtype.itemsize
    signed = a.view(np.int32 if bits == 32 else np.int64).ravel()
    u = signed.view(np.uint32 if bits == 32 else np.uint64)
    # the arithmetic shift spreads the sign: all ones for a negative (~u), else 0 (u | top)
    m = (signed >> (bits - 1)).view(u.dtype)
    m |= u.dtype.type(1 << (bits - 1))
    m ^= u
    return m


def key_float(key: int, dtype) -> float:
    """The value of a :func:`float_keys` key."""
    bits = 8 * np.dtype(dtype).itemsize
    top, mask = 1 << (bits - 1), (1 << bits) - 1
    u = key ^ top if key >= top else ~key & mask
    return float(np.array([u], np.uint32 if bits == 32 else np.uint64).view(dtype)[0])


class RadixSelect:
    """Exact order statistics of keys (:func:`float_keys`) seen in passes over
    bands: each pass (:meth:`add` on every band, then :meth:`refine`) fixes
    the next 16 bits of each wanted rank, so 32-bit keys take two passes and
    64-bit four, with one 2^16-bin histogram per distinct prefix; the first
    pass also counts the keys, from which ``refine`` takes the ranks.

    >>> v = np.random.default_rng(0).normal(size=1001)
    >>> r = RadixSelect(64)
    >>> while True:
    ...     for part in (v[:400], v[400:]):
    ...         r.add(float_keys(part))
    ...     if r.refine(lambda n: ((n - 1) // 2,)):
    ...         break
    >>> key_float(r.values()[0], np.float64) == float(np.median(v))
    True
    """

    def __init__(self, bits: int):
        self.bits = bits
        self.known = 0
        self.total = 0
        self.targets: list[list[int]] | None = None  # [rank within prefix, prefix]
        self.hist = {0: np.zeros(1 << 16, np.int64)}

    def add(self, keys: np.ndarray) -> None:
        k = np.asarray(keys).ravel()
        if self.known == 0:
            self.total += k.size
        shift = self.bits - self.known - 16
        for p, h in self.hist.items():
            sel = k if self.known == 0 else k[(k >> (self.bits - self.known)) == p]
            h += np.bincount(((sel >> shift) & 0xFFFF).astype(np.intp), minlength=1 << 16)

    def refine(self, ranks) -> bool:
        """After a pass; ``ranks(total)`` the wanted ranks (used once). True when done."""
        if self.targets is None:
            self.targets = [[int(r), 0] for r in ranks(self.total)]
        for t in self.targets:
            cum = np.cumsum(self.hist[t[1]])
            d = int(np.searchsorted(cum, t[0], side="right"))
            t[0] -= int(cum[d - 1]) if d else 0
            t[1] = (t[1] << 16) | d
        self.known += 16
        self.hist = {t[1]: np.zeros(1 << 16, np.int64) for t in self.targets}
        return self.known == self.bits

    def values(self) -> list[int]:
        """The keys at the wanted ranks."""
        return [t[1] for t in self.targets]
