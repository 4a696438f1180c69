"""Issue 19's check at a quarter of its size: a 9 x 25 MP bracket merges by
bands within its memory budget, with the untiled merge's radiance on a crop.

The issue's own figure (9 x 100 MP, peak <= 1.5 GB) takes about 4 minutes on
two cores and 4 GB of scratch disk, so it is a bench item
(:func:`lumigraph.hdr.bench_tiles.merge_100mp_check`, in ``make bench``).
Here 9 x 25 MP (8-bit RGB, 675 MB of TIFFs, rendered band by band so the test
never holds an image): whole, its working set is ~1.75 GB
(:func:`lumigraph.hdr.tiled.merge_bytes_per_pixel` x pixels); by bands with
``--memory 600MB`` the command's own peak (its ``VmHWM``) must stay within
those 600 MB, the budget the band height was chosen from, a bound that scales
with the band, not with the image.
"""

from __future__ import annotations

import json

import pytest

from lumigraph.capture.tiles import parse_memory
from lumigraph.hdr.bench_tiles import crop_matches, peak_run, render_bracket
from lumigraph.hdr.response import ResponseCurve
from lumigraph.hdr.tiled import merge_bytes_per_pixel

H, W = 4330, 5773  # 25 MP at 4:3
BUDGET = "600MB"


@pytest.mark.slow
def test_25mp_bracket_merges_by_bands_within_the_budget(tmp_path):
    render_bracket(tmp_path / "b", height=H, width=W)
    ResponseCurve.linear(8, 1).save(tmp_path / "r.json")
    rc, peak, _, err = peak_run(["hdr", "merge", tmp_path / "b", "--response",
                                 tmp_path / "r.json", "--out", tmp_path / "t.exr", "-q",
                                 "--memory", BUDGET])
    assert rc == 0, err
    meta = json.loads((tmp_path / "t.exr.meta.json").read_text())
    tiles = meta["tiles"]
    assert tiles["tiled"] and "over the" in tiles["reason"] and tiles["bands"] >= 3
    whole = sum(merge_bytes_per_pixel(9, 3, 1)) * H * W
    assert whole > 2 * parse_memory(BUDGET)  # the budget is far below the untiled working set
    assert peak <= parse_memory(BUDGET), f"peak {peak / 1e9:.2f} GB"
    assert meta["quality"]["clipped_everywhere"] > 0 and meta["quality"]["black_everywhere"] > 0
    assert crop_matches(tmp_path / "b", tmp_path / "t.exr", rows=tiles["rows"], width=W)
