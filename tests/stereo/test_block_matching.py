"""SSD block matching against exact ground truth."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from lumigraph.capture.render import render
from lumigraph.stereo.block_matching import match
from lumigraph.stereo.luma import luma_codes, noise_sigma_smooth_blocks


@pytest.mark.parametrize("prefilter, reach", [("none", 5), ("local-mean", 9)])
def test_rendered_pair_accuracy_bounded_on_both_sides(prefilter, reach):
    s = render("stereo-pair", size=(240, 180))
    gt = s.gt_arrays["disparity"]
    res = match(s.images[0], s.images[1], max_disp=s.gt["suggested_max_disp"] - 1, window=9,
                prefilter=prefilter)
    known = np.isfinite(gt)
    e = np.abs(res.disparity - gt)[known]
    est = np.isfinite(e)
    # non-occluded textured scene: most pixels matched, sub-pixel accurate
    assert est.mean() > 0.8
    assert 0 < np.median(e[est]) < 0.25
    # gross errors only where the 9x9 window straddles a depth edge (radius 4;
    # the prefilter's 9x9 mean reaches 4 px further)
    from scipy import ndimage

    Z = np.nan_to_num(s.gt_arrays["depth"], nan=99)
    edge = (ndimage.maximum_filter(Z, 3) - ndimage.minimum_filter(Z, 3)) > 0.05
    interior = (ndimage.distance_transform_edt(~edge) > reach)[known]
    assert np.mean(e[est & interior] > 2) < 0.01
    # occluded pixels (GT NaN inside the image) are mostly refused by the LR check
    occl = ~known
    occl[:, : int(gt[known].max()) + 2] = False  # the left band has no partner at all
    assert np.isnan(res.disparity[occl]).mean() > 0.6


def test_subpixel_shift_recovered():
    rng = np.random.default_rng(3)
    base = gaussian_filter(rng.uniform(0, 255, (60, 200)), 2.0)
    x = np.arange(200)
    shift = 7.3
    right = base
    left = np.stack([np.interp(x - shift, x, row) for row in base])  # left(x) = right(x - d)
    res = match(left.astype(np.float32), right.astype(np.float32), max_disp=16, window=9)
    d = res.disparity[10:-10, 30:-10]
    assert np.isfinite(d).mean() > 0.9
    # parabola fits of SSD have a known bias of up to ~0.1 px towards integers
    assert 0.0 < abs(np.nanmedian(d) - shift) < 0.12


def test_auto_window_recorded_and_noise_estimate():
    s = render("stereo-pair", size=(160, 120), textureless=True)
    res = match(s.images[0], s.images[1], max_disp=31, window="auto")
    auto = res.info["auto"]
    assert auto["candidates"] == [5, 9, 15]
    shares = list(auto["share_of_pixels"].values()) + [auto["no_window_textured"]]
    assert abs(sum(shares) - 1) < 1e-9
    assert set(np.unique(res.window)) <= {0, 5, 9, 15}


def test_noise_estimate_on_known_noise():
    # flat and smoothly shaded areas with sigma 3 noise: within 10 %
    rng = np.random.default_rng(4)
    y, x = np.mgrid[0:120, 0:160]
    img = 80 + 0.3 * x + 40 * (y > 60) + rng.normal(0, 3, (120, 160))
    assert 2.7 < noise_sigma_smooth_blocks(img.astype(np.float32)) < 3.3


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(max_disp=0), "max_disp"), (dict(max_disp=8, window=4), "window"),
    (dict(max_disp=8, window="big"), "window")])
def test_bad_arguments(kwargs, fragment):
    a = np.zeros((20, 30), np.float32)
    with pytest.raises(ValueError, match=fragment):
        match(a, a, **kwargs)


def test_shape_mismatch():
    with pytest.raises(ValueError, match="right"):
        match(np.zeros((20, 30)), np.zeros((20, 31)), max_disp=4)


def test_inputs_not_mutated():
    s = render("stereo-pair", size=(96, 72))
    a, b = s.images[0].copy(), s.images[1].copy()
    match(a, b, max_disp=16)
    assert np.array_equal(a, s.images[0]) and np.array_equal(b, s.images[1])


@pytest.mark.parametrize("channels", ["luma", "color"])
@pytest.mark.parametrize("window, max_disp", [(9, 24), (31, 130)])
def test_integer_and_float_paths_agree(window, max_disp, channels):
    # 8-bit pairs are matched on exact integer SSD (of quarter-code luma, or
    # of the code values of R, G, B), low bits dropped when window sums and
    # the disparity code would not fit 30 bits (the (31, 130) case); float
    # pairs on float32. The same scene must give the same matches: the
    # quarter-code rounding of luma (sigma 0.07 code values) is far below the
    # noise of 1 code value rendered into it, and colour is exact. Without the
    # prefilter: its integer response is rounded to the code, a further noise
    # the float path does not have (the engines' agreement on prefiltered
    # pairs is tested below).
    s = render("stereo-pair", size=(320, 120) if max_disp > 100 else (160, 120))
    kw = dict(max_disp=max_disp, window=window, channels=channels, prefilter="none")
    a = match(s.images[0], s.images[1], **kw)
    if channels == "luma":
        fl, fr = luma_codes(s.images[0]), luma_codes(s.images[1])
    else:
        fl, fr = s.images[0].astype(np.float32), s.images[1].astype(np.float32)
    b = match(fl, fr, **kw)
    assert a.info["channels"] == b.info["channels"] == ("luma" if channels == "luma" else "rgb")
    both = np.isfinite(a.disparity) & np.isfinite(b.disparity)
    assert both.mean() > 0.5
    assert np.mean(np.abs(a.disparity[both] - b.disparity[both]) < 0.1) > 0.98
    assert abs(a.valid_fraction - b.valid_fraction) < 0.02
    # costs are reported in code values² per pixel on both paths
    ca, cb = a.cost[both], b.cost[both]
    assert 0.9 < np.median(ca / np.maximum(cb, 1e-6)) < 1.1


# --- compiled kernel (stereo/_ssd.c) against the numpy path -----------------
def _same(a, b):
    return (np.array_equal(a.disparity, b.disparity, equal_nan=True)
            and np.array_equal(a.cost, b.cost, equal_nan=True)
            and np.array_equal(a.window, b.window)
            and a.info["rejected_fraction"] == b.info["rejected_fraction"])


@pytest.mark.parametrize("window, max_disp, size, kw", [
    (9, 31, (160, 120), {}),
    (5, 31, (160, 120), dict(distinct=0.5, uniqueness=0.1, lr_tolerance=0)),
    ("auto", 31, (160, 120), dict(distinct=1.0)),
    (15, 3, (96, 72), dict(subpixel=False)),   # window wider than the disparity padding
    (31, 130, (320, 96), {}),                  # window sums shifted to fit 30 bits
    ("auto", 31, (160, 120), dict(prefilter="local-mean")),
    (9, 31, (160, 120), dict(prefilter="local-mean", prefilter_cap=4.0)),  # clipping active
    (9, 31, (160, 120), dict(channels="color")),
    ("auto", 31, (160, 120), dict(channels="color", distinct=1.0)),
    (31, 130, (320, 96), dict(channels="color")),
    (9, 31, (160, 120), dict(channels="color", prefilter="local-mean")),
])
def test_compiled_kernel_identical_to_numpy_path(window, max_disp, size, kw, monkeypatch):
    # the kernel's integer SSD and float32 decision are specified to reproduce
    # the numpy path exactly on 8-bit input: any difference is a bug
    import lumigraph.stereo.block_matching as bm

    assert bm._kernel() is not None, "stereo/_ssd.c was not built (pip install -e . needs a C compiler)"
    s = render("stereo-pair", size=size, textureless=True)
    a = match(s.images[0], s.images[1], max_disp=max_disp, window=window, **kw)
    b = match(s.images[0], s.images[1], max_disp=max_disp, window=window, engine="numpy", **kw)
    assert (a.info["engine"], b.info["engine"]) == ("c", "numpy")
    assert 0.3 < a.valid_fraction < 1
    assert _same(a, b)
    # the portable (non-AVX2) build of the kernel too
    monkeypatch.setenv("LUMIGRAPH_SSD_BASELINE", "1")
    assert _same(match(s.images[0], s.images[1], max_disp=max_disp, window=window, **kw), b)


def test_missing_kernel_falls_back_with_one_warning(monkeypatch):
    import sys

    import lumigraph.stereo.block_matching as bm

    s = render("stereo-pair", size=(96, 72))
    ref = match(s.images[0], s.images[1], max_disp=16, window=5)
    monkeypatch.setitem(sys.modules, "lumigraph.stereo._ssd", None)  # import fails
    bm._kernel.cache_clear()
    try:
        with pytest.warns(UserWarning, match="numpy path"):
            a = match(s.images[0], s.images[1], max_disp=16, window=5)
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("error")
            b = match(s.images[0], s.images[1], max_disp=16, window=5)
    finally:
        bm._kernel.cache_clear()
    assert a.info["engine"] == b.info["engine"] == "numpy"
    assert _same(a, ref) and _same(b, ref)


def test_bad_engine():
    a = np.zeros((20, 30), np.uint8)
    with pytest.raises(ValueError, match="engine"):
        match(a, a, max_disp=4, engine="gpu")


def test_local_mean_prefilter_removes_an_offset_between_views():
    # the local-mean response of a + c is that of a, exactly in integers
    # (81(a + c) - (S + 81c) = 81a - S), so an offset added to the right view
    # leaves the prefiltered match unchanged; plain SSD is hurt by it
    import cv2

    s = render("stereo-pair", size=(160, 120))
    gl = cv2.cvtColor(s.images[0], cv2.COLOR_RGB2GRAY)
    gr = cv2.cvtColor(s.images[1], cv2.COLOR_RGB2GRAY)
    assert int(gr.max()) + 20 <= 255  # no saturation, so the offset is exact
    brighter = gr + np.uint8(20)
    gt = s.gt_arrays["disparity"]
    known = np.isfinite(gt)

    def bad2(res):
        return float(np.mean(~(np.abs(res.disparity[known] - gt[known]) <= 2)))

    kw = dict(max_disp=int(s.gt["suggested_max_disp"]) - 1, window=9)
    a = match(gl, gr, prefilter="local-mean", **kw)
    b = match(gl, brighter, prefilter="local-mean", **kw)
    assert np.array_equal(a.disparity, b.disparity, equal_nan=True)
    assert a.info["prefilter"] == "local-mean"
    plain, plain_off = (match(gl, gr, prefilter="none", **kw),
                        match(gl, brighter, prefilter="none", **kw))
    assert bad2(plain_off) > bad2(plain) + 0.2


def test_local_mean_prefilter_matches_the_contrast_of_a_darker_view():
    # a right view at 0.6x the exposure (half a code of rounding) scales every
    # local response by 0.6: the contrast ratio must come out 1/0.6 to within
    # what the rounding can move a median absolute response of ~10 codes
    # (0.5 / 10 relative), and the match then stays as good as with equal
    # exposures, where the plain SSD loses most pixels
    import cv2

    from lumigraph.stereo.block_matching import _response_gain

    s = render("stereo-pair", size=(160, 120))
    gl = cv2.cvtColor(s.images[0], cv2.COLOR_RGB2GRAY)
    gr = cv2.cvtColor(s.images[1], cv2.COLOR_RGB2GRAY)
    darker = np.rint(0.6 * gr.astype(np.float64)).astype(np.uint8)
    g = _response_gain(gl.astype(np.float32), darker.astype(np.float32))
    g0 = _response_gain(gl.astype(np.float32), gr.astype(np.float32))
    assert abs(g / g0 * 0.6 - 1) < 0.05
    gt = s.gt_arrays["disparity"]
    known = np.isfinite(gt)

    def bad2(res):
        return float(np.mean(~(np.abs(res.disparity[known] - gt[known]) <= 2)))

    kw = dict(max_disp=int(s.gt["suggested_max_disp"]) - 1, window=9)
    same, dark = match(gl, gr, **kw), match(gl, darker, **kw)
    assert dark.info["prefilter"] == "local-mean"
    # 0.6x the signal against the same noise: allow a few per cent more pixels lost
    assert bad2(dark) <= bad2(same) + 0.05
    assert bad2(match(gl, darker, prefilter="none", **kw)) > bad2(dark) + 0.2


@pytest.mark.parametrize("kw, fragment", [(dict(prefilter="sobel"), "prefilter"),
                                          (dict(prefilter="local-mean", prefilter_cap=0), "prefilter_cap")])
def test_bad_prefilter(kw, fragment):
    a = np.zeros((20, 30), np.uint8)
    with pytest.raises(ValueError, match=fragment):
        match(a, a, max_disp=4, **kw)


def test_colour_matches_hues_of_equal_luma():
    # A texture carried almost wholly by hue: red and green move against each
    # other so that luma keeps only a faint texture (std 0.8, below the luma
    # noise std 1.3 of per-channel noise 2), while each channel varies by
    # tens of code values. Luma has next to nothing to match (refused as
    # textureless, or wrong); the colour SSD sees the channels and matches.
    rng = np.random.default_rng(3)
    h, w, shift = 60, 120, 7
    chroma = gaussian_filter(rng.normal(0, 1, (h, w + shift)), 1.2)
    luma = gaussian_filter(rng.normal(0, 1, (h, w + shift)), 1.2)
    chroma *= 40 / chroma.std()
    luma *= 0.8 / luma.std()
    img = np.stack([128 + luma + chroma, 128 + luma - chroma * 0.299 / 0.587, 128 + luma], -1)
    left, right = img[:, :w], img[:, shift:shift + w]      # left x sees right x - shift

    def noisy(a):
        return np.clip(np.rint(a + rng.normal(0, 2, a.shape)), 0, 255).astype(np.uint8)

    L, R = noisy(left), noisy(right)
    ok = {}
    for channels in ("luma", "color"):
        d = match(L, R, max_disp=15, window=9, channels=channels).disparity[:, 20:]
        ok[channels] = np.mean(np.abs(d - shift) <= 0.5)
    assert ok["color"] > 0.95 > 0.5 > ok["luma"], ok


@pytest.mark.parametrize("channels", ["luma", "color"])
def test_wide_window_sums_do_not_wrap(channels):
    # 8 px blocks of 0 or 255: a 63 px window's sum of squared differences
    # reaches 63² · 3 · 1020² ≈ 1.2e10 at a wrong disparity, far past int32; the
    # numpy path must give the C kernel's int64 answer, not wrapped costs
    import lumigraph.stereo.block_matching as bm

    assert bm._kernel() is not None
    rng = np.random.default_rng(3)
    left = np.kron(rng.random((20, 30, 3)) < 0.5, np.ones((8, 8, 1))).astype(np.uint8) * 255
    right = np.roll(left, -7, axis=1)  # disparity 7 except where the roll wraps
    a = match(left, right, max_disp=24, window=63, channels=channels)
    b = match(left, right, max_disp=24, window=63, channels=channels, engine="numpy")
    assert (a.info["engine"], b.info["engine"]) == ("c", "numpy")
    assert _same(a, b)
    d = a.disparity[:, 7 + 32: 240 - 7 - 32]  # windows clear of the wrapped columns
    ok = np.isfinite(d)
    assert ok.mean() > 0.5 and np.all(np.abs(d[ok] - 7) < 0.5)
