"""HDR on torch's CPU device against the numpy code: merge (every weighting
and option), Reinhard 2002 global and local tone mapping, and HDR video's
neighbour warp. Bounds derived from the arithmetic, not measured."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("kornia")

from lumigraph.hdr import reinhard2002 as R  # noqa: E402
from lumigraph.hdr import reinhard2002_torch as T  # noqa: E402
from lumigraph.hdr.merge import merge  # noqa: E402
from lumigraph.hdr.response import ResponseCurve  # noqa: E402

U32 = 2.0 ** -24  # float32 unit roundoff
TIMES = [1 / 64, 1 / 8, 1.0, 8.0]


def _radiance(h=41, w=57, seed=0):
    rng = np.random.default_rng(seed)
    return np.exp(rng.normal(-2.0, 2.5, (h, w, 3))).astype(np.float32)


def _bracket(x, bits, seed=1):
    rng = np.random.default_rng(seed)
    top = 2 ** bits - 1
    z = [np.clip(np.round(x * t * top * (1 + 0.01 * rng.standard_normal(x.shape))), 0, top)
         for t in TIMES]
    z = np.stack(z).astype(np.uint8 if bits == 8 else np.uint16)
    z[0, :5, :7] = top // 2  # a bright object moving through the shortest exposure: a ghost
    return z


@pytest.mark.parametrize("bits", [8, 12])
@pytest.mark.parametrize("options", [{}, {"weights": "hat"}, {"deghost": True},
                                     {"weights": "hat", "deghost": True, "reference": 1},
                                     {"full_well_e": 2e4, "read_noise_e": 3.0, "clip_margin": 0.05}])
def test_merge_matches_numpy(bits, options):
    x = _radiance()
    z = _bracket(x, bits)
    curve = ResponseCurve.linear(bits, 3)
    a = merge(z, TIMES, curve, device="torch-cpu", **options)
    b = merge(z, TIMES, curve, **options)
    # Both read the same float32 tables and add the P = 4 exposures' w X and
    # w in the same order: each sum of non-negative terms is within
    # (P - 1) u of exact, the quotient adds u; both sides: factor 2.
    p = len(TIMES)
    rel = np.abs(a.radiance - b.radiance) / np.maximum(np.abs(b.radiance), np.float32(1e-30))
    assert rel.max() <= 2 * (2 * (p - 1) + 1) * U32
    # the flags are decisions on identical float32 numbers: identical
    assert np.array_equal(a.flags, b.flags)
    assert a.warnings == b.warnings
    assert b.stats["black_everywhere"] > 0 and b.stats["clipped_everywhere"] > 0  # fills exercised
    if options.get("deghost"):
        assert b.stats["ghost"] > 0


def test_merge_bad_option_is_the_same_error():
    z = _bracket(_radiance(5, 6), 8)
    from lumigraph.capture.errors import InputError

    with pytest.raises(InputError, match="full_well_e"):
        merge(z, TIMES, ResponseCurve.linear(8, 3), weights="hat", full_well_e=1e4,
              device="torch-cpu")


# ------------------------------------------------------------------ tone mapping
def _log_avg_rel(lum):
    """Relative error of the log-average (eq. 1) between the two sides: each
    log in float32 is within 2 u |log| of exact (both sides: 4 u), the mean
    is summed in float64 (negligible), exp keeps the relative error."""
    return 4 * U32 * float(np.abs(np.log(1e-6 + lum.astype(np.float64))).max()) + 2 * U32


def test_gaussian_blur_matches_scipy():
    import scipy.ndimage as ndi

    img = np.random.default_rng(4).random((23, 61)).astype(np.float32)
    for sigma in (0.35, 1.6, 15.2, 40.0):         # 40: the kernel is wider than the image
        got = T.gaussian_blur(torch.from_numpy(img), sigma).numpy()
        want = ndi.gaussian_filter(img, sigma, output=np.float32)
        k = len(T.gaussian_kernel(sigma))
        # per pass: torch sums K float32 products (<= K u M; positive weights
        # summing to 1), scipy rounds its double sum once (u M); two passes
        assert np.abs(got - want).max() <= 2 * (k + 1) * U32 * img.max() * 2


def test_global_tonemap_codes_match():
    x = _radiance(37, 53, seed=5)
    got = T.tonemap_torch(x, method="reinhard", device="torch-cpu").astype(np.int64)
    want = R.tonemap(x, method="reinhard").astype(np.int64)
    # The numpy operator is float64; torch's float32 chain (luminance 3 u,
    # log-average, scaling 2 u, eq. 4 about 6 u, ratio and product 2 u, the
    # sRGB power 4 u) leaves the encoded value within
    # d = 2 e_l + 20 u (relative) of it, d * 255 codes. Codes are equal
    # except where the exact value lies within that of a rounding boundary.
    lum = R._luminance(np.maximum(x.astype(np.float64), 0))
    ld = R.global_operator(lum)
    ratio = np.where(lum > 0, ld / lum, 0.0)
    f = R.srgb_encode(np.maximum(x.astype(np.float64), 0) * ratio[..., None]) * 255
    d = (2 * _log_avg_rel(lum) + 20 * U32) * 255 + 255 * U32
    near = np.abs(f - np.floor(f) - 0.5) <= d
    assert np.array_equal(got[~near], want[~near])
    assert np.abs(got - want).max() <= 1


def _stable(lum):
    """``(stable, rel)``: the pixels where eq. 9 must pick the same scale on
    both sides, and the relative bound of the local operator's output there.

    The log-average's relative error e_l scales l; l >= 0 and the weights
    are positive, so a pass's rounding error is relative to its own result
    (K u sum |w x| = K u V): each blur is within db V, db = 4 (K + 1) u,
    of the other side's (two passes, both sides); the output l / (1 + V1)
    then differs by at most out (2 e_l + 4 u + db).
    Eq. 9's choice: V = (V1 - V2) / (2^phi a / s^2 + V1) against eps. In
    float64 (the exact reference), a pixel whose |V| at some scale up to the
    chosen one is within the two sides' error of eps may choose differently:
    |dV| <= db (V1 + V2 + |V| V1) / (c_s + V1) + (3 u + 2 e_l) |V|, both
    sides: factor 2. Only the others are compared.
    """
    import scipy.ndimage as ndi

    key, phi, eps, scales = 0.18, 8.0, 0.05, 8
    e_l = _log_avg_rel(lum)
    lw = float(np.exp(np.mean(np.log(1e-6 + lum.astype(np.float64)))))
    l = lum.astype(np.float64) * key / lw
    k_max = len(T.gaussian_kernel(1.6 ** scales / (2 * math.sqrt(2))))
    db = 4 * (k_max + 1) * U32
    s = 1.0
    v1 = ndi.gaussian_filter(l, s / (2 * math.sqrt(2)))
    stable = np.ones(l.shape, bool)
    done = np.zeros(l.shape, bool)
    for _ in range(scales):
        v2 = ndi.gaussian_filter(l, s * 1.6 / (2 * math.sqrt(2)))
        den = 2 ** phi * key / s ** 2 + v1
        v = (v1 - v2) / den
        dv = 2 * (db * (v1 + v2 + np.abs(v) * v1) / den + (3 * U32 + 2 * e_l) * np.abs(v))
        stable &= done | (np.abs(np.abs(v) - eps) > dv)
        done |= np.abs(v) >= eps
        v1, s = v2, s * 1.6
    return stable, 2 * e_l + 4 * U32 + db


def test_local_operator_matches_where_the_scale_choice_is_stable():
    x = _radiance(45, 64, seed=6)
    lum = R._luminance(x.astype(np.float64)).astype(np.float32)
    got = T.local_operator_torch(torch.from_numpy(lum)).numpy()
    want = R.local_operator(lum)
    stable, rel = _stable(lum)
    assert stable.mean() > 0.5          # the comparison is not vacuous
    assert np.all((np.abs(got - want) <= want * rel)[stable])


def test_local_tonemap_codes_within_one_where_stable():
    x = _radiance(33, 48, seed=8)
    got = T.tonemap_torch(x, method="reinhard-local", device="torch-cpu").astype(np.int64)
    want = R.tonemap(x, method="reinhard-local").astype(np.int64)
    lum = R._luminance(x.astype(np.float64)).astype(np.float32)
    stable, rel = _stable(lum)
    # where eq. 9 picks the same scale the display values differ by at most
    # rel + 20 u relative (the encoding chain, as for the global operator),
    # far below a code: codes at most one apart (a rounding boundary between)
    assert rel < 1 / 255
    assert stable.mean() > 0.5
    assert np.abs(got - want).max(axis=2)[stable].max() <= 1
    assert got.shape == want.shape and got.dtype == want.dtype


def test_tonemap_device_checks_the_radiance_first():
    from lumigraph.capture.errors import InputError

    bad = np.full((4, 4, 3), np.nan, np.float32)
    with pytest.raises(InputError, match="radiance"):
        R.tonemap(bad, device="torch-cpu")


# ------------------------------------------------------------------ HDR video
def test_video_warp_matches_cv2_remap():
    from lumigraph.capture.device import resolve_device
    from lumigraph.hdr.kang2003 import _grid, _Linear, _warp_neighbour
    from lumigraph.hdr.video_torch import warp_neighbour_torch

    rng = np.random.default_rng(9)
    h, w = 19, 27
    xv = rng.random((2, h, w, 3)).astype(np.float32) * 4
    rel = [xi > 0.5 for xi in xv]
    video = _Linear(x=list(xv), reliable=rel, var=list(xv * 0.01))
    # a smooth flow with arbitrary fractions
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    m = _grid(h, w) + np.stack([1.3 * np.sin(ys / 5), 0.7 * np.cos(xs / 4)], -1).astype(np.float32)
    a = warp_neighbour_torch(video, 1, m, resolve_device("torch-cpu"))
    b = _warp_neighbour(video, 1, m)
    # cv2.remap rounds the sample position to 1/32 px (INTER_TAB_SIZE): the
    # bilinear sums of the weighted value and of the reliability weight each
    # move by at most 1/64 px x the largest adjacent difference per axis
    # (values: G; weights: 1), plus the coordinate rounding of the torch path
    # (8 u (W - 1) px) and 4 u M per sum. Where the reliability weight is
    # above 1/2 (a.reliable), the normalised value x = S / R moves by at most
    # (dS + x dR) / R <= 2 (dS + x dR).
    both = a.reliable & b.reliable
    vals = np.where(video.reliable[1], video.x[1], 0.0)
    g = max(np.abs(np.diff(vals, axis=0)).max(), np.abs(np.diff(vals, axis=1)).max())
    dpos = 2 * (1 / 64 + 8 * U32 * (w - 1))
    ds = dpos * g + 8 * U32 * vals.max()
    dr = dpos * 1.0 + 8 * U32
    bound = 2 * (ds + np.abs(b.x) * dr)
    assert both.mean() > 0.5
    assert np.all(np.abs(a.x - b.x)[both] <= bound[both])
