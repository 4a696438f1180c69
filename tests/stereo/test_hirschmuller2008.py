"""Semi-global matching: the compiled kernel against its numpy twin, exact
answers on exact shifts, the unmatched left band, and the option checks."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from lumigraph.capture.errors import InputError
from lumigraph.stereo import hirschmuller2008 as sgm

KERNEL = sgm._kernel()
needs_kernel = pytest.mark.skipif(KERNEL is None, reason="stereo/_sgm.c was not built")


def _shifted_pair(d=6, shape=(36, 64), seed=0, blur=1.0):
    """A textured right image and the left one seeing it ``d`` px to the
    right (``x_right = x_left - d``); the left band ``x < d`` shows fresh
    texture that the right image does not contain."""
    rng = np.random.default_rng(seed)
    h, w = shape
    right = gaussian_filter(rng.uniform(0, 255, (h, w)), blur)
    left = np.empty_like(right)
    left[:, d:] = right[:, :w - d]
    left[:, :d] = gaussian_filter(rng.uniform(0, 255, (h, d + 8)), blur)[:, :d]
    return left.astype(np.uint8), right.astype(np.uint8)


@needs_kernel
@pytest.mark.parametrize("cost,cost_window,paths,lr_check", [("census", 1, 8, "winners"),
                                                             ("census", 3, 8, "paper"),
                                                             ("census", 5, 4, "winners"),
                                                             ("ssd", 3, 8, "winners")])
def test_kernel_and_numpy_twin_agree_exactly(cost, cost_window, paths, lr_check):
    left, right = _shifted_pair(shape=(30, 48), seed=1)
    kw = dict(max_disp=11, cost=cost, cost_window=cost_window, paths=paths, lr_check=lr_check)
    if cost_window == 5:
        kw["p2"] = 60  # the uint16 bound for a 5x5 window
    a = sgm.match(left, right, **kw)
    b = sgm.match(left, right, engine="numpy", **kw)
    assert (a.info["engine"], b.info["engine"]) == ("c", "numpy")
    np.testing.assert_array_equal(a.disparity, b.disparity)
    np.testing.assert_array_equal(a.cost, b.cost)
    assert a.info["rejected_fraction"] == b.info["rejected_fraction"]


@needs_kernel
def test_each_kernel_step_matches_numpy():
    left, right = _shifted_pair(shape=(25, 40), seed=2)
    cl, cr = sgm.census(left, kernel=KERNEL), sgm.census(right, kernel=KERNEL)
    np.testing.assert_array_equal(cl, sgm.census(left))
    for r in (0, 1, 2):
        C = sgm._census_cost(cl, cr, 9, r, 999, KERNEL)
        np.testing.assert_array_equal(C, sgm._census_cost(cl, cr, 9, r, 999, None))
    # an edge-adapted P2 and the 8 paths; random guide so that every P2 branch is taken
    g = np.random.default_rng(3).integers(0, 256, left.shape).astype(np.uint8)
    S = sgm.aggregate(C, g, p1=30, p2=700, edge=8, kernel=KERNEL)
    np.testing.assert_array_equal(S, sgm.aggregate(C, g, p1=30, p2=700, edge=8))
    wa, wb = sgm.winners(S, kernel=KERNEL), sgm.winners(S)
    for k in wa:
        np.testing.assert_array_equal(wa[k], wb[k], err_msg=k)
    assert sgm.winners(S, right=False, kernel=KERNEL).keys() == wa.keys() - {"best_r"}
    # the left pixels' claims on the right image, half of them allowed to claim
    ok = np.random.default_rng(4).random(wa["best"].shape) < 0.5
    np.testing.assert_array_equal(sgm.claims(wa["best"], wa["sb"], ok, kernel=KERNEL),
                                  sgm.claims(wa["best"], wa["sb"], ok))


def test_census_definition():
    img = np.arange(9 * 7, dtype=np.uint8).reshape(7, 9)  # strictly increasing in raster order
    code = int(sgm.census(img)[3, 4])
    # the centre is the 32nd of 63 values: exactly the 31 window pixels before it are darker
    assert code == (1 << 31) - 1


@pytest.mark.parametrize("engine", ["auto", "numpy"])
def test_exact_shift_is_found_exactly_and_the_left_band_is_unknown(engine):
    d_true = 6
    left, right = _shifted_pair(d=d_true, seed=4)
    res = sgm.match(left, right, max_disp=15, engine=engine)
    d = res.disparity
    # no right pixel exists for x < d_true: never a guessed value there
    assert np.isnan(d[:, :d_true]).all()
    inner = d[:, d_true + 8:]  # clear of the band and of the census window next to it
    ok = np.isfinite(inner)
    assert ok.mean() > 0.9
    # the integer minimum is exact on an exact shift; the parabola moves it by
    # at most half a pixel (its vertex lies between the neighbours)
    assert np.all(np.abs(inner[ok] - d_true) <= 0.5)


def test_range_too_small_warns():
    # every true disparity (12) lies beyond the range searched (8): on this
    # random texture no candidate fits, the winners match no better than the
    # best of a few random codes, and the result says so
    left, right = _shifted_pair(d=12, shape=(36, 80), seed=5)
    res = sgm.match(left, right, max_disp=8)
    assert res.info["median_match_cost"] > sgm.COST_WARNING
    assert any("max_disp" in w and "range" in w for w in res.info["warnings"])
    # the same pair searched wide enough matches exactly and does not warn
    res = sgm.match(left, right, max_disp=20)
    assert res.info["warnings"] == [] and res.info["median_match_cost"] == 0


def test_float_and_colour_inputs():
    left, right = _shifted_pair(d=5, seed=6)
    a = sgm.match(left, right, max_disp=10)
    # colour: the luma of grey RGB is the grey value
    b = sgm.match(np.dstack([left] * 3), np.dstack([right] * 3), max_disp=10)
    np.testing.assert_array_equal(a.disparity, b.disparity)
    # a float pair scaled to another range is matched on its 8-bit rescaling
    c = sgm.match(left / 255.0 * 1000 + 10, right / 255.0 * 1000 + 10, max_disp=10)
    assert np.nanmedian(c.disparity[:, 15:]) == pytest.approx(5, abs=0.5)


def test_option_checks_name_the_argument():
    with pytest.raises(InputError, match=r"^max_disp: expected an integer in \[1, 63\]"):
        sgm.check_sgm_options((48, 64), max_disp=64)
    with pytest.raises(InputError, match="^cost: expected one of census, ssd"):
        sgm.check_sgm_options((48, 64), max_disp=16, cost="sad")
    with pytest.raises(InputError, match="^cost_window: the SSD cost needs a window"):
        sgm.check_sgm_options((48, 64), max_disp=16, cost="ssd", cost_window=1)
    with pytest.raises(InputError, match="^p2: expected p2 >= p1"):
        sgm.check_sgm_options((48, 64), max_disp=16, p1=10, p2=5)
    with pytest.raises(InputError, match="^p2: too large"):
        sgm.check_sgm_options((48, 64), max_disp=16, cost_window=5, p2=1000)
    with pytest.raises(InputError, match="^lr_check: expected one of winners, paper"):
        sgm.match(np.zeros((20, 30), np.uint8), np.zeros((20, 30), np.uint8), max_disp=4,
                  lr_check="both")
    with pytest.raises(InputError, match="^left: image 8x6 is smaller than the census window"):
        sgm.check_sgm_options((6, 8), max_disp=4)
    a = np.zeros((20, 30), np.uint8)
    with pytest.raises(InputError, match="^right: size 29x20 differs"):
        sgm.match(a, a[:, :29], max_disp=4)


@pytest.mark.parametrize("row, kept", [
    ([9000, 9000, 2000, 1000, 1200, 1002, 9000, 9000], True),   # minimum towards 4; 5 is its valley's far wall
    ([9000, 1002, 1200, 1000, 2000, 9000, 9000, 9000], True),   # the mirror image: minimum towards 3
    ([9000, 9000, 2000, 1000, 1200, 9000, 1002, 9000], False),  # a second minimum 3 px away
    ([9000, 9000, 1200, 1000, 2000, 1002, 9000, 9000], False),  # near-tie on the side away from the minimum
])
def test_uniqueness_leaves_out_the_valley_of_the_subpixel_minimum(row, kept):
    # best d = 4 (cost 1000); the runner-up within 0.5 % of it is refused by the
    # plain test unless it is the far wall of the valley the parabola puts the
    # minimum in (1.5 px from it at most)
    S = np.full((1, 8, 8), 9000, np.uint16)
    S[0, 7] = np.roll(row, 1)  # pixel x = 7 sees every d; the minimum moves to d = 4
    win = sgm.winners(S, right=False)
    assert win["best"][0, 7] == 4
    kw = dict(D=8, uniqueness=0.005, lr_tolerance=-1, subpixel=True)
    plain, _ = sgm._decide(win, **kw)
    valley, _ = sgm._decide(win, **kw, S=S)
    assert np.isnan(plain[0, 7])
    assert np.isfinite(valley[0, 7]) == kept
