"""`separate` by bands of rows gives the untiled arrays, bit for bit (issue 19)."""

import numpy as np
import pytest

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
    # the black/white frames read by bands too: the black level's percentile and median
    # from exact order statistics
    del kw["black"], kw["white"]
    _same(whole, separate_bands(_reader(ims), height=h, rows=13, count=len(ims), **kw,
                                read_flat=lambda y0, y1: (flat["black"][y0:y1],
                                                          flat["white"][y0:y1])))


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


def _synthetic(width, channels, method="checker"):
    """A stack made row by row (no whole image is ever held): the reader of rows
    ``y0:y1``, any band, the same values; 8 checker captures or 3 sinusoids."""
    pat = np.asarray(checker_set((width, 8), square=4, shifts=2).images, np.float32)  # period 8
    xs = np.arange(width, dtype=np.float32)

    def read(y0, y1):
        y = np.arange(y0, y1, dtype=np.float32)[:, None, None]
        x = xs[None, :, None]
        c = np.arange(channels, dtype=np.float32)
        d = 0.4 + 0.3 * np.sin(0.05 * x + 0.07 * y + c)
        g = 0.2 + 0.1 * np.cos(0.03 * x - 0.04 * y + c)
        noise = 0.005 * np.sin(12.9898 * x + 78.233 * y + 3.1 * c)  # deterministic per pixel
        if method == "sinusoid":
            p = np.stack([0.5 + 0.5 * np.cos(2 * np.pi * (xs[None, :] + y[..., 0]) / 8 + ph)
                          for ph in (0, 2 * np.pi / 3, 4 * np.pi / 3)])
        else:
            p = pat[:, np.arange(y0, y1) % 8]
        return (d * p[..., None] + 0.5 * g + noise).astype(np.float32)

    return read


