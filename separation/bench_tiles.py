"""Bench rows: ``separate`` by bands of rows, peak memory against image size.

:func:`tile_rows` renders 8 checker captures (shifted boards and their
complements, square 8 px; a smooth direct and global image, 16-bit RGB TIFFs
written band by band, so the bench never holds one) at each size, and 3
sinusoids at the largest (no complement pairs: the spatial residue check's
halo and two more passes), separates
them through the command line (``--tile-rows auto --memory 1GB``: the
analysis pass, then direct/global/mask written band by band) and reads the
child's own peak resident memory (``VmHWM``,
:func:`lumigraph.hdr.bench_tiles.peak_run`). Memory does not depend on the
content, so no scene is tuned on; the target: the peak stays within the
budget at every size. The peer is the untiled run (``--tile-rows off``) of
the same captures, up to the size it can hold; its files must be the banded
run's, byte for byte.

Examples
--------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> files = render_checker(d, height=20, width=30, rows=8)
>>> len(files), files[0].name, files[-1].name
(10, 'c0.tif', 'white.tif')
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from lumigraph.capture.bench import Check, Row
from lumigraph.capture.tiles import TiffRowWriter, bands

STAGE = "scale"
SQUARE = 8
BLACK = 0.1  # the projector's black level in the checker captures and the black frame
SIZES_MP = (4, 16, 64)
QUICK_MP = (1, 4)
BUDGET = "1GB"
WHOLE_UP_TO_MP = 4  # the untiled peer runs up to here (8 x 16 MP RGB whole needs ~6 GB)


def render_checker(folder, *, height: int, width: int, rows: int = 256,
                   method: str = "checker") -> list[Path]:
    """Captures ``c0.tif`` … (16-bit RGB), ``rows`` rows at a time:
    ``direct · pattern + global / 2`` with smooth direct and global images;
    ``method`` checker: 8 boards (square 8 px, 2 shifts, and complements), then
    ``black.tif`` (the projector's black level 0.1) and ``white.tif``;
    sinusoid: 3 phase-shifted sinusoids of period 16 px along the diagonal."""
    from lumigraph.capture.patterns import checker_set

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    period = 2 * SQUARE
    pat = np.asarray(checker_set((width, period), square=SQUARE, shifts=2).images, np.float32)
    phases = (0.0, 2 * np.pi / 3, 4 * np.pi / 3)
    count = len(pat) if method == "checker" else len(phases)
    files = [folder / f"c{i}.tif" for i in range(count)]
    if method == "checker":  # and the projector's all-black (b = 0.1) and all-white frames
        files += [folder / "black.tif", folder / "white.tif"]
    writers = [TiffRowWriter(f, width, height, 3, np.uint16, rows) for f in files]
    try:
        for b in bands(height, rows):
            y = np.arange(b.y0, b.y1, dtype=np.float32)[:, None, None]
            x = np.arange(width, dtype=np.float32)[None, :, None]
            c = np.arange(3, dtype=np.float32)
            d = 0.35 + 0.25 * np.sin(6.0 * x / width + 4.0 * y / height + c)
            g = 0.15 + 0.1 * np.cos(5.0 * x / width - 3.0 * y / height + c)
            for k, wr in enumerate(writers):
                if k >= count:  # black, white: every light path scales with the projector
                    v = (BLACK if k == count else 1.0) * (d + g)
                elif method == "checker":  # unlit squares at the black level
                    p = pat[k, np.arange(b.y0, b.y1) % period][..., None]
                    v = d * (BLACK + (1 - BLACK) * p) + 0.5 * (1 + BLACK) * g
                else:
                    v = d * (0.5 + 0.5 * np.cos(2 * np.pi * (x + y) / period + phases[k])) + 0.5 * g
                wr.write(np.round(np.clip(v, 0, 1) * 65535).astype(np.uint16))
    finally:
        for wr in writers:
            wr.close()
    return files


def tile_rows(quick: bool = False, *, sizes_mp=SIZES_MP, budget: str = BUDGET,
              workdir=None) -> tuple[list[Row], list[Check]]:
    """Peak memory of ``separate`` by bands against image size, beside the
    untiled run where it fits (``quick``: 1 and 4 MP). Rows: one per size and
    mode (``value``: MP; ``error``: peak GB). Checks: every banded peak within
    the budget; the banded files byte-identical to the untiled run's. A row
    provider of ``lumigraph bench scale``."""
    import tempfile

    from lumigraph.capture.tiles import parse_memory
    from lumigraph.hdr.bench_tiles import peak_run
    from lumigraph.separation.result import FILES

    sizes = QUICK_MP if quick else tuple(sizes_mp)
    # checker at every size; sinusoid (no complement pairs: the spatial residue check's
    # halo and extra passes) at the largest
    cases = [("checker", mp) for mp in sizes] + [("sinusoid", sizes[-1])]
    rows: list[Row] = []
    peaks, same = [], []
    with tempfile.TemporaryDirectory(dir=workdir) as d:
        d = Path(d)
        for method, mp in cases:
            side = int(math.sqrt(mp * 1e6 * 3 / 4))
            h, w = side, side * 4 // 3
            files = render_checker(d / f"c{mp}", height=h, width=w, method=method)
            outs = {}
            for mode, extra in (("tiled", ["--tile-rows", "auto", "--memory", budget]),
                                ("whole", ["--tile-rows", "off"])):
                if mode == "whole" and mp > WHOLE_UP_TO_MP:
                    continue
                out = d / f"{mode}{mp}"
                flats = ["--black", files[-2], "--white", files[-1]] if method == "checker" else []
                caps = files[:-2] if flats else files
                rc, peak, dt, err = peak_run(["separate", *caps, *flats, "--method", method,
                                              "--out", out, "-q", *extra])
                meta = json.loads((out / "direct.exr.meta.json").read_text()) if rc == 0 else {}
                rows.append(Row(STAGE, f"separate {method}, {len(caps)} x {mp} MP 16-bit RGB "
                                       f"({w}x{h}){' + black/white' if flats else ''}",
                                f"{mode} ({' '.join(extra)}), peak RSS GB",
                                None if mode == "tiled" else "untiled separate", "megapixels",
                                mp, dt, (dt,), peak / 1e9, "ok" if rc == 0 else "failed",
                                {"tiles": meta.get("tiles"), "stderr": err[-300:]}))
                if rc == 0:
                    outs[mode] = out
                if mode == "tiled":
                    peaks.append((f"{method} {mp} MP", peak))
            if len(outs) == 2:
                same.append(all((outs["tiled"] / f).read_bytes() == (outs["whole"] / f).read_bytes()
                                for f in FILES))
            for f in files:
                f.unlink()
            for o in outs.values():
                for f in o.iterdir():
                    f.unlink()
    worst = max((p for _, p in peaks), default=math.nan)
    limit = parse_memory(budget)
    checks = [Check(f"[reported] separate by bands, 8 checker captures of "
                    f"{', '.join(map(str, sizes))} MP and 3 sinusoids of {sizes[-1]} MP: peak RSS "
                    f"<= the {budget} budget at every size", worst / 1e9, limit / 1e9,
                    all(p <= limit for _, p in peaks) and len(peaks) == len(cases),
                    ", ".join(f"{k}: {p / 1e9:.2f} GB" for k, p in peaks)),
              Check("[reported] separate by bands: direct/global/mask byte-identical to the "
                    "untiled run", float(sum(same)), float(len(same)), all(same) and bool(same),
                    f"{sum(same)}/{len(same)} runs identical")]
    return rows, checks
