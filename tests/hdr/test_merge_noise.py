"""``lumigraph hdr merge --noise``: variance-optimal weights with the sensor's noise."""

import json

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture.io import read_exr
from lumigraph.capture.render import render
from lumigraph.hdr.response import ResponseCurve

FULL_WELL, READ_NOISE = 20000.0, 100.0  # a read-noise-limited sensor, far from the defaults


@pytest.fixture(scope="module")
def noisy(tmp_path_factory):
    d = tmp_path_factory.mktemp("noisy")
    s = render("bracket", size=(160, 120), full_well=FULL_WELL, read_noise=READ_NOISE, seed=1)
    s.save(d / "bracket")
    # The exact curve, so only the weights differ between the merges.
    ResponseCurve("gt", 8, s.gt_arrays["g"]).save(d / "r.json")
    return d, s


def _rel_rms(path, s):
    est = read_exr(path)[..., :3].astype(np.float64)
    truth = s.gt_arrays["radiance"].astype(np.float64) * s.gt["exposure_scale"]
    t = np.asarray(s.stack["exposure_times_s"])
    x = truth[None] * t[:, None, None, None]
    # Pixels well exposed in expectation in at least one exposure (from the truth, not
    # the noisy codes, so the set is the same for every merge).
    well = ((x > 0.05) & (x < 0.9)).any(axis=0)
    e, tr = est[well], truth[well]
    scale = np.sum(e / tr) / np.sum((e / tr) ** 2)  # one global scale (relative radiance)
    return float(np.sqrt(np.mean(((scale * e - tr) / tr) ** 2))), e.size


def test_noise_aware_merge_beats_default_weights(noisy, tmp_path):
    d, s = noisy
    errs, n = {}, 0
    for name, extra in (("default", ()), ("noise", ("--noise", f"{FULL_WELL:g},{READ_NOISE:g}"))):
        out = tmp_path / f"{name}.exr"
        r = lumigraph("hdr", "merge", d / "bracket", "--response", d / "r.json", "--out", out,
                      "-q", *extra)
        assert r.returncode == 0, r.stderr
        errs[name], n = _rel_rms(out, s)
    meta = json.loads((tmp_path / "noise.exr.meta.json").read_text())
    assert meta["params"]["noise"] == {"full_well_e": FULL_WELL, "read_noise_e": READ_NOISE,
                                       "source": "given (--noise)"}
    meta = json.loads((tmp_path / "default.exr.meta.json").read_text())
    assert meta["params"]["noise"]["source"].startswith("library default")
    # Margin from the sample size alone: an RMS over N independent pixel-channels
    # has a relative sampling error of about 1/sqrt(2N), so the noise-aware merge
    # must beat the default by more than three of those (about 1 % at N ~ 4e4)
    # to count as better rather than as a draw of the noise. The lower bound
    # says neither merge equals the truth.
    assert 0 < errs["noise"] < (1 - 3 / np.sqrt(2 * n)) * errs["default"], (errs, n)


@pytest.mark.parametrize("value, fragment", [
    ("20000", "two numbers"), ("20000,4,1", "two numbers"), ("abc,4", "cannot read"),
    ("-5,4", "full well"), ("0,4", "full well"), ("20000,-1", "read noise"),
    ("inf,4", "full well"), ("20000,nan", "read noise")])
def test_bad_noise_exits_2_and_writes_nothing(noisy, tmp_path, value, fragment):
    d, _ = noisy
    out = tmp_path / "x.exr"
    r = lumigraph("hdr", "merge", d / "bracket", "--response", d / "r.json", "--out", out,
                  f"--noise={value}")
    assert_clean_error(r, "--noise", fragment)
    assert not out.exists() and not list(tmp_path.iterdir())


def test_noise_with_hat_weights_is_refused(noisy, tmp_path):
    d, _ = noisy
    r = lumigraph("hdr", "merge", d / "bracket", "--response", d / "r.json", "--out",
                  tmp_path / "x.exr", "--weights", "hat", "--noise", "20000,4")
    assert_clean_error(r, "--noise", "variance")
    assert not list(tmp_path.iterdir())