@pytest.mark.parametrize(("method", "n", "tile"), [("checker", 8, 16), ("sinusoid", 3, 6)])
def test_outputs_by_rows_peak_memory_grows_with_the_band_not_the_image(tmp_path, method, n, tile):
    """Files written band by band: the per-pixel passes hold one band (and, for the
    spatial residue check, its halo), whatever the height."""
    import tracemalloc

    from lumigraph.separation.residue import PERCENTILE_BYTES
    from lumigraph.separation.result import Separation, SeparationWriter
    from lumigraph.separation.separate import residue_window
    from lumigraph.separation.tiled import separate_rows

    w, c, rows = 200, 3, 5
    read = _synthetic(w, c, method)
    peaks = {}
    for h in (128, 1024):  # 8x the pixels, the same band; 5 rows divide neither
        seen = []

        def write(d, g, m, out=None, seen=seen):
            if not seen:  # the analysis is done: from here on the per-pixel passes
                tracemalloc.reset_peak()
                seen.append(tracemalloc.get_traced_memory()[0])
            out.write(d, g, m)

        tracemalloc.start()
        try:
            with SeparationWriter(tmp_path / str(h), width=w, height=h, channels=c) as out:
                r = separate_rows(read, height=h, rows=rows, count=n, noise_sigma=0.005,
                                  method=method, tile=tile,
                                  write=lambda *band, out=out: write(*band, out=out))
                peaks[h] = tracemalloc.get_traced_memory()[1] - seen[0]
                out.finish(meta={}, method=r.method, params=r.params, quality=r.quality,
                           warnings=r.warnings)  # (hashes the files a chunk at a time)
        finally:
            tracemalloc.stop()
    # a band's working set as the command's plan counts it (per pixel: the captures as
    # codes and float32 copies with their temporaries, the outputs and the writers' copies;
    # without pairs the box means too, on the band and its halo)
    spatial = method != "checker"
    band = (rows + 2 * (residue_window(tile) // 2 if spatial else 0)) * w * c * (
        n * (4 + 16) + 56 + (48 if spatial else 0))
    whole_outputs = 1024 * w * (8 * c + 1)  # what assembling the outputs would hold
    assert band < whole_outputs / 4  # the check below tells the two apart
    assert peaks[1024] <= peaks[128] + band / 4, peaks
    # the spatial check's two exact percentiles hold fixed-size histograms besides
    assert peaks[1024] <= band + (2 * PERCENTILE_BYTES if spatial else 0), peaks
    # and the files are the untiled run's
    whole = separate(read(0, 128), noise_sigma=0.005, method=method, tile=tile)
    got = Separation.load(tmp_path / "128")
    assert got.direct.tobytes() == whole.direct.tobytes()
    assert got.mask.tobytes() == whole.mask.tobytes()


def test_save_writes_what_the_whole_image_writers_write(tmp_path):
    """`Separation.save` goes through the banded writer: the EXRs are `write_exr`'s bytes,
    the mask `write_image`'s pixels; a writer left by an error leaves nothing behind."""
    from lumigraph.capture import io
    from lumigraph.separation.result import Separation, SeparationWriter

    for ch in (1, 3):
        s = separate(_synthetic(40, ch)(0, 24))
        s.save(tmp_path / str(ch), meta={})
        io.write_exr(tmp_path / f"d{ch}.exr", s.direct)
        assert (tmp_path / str(ch) / "direct.exr").read_bytes() == \
            (tmp_path / f"d{ch}.exr").read_bytes()
        assert (io.read_image(tmp_path / str(ch) / "mask.png") == s.mask).all()
        assert Separation.load(tmp_path / str(ch)).global_.tobytes() == s.global_.tobytes()
    with pytest.raises(RuntimeError), SeparationWriter(tmp_path / "x", width=4, height=4,
                                                       channels=1) as out:
        out.write(np.zeros((2, 4, 1), np.float32), np.zeros((2, 4, 1), np.float32),
                  np.zeros((2, 4), np.uint8))
        raise RuntimeError("cut short")
    assert list((tmp_path / "x").iterdir()) == []


@pytest.mark.parametrize(("method", "tile", "take"), [
    ("sinusoid", 16, None), ("sinusoid", 6, None), ("single", 16, None), ("single", 6, None),
    ("occluder", 16, None),  # its lit fraction measured by bands (a percentile, counts)
    ("checker", 16, 3)])  # 3 checker boards, no complement among them: max/min, spatial check
def test_spatial_residue_methods_by_bands_are_the_untiled_run(method, tile, take):
    """Without complement pairs the residue check is spatial (a box of ~tile px, a
    percentile floor): by bands with a halo, and `single`'s tiles across band edges."""
    s = render("projector")
    q = 2 ** s.bit_depth - 1
    ims = np.stack([s.images[s.image_names.index(n)].astype(np.float32) / q
                    for n in s.stack["sets"][method][:take]])[::-1, ..., None]  # reversed order
    h = ims.shape[1]
    kw = {"method": method, "noise_sigma": 1e-3, "quant_step": 1.0 / q, "saturation": 0.98,
          "tile": tile, "estimator": "maxmin"}
    whole = separate(ims, **kw)
    assert whole.quality["residue"]["check"].startswith("spatial")
    for rows in (13, 5):  # neither divides 96 nor is a multiple of the tile
        _same(whole, separate_bands(_reader(ims), height=h, rows=rows, count=len(ims), **kw))


def test_sinusoid_larger_than_the_pairing_sample_by_bands():
    # 210 x 160 x 3 values per image > pairing.SAMPLES: the phase check's sample is gathered
    x = np.arange(160)[None, :, None]
    y = np.arange(210)[:, None, None]
    rng = np.random.default_rng(2)
    d = rng.uniform(0.2, 0.7, (210, 160, 3))
    g = rng.uniform(0.05, 0.3, (210, 160, 3))
    ims = np.stack([d * (0.5 + 0.5 * np.cos(2 * np.pi * (x + y) / 8 + p)) + 0.5 * g
                    for p in (4 * np.pi / 3, 0, 2 * np.pi / 3)])
    ims = (ims + rng.normal(0, 0.01, ims.shape)).astype(np.float32)
    whole = separate(ims, method="sinusoid", noise_sigma=0.01)
    assert len(whole.params["phase_spacing_deg"]) == 3
    _same(whole, separate_bands(_reader(ims), height=210, rows=37, count=3, method="sinusoid",
                                noise_sigma=0.01))


def test_box_mean_and_percentile_by_bands_are_the_whole_image():
    from lumigraph.separation.residue import Percentile, box_mean, strided_percentile

    rng = np.random.default_rng(5)
    x = rng.lognormal(0, 2, (47, 23, 3)).astype(np.float32)  # 5 decades
    whole = box_mean(x, 9)
    p = Percentile()
    parts = []
    for y0 in range(0, 47, 6):
        y1 = min(47, y0 + 6)
        r0, r1 = max(0, y0 - 4), min(47, y1 + 4)
        s0 = r0 if r0 == 0 else r0 + 4
        parts.append(box_mean(x[r0:r1], 9, top=r0 == 0, bottom=r1 == 47)[y0 - s0:y1 - s0])
        p.add_high(parts[-1], y0=y0)
    assert np.concatenate(parts).tobytes() == whole.tobytes()
    for y0, part in zip(range(0, 47, 6), parts, strict=True):
        p.add_low(part, y0=y0)
    assert p.result() == strided_percentile(whole)
    # the same order statistics as numpy's percentile: equal within float32 rounding
    ref = np.percentile(np.abs(whole[::4, ::4]), 99)
    assert abs(p.result() - ref) <= 2 * np.finfo(np.float32).eps * ref


@pytest.mark.parametrize("method", ["checker", "sinusoid", "single", "occluder"])
def test_cli_by_rows_from_tiffs_is_the_untiled_run(run_cli, tmp_path, method):
    """`separate --tile-rows 13` reading 16-bit TIFFs by rows writes the bytes of `--tile-rows off`."""
    import json

    import tifffile

    s = render("projector")
    names = s.stack["sets"][method]
    files = []
    for n in [*names, "black.png", "white.png"]:
        f = tmp_path / n.replace(".png", ".tif")
        tifffile.imwrite(f, s.images[s.image_names.index(n)], rowsperstrip=8)
        files.append(f)
    common = ["separate", *files[:-2], "--method", method, "--black", files[-2], "--white",
              files[-1], "--tile", "6", "-q"]
    for t in ("off", "13"):
        r = run_cli(*common, "--tile-rows", t, "--out", tmp_path / t)
        assert r.returncode == 0, r.stderr
    for f in ("direct.exr", "global.exr", "mask.png"):
        assert (tmp_path / "13" / f).read_bytes() == (tmp_path / "off" / f).read_bytes()
    meta = json.loads((tmp_path / "13" / "direct.exr.meta.json").read_text())
    tiles = meta["tiles"]
    assert tiles["tiled"] and tiles["rows"] == 13 and tiles["read_whole"] == []
    assert meta["params"]["b_source"].startswith("measured")  # black/white read by rows
    if method == "checker":  # a torch estimator runs whole: refused by bands, before any work
        from types import SimpleNamespace

        from lumigraph.capture.errors import InputError
        from lumigraph.separation.cli import _plan

        args = SimpleNamespace(tile_rows=8, method=method, memory=None, tile=6,
                               estimator="pairs")
        with pytest.raises(InputError) as e:
            _plan(args, (files[:-2], None, None, None, None, None),
                  SimpleNamespace(uses_torch=True, name="torch-cpu"))
        assert e.value.where == "device" and "--tile-rows off" in e.value.problem
