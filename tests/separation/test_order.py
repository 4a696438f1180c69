"""Separation whatever the file order: complements found from the captures (issue 16).

The documented order is ``capture.patterns`` order (boards, then complements);
a sorted listing puts each board next to its complement. Every permutation
must give the same direct, global and mask, bit for bit (the stack is put in
an order fixed by its content before any floating-point reduction).
"""

import numpy as np
import pytest
from conftest import lumigraph

from lumigraph.capture import io
from lumigraph.capture.errors import InputError
from lumigraph.capture.patterns import checker_set
from lumigraph.capture.render import render
from lumigraph.separation import separate
from lumigraph.separation.pairing import find_pairs


def _sets(s):
    top = 2 ** s.bit_depth - 1
    ims = {n: im.astype(np.float32) / top for n, im in zip(s.image_names, s.images, strict=True)}
    return {m: np.stack([ims[n] for n in names])[..., None] for m, names in s.stack["sets"].items()}, top


@pytest.fixture(scope="module")
def scene():
    return render("projector")


@pytest.fixture(scope="module")
def noisy():
    return render("projector", full_well=200.0, read_noise=60.0, repeats=2)


def _same(r0, r1):
    np.testing.assert_array_equal(r0.direct, r1.direct)
    np.testing.assert_array_equal(r0.global_, r1.global_)
    np.testing.assert_array_equal(r0.mask, r1.mask)


