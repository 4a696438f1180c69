"""Merging an exposure bracket into a radiance map, with weights that know
about noise and saturation.

Each exposure ``j`` gives an estimate of relative radiance ``X̂_j =
f⁻¹(Z_j) / Δt_j`` (reference ch. 6, eq. 6.4); the merge is their weighted
mean. The default weights are the variance-optimal ones (Granados et al.
2010, doi:10.1109/CVPR.2010.5540208; Hanji et al. 2020,
doi:10.1007/978-3-030-58542-6_23): ``w_j = 1 / Var(X̂_j)`` with

``Var(X̂_j) = (X/n_sat + (σ_read/n_sat)² + (dX/dz)²/12) / Δt_j²``

for a sensor whose well holds ``n_sat`` electrons at ``X = f⁻¹(z_max)``
(shot noise, read noise and quantisation through the response's slope).
``weights="hat"`` gives Debevec–Malik's triangle instead.

Units are consistent whatever the bit depth: every response here maps the
top code to 1 (:func:`hdr.response.normalise_g`), so a
linear 8-bit and a linear 16-bit capture of one scene merge to the same
numbers. Codes within ``clip_margin`` of 0 or ``z_max`` get no weight (the
noise there is truncated). A pixel clipped in every exposure is set to the
lower bound the shortest saturated exposure gives (``f⁻¹(z_hi)/Δt``) and flagged
:data:`CLIPPED`; one black in every exposure gets the upper bound from the
longest exposure and :data:`BLACK` — never a silent 0 or mid-grey — with one
colour per pixel, not one bound per channel (:func:`_fill_bounds`).

The work runs in row blocks on a thread pool (numpy releases the GIL), so
peak memory is the inputs, the float32 output, its mask and a few blocks.

Examples
--------
>>> from lumigraph.hdr.response import ResponseCurve
>>> x = np.array([[[20 / 255], [100 / 255], [5.0]]])  # (1, 3, 1) radiance
>>> t = [0.5, 2.0]
>>> z = np.stack([np.clip(np.round(x * ti * 255), 0, 255) for ti in t]).astype(np.uint8)
>>> m = merge(z, t, ResponseCurve.linear(8, 1))
>>> [round(float(v), 3) for v in m.radiance[0, :, 0]], m.flags[0, :, 0].tolist()
([0.078, 0.392, 1.953], [0, 0, 1])
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from lumigraph.capture.batch import default_threads
from lumigraph.capture.errors import InputError
from lumigraph.hdr.response import ResponseCurve
from lumigraph.hdr.samples import check_stack, hat_weight

CLIPPED = 1  # saturated in every exposure: the value is a lower bound
BLACK = 2  # black in every exposure: the value is an upper bound
GHOST = 4  # an exposure disagreed with the reference and was left out
_EMPTY = 128  # internal, cleared before return: no exposure measured the pixel-channel
WEIGHTS = ("variance", "hat")
# The variance weights' sensor when none is given: electrons at saturation and
# read noise in electrons RMS (a default, not estimated from the images).
FULL_WELL_E = 10000.0
READ_NOISE_E = 5.0


@dataclass(frozen=True)
class RadianceMap:
    """A merged radiance map.

    Attributes
    ----------
    radiance : ndarray, ``(H, W, C)`` float32
        Relative linear radiance (exposure per second, ``f⁻¹`` units).
    flags : ndarray, ``(H, W, C)`` uint8
        Bit flags per channel: :data:`CLIPPED`, :data:`BLACK`, :data:`GHOST`.
    exposure_times_s : tuple of float
    weights : str
    warnings : tuple of str
    """

    radiance: np.ndarray
    flags: np.ndarray
    exposure_times_s: tuple[float, ...]
    weights: str = "variance"
    warnings: tuple[str, ...] = ()
    stats: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.radiance.dtype != np.float32 or self.radiance.ndim != 3:
            raise TypeError(f"radiance: expected (H, W, C) float32, got {self.radiance.shape} "
                            f"{self.radiance.dtype}")
        if self.flags.shape != self.radiance.shape or self.flags.dtype != np.uint8:
            raise ValueError(f"flags: expected {self.radiance.shape} uint8, got "
                             f"{self.flags.shape} {self.flags.dtype}")

    @property
    def mask(self) -> np.ndarray:
        """``(H, W)`` bool: True where some channel is clipped or black everywhere."""
        return (self.flags & (CLIPPED | BLACK)).any(axis=2)


def variance_weight_table(exposure_table: np.ndarray, *, full_well_e: float = FULL_WELL_E,
                          read_noise_e: float = READ_NOISE_E, clip_margin: float = 0.02) -> np.ndarray:
    """``1 / Var(f⁻¹(z))`` per channel and code (before the ``Δt²`` factor).

    Parameters
    ----------
    exposure_table : ndarray, ``(C, 2**bit_depth)``
        ``f⁻¹(z)`` (:meth:`ResponseCurve.exposure_table`).

    Returns
    -------
    ndarray, ``(C, 2**bit_depth)`` float64, zero at clipped codes. Noise model
    in the module docstring; ``X`` is taken relative to ``f⁻¹(z_max)``.

    Examples
    --------
    >>> w = variance_weight_table(ResponseCurve.linear(8, 1).exposure_table())
    >>> bool(w[0, 50] > w[0, 200] > 0), float(w[0, 255])  # shot noise grows with X
    (True, 0.0)
    """
    x = np.asarray(exposure_table, dtype=np.float64)
    zmax = x.shape[1] - 1
    sat = x[:, -1:]
    xs = x / sat
    slope = np.gradient(xs, axis=1)
    var = xs / full_well_e + (read_noise_e / full_well_e) ** 2 + slope ** 2 / 12.0
    w = 1.0 / (np.maximum(var, 1e-30) * sat ** 2)
    z = np.arange(zmax + 1)
    w[:, (z < clip_margin * zmax) | (z > (1 - clip_margin) * zmax) | (z == 0) | (z == zmax)] = 0.0
    return w


def check_noise(weights: str = "variance", full_well_e: float | None = None,
                read_noise_e: float | None = None) -> tuple[float, float]:
    """Check :func:`merge`'s weights and noise model (before any image is
    read); returns ``(full_well_e, read_noise_e)`` as floats, the defaults
    :data:`FULL_WELL_E` and :data:`READ_NOISE_E` where ``None``.

    Raises
    ------
    InputError
        Naming ``weights`` (not ``"variance"`` or ``"hat"``), ``full_well_e``
        (not finite and > 0) or ``read_noise_e`` (not finite and >= 0), or the
        one given with ``weights="hat"`` (the noise model is the variance
        weights').

    Examples
    --------
    >>> check_noise(), check_noise("variance", 20000, 4)
    ((10000.0, 5.0), (20000.0, 4.0))
    >>> try:
    ...     check_noise("hat", 20000, 4)
    ... except InputError as e:
    ...     print(e)
    full_well_e: applies to weights 'variance' only
    """
    if weights not in WEIGHTS:
        raise InputError("weights", f"expected 'variance' or 'hat', got {weights!r}")
    given = [n for n, v in (("full_well_e", full_well_e), ("read_noise_e", read_noise_e))
             if v is not None]
    if given and weights != "variance":
        raise InputError(given[0], "applies to weights 'variance' only")
    fw = FULL_WELL_E if full_well_e is None else full_well_e
    rn = READ_NOISE_E if read_noise_e is None else read_noise_e
    if not (math.isfinite(fw) and fw > 0):
        raise InputError("full_well_e", f"full well must be a positive number of electrons, got {fw}")
    if not (math.isfinite(rn) and rn >= 0):
        raise InputError("read_noise_e", f"read noise must be >= 0 electrons RMS, got {rn}")
    return float(fw), float(rn)


def _fill_bounds(num, empty, zb, t, x_tab, hi_code, bound_lo, fb):
    """Fill the pixel-channels no exposure measured (``empty``) in place, one
    colour per pixel, and flag them.

    A channel saturated in some exposure is at least ``f⁻¹(z_hi)/Δt`` of the
    shortest such (:data:`CLIPPED`); one dark in every exposure is at most
    ``f⁻¹(z_lo)/Δt_longest`` (:data:`BLACK`). Per channel those bounds differ
    (each channel's curve), so filling each channel with its own bound
    paints a black night sky in saturated speckle once tone-mapped. Instead,
    per pixel: where other channels were measured, a black channel takes
    ``min(bound, their mean)`` and a clipped one ``max(bound, their mean)``
    (never brighter, resp. darker, than the pixel's own colour says); where
    none was, every black channel takes the smallest of their bounds and
    every clipped one the largest — one grey within every channel's bound.
    """
    zmax = x_tab.shape[1] - 1
    c = empty.shape[2]
    w = empty.shape[1]
    num2, empty2, fb2 = num.reshape(-1, c), empty.reshape(-1, c), fb.reshape(-1, c)
    # Only the pixels with an empty channel, as (n, C) rows: blocks of a large
    # merge hold a few such pixels among thousands. (Reductions over the short
    # channel axis are written out per channel: numpy's are slow there.)
    any_e = empty2[:, 0].copy()
    for k in range(1, c):
        any_e |= empty2[:, k]
    flat = np.flatnonzero(any_e)
    py, px = np.divmod(flat, w)
    e = empty2[flat]  # (n, C)
    vals = num2[flat]
    # Saturated somewhere means saturated in the longest exposure (a code only
    # grows with exposure); the shortest saturated one gives the bound, looked up
    # for those few entries only.
    j_order = np.argsort(t)
    sat = e & (zb[j_order[-1]][py, px] > hi_code)
    val = np.broadcast_to(bound_lo.astype(np.float32)[None], e.shape).copy()
    si, sc = np.nonzero(sat)
    if si.size:
        vs = np.full(si.size, np.nan, np.float32)
        for j in j_order[::-1]:  # longest first, so the shortest wins
            sj = zb[j][py[si], px[si], sc] > hi_code
            vs[sj] = x_tab[sc[sj], min(hi_code, zmax)] / t[j]
        val[si, sc] = vs
    black, clip = e & ~sat, e & sat
    n_meas = np.zeros(flat.size, np.int32)
    tot = np.zeros(flat.size, np.float32)
    gb = np.full(flat.size, np.inf, np.float32)
    gc = np.full(flat.size, -np.inf, np.float32)
    for k in range(c):
        m_k = ~e[:, k]
        n_meas += m_k
        tot += np.where(m_k, vals[:, k], 0)
        gb = np.where(black[:, k], np.minimum(gb, val[:, k]), gb)
        gc = np.where(clip[:, k], np.maximum(gc, val[:, k]), gc)
    has = n_meas > 0
    mean_meas = tot / np.maximum(n_meas, 1)
    for k in range(c):
        vk = np.where(black[:, k], np.where(has, np.minimum(val[:, k], mean_meas), gb),
                      np.where(has, np.maximum(val[:, k], mean_meas), gc))
        vals[:, k] = np.where(e[:, k], vk, vals[:, k])
    num2[flat] = vals
    f = fb2[flat]
    f[clip] |= CLIPPED
    f[black] |= BLACK
    fb2[flat] = f


def clip_codes(code_max: int, clip_margin: float) -> tuple[int, int]:
    """The codes at and beyond which a pixel counts as black or clipped:
    ``(⌈margin · z_max⌉, ⌊(1 − margin) · z_max⌋)``."""
    return int(math.ceil(clip_margin * code_max)), int(math.floor((1 - clip_margin) * code_max))


def merge(images: np.ndarray, exposure_times_s, response: ResponseCurve, *,
          weights: str = "variance", full_well_e: float | None = None,
          read_noise_e: float | None = None,
          clip_margin: float = 0.02, deghost: bool = False, deghost_sigma: float = 4.0,
          reference: int | None = None, block_rows: int | None = None,
          workers: int | None = None, device="cpu") -> RadianceMap:
    """Merge a bracket into relative radiance.

    Parameters
    ----------
    images : ndarray, ``(P, H, W, C)`` uint8/uint16 codes
    exposure_times_s : sequence of float, ``(P,)``
        Exposure times (or relative exposures), seconds.
    response : ResponseCurve
        Its bit depth is the codes'; one channel or ``C``.
    weights : {"variance", "hat"}
        Variance-optimal (noise- and saturation-aware) or Debevec's hat.
    full_well_e, read_noise_e : float, optional
        Noise model of the variance weights (electrons at saturation, > 0;
        read noise RMS, >= 0; both finite); only their ratio to each other and
        the response matter. Default :data:`FULL_WELL_E`, :data:`READ_NOISE_E`;
        given only with ``weights="variance"`` (:func:`check_noise`).
    clip_margin : float
        Fraction of the code range at each end that counts as clipped.
    deghost : bool
        Leave out, per pixel and channel, exposures whose estimate differs
        from the reference exposure's by more than ``deghost_sigma`` standard
        deviations (moving content); flagged :data:`GHOST`.
    reference : int, optional
        Reference exposure for deghosting (default: the one with the most
        well-exposed pixels).
    block_rows, workers : int, optional
        Row-block size (default: about 16k pixel-channels, cache-sized) and
        thread count (default: CPU count, at most 4).
    device : {"cpu", "cuda", "torch-cpu", "auto"}
        Where the per-pixel work runs (:mod:`lumigraph.capture.device`):
        ``"cpu"`` is this numpy code; a torch device runs
        :func:`hdr.merge_torch.merge_torch` (same result within float32
        rounding, same flags).

    Returns
    -------
    RadianceMap

    Raises
    ------
    InputError
        A bad bracket (:func:`hdr.samples.check_stack`), weights or noise model
        (:func:`check_noise`), or a curve whose channels do not fit.
    """
    if device != "cpu":
        from lumigraph.capture.device import resolve_device

        dev = resolve_device(device)
        if dev.uses_torch:
            from lumigraph.hdr.merge_torch import merge_torch

            return merge_torch(images, exposure_times_s, response, weights=weights,
                               full_well_e=full_well_e, read_noise_e=read_noise_e,
                               clip_margin=clip_margin, deghost=deghost,
                               deghost_sigma=deghost_sigma, reference=reference, device=dev)
    z, t, bd = check_stack(images, exposure_times_s, bit_depth=response.bit_depth)
    full_well_e, read_noise_e = check_noise(weights, full_well_e, read_noise_e)
    p, h, w, c = z.shape
    if response.channels not in (1, c):
        raise InputError("response", f"curve has {response.channels} channels, images have {c}")
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
    # Per exposure: LUTs of w and w·X̂ (float32: the accumulation is float32 too).
    wl = np.empty((p, c, zmax + 1), np.float32)
    wxl = np.empty((p, c, zmax + 1), np.float32)
    xl = np.empty((p, c, zmax + 1), np.float32)
    for j in range(p):
        wj = w_tab * (t[j] ** 2 if weights == "variance" else 1.0)
        xl[j] = x_tab / t[j]
        wl[j] = wj
        wxl[j] = wj * x_tab / t[j]
    lo_code, hi_code = clip_codes(zmax, clip_margin)
    j_long = int(np.argmax(t))
    bound_lo = (x_tab[:, max(lo_code, 0)] / t[j_long]).astype(np.float32)
    if deghost:
        if reference is None:
            good = [np.count_nonzero((z[j] > lo_code) & (z[j] < hi_code)) for j in range(p)]
            reference = int(np.argmax(good))
        if not 0 <= reference < p:
            raise ValueError(f"reference: expected 0..{p - 1}, got {reference}")
        if var_tab is None:
            var_tab = np.where(w_tab > 0, 1.0, np.inf)  # hat: a flat noise guess
        vl = np.stack([(var_tab / (t[j] ** 2 if weights == "variance" else 1.0))
                       .astype(np.float32) for j in range(p)])
    out = np.empty((h, w, c), np.float32)
    flags = np.zeros((h, w, c), np.uint8)

    # Channel-interleaved LUTs: one gather per exposure covers every channel of a
    # contiguous row block (index = code + channel * 2**bit_depth). Without
    # deghosting, w·X̂ and w are packed as the real and imaginary parts of one
    # complex64 table, so each exposure costs one 8-byte gather and one add.
    n_codes = zmax + 1
    ch_off = (np.arange(c) * n_codes).astype(np.int32)
    wl_f, wxl_f, xl_f = wl.reshape(p, -1), wxl.reshape(p, -1), xl.reshape(p, -1)
    if deghost:
        vl_f = vl.reshape(p, -1)
    else:
        cl_f = (wxl_f + 1j * wl_f).astype(np.complex64)
    if block_rows is None:
        # ~16k pixel-channels per block: the block's arrays stay in cache.
        block_rows = max(1, 16384 // max(w * c, 1))
    tiny = np.float32(1e-30)

    def do_block(r0, r1):
        if not deghost:
            acc = np.zeros((r1 - r0, w, c), np.complex64)
            ij = np.empty((r1 - r0, w, c), np.int32)
            tmp = np.empty((r1 - r0, w, c), np.complex64)
            for j in range(p):
                np.add(z[j, r0:r1], ch_off, out=ij)
                acc += np.take(cl_f[j], ij, out=tmp)
            num, den = acc.real, acc.imag
        else:
            num = np.zeros((r1 - r0, w, c), np.float32)
            den = np.zeros((r1 - r0, w, c), np.float32)
            ir = z[reference, r0:r1].astype(np.int32) + ch_off
            xr, vr = xl_f[reference][ir], vl_f[reference][ir]
            ref_ok = np.isfinite(vr)
            ghost = np.zeros((r1 - r0, w, c), bool)
            ij = np.empty((r1 - r0, w, c), np.int32)
            for j in range(p):
                np.add(z[j, r0:r1], ch_off, out=ij)
                wj = wl_f[j][ij]
                if j != reference:
                    d2 = (xl_f[j][ij] - xr) ** 2
                    bad = ref_ok & (wj > 0) & (d2 > deghost_sigma ** 2 * (vl_f[j][ij] + vr))
                    wj[bad] = 0.0
                    ghost |= bad
                    wx = wxl_f[j][ij]
                    wx[bad] = 0.0
                    num += wx
                else:
                    num += wxl_f[j][ij]
                den += wj
            flags[r0:r1][ghost] |= GHOST
        # Where no exposure has weight both sums are 0: 0 / tiny = 0, marked for the fill.
        np.divide(num, np.maximum(den, tiny), out=out[r0:r1])
        flags[r0:r1] |= (den <= 0).view(np.uint8) * _EMPTY  # no exposure measured it

    # The fill of unmeasured pixels runs once per chunk of many blocks (its cost is
    # per call, not per pixel, when few pixels need it).
    n_workers = workers or default_threads()
    # (~64k pixel-channels a chunk: the fill's temporaries stay small beside the output)
    chunk_rows = max(block_rows, min(-(-h // n_workers), max(1, (1 << 16) // max(w * c, 1))))

    def do_chunk(r0):
        r1 = min(r0 + chunk_rows, h)
        for b0 in range(r0, r1, block_rows):
            do_block(b0, min(b0 + block_rows, r1))
        fl = flags[r0:r1]
        empty = (fl & _EMPTY).astype(bool)
        if empty.any():
            fl &= np.uint8(~_EMPTY & 0xFF)
            _fill_bounds(out[r0:r1], empty, z[:, r0:r1], t, x_tab, hi_code, bound_lo, fl)

    starts = range(0, h, chunk_rows)
    if n_workers > 1 and len(starts) > 1:
        with ThreadPoolExecutor(n_workers) as ex:
            list(ex.map(do_chunk, starts))
    else:
        for r0 in starts:
            do_chunk(r0)
    warnings, stats = merge_report(flag_counts(flags, deghost=deghost), reference=reference)
    return RadianceMap(out, flags, tuple(float(x) for x in t), weights, warnings, stats)


def flag_counts(flags: np.ndarray, *, deghost: bool) -> dict[str, int]:
    """The counts :func:`merge_report` needs from ``(H, W, C)`` flags; counts
    of rows add up, so a merge by bands sums them."""
    return {"clipped_everywhere": int(np.count_nonzero(flags & CLIPPED)),
            "black_everywhere": int(np.count_nonzero(flags & BLACK)),
            "black_everywhere_pixels": int(np.count_nonzero((flags & BLACK).any(axis=2))),
            "clipped_everywhere_pixels": int(np.count_nonzero((flags & CLIPPED).any(axis=2))),
            "ghost": int(np.count_nonzero(flags & GHOST)) if deghost else 0}


def merge_report(counts: dict[str, int], *, reference: int | None) -> tuple[tuple[str, ...], dict]:
    """:attr:`RadianceMap.warnings` and :attr:`RadianceMap.stats` from
    :func:`flag_counts` (of the whole image)."""
    warnings = []
    n_clip, n_black = counts["clipped_everywhere"], counts["black_everywhere"]
    if n_clip:
        warnings.append(f"{n_clip} pixel-channels are clipped in every exposure: set to the lower "
                        "bound from the shortest saturated exposure and flagged (add a shorter exposure)")
    if n_black:
        warnings.append(f"{n_black} pixel-channels are black in every exposure: set to the upper "
                        "bound from the longest exposure, one grey per pixel, and flagged (add a "
                        "longer exposure)")
    stats = {"clipped_everywhere": n_clip, "black_everywhere": n_black,
             "black_everywhere_pixels": counts["black_everywhere_pixels"],
             "clipped_everywhere_pixels": counts["clipped_everywhere_pixels"],
             "fill": "one colour per pixel: min/max(bound, measured channels' mean), else one "
                     "grey within every channel's bound",
             "ghost": counts["ghost"],
             "reference": reference}
    return tuple(warnings), stats
