"""`separate` by bands of rows gives the untiled arrays, bit for bit (issue 19)."""

import numpy as np
import pytest

from lumigraph.capture.errors import InputError
from lumigraph.capture.patterns import checker_set
from lumigraph.capture.render import render
from lumigraph.separation.separate import separate
from lumigraph.separation.tiled import separate_bands


def _same(whole, tiled):
    assert whole.direct.shape == tiled.direct.shape
    assert whole.direct.tobytes() == tiled.direct.tobytes()
    assert whole.global_.tobytes() == tiled.global_.tobytes()
    assert whole.mask.tobytes() == tiled.mask.tobytes()
    assert whole.params == tiled.params
    assert whole.quality == tiled.quality
    assert whole.warnings == tiled.warnings


def _reader(stack):
    return lambda y0, y1: stack[:, y0:y1]


def test_projector_scene_by_bands_is_the_untiled_run():
    s = render("projector")
    names = s.stack["sets"]["checker"]
    q = 2 ** s.bit_depth - 1
    ims = np.stack([s.images[s.image_names.index(n)].astype(np.float32) / q for n in names])
    ims = ims[..., None] if ims.ndim == 3 else ims
    ims = ims[np.random.default_rng(3).permutation(len(ims))]  # any file order
    h = ims.shape[1]
    flat = {k: s.images[s.image_names.index(f"{k}.png")].astype(np.float32) / q
            for k in ("black", "white")}
    flat = {k: v[..., None] if v.ndim == 2 else v for k, v in flat.items()}
    kw = {"noise_sigma": 1e-3, "quant_step": 1.0 / q, "saturation": 0.98, **flat}
    whole = separate(ims, **kw)
    assert whole.params["b_source"].startswith("measured")  # the flat frames are used
    for rows in (13, 1, h):  # 13 does not divide the height; 1 row; one band
        assert h % 13
        _same(whole, separate_bands(_reader(ims), height=h, rows=rows, count=len(ims), **kw))


@pytest.mark.parametrize("estimator", ["pairs", "maxmin"])
def test_larger_than_the_pairing_sample_by_bands(estimator):
    # 210 x 160 x 3 values per image > pairing.SAMPLES: the sample is gathered by bands
    ps = checker_set((160, 210), square=6, shifts=3)
    rng = np.random.default_rng(0)
    d = rng.uniform(0.1, 0.7, (210, 160, 3))
    g = rng.uniform(0.05, 0.3, (210, 160, 3))
    ims = np.stack([d * p[..., None] + 0.5 * g for p in ps.images])
    ims = (ims + rng.normal(0, 0.01, ims.shape)).astype(np.float32)
    whole = separate(ims, estimator=estimator, noise_sigma=0.01)
    tiled = separate_bands(_reader(ims), height=210, rows=37, count=len(ims),
                           estimator=estimator, noise_sigma=0.01)
    _same(whole, tiled)


def test_methods_not_done_by_bands_are_refused():
    ims = np.ones((3, 8, 8, 1), np.float32)
    with pytest.raises(InputError) as e:
        separate_bands(_reader(ims), height=8, rows=3, count=3, method="sinusoid")
    assert e.value.where == "method"


def test_cli_by_rows_from_tiffs_is_the_untiled_run(run_cli, tmp_path):
    """`separate --tile-rows 13` reading 16-bit TIFFs by rows writes the bytes of `--tile-rows off`."""
    import json

    import tifffile

    s = render("projector")
    names = s.stack["sets"]["checker"]
    files = []
    for n in [*names, "black.png", "white.png"]:
        f = tmp_path / n.replace(".png", ".tif")
        tifffile.imwrite(f, s.images[s.image_names.index(n)], rowsperstrip=8)
        files.append(f)
    common = ["separate", *files[:-2], "--black", files[-2], "--white", files[-1], "-q"]
    for t in ("off", "13"):
        r = run_cli(*common, "--tile-rows", t, "--out", tmp_path / t)
        assert r.returncode == 0, r.stderr
    for f in ("direct.exr", "global.exr", "mask.png"):
        assert (tmp_path / "13" / f).read_bytes() == (tmp_path / "off" / f).read_bytes()
    tiles = json.loads((tmp_path / "13" / "direct.exr.meta.json").read_text())["tiles"]
    assert tiles["tiled"] and tiles["rows"] == 13 and tiles["read_whole"] == []
    r = run_cli(*common[:-5], "--method", "sinusoid", "--tile-rows", "8", "--out", tmp_path / "s")
    from conftest import assert_clean_error

    assert_clean_error(r, "method", "--tile-rows off")
