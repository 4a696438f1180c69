"""Bench rows: ``hdr merge`` by bands of rows, peak memory against image size.

:func:`tile_rows` renders 9-exposure brackets of 4, 16 and 64 MP (smooth
log-normal radiance with clipped highlights and black shadows, written band by
band as striped 8-bit RGB TIFFs, so the bench itself never holds one), merges
each through the command line with ``--memory`` and reads the child's own
peak resident memory (``VmHWM``, :func:`peak_run`). Memory does not depend on
the content, so no scene is tuned on; the target is the issue's: the peak
stays within the budget whatever the size (the band shrinks as the width
grows). The untiled merge of the same bracket is the peer (same process kind,
same inputs), up to the size it can hold.

Examples
--------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> times = render_bracket(d, height=20, width=30, rows=8)
>>> len(times), sorted(p.name for p in d.iterdir())[:2]
(9, ['e0.tif', 'e1.tif'])
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from lumigraph.capture.bench import Check, Row
from lumigraph.capture.tiles import TiffRowWriter, bands

STAGE = "scale"
EXPOSURES = 9
STOPS = 1.0  # between exposures: 9 exposures span 8 stops


def radiance_rows(y0: int, y1: int, width: int, *, seed: int = 0) -> np.ndarray:
    """Rows ``y0:y1`` of the bench scene's radiance, ``(n, W, 3)`` float32:
    a smooth field over 14 stops with texture (some pixels clipped in every
    exposure, some black in every one), the same whatever the band
    (a function of the pixel's position and the seed only)."""
    y = np.arange(y0, y1, dtype=np.float32)[:, None]
    x = np.arange(width, dtype=np.float32)[None, :]
    f = (2 * np.pi) / 997.0
    ln = 3.5 * np.sin(x * f * (1 + 0.1 * seed)) * np.cos(y * f * 0.7) \
        + 1.5 * np.sin((x + 3 * y) * f * 11) + 0.5
    base = np.exp(ln)
    return np.stack([base * k for k in (1.0, 0.8, 0.6)], axis=-1).astype(np.float32)


def render_bracket(folder, *, height: int, width: int, rows: int = 256, seed: int = 0,
                   exposures: int = EXPOSURES) -> list[float]:
    """Write ``e{i}.tif`` (8-bit RGB, strips of ``rows``) and ``stack.json``
    for the bench scene, band by band; returns the exposure times."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    times = [0.001 * 2.0 ** (STOPS * i) for i in range(exposures)]
    writers = [TiffRowWriter(folder / f"e{i}.tif", width, height, 3, np.uint8, rows)
               for i in range(exposures)]
    try:
        for b in bands(height, rows):
            x = radiance_rows(b.y0, b.y1, width, seed=seed)
            for t, wr in zip(times, writers, strict=True):
                wr.write(np.clip(np.rint(x * np.float32(t * 255 * 8)), 0, 255).astype(np.uint8))
    finally:
        for wr in writers:
            wr.close()
    (folder / "stack.json").write_text(json.dumps(
        {"schema": "lumigraph.stack", "schema_version": 1,
         "images": [f"e{i}.tif" for i in range(exposures)], "exposure_times_s": times,
         "bit_depth": 8}))
    return times


_PEAK = ("import sys\n"
         "from lumigraph.command import main\n"
         "rc = main(sys.argv[1:])\n"
         "hwm = [ln.split()[1] for ln in open('/proc/self/status') if ln.startswith('VmHWM')]\n"
         "print('PEAK_KB', hwm[0])\n"
         "sys.exit(rc)\n")


def peak_run(argv, *, timeout: float = 1800) -> tuple[int, float, float, str]:
    """Run ``lumigraph *argv`` in a child; ``(exit status, its peak resident
    bytes, wall seconds, stderr)``. The peak is the child's own ``VmHWM``,
    read by itself at exit: ``ru_maxrss`` would carry the parent's resident
    size over the exec (Linux keeps it)."""
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", _PEAK, *map(str, argv)], capture_output=True,
                       text=True, timeout=timeout)
    dt = time.perf_counter() - t0
    peak = math.nan
    for line in p.stdout.splitlines():
        if line.startswith("PEAK_KB"):
            peak = float(line.split()[1]) * 1024
    return p.returncode, peak, dt, p.stderr


def crop_matches(bracket, radiance_exr, *, rows: int, width: int, half: int = 100) -> bool:
    """The radiance a by-bands merge wrote equals, to the bit, the whole-image
    :func:`hdr.merge.merge` of a crop (``2·half`` rows across the first band
    boundary, ``2·half`` columns at the middle), the crop read from the bracket's
    files and the radiance from the EXR, by rows."""
    from lumigraph.capture.tiles import ExrRows, read_stack_rows
    from lumigraph.hdr.merge import merge
    from lumigraph.hdr.response import ResponseCurve

    y0, y1 = max(0, rows - half), rows + half
    x0, x1 = width // 2 - half, width // 2 + half
    st = read_stack_rows([bracket], rows=rows)  # only its readers are used here
    try:
        z = st.read(y0, y1)[:, :, x0:x1]
        times = st.exposure_times_s
    finally:
        st.close()
    crop = merge(z, times, ResponseCurve.linear(8, 1)).radiance
    src = ExrRows(radiance_exr)
    try:
        got = src.read(y0, y1)[:, x0:x1]
    finally:
        src.close()
    return got.tobytes() == crop.tobytes()


def merge_100mp_check(*, workdir=None, megapixels: float = 100, budget: str = "1GB",
                      bound_gb: float = 1.5) -> tuple[list[Row], list[Check]]:
    """The issue's check: a 9 x 100 MP rendered bracket merges by bands with
    peak RSS <= 1.5 GB and the radiance of the untiled merge of a crop.
    (About 4 minutes on 2 cores and 4 GB of scratch disk: a bench item; the
    tests run it at 25 MP, tests/hdr/test_tiled_large.py.)"""
    import tempfile

    from lumigraph.hdr.response import ResponseCurve

    with tempfile.TemporaryDirectory(dir=workdir) as d:
        d = Path(d)
        side = int(math.sqrt(megapixels * 1e6 * 3 / 4))
        h, w = side, side * 4 // 3
        t0 = time.perf_counter()
        render_bracket(d / "b", height=h, width=w)
        t_render = time.perf_counter() - t0
        ResponseCurve.linear(8, 1).save(d / "r.json")
        rc, peak, dt, err = peak_run(["hdr", "merge", d / "b", "--response", d / "r.json",
                                      "--out", d / "t.exr", "-q", "--memory", budget])
        meta = json.loads((d / "t.exr.meta.json").read_text()) if rc == 0 else {}
        same = rc == 0 and crop_matches(d / "b", d / "t.exr", rows=meta["tiles"]["rows"],
                                        width=w)
    row = Row(STAGE, f"hdr merge, 9 x {megapixels:g} MP 8-bit RGB ({w}x{h})",
              f"tiled (--memory {budget}), peak RSS GB", None, "megapixels", megapixels, dt,
              (dt,), peak / 1e9, "ok" if rc == 0 else "failed",
              {"tiles": meta.get("tiles"), "render_s": t_render, "stderr": err[-300:]})
    check = Check(f"[reported] issue 19: 9 x {megapixels:g} MP bracket merges by bands with peak "
                  f"RSS <= {bound_gb} GB and the untiled merge's radiance on a crop",
                  peak / 1e9, bound_gb, rc == 0 and peak / 1e9 <= bound_gb and same,
                  f"peak {peak / 1e9:.2f} GB, {dt:.0f} s, crop identical: {same}")
    return [row], [check]


SIZES_MP = (4, 16, 64)
BUDGET = "1GB"
BUDGET_BYTES = 1e9
WHOLE_UP_TO_MP = 16  # the untiled peer runs up to here (64 MP whole needs ~2.3 GB)


def tile_rows(quick: bool = False, *, sizes_mp=SIZES_MP, budget: str = BUDGET,
              workdir=None, issue_check: bool = True) -> tuple[list[Row], list[Check]]:
    """Peak memory of ``hdr merge`` by bands (``--tile auto --memory 1GB``)
    against image size, beside the untiled merge (``--tile off``) where it fits;
    and (not ``quick``, ``issue_check``) :func:`merge_100mp_check`.

    ``quick``: 1 and 4 MP only. Rows: one per size and mode (``value``: MP;
    ``error``: peak GB). Check: every tiled peak within the budget, and the
    tiled radiance byte-identical to the untiled one where both ran. A row
    provider of ``lumigraph bench scale`` (called with ``quick``)."""
    import tempfile

    from lumigraph.hdr.response import ResponseCurve

    sizes = (1, 4) if quick else tuple(sizes_mp)
    rows: list[Row] = []
    peaks, same = [], []
    with tempfile.TemporaryDirectory(dir=workdir) as d:
        d = Path(d)
        ResponseCurve.linear(8, 1).save(d / "r.json")
        for mp in sizes:
            side = int(math.sqrt(mp * 1e6 * 3 / 4))
            h, w = side, side * 4 // 3
            bracket = d / f"b{mp}"
            render_bracket(bracket, height=h, width=w)
            outs = {}
            for mode, extra in (("tiled", ["--tile", "auto", "--memory", budget]),
                                ("whole", ["--tile", "off"])):
                if mode == "whole" and mp > WHOLE_UP_TO_MP:
                    continue
                out = d / f"{mode}{mp}.exr"
                rc, peak, dt, err = peak_run(["hdr", "merge", bracket, "--response", d / "r.json",
                                              "--out", out, "-q", *extra])
                meta = json.loads(Path(str(out) + ".meta.json").read_text()) if rc == 0 else {}
                rows.append(Row(STAGE, f"hdr merge, 9 x {mp} MP 8-bit RGB ({w}x{h})",
                                f"{mode} ({' '.join(extra)}), peak RSS GB",
                                None if mode == "tiled" else "untiled merge", "megapixels", mp,
                                dt, (dt,), peak / 1e9, "ok" if rc == 0 else "failed",
                                {"tiles": meta.get("tiles"), "stderr": err[-300:]}))
                if rc == 0:
                    outs[mode] = out
                if mode == "tiled":
                    peaks.append((mp, peak))
            if len(outs) == 2:
                same.append(outs["tiled"].read_bytes() == outs["whole"].read_bytes())
            for f in bracket.iterdir():
                f.unlink()
            for f in d.glob(f"*{mp}.exr*"):
                f.unlink()
    worst = max((p for _, p in peaks), default=math.nan)
    from lumigraph.capture.tiles import parse_memory

    limit = parse_memory(budget)
    checks = [Check(f"[reported] hdr merge by bands, 9 exposures of {', '.join(map(str, sizes))} "
                    f"MP: peak RSS <= the {budget} budget at every size", worst / 1e9, limit / 1e9,
                    all(p <= limit for _, p in peaks) and len(peaks) == len(sizes),
                    ", ".join(f"{mp} MP: {p / 1e9:.2f} GB" for mp, p in peaks)),
              Check("[reported] tiled radiance byte-identical to the untiled merge",
                    float(sum(same)), float(len(same)), all(same) and bool(same),
                    f"{sum(same)}/{len(same)} sizes identical")]
    if issue_check and not quick:
        more_rows, more_checks = merge_100mp_check(workdir=workdir)
        rows, checks = [*rows, *more_rows], [*checks, *more_checks]
    return rows, checks
