"""`separate` by bands of rows: the same files as the untiled run, peak memory bounded by the band.

Every method (checker, sinusoid, single, occluder). The captures are read one
band at a time through ``read(y0, y1) -> (N, y1 - y0, W, C)`` float32
(linear), several times; :func:`separate_rows` hands each band's direct,
global and mask to ``write`` as soon as they are computed
(:class:`separation.result.SeparationWriter` writes them by rows), so no
output is held whole either.

1. The whole-image analysis, from order-free statistics gathered band by
   band: the all-dark check (maxima), the content keys of the canonical order
   (:func:`separation.pairing.fixed_sum`, and a blake2b of the bytes fed in
   row order for ties), the complement search and the sinusoid phase check on
   the fixed sample of :func:`separation.pairing.find_pairs` (gathered at the
   same flat indices), the noise line (:func:`separation.nayar2006.noise_fit`
   on the same every-k-th values), and the occluder's lit fraction (the 90th
   percentile of ``L⁺ − L⁻`` from exact order statistics,
   :class:`separation.residue.Percentile`, then integer counts).
2. :func:`separation.separate.evaluate`, band by band, with the analysis
   fixed. With complement pairs it is per pixel and the residue flags are
   integer sums. Without them (sinusoid, single, occluder, checker max/min
   unpaired) the residue check is spatial: each band is evaluated with a halo
   of half the check's box (``single``: on whole tiles from the image's
   origin, one tile row beyond, for its bilinear tile centres), the box means
   are band-exact (:func:`separation.residue.box_mean`) and their percentile
   floors exact order statistics, so two more passes follow the one that
   writes the outputs.

The black/white frames, given as ``read_flat``, are read by bands too (the
black level's percentile and median from exact order statistics,
:func:`separation.nayar2006.black_level_rows`); see ``docs/decisions/tiles.md``.

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.patterns import checker_set
>>> ps = checker_set((16, 20), square=4, shifts=2)
>>> rng = np.random.default_rng(1)
>>> d = rng.uniform(0.2, 0.8, (20, 16)); g = np.full((20, 16), 0.2)
>>> ims = np.stack([d * p + 0.5 * g for p in ps.images])[..., None].astype(np.float32)
>>> from lumigraph.separation.separate import separate
>>> whole = separate(ims)
>>> s = separate_bands(lambda y0, y1: ims[:, y0:y1], height=20, rows=7, count=len(ims))
>>> bool((s.direct == whole.direct).all() and (s.global_ == whole.global_).all())
True
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import EstimationError, InputError
from lumigraph.capture.tiles import bands
from lumigraph.separation import nayar2006, pairing
from lumigraph.separation.methods import EXACT_IMAGES, METHODS, MIN_IMAGES
from lumigraph.separation.result import Separation
from lumigraph.separation.separate import (
    RESIDUE_WARN_FRACTION,
    black_level_of,
    check_options,
    checker_pairs,
    evaluate,
    mask_counts,
    residue_window,
)

__all__ = ["TILED_METHODS", "RowsSeparation", "separate_bands", "separate_rows"]

TILED_METHODS = ("checker", "sinusoid", "single", "occluder")


@dataclass(frozen=True)
class RowsSeparation:
    """What :func:`separate_rows` returns beside the rows it wrote: the
    :class:`Separation`'s ``method``, ``params``, ``quality`` and ``warnings``
    (the same as the whole-image run's), and the number of bands."""

    method: str
    params: dict
    quality: dict
    warnings: tuple[str, ...]
    bands: int


def separate_bands(read, *, height: int, rows: int, count: int, **options) -> Separation:
    """:func:`separate_rows` with the bands assembled into a :class:`Separation`
    in memory (for a caller that wants the arrays; the command line writes the
    bands as they come, :class:`separation.result.SeparationWriter`)."""
    parts: list = []
    r = separate_rows(read, height=height, rows=rows, count=count,
                      write=lambda *band: parts.append(band), **options)
    d, g, m = (np.concatenate(x) for x in zip(*parts, strict=True))
    return Separation(d, g, m, r.method, r.params, r.quality, r.warnings)


def separate_rows(read, *, height: int, rows: int, count: int, write, method: str = "checker",
                  alpha: float | None = None, b: float | None = None, black=None, white=None,
                  complement_of=None, estimator: str = "pairs", noise_sigma: float = 0.0,
                  quant_step: float = 0.0, saturation: float | None = None, tile: int = 16,
                  names=None, read_flat=None) -> RowsSeparation:
    """:func:`separation.separate.separate` on captures read in bands of ``rows`` rows,
    each band's outputs handed to ``write`` as soon as they are computed.

    Parameters
    ----------
    read : callable
        ``read(y0, y1)`` → ``(count, y1 - y0, W, C)`` float32 linear captures,
        rows ``y0`` to ``y1`` (called two or three times per band: once per pass).
    write : callable
        ``write(direct, global_, mask)`` once per band, top to bottom:
        ``(n, W, C)`` float32, ``(n, W, C)`` float32, ``(n, W)`` uint8.
    height, rows, count : int
        Image height, band height (any; need not divide ``height``), number of captures.
    black, white : ndarray, ``(H, W, C)``, optional
        The all-black/all-white frames, whole.
    read_flat : callable, optional
        Instead of ``black``/``white``: ``read_flat(y0, y1)`` → their rows
        ``(black, white)`` float32 linear, so they are read by bands too
        (:func:`separation.nayar2006.black_level_rows`: six passes over them).
    Other parameters are :func:`separate`'s.

    Returns
    -------
    RowsSeparation
        The rows written and these are equal, bit for bit, to :func:`separate`
        on the whole stack (checked in ``tests/separation/test_tiled.py``).

    Raises
    ------
    InputError
        ``method`` not in :data:`TILED_METHODS`, checker captures without complements found, or what
        :func:`separate` raises.
    """
    METHODS.resolve(method)
    if method not in TILED_METHODS:
        raise InputError("method", f"{method!r} is not done by bands; use tile off")
    if count < MIN_IMAGES[method]:
        raise EstimationError("<images>", f"method {method!r} needs at least "
                                          f"{MIN_IMAGES[method]} images, got {count}")
    if method in EXACT_IMAGES and count != EXACT_IMAGES[method]:
        raise EstimationError("<images>", f"method {method!r} takes exactly {EXACT_IMAGES[method]} "
                                          f"image(s), got {count}")
    if isinstance(rows, bool) or not isinstance(rows, int | np.integer) or rows < 1:
        raise InputError("rows", f"expected a band height of at least 1 row, got {rows!r}")
    names = list(names) if names is not None else [f"image {i}" for i in range(count)]
    check_options(alpha=alpha, b=b, tile=tile, noise_sigma=noise_sigma, saturation=saturation)
    quant = quant_step / np.sqrt(12.0)
    floor = 3.0 * np.hypot(noise_sigma, quant) + 1e-7
    noise = float(np.hypot(noise_sigma, quant))
    plan = bands(height, rows)

    # pass 1: order-free statistics, band by band
    peak = np.full(count, -np.inf)
    full_peak = np.full(count, -np.inf)
    sums = [0] * count
    hashers = [hashlib.blake2b(digest_size=16) for _ in range(count)]
    width = chans = None
    sample_parts = []
    for band in plan:
        y0, y1 = band.y0, band.y1
        a = nayar2006.validate_stack(read(y0, y1), need=1, method=method)
        if width is None:
            width, chans = a.shape[2], a.shape[3]
            per_image = height * width * chans
            sidx = (pairing._sample_index(per_image) if per_image > pairing.SAMPLES else
                    np.arange(per_image))
        first = (-y0) % 4  # the untiled check looks at rows 0, 4, 8, ...
        if first < len(a[0]):
            peak = np.maximum(peak, a[:, first::4, ::4].reshape(count, -1).max(axis=1))
        full_peak = np.maximum(full_peak, a.reshape(count, -1).max(axis=1))
        for i in range(count):
            sums[i] += pairing.fixed_sum(a[i])
            hashers[i].update(np.ascontiguousarray(a[i]).tobytes())
        lo, hi = y0 * width * chans, y1 * width * chans
        sel = sidx[(sidx >= lo) & (sidx < hi)] - lo
        sample_parts.append(a.reshape(count, -1)[:, sel])
    for i in range(count):
        p = peak[i] if peak[i] > floor else full_peak[i]
        if p <= floor:
            raise InputError(names[i], f"all-dark frame (brightest value {p:.3g} is within the "
                                       "noise); check the projector and the exposure")
    seen: dict[int, int] = {}
    for v in sums:
        seen[v] = seen.get(v, 0) + 1
    keys = [(v, h.digest() if seen[v] > 1 else b"") for v, h in zip(sums, hashers, strict=True)]
    sample = np.concatenate(sample_parts, axis=1)
    del sample_parts
    params: dict = {"method": method}
    order = list(range(count))
    comp = None
    if method != "single":  # one image: nothing to put in order (as separate())
        pre, _ = pairing.canonical_order(sample, keys=keys)
        if complement_of is not None and len(complement_of) != count:
            raise InputError("complement_of", f"expected {count} entries, got {len(complement_of)}")
        if method == "checker":
            # the sample is what find_pairs draws from the whole images: the same scores
            comp = checker_pairs(sample, names=names, noise=noise, order=pre,
                                 complement_of=complement_of, estimator=estimator, info=params)
        elif method == "sinusoid":
            # phase_spacing samples the same flat indices of the whole images
            sp = pairing.phase_spacing(sample[pre], names=[names[k] for k in pre], noise=noise)
            iu = np.triu_indices(count, 1)
            if np.isfinite(sp[iu]).all():
                params["phase_spacing_deg"] = [round(float(v), 1) for v in sp[iu]]
        order, comp = pairing.canonical_order(sample, comp, keys=keys)
        names = [names[k] for k in order]
    del sample
    measure = None
    if read_flat is not None:
        ranges = [(band.y0, band.y1) for band in plan]
        measure = lambda: nayar2006.black_level_rows(read_flat, ranges, floor=floor)  # noqa: E731
    b = black_level_of(b, black=black, white=white, floor=floor, info=params, measure=measure)
    var0, var1 = quant ** 2 + noise_sigma ** 2, 0.0
    if method == "checker":
        alpha = 0.5 if alpha is None else alpha
        comp = list(comp) if comp is not None else [-1] * count
    # the noise line: the pair sums at every k-th flat value, gathered band by band
    pairs = sorted({(min(i, j), max(i, j)) for i, j in enumerate(comp or []) if j >= 0 and j != i})
    step = nayar2006.noise_step(height * width * chans)

    def ordered(y0, y1):
        a = nayar2006.validate_stack(read(y0, y1), need=1, method=method)
        return a[order] if order != list(range(count)) else a

    if len(pairs) >= 2:
        parts = []
        for band in plan:
            a = ordered(band.y0, band.y1)
            off = (-band.y0 * width * chans) % step  # first flat index of the band on the stride
            parts.append(np.stack([(a[i] + a[j]).ravel()[off::step] for i, j in pairs]))
        s0, s1 = nayar2006.noise_fit(np.concatenate(parts, axis=1))
        var0, var1 = var0 + s0, s1

    alpha_measured = method == "occluder" and alpha is None
    if alpha_measured:
        alpha = _occluder_alpha(ordered, plan, count=count)
    fn = METHODS.resolve(method)
    kw = {"fn": fn, "method": method, "alpha": alpha, "b": b, "comp": comp,
          "estimator": estimator, "var0": var0, "var1": var1, "saturation": saturation,
          "tile": tile}
    if comp is not None and any(j >= 0 for j in comp):  # evaluate()'s rule
        counts, flagged, ev_params = _pass_pairs(ordered, plan, write, kw)
        residue = {"check": "per-pair global disagreement"}
    else:
        counts, flagged, ev_params = _pass_spatial(ordered, plan, write, kw, height=height)
        residue = {"check": "spatial pattern-scale contrast"}
    params.update(ev_params)
    if alpha_measured:  # measured here, by bands, and given to the per-pixel step
        params["alpha_source"] = "measured"
    frac = float(flagged / max(counts["valid"], 1))
    quality = {"noise_model": {"variance_at_zero": float(var0), "variance_slope": float(var1)},
               "mask_counts": counts,
               "residue": {**residue, "fraction": frac, "warn_above": RESIDUE_WARN_FRACTION}}
    warnings = []
    if frac > RESIDUE_WARN_FRACTION:
        warnings.append(f"high-frequency residue: the pattern survives into the global image in "
                        f"{100 * frac:.1f}% of the trusted pixels (a mirror-like surface, or a "
                        "pattern too coarse for the scene); the split is unreliable there")
    return RowsSeparation(method, params, quality, tuple(warnings), len(plan))


def _add(counts: dict, more: dict) -> None:
    for k, v in more.items():
        counts[k] = counts.get(k, 0) + v


def _occluder_alpha(ordered, plan, *, count):
    """:func:`separation.nayar2006.occluder_lit_fraction` by bands: the 90th
    percentile of ``L⁺ − L⁻`` on every 2nd row and column (exact:
    :class:`separation.residue.Percentile`, two passes), then the lit counts
    (integers) in a third."""
    from lumigraph.separation.residue import Percentile

    step = 2  # occluder_lit_fraction's

    def extremes(band):
        a = ordered(band.y0, band.y1)
        lp, lm = nayar2006.extremes(a)
        return a, lp, lm

    pc = Percentile(nayar2006.OCCLUDER_PERCENTILE, stride=step, absolute=False)
    for band in plan:
        _, lp, lm = extremes(band)
        pc.add_high(lp - lm, y0=band.y0)
    for band in plan:
        _, lp, lm = extremes(band)
        pc.add_low(lp - lm, y0=band.y0)
    top = pc.result()
    lit = total = 0
    for band in plan:
        a, lp, lm = extremes(band)
        first = (-band.y0) % step
        n_lit, n = nayar2006.occluder_lit_counts(a[:, first::step, ::step], lp[first::step, ::step],
                                                 lm[first::step, ::step], top=top)
        lit, total = lit + n_lit, total + n
    return nayar2006.occluder_alpha(lit, total, frames=count)


def _pass_pairs(ordered, plan, write, kw):
    """Pass 2 with complement pairs: per pixel, band by band; the per-pair
    residue flags are per pixel too (an integer sum)."""
    counts: dict = {}
    flagged = 0
    params: dict = {}
    for band in plan:
        ev = evaluate(ordered(band.y0, band.y1), **kw)
        params = ev.params
        _add(counts, ev.counts)
        flagged += ev.residue_flagged
        write(ev.direct, ev.global_, ev.mask)
        del ev
    return counts, flagged, params


def _pass_spatial(ordered, plan, write, kw, *, height):
    """Passes 2-4 without complement pairs (sinusoid, single, checker max/min
    unpaired): :func:`separation.residue.spatial_residue` by bands. Each band
    is evaluated with a halo of ``window // 2`` rows (the box mean's reach;
    ``single`` also on whole tiles, one tile row beyond: its bilinear
    interpolation between tile centres), so its rows are the whole image's.
    Pass 2 writes the outputs and histograms the high bits of the
    percentile's sample, pass 3 its low bits
    (:class:`separation.residue.Percentile`: the floors to the bit), pass 4
    counts the flags."""
    from lumigraph.separation.residue import Percentile, box_mean, residue_flags

    method, tile = kw["method"], kw["tile"]
    window = residue_window(tile)
    r = window // 2

    def rows_eval(y0, y1):
        # the evaluation of exactly rows y0:y1 of the image
        if method == "single":  # whole tiles from the image's origin, one tile row beyond
            t0 = max(0, (y0 // tile - 1) * tile)
            t1 = min(height, (-(-y1 // tile) + 1) * tile)
        else:  # per pixel
            t0, t1 = y0, y1
        ev = evaluate(ordered(t0, t1), **kw)
        s = slice(y0 - t0, y1 - t0)
        return ev.direct[s], ev.global_[s], ev.mask[s], ev.mean_image[s], ev.params

    def band_rows(band):
        r0, r1 = max(0, band.y0 - r), min(height, band.y1 + r)
        d, g, m, mean, params = rows_eval(r0, r1)
        core = slice(band.y0 - r0, band.y1 - r0)
        s0 = r0 if r0 == 0 else r0 + r  # the first row the box means cover
        box = slice(band.y0 - s0, band.y1 - s0)
        edges = {"top": r0 == 0, "bottom": r1 == height}
        sg = box_mean(g, window, **edges)[box]
        sm = box_mean(mean, window, **edges)[box]
        return d[core], g[core], m[core], mean[core], sg, sm, params

    pg, pm = Percentile(), Percentile()
    counts: dict = {}
    params: dict = {}
    for band in plan:  # pass 2: the outputs, the percentiles' high bits
        d, g, m, mean, sg, sm, params = band_rows(band)
        write(d, g, m)
        _add(counts, mask_counts(m))
        pg.add_high(sg, y0=band.y0)
        pm.add_high(sm, y0=band.y0)
        del d, g, m, mean, sg, sm
    for band in plan:  # pass 3: their low bits
        _, _, _, _, sg, sm, _ = band_rows(band)
        pg.add_low(sg, y0=band.y0)
        pm.add_low(sm, y0=band.y0)
    from lumigraph.separation.residue import REF_FRACTION

    ref_g, ref_m = REF_FRACTION * pg.result(), REF_FRACTION * pm.result()
    flagged = 0
    for band in plan:  # pass 4: the flags
        _, g, m, mean, sg, sm, _ = band_rows(band)
        flagged += int((residue_flags(g, sg, ref_g, mean, sm, ref_m) & (m == 0)).sum())
    return counts, flagged, params
