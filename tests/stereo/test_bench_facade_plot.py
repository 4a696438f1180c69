"""The facade bench's picture: VDTM per new view against the issue's two
references, with the 2 dB target (stereo/bench_facade.py ``_plot``)."""

from __future__ import annotations

import numpy as np

from lumigraph.capture.bench import Row
from lumigraph.capture.io import read_image
from lumigraph.stereo.bench_facade import _plot, stage

BLUE = np.array([31, 119, 180])  # the layer's markers (#1f77b4)


def row(case, method, value):
    return Row("facade", case, method, None, "", None, float("nan"), (), value, "ok")


def test_the_picture_draws_each_view_against_both_references(tmp_path):
    rows = []
    for case, (blend, layer, uni, near) in {"facade s0 view_0 (tuned)": (30, 31, 28, 27),
                                            "facade s1 view_0 (reported)": (33, 35, 28, 30)}.items():
        rows += [row(case, "VDTM blend: PSNR dB", blend),
                 row(case, "VDTM blend + reflection layer: PSNR dB", layer),
                 row(case, "uniform average: PSNR dB", uni),
                 row(case, "nearest photograph: PSNR dB", near),
                 row(case, "solve, exact marks", 1e-15)]  # a single figure: not drawn
    path = tmp_path / "facade.png"
    _plot(path, stage(quick=True), rows)
    img = read_image(path)[..., :3].astype(int)
    # the markers are solid; the dashed target line is thin and anti-aliased
    assert (np.abs(img - BLUE).sum(-1) < 30).sum() > 20
    r, g, b = np.moveaxis(img, -1, 0)
    assert ((r > 150) & (g < 120) & (b < 120)).sum() > 20


def test_the_picture_is_written_without_vdtm_rows(tmp_path):
    path = tmp_path / "facade.png"
    _plot(path, stage(quick=True), [row("house s1 (tuned)", "solve, exact marks", 1e-15)])
    assert path.stat().st_size > 0
