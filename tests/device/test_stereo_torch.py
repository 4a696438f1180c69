"""``stereo match`` (SSD block matching, SGM's aggregation) and flow warping
on the torch path (torch's CPU device) against numpy/OpenCV and the C kernels.

Block matching, integer inputs: the cost volume is integer arithmetic (exact
window sums, an arithmetic shift or a float64 scale and truncation, as the
numpy path and the C kernel), so the encoded costs, and hence every
decision, are equal: bound 0. (Past 2³¹ per window sum OpenCV's int32 box
filter in the numpy path wraps; the torch path sums in int64 as the C kernel
does, and is compared with the kernel there.) Float inputs
holding integer values: squares and window sums are exact in float64 and in
float32, and the scaling is one float32 product on both sides: bound 0 again.
Other float inputs: both round a float64 window sum ``S`` to float32 and may
differ by one float32 ulp of it; scaled by ``unit/n`` and truncated, an
encoded cost moves by at most ``1 + 2⁻²²·c_max`` units (``c_max`` the
largest cost, ``2^(30 − nb)``).

Flow warping: bilinear and Keys bicubic sums (bounds derived in
``test_remap_torch.py``): ``8u·max|p|`` and ``92u·max|p|``, ``u = 2⁻²⁴``.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("kornia")

from lumigraph.capture.device import resolve_device  # noqa: E402
from lumigraph.stereo import block_matching as bm  # noqa: E402
from lumigraph.stereo import block_matching_torch  # noqa: E402
from lumigraph.stereo.pyramid import forward_backward, warp  # noqa: E402

U = 2.0 ** -24


def _pair(seed=0, h=45, w=83, disp=7, colour=False):
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(seed)
    shape = (h, w, 3) if colour else (h, w)
    sig = (1.5, 1.5, 0) if colour else 1.5
    right = gaussian_filter(rng.uniform(0, 255, shape), sig)
    left = np.roll(right, disp, axis=1) + rng.normal(0, 2.0, shape)
    left[:, :disp] = rng.uniform(0, 255, left[:, :disp].shape)  # the occluded strip
    return left, right


def _same(a, b):
    np.testing.assert_array_equal(a.disparity, b.disparity)
    np.testing.assert_array_equal(a.cost, b.cost)
    np.testing.assert_array_equal(a.window, b.window)


@pytest.mark.parametrize("colour", [False, True])
@pytest.mark.parametrize("window", [5, "auto"])
@pytest.mark.parametrize("kind", ["uint8", "float-integers"])
def test_block_matching_equals_numpy(colour, window, kind):
    left, right = _pair(colour=colour)
    if kind == "uint8":
        left, right = (np.clip(x, 0, 255).astype(np.uint8) for x in (left, right))
    else:
        left, right = (np.round(np.clip(x, 0, 255)).astype(np.float32) for x in (left, right))
    kw = dict(max_disp=15, window=window, channels="color" if colour else "luma")
    ref = bm.match(left, right, engine="numpy", **kw)
    got = bm.match(left, right, device="torch-cpu", **kw)
    _same(got, ref)
    assert got.info["engine"] == "torch-cpu"


def test_block_matching_past_int32_equals_the_c_kernel_and_bands_agree():
    """A 63-px window of quarter-code luma differing by 255 codes everywhere
    sums to 63² · 1020² > 2³¹: the torch path sums exactly, as the C kernel;
    and 150 rows split into bands join seamlessly."""
    if bm._kernel() is None:
        pytest.skip("the C kernel stereo/_ssd.c is not built")
    rng = np.random.default_rng(1)
    left = (rng.integers(0, 2, (150, 90)) * 255).astype(np.uint8)
    right = 255 - left
    kw = dict(max_disp=8, window=63, texture_snr=0.0, uniqueness=0.0, lr_tolerance=-1)
    ref = bm.match(left, right, **kw)
    assert ref.info["engine"] == "c"
    _same(bm.match(left, right, device="torch-cpu", **kw), ref)


@pytest.mark.parametrize("window", [7, "auto"])
def test_block_matching_float_costs_within_rounding(window):
    left, right = (x.astype(np.float32) / 255.0 for x in _pair(seed=2))
    L, R, gray, code = bm._match_images(left, right, channels="luma")
    _, windows = bm._check_search(L.shape, max_disp=15, window=window, engine="auto",
                                  texture_snr=1.0, uniqueness=0.02)
    noise = bm._noise(left, gray, 1, texture_snr=1.0)
    _, pick = bm._texture([gray], windows, tuple(noise.threshold for _ in windows))
    D = 16
    costs = bm._costs(windows, pick, D=D, integer=False, span=bm._span(L, R), nch=1, code=code)
    Lp, Rp = bm._padded(L, R, D)
    ref = bm._scan_numpy_bands(Lp, Rp, D=D, costs=costs, n_threads=1)
    got = block_matching_torch.scan(Lp, Rp, D=D, costs=costs, device=resolve_device("torch-cpu"))
    delta = 1 + 2.0 ** -22 * 2 ** (30 - costs.nb)
    for r, g in zip(ref, got, strict=True):
        assert g.dtype == np.int32 and g.shape == r.shape
        both = (r != bm._INT_MAX) & (g != bm._INT_MAX)
        assert np.array_equal(r == bm._INT_MAX, g == bm._INT_MAX)
        assert np.abs((r[both] >> costs.nb).astype(np.int64) - (g[both] >> costs.nb)).max() <= delta


@pytest.mark.parametrize("paths,edge", [(8, 8), (4, 0)])
def test_sgm_aggregation_equals_the_c_kernel_and_the_numpy_twin(paths, edge):
    """Integer arithmetic throughout (int32 path costs, the P2 adaptation by
    floor division, the sum wrapped to uint16): bound 0."""
    from lumigraph.stereo import hirschmuller2008 as sgm
    from lumigraph.stereo import hirschmuller2008_torch

    rng = np.random.default_rng(paths + edge)
    cost = rng.integers(0, sgm.CENSUS_MAX * 9, (21, 34, 11)).astype(np.uint16)
    guide = rng.integers(0, 256, (21, 34)).astype(np.uint8)
    kw = dict(p1=12 * 9, p2=200 * 9, edge=edge, paths=paths)
    got = hirschmuller2008_torch.aggregate(cost, guide, device="torch-cpu", **kw)
    np.testing.assert_array_equal(got, sgm.aggregate(cost, guide, kernel=None, **kw))
    if sgm._kernel() is not None:
        np.testing.assert_array_equal(got, sgm.aggregate(cost, guide, kernel=sgm._kernel(), **kw))


def test_sgm_match_equals_cpu():
    from lumigraph.stereo.hirschmuller2008 import match as sgm

    left, right = (np.clip(x, 0, 255).astype(np.uint8) for x in _pair(seed=5))
    ref = sgm(left, right, max_disp=15)
    got = sgm(left, right, max_disp=15, device="torch-cpu")
    np.testing.assert_array_equal(got.disparity, ref.disparity)
    np.testing.assert_array_equal(got.cost, ref.cost)
    assert got.info["aggregation_device"] == "torch-cpu"


def _flow_scene(seed=0, h=33, w=47):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    img = (np.sin(0.3 * x) + 0.5 * np.cos(0.17 * y) + 0.2 * rng.random((h, w))).astype(np.float32)
    flow = np.stack([1.5 + 2 * np.sin(0.1 * y), -0.75 + np.cos(0.13 * x)], -1).astype(np.float32)
    flow += rng.normal(0, 0.5, flow.shape).astype(np.float32)
    return img, flow


@pytest.mark.parametrize("cubic,border", [(True, "replicate"), (False, "replicate"),
                                          (False, "constant")])
@pytest.mark.parametrize("channels", [1, 2, 3])
def test_warp_equals_opencv(cubic, border, channels):
    img, flow = _flow_scene()
    if channels > 1:
        img = np.stack([img * (1 + 0.5 * c) for c in range(channels)], -1)
    ref = warp(img, flow, cubic=cubic, border=border)
    got = warp(img, flow, cubic=cubic, border=border, device="torch-cpu")
    assert got.shape == ref.shape and got.dtype == ref.dtype
    np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
    ok = np.isfinite(ref)
    k = 92 if cubic else 8
    np.testing.assert_allclose(got[ok], ref[ok], rtol=0, atol=k * U * float(np.abs(img).max()))


def test_warp_known_integer_shift_is_exact():
    img, _ = _flow_scene(1)
    flow = np.zeros(img.shape + (2,), np.float32)
    flow[..., 0], flow[..., 1] = 3.0, -2.0  # sample at (x + 3, y - 2)
    got = warp(img, flow, cubic=False, border="constant", device="torch-cpu")
    np.testing.assert_array_equal(got[2:, :-4], img[:-2, 3:-1])
    assert np.isnan(got[:2]).all() and np.isnan(got[:, -3:]).all()


def test_forward_backward_equals_numpy_away_from_the_threshold():
    _, f = _flow_scene(2)
    b = -f + np.random.default_rng(3).normal(0, 0.6, f.shape).astype(np.float32)
    bad_n, rt_n = forward_backward(f, b)
    bad_t, rt_t = forward_backward(f, b, device="torch-cpu")
    # the warped backward flow differs by db; err2 = |f + bw|² and the bound
    # 0.01(|f|² + |bw|²) + 0.5 move by at most the amounts below (+ rounding)
    db = 8 * U * float(np.abs(b).max())
    s = np.abs(f + warp(b, f, border="constant", cubic=False))
    bw = np.abs(warp(b, f, border="constant", cubic=False))
    d_err = 2 * s.sum(-1) * db + 2 * db * db + 0.02 * bw.sum(-1) * db
    err2 = np.where(np.isfinite(rt_n), rt_n.astype(np.float64) ** 2, np.inf)
    bound = 0.01 * ((f ** 2).sum(-1) + (bw ** 2).sum(-1)) + 0.5
    clear = ~(np.abs(err2 - bound) <= d_err + 8 * U * (err2 + bound))
    np.testing.assert_array_equal(bad_t[clear], bad_n[clear])
    fin = np.isfinite(rt_n)
    np.testing.assert_array_equal(np.isfinite(rt_t), fin)
    np.testing.assert_allclose(rt_t[fin], rt_n[fin], rtol=0,
                               atol=float(np.sqrt(2) * db + 8 * U * rt_n[fin].max()))


def _write_pair(tmp_path):
    from lumigraph.capture import io

    left, right = (np.clip(x, 0, 255).astype(np.uint8) for x in _pair(seed=4))
    io.write_image(tmp_path / "l.png", left)
    io.write_image(tmp_path / "r.png", right)
    return left, right


def _clean_error(rc, capsys, *fragments):
    """Exit 2 and one line 'error: ...' naming the fragments (in-process: a
    fresh interpreter per command would cost seconds of torch import)."""
    assert rc == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    for f in fragments:
        assert f in lines[0], (f, lines[0])


def test_cli_match_ssd_torch_cpu_equals_the_library(tmp_path):
    from lumigraph.capture.io import read_pfm
    from lumigraph.stereo.cli import main

    left, right = _write_pair(tmp_path)
    out = tmp_path / "d.pfm"
    assert main(["match", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--method", "ssd",
                 "--max-disp", "15", "--device", "torch-cpu", "--out", str(out), "-q"]) == 0
    ref = bm.match(left, right, max_disp=15).disparity
    np.testing.assert_array_equal(read_pfm(out), ref)  # unknown: inf in the file, NaN read back


def test_cli_match_sgm_torch_cpu_equals_the_library(tmp_path):
    from lumigraph.capture.io import read_pfm
    from lumigraph.stereo.cli import main
    from lumigraph.stereo.hirschmuller2008 import match as sgm

    left, right = _write_pair(tmp_path)
    out = tmp_path / "d.pfm"
    assert main(["match", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--max-disp", "15",
                 "--device", "torch-cpu", "--out", str(out), "-q"]) == 0
    np.testing.assert_array_equal(read_pfm(out), sgm(left, right, max_disp=15).disparity)


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
def test_cli_cuda_without_gpu_is_exit_2(tmp_path, capsys):
    from lumigraph.stereo.cli import main

    _write_pair(tmp_path)
    out = tmp_path / "d.pfm"
    _clean_error(main(["match", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--method",
                       "ssd", "--max-disp", "15", "--device", "cuda", "--out", str(out)]), capsys,
                 "--device", "no CUDA GPU")
    assert not out.exists()
