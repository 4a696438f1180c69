"""HDR merge and tone mapping by bands of rows, for images larger than memory.

The same numbers as the whole-image functions, band by band
(:mod:`capture.tiles`): :func:`merge_rows` runs :func:`hdr.merge.merge`
on each band of the bracket (a per-pixel weighted mean; the one global
choice, the deghosting reference, comes from the first pass's histograms) and
:func:`tonemap_rows` runs :func:`hdr.reinhard2002.tonemap` on each band with
the statistics of the whole image (:func:`hdr.reinhard2002.tonemap_statistics`,
a first pass) and, for the local operator, a halo of
:func:`hdr.reinhard2002.local_halo` rows (its widest blur's support). Every
value computed is the one the whole-image call computes: the outputs are
identical, and scanline OpenEXR even byte for byte
(tests/hdr/test_tiled.py).

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.tiles import ArrayRows
>>> from lumigraph.hdr.reinhard2002 import tonemap
>>> rng = np.random.default_rng(0)
>>> x = np.exp(rng.normal(0, 2, (37, 23, 3))).astype(np.float32)
>>> got = []
>>> _ = tonemap_rows(ArrayRows(x), rows=5, method="reinhard-local", write=got.append)
>>> bool((np.concatenate(got) == tonemap(x, method="reinhard-local")).all())
True
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.capture.tiles import RowSource, StackRows, bands
from lumigraph.hdr.merge import (
    check_noise,
    clip_codes,
    flag_counts,
    merge,
    merge_report,
)
from lumigraph.hdr.response import ResponseCurve


@dataclass(frozen=True)
class RowsResult:
    """What a by-rows run returns beside the rows it wrote: ``warnings`` and
    ``stats`` as the whole-image result has them, and the bands."""

    warnings: tuple[str, ...] = ()
    stats: dict = field(default_factory=dict)
    bands: int = 0


def merge_bytes_per_pixel(images: int, channels: int, itemsize: int) -> tuple[float, float]:
    """:func:`merge_rows`'s working set per pixel of a band: the bracket's
    rows and one image's read buffer, the float32 result and flags, the
    writer's per-channel copies; and what the band's output holds until
    written (for :func:`capture.tiles.plan_rows`)."""
    c = channels
    return float(images * c * itemsize + c * itemsize + 4 * c + c + 1 + 8 * c), 0.0


def merge_rows(stack: StackRows, exposure_times_s, response: ResponseCurve, *, rows: int,
               write_radiance: Callable[[np.ndarray], object],
               write_flags: Callable[[np.ndarray], object], weights: str = "variance",
               full_well_e: float | None = None, read_noise_e: float | None = None,
               clip_margin: float = 0.02, deghost: bool = False,
               reference: int | None = None) -> RowsResult:
    """:func:`hdr.merge.merge` of a stack read by rows, ``rows`` at a time.

    Parameters
    ----------
    stack : StackRows
        From :func:`capture.tiles.read_stack_rows` (its histograms choose the
        deghosting reference as :func:`hdr.merge.merge` does).
    rows : int
        Rows per band (>= 1).
    write_radiance, write_flags : callable
        Called once per band, top to bottom, with its ``(n, W, C)`` float32
        radiance and its ``(n, W)`` uint8 flags (the channels' OR).
    Other parameters
        As :func:`hdr.merge.merge`.

    Returns
    -------
    RowsResult
        The warnings and stats :func:`hdr.merge.merge` gives for the whole image.
    """
    check_noise(weights, full_well_e, read_noise_e)
    if stack.dtype.kind not in "ui":
        raise InputError(stack.paths[0], "float images are already linear; merge needs code values")
    p = len(stack.sources)
    if deghost and reference is None:
        zmax = response.code_max
        lo, hi = clip_codes(zmax, clip_margin)
        # merge()'s rule on the whole image: the exposure with the most pixel-channels
        # strictly between the clip codes
        good = [int(h[lo + 1:hi].sum()) for h in stack.histograms]
        reference = int(np.argmax(good))
    if reference is not None and not 0 <= reference < p:
        raise ValueError(f"reference: expected 0..{p - 1}, got {reference}")
    h = stack.shape[0]
    totals: dict[str, int] = {}
    plan = bands(h, rows)
    for b in plan:
        z = stack.read(b.y0, b.y1)
        m = merge(z, exposure_times_s, response, weights=weights, full_well_e=full_well_e,
                  read_noise_e=read_noise_e, clip_margin=clip_margin, deghost=deghost,
                  reference=reference)
        del z
        for k, v in flag_counts(m.flags, deghost=deghost).items():
            totals[k] = totals.get(k, 0) + v
        write_radiance(m.radiance)
        write_flags(np.bitwise_or.reduce(m.flags, axis=2).astype(np.uint8))
    warnings, stats = merge_report(totals, reference=reference)
    return RowsResult(warnings, stats, len(plan))


def tonemap_bytes_per_pixel(method: str, channels: int, bit_depth: int) -> tuple[float, float]:
    """:func:`tonemap_rows`'s working set per pixel read (the radiance rows,
    float64 band temporaries, the local operator's float32 scale pyramid) and
    per output pixel held until written."""
    c = channels
    per = 4 * c + 8 * 3 * 2 + (8 if method == "reinhard" else 4 * 7 + 1)
    return float(per), float(3 * (bit_depth // 8))


def tonemap_rows(source: RowSource, *, rows: int, write: Callable[[np.ndarray], object],
                 method: str = "reinhard", key: float = 0.18, white: float | None = None,
                 bit_depth: int = 8) -> RowsResult:
    """:func:`hdr.reinhard2002.tonemap` of a radiance map read by rows.

    A first pass gathers :func:`hdr.reinhard2002.tonemap_statistics` over the
    bands; the second maps each band with them, the local operator reading
    :func:`hdr.reinhard2002.local_halo` rows above and below (its blurs
    reach that far; beyond the image they reflect, as the whole image's do).

    Parameters
    ----------
    source : RowSource
        ``(H, W, 3)`` or ``(H, W, 1)`` linear radiance (a 4th channel, alpha,
        is dropped as ``hdr tonemap`` does).
    rows : int
        Rows per band.
    write : callable
        Called per band, top to bottom, with its ``(n, W, 3)`` uint8/uint16 rows.
    Other parameters
        As :func:`hdr.reinhard2002.tonemap`.
    """
    from lumigraph.hdr.reinhard2002 import (
        check_key,
        local_halo,
        tonemap,
        tonemap_statistics,
    )

    check_key(key)
    h = source.shape[0]
    nch = min(source.shape[2], 3)

    def read(y0, y1):
        return source.read(y0, y1)[..., :nch]

    halo = local_halo() if method == "reinhard-local" else 0
    stats = tonemap_statistics((read(b.y0, b.y1) for b in bands(h, rows)), method=method)
    plan = bands(h, rows, halo=halo)
    for b in plan:
        out = tonemap(read(b.r0, b.r1), method=method, key=key, white=white,
                      bit_depth=bit_depth, statistics=stats)
        write(out[b.core])
    return RowsResult((), {"log_average": stats.log_average,
                           "max_luminance": stats.max_luminance}, len(plan))
