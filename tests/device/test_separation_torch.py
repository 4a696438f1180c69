"""``separate`` on the torch path (torch's CPU device) against numpy.

Bounds, from the arithmetic (``u = 2⁻²⁴``, float32):

- checker (pairs and max/min) and occluder: the torch path performs numpy's
  operations in numpy's order and precision (stack sums one image after
  another, scalars as float32, the pair means in float64 as numpy promotes
  them; max/min are exact), and IEEE operations are correctly rounded on
  both, so the results are equal: bound 0. A threshold (a pair's
  decisiveness) therefore also decides alike, which a bound > 0 could not
  promise.
- sinusoid: numpy forms ``Σ_k cos φ_k I_k`` with a BLAS dot (its own order,
  maybe fused multiply-adds), torch with products summed in turn. Each of the
  two 3-term sums is within ``3u·Σ|I_k| ≤ 9u·max I`` of exact, so the two
  paths' sums differ by ``18u·max I``; the amplitude ``(2/3)·|(c, s)|`` moves
  by at most ``(2/3)·√2`` times that (≈ 17u·max I) plus its own rounding
  (4u·max I); ``L_d = amp/(0.5(1 − b))`` scales this by ``2/(1 − b)``, and
  ``L_g`` (the same mean minus ``L_d``) by as much plus one rounding of its
  own size.
- single: the tile means' summation order (bound in its test).
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("kornia")

from lumigraph.capture.patterns import checker_set  # noqa: E402
from lumigraph.separation import nayar2006, nayar2006_torch  # noqa: E402
from lumigraph.separation.separate import separate  # noqa: E402

U = 2.0 ** -24
H, W = 36, 52  # asymmetric


def _scene(seed=0, channels=3):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.1, 1.0, (H, W, channels)), rng.uniform(0.05, 0.5, (H, W, channels))


def _checker_stack(seed=0, noise=0.01, b=0.05):
    d, g = _scene(seed)
    ps = checker_set((W, H), square=6, shifts=3)
    rng = np.random.default_rng(seed + 100)
    ims = np.stack([d * (b + (1 - b) * p[..., None]) + (b + (1 - b) * 0.5) * g for p in ps.images])
    ims = ims + rng.normal(0, noise, ims.shape)
    return ims.astype(np.float32), list(ps.complement_of)


@pytest.mark.parametrize("estimator", ["pairs", "maxmin"])
def test_checker_equals_numpy(estimator):
    ims, comp = _checker_stack()
    ref = nayar2006.checker(ims, complement_of=comp, estimator=estimator, b=0.05)
    got = nayar2006_torch.checker(ims, complement_of=comp, estimator=estimator, b=0.05,
                                  device="torch-cpu")
    for r, g in zip(ref[:2], got[:2], strict=True):
        assert g.dtype == np.float32 and g.shape == (H, W, 3)
        np.testing.assert_array_equal(g, r)
    for key in ("l_plus", "l_minus", "pairs_used"):
        if key in ref[2]:
            np.testing.assert_array_equal(got[2][key], ref[2][key])


def test_occluder_equals_numpy():
    d, g = _scene(1, channels=1)
    frames = []
    for k in range(6):  # a bar sweeping across, lit fraction ~ 5/6
        lit = np.ones((H, W, 1))
        lit[:, k * W // 6:(k + 1) * W // 6] = 0
        frames.append(d * lit + (5 / 6) * g)
    ims = np.asarray(frames, np.float32)
    ref = nayar2006.occluder(ims)
    got = nayar2006_torch.occluder(ims, device="torch-cpu")
    np.testing.assert_array_equal(got[0], ref[0])
    np.testing.assert_array_equal(got[1], ref[1])
    assert got[2]["alpha"] == ref[2]["alpha"]


def test_sinusoid_within_float32_rounding():
    d, g = _scene(2)
    b = 0.05
    x = np.linspace(0, 17, W)[None, :, None]
    ims = np.stack([d * (b + (1 - b) * (0.5 + 0.5 * np.cos(x + p))) + 0.5 * (1 + b) * g
                    for p in (0, 2 * np.pi / 3, 4 * np.pi / 3)]).astype(np.float32)
    ref = nayar2006.sinusoid(ims, b=b)
    got = nayar2006_torch.sinusoid(ims, b=b, device="torch-cpu")
    top = float(ims.max())
    tol_d = 2 / (1 - b) * (17 + 4) * U * top
    np.testing.assert_allclose(got[0], ref[0], rtol=0, atol=tol_d)
    np.testing.assert_allclose(got[1], ref[1], rtol=0, atol=tol_d + 4 * U * float(np.abs(ref[1]).max()))


def test_separate_end_to_end_equals_numpy():
    ims, _ = _checker_stack(seed=3)
    order = np.random.default_rng(4).permutation(len(ims))  # pairs found from the data
    ref = separate(ims[order], method="checker", noise_sigma=0.01, saturation=2.0)
    got = separate(ims[order], method="checker", noise_sigma=0.01, saturation=2.0,
                   device="torch-cpu")
    np.testing.assert_array_equal(got.direct, ref.direct)
    np.testing.assert_array_equal(got.global_, ref.global_)
    np.testing.assert_array_equal(got.mask, ref.mask)
    assert got.params["device"] == "torch-cpu" and "device" not in ref.params


@pytest.mark.parametrize("tile", [8, 16])
def test_single_within_float32_rounding(tile):
    """Tile means of ``k`` sorted values: numpy sums them pairwise, torch in
    its own order; each sum is within ``(k − 1)u·Σ|x|`` of exact, so the
    means differ by at most ``2(k − 1)u·M + 2u·M`` (``M`` the largest value).
    The bilinear interpolation of the tile values adds ``8u·M`` and one ulp
    of a tile position times the largest step between tiles (``≤ M``).
    ``L_d = (L⁺ − L⁻)/(1 − b)`` doubles δ and divides by ``1 − b``;
    ``L_g = (L⁻ − b L⁺)/(a(1 − b))`` with ``a = b + (1 − b)α``."""
    rng = np.random.default_rng(5)
    stripe = (np.arange(W) % 4 < 2).astype(float)
    img = (rng.uniform(0.3, 0.9, (H, W, 3)) * stripe[None, :, None]
           + 0.1 * rng.uniform(0.5, 1.0, (H, W, 3)))[None].astype(np.float32)
    b, alpha = 0.05, 0.5
    ref = nayar2006.single(img, tile=tile, b=b, alpha=alpha)
    got = nayar2006_torch.single(img, tile=tile, b=b, alpha=alpha, device="torch-cpu")
    M = float(img.max())
    k = max(1, round(0.2 * tile * tile))
    delta = (2 * (k - 1) + 2 + 8) * U * M + float(np.spacing(np.float32(max(H, W) / tile))) * M
    a = b + (1 - b) * alpha
    np.testing.assert_allclose(got[0], ref[0], rtol=0, atol=2 * delta / (1 - b) + 4 * U * M)
    np.testing.assert_allclose(got[1], ref[1], rtol=0,
                               atol=(1 + b) * delta / (a * (1 - b)) + 4 * U * M)
    sep = separate(img, method="single", tile=tile, device="torch-cpu")
    assert sep.params["device"] == "torch-cpu"


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
def test_cli_cuda_without_gpu_is_exit_2(tmp_path, capsys):
    from lumigraph.capture import io
    from lumigraph.separation.cli import main

    ims, _ = _checker_stack()
    files = []
    for k, im in enumerate(ims):
        files.append(tmp_path / f"c{k}.png")
        io.write_image(files[-1], np.clip(im * 200, 0, 255).astype(np.uint8))
    out = tmp_path / "sep"
    # in-process: a fresh interpreter per command costs seconds of torch import
    assert main([*map(str, files), "--out", str(out), "--device", "cuda"]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: --device") and "no CUDA GPU" in lines[0]
    assert not out.exists()
