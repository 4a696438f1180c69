"""Projector patterns: exact complements, lit fractions, periodic cell composition, CLI."""

import json

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture import io
from lumigraph.capture import patterns as pt


def test_checker_complements_and_shifts_visit_every_phase():
    ps = pt.checker_set((48, 24), square=6, shifts=3)
    m = len(ps) // 2
    assert len(ps) == 18 and ps.complement_of[:m] == tuple(range(m, 2 * m))
    assert np.all(ps.images[:m] + ps.images[m:] == 1.0)
    # every pixel is on in exactly half of the images, and each shift is distinct
    assert np.all(ps.images.sum(axis=0) == m)
    assert len({im.tobytes() for im in ps.images}) == len(ps)


def test_block_sinusoid_stripe_occluder():
    b = pt.block_set((16, 16), alpha=0.25, tile=4)
    assert all(a == 0.25 for a in b.lit_fraction)
    assert np.all(b.images.sum(axis=0) == 4)  # each pixel lit in 4 of the 16 shifts
    s = pt.sinusoid_set((12, 3), period=6)
    np.testing.assert_allclose(s.images.sum(axis=0), 1.5, atol=1e-6)
    assert pt.stripe_set((8, 2), period=4).lit_fraction == (0.5,)
    o = pt.occluder_set((8, 2), period=4, width=1)
    assert np.all((1 - o.images).sum(axis=0) == 1)  # every pixel shadowed exactly once


def test_cell_weights_recompose_patterns_exactly():
    n = 4
    for ps in (pt.checker_set((16, 12), square=2, shifts=2), pt.sinusoid_set((16, 12), period=4),
               pt.occluder_set((16, 12), period=4)):
        for im in ps.images:
            w = pt.cell_weights(im, cell=1, period_cells=n)
            y, x = np.mgrid[0:12, 0:16]
            np.testing.assert_array_equal(w[y % n, x % n], im)
    with pytest.raises(ValueError, match="periodic"):
        pt.cell_weights(pt.stripe_set((16, 4), period=8).images[0], cell=1, period_cells=4)


def test_patterns_cli_writes_pngs_and_stack(tmp_path):
    r = lumigraph("separate", "patterns", "--kind", "checker", "--size", "64x48", "--square", "8",
                  "--shifts", "2", "--out", tmp_path / "p", "-q")
    assert r.returncode == 0, r.stderr
    st = json.loads((tmp_path / "p" / "stack.json").read_text())
    assert len(st["images"]) == 8 and st["pattern"]["complement_of"][0] == 4
    im = io.read_image(tmp_path / "p" / st["images"][0])
    assert im.shape == (48, 64) and im.dtype == np.uint8 and set(np.unique(im)) == {0, 255}
    assert_clean_error(lumigraph("separate", "patterns", "--square", "7", "--shifts", "2",
                                 "--out", tmp_path / "q"), "square")
    assert not (tmp_path / "q").exists()


@pytest.mark.parametrize("make, kw, where, flags, flag", [
    (pt.checker_set, dict(square=7, shifts=2), "square", ["--square", "7", "--shifts", "2"], "--square"),
    (pt.checker_set, dict(square=8, shifts=0), "shifts", ["--shifts", "0"], "--shifts"),
    (pt.block_set, dict(alpha=1.5), "alpha", ["--kind", "block", "--alpha", "1.5"], "--alpha"),
    (pt.block_set, dict(alpha=0.3, tile=1), "tile",
     ["--kind", "block", "--alpha", "0.3", "--tile-cells", "1"], "--tile-cells"),
    (pt.block_set, dict(alpha=0.3, cell=0), "cell",
     ["--kind", "block", "--alpha", "0.3", "--square", "0"], "--square"),
    (pt.sinusoid_set, dict(period=2), "period", ["--kind", "sinusoid", "--period", "2"], "--period"),
    (pt.stripe_set, dict(period=1), "period", ["--kind", "stripe", "--period", "1"], "--period"),
    (pt.occluder_set, dict(period=5, width=2), "period",
     ["--kind", "occluder", "--period", "5", "--width", "2"], "--period"),
    (pt.occluder_set, dict(width=0), "width", ["--kind", "occluder", "--width", "0"], "--width")])
def test_pattern_library_names_the_argument_and_the_cli_the_flag(tmp_path, make, kw, where,
                                                                 flags, flag):
    from lumigraph.capture.errors import InputError

    with pytest.raises(InputError) as e:
        make((16, 12), **kw)
    assert e.value.where == where
    assert_clean_error(lumigraph("separate", "patterns", *flags, "--out", tmp_path / "q"), flag)
    assert not (tmp_path / "q").exists()


def test_patterns_alpha_is_checked_whatever_the_kind(tmp_path):
    assert_clean_error(lumigraph("separate", "patterns", "--kind", "checker", "--alpha", "0",
                                 "--out", tmp_path / "q"), "--alpha", "> 0 and < 1")
    assert not (tmp_path / "q").exists()