def _orders(n, seed):
    rng = np.random.default_rng(seed)
    glob = [k for i in range(n // 2) for k in (i, i + n // 2)]  # board next to its complement
    return [glob, glob[::-1]] + [list(rng.permutation(n)) for _ in range(4)]


@pytest.mark.parametrize("which", ["clean", "noisy"])
def test_checker_any_order_is_bit_identical_to_the_documented_one(scene, noisy, which):
    s = scene if which == "clean" else noisy
    sets, top = _sets(s)
    a = sets["checker"]
    ref = separate(a, method="checker", quant_step=1 / top)  # documented order, pairs found
    lay = separate(a, method="checker", quant_step=1 / top,
                   complement_of=s.stack["patterns"]["checker"]["complement_of"])
    if which == "clean":  # with repeated frames either copy of a complement is a valid partner
        _same(ref, lay)
    assert ref.params["pairs_source"] == "found from the captures"
    for order in _orders(len(a), seed=1 if which == "clean" else 2):
        _same(ref, separate(a[order], method="checker", quant_step=1 / top))
        comp = find_pairs(a[order]).complement_of
        # found pairs are true complements (the rendered layout; with repeated
        # frames, either copy of the complement pattern)
        truth = s.stack["patterns"]["checker"]["complement_of"]
        for i, j in enumerate(comp):
            assert truth[order[i]] % 8 == order[j] % 8


def test_checker_maxmin_and_other_methods_any_order(scene):
    sets, top = _sets(scene)
    a = sets["checker"]
    ref = separate(a, method="checker", estimator="maxmin", quant_step=1 / top)
    for order in _orders(len(a), seed=3)[:3]:
        _same(ref, separate(a[order], method="checker", estimator="maxmin", quant_step=1 / top))
    import itertools

    sn = sets["sinusoid"]
    ref = separate(sn, method="sinusoid", quant_step=1 / top)
    assert all(abs(v - 120) < 10 for v in ref.params["phase_spacing_deg"])
    for perm in itertools.permutations(range(3)):
        _same(ref, separate(sn[list(perm)], method="sinusoid", quant_step=1 / top))
    oc = sets["occluder"]
    ref = separate(oc, method="occluder", quant_step=1 / top)
    for order in ([3, 2, 1, 0], [1, 3, 0, 2]):
        _same(ref, separate(oc[order], method="occluder", quant_step=1 / top))


def test_black_level_pairs_and_order(tmp_path):
    """A black level b adds b x the complement to every board: the pair sum is
    (1 + b) W for every pair, so the pairing is unchanged; the contrast
    shrinks by (1 - b) and the pairs stay decisive while it is above 6 noise
    deviations."""
    s = render("projector", b=0.15)
    sets, top = _sets(s)
    a = sets["checker"]
    ref = separate(a, method="checker", b=0.15, quant_step=1 / top)
    for order in _orders(len(a), seed=4)[:3]:
        _same(ref, separate(a[order], method="checker", b=0.15, quant_step=1 / top))
    # synthetic: b up to 0.9 with sigma = 0.002 and contrast (1 - b) 0.3 = 0.03: pairs found
    ps = checker_set((32, 32), square=4, shifts=2)
    rng = np.random.default_rng(8)
    for b in (0.5, 0.9):
        ims = np.stack([0.3 * (b + (1 - b) * p) + (1 + b) / 2 * 0.2 for p in ps.images])
        ims = (ims + rng.normal(0, 0.002, ims.shape))[..., None].astype(np.float32)
        perm = rng.permutation(len(ims))
        got = find_pairs(ims[perm], noise=0.002)
        assert got.decisive
        assert [perm[j] for j in got.complement_of] == [ps.complement_of[k] for k in perm]


def test_cli_glob_order_equals_documented_order(scene, tmp_path):
    """The issue's case: files named so that a sorted listing puts each board
    next to its complement (checker_dx3_dy0.png, checker_dx3_dy0_inv.png, ...)."""
    d = tmp_path / "scene"
    scene.save(d)
    names = scene.stack["sets"]["checker"]
    m = len(names) // 2
    cap = tmp_path / "cap"
    cap.mkdir()
    offs = scene.stack["patterns"]["checker"]["offsets"]
    for k, n in enumerate(names):
        dx, dy = offs[k % m]
        dest = cap / f"checker_dx{dx}_dy{dy}{'_inv' if k >= m else ''}.png"
        dest.write_bytes((d / n).read_bytes())
    listed = sorted(cap.glob("*.png"))
    assert listed[1].name.endswith("_inv.png")
    r1 = lumigraph("separate", *listed, "--b", "0", "--out", tmp_path / "glob", "-q")
    r0 = lumigraph("separate", *[d / n for n in names], "--b", "0", "--out", tmp_path / "doc", "-q")
    assert r0.returncode == 0 and r1.returncode == 0, r0.stderr + r1.stderr
    for f in ("direct.exr", "global.exr"):
        np.testing.assert_array_equal(io.read_exr(tmp_path / "glob" / f), io.read_exr(tmp_path / "doc" / f))


def test_unpairable_captures_are_refused(scene, tmp_path):
    sets, top = _sets(scene)
    a, names = sets["checker"], list(scene.stack["sets"]["checker"])
    # a missing complement (checker_05's partner checker_01 left out)
    keep = [0, 2, 3, 4, 5, 6, 7]
    with pytest.raises(InputError) as e:
        separate(a[keep], method="checker", names=[names[k] for k in keep])
    assert e.value.where == "checker_05.png" and "no complement" in e.value.problem
    # mixed patterns: a sinusoid among the boards
    mixed = np.concatenate([a, sets["sinusoid"][:2]])
    with pytest.raises(InputError) as e:
        separate(mixed, method="checker", names=names + ["sinusoid_0.png", "sinusoid_1.png"])
    assert e.value.where.startswith("sinusoid_")
    # the all-black and all-white frames globbed in with the boards: complements of
    # each other, but not patterns
    flat = np.concatenate([a, sets["flat"]])
    with pytest.raises(InputError) as e:
        separate(flat, method="checker", names=names + ["black.png", "white.png"])
    assert e.value.where in ("black.png", "white.png") and "all-" in e.value.problem
    # the textbook max/min needs no pairs: it runs
    assert separate(a[keep], method="checker", estimator="maxmin").direct.shape == a.shape[1:]
    # a layout the captures contradict
    with pytest.raises(InputError) as e:
        separate(a, method="checker", complement_of=[1, 0, 3, 2, 5, 4, 7, 6], names=names)
    assert "layout" in e.value.problem
    # the same sinusoid phase twice
    sn = sets["sinusoid"]
    with pytest.raises(InputError) as e:
        separate(sn[[0, 1, 1]], method="sinusoid", names=["s0", "s1", "s1b"])
    assert e.value.where == "s1b" and "same sinusoid phase" in e.value.problem


def test_sets_without_complements_are_not_paired():
    """Block patterns (lit fraction 1/4) have no complements: nothing is paired,
    nothing refused, the max/min over shifts is used whatever the order."""
    from lumigraph.capture.patterns import block_set

    ps = block_set((32, 32), alpha=0.25, tile=4)
    ims = np.stack([0.6 * p + 0.25 * 0.2 for p in ps.images])[..., None].astype(np.float32)
    assert set(find_pairs(ims).complement_of) == {-1}
    ref = separate(ims, method="checker", alpha=0.25)
    assert ref.params["estimator"] == "maxmin"
    perm = np.random.default_rng(5).permutation(len(ims))
    _same(ref, separate(ims[perm], method="checker", alpha=0.25))
    np.testing.assert_allclose(ref.direct, 0.6, atol=1e-5)
