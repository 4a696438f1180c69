"""HDR video (Kang et al. 2003) against the exact per-frame radiance of ``bracket_video``."""

import json

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture.io import read_exr
from lumigraph.capture.render import render
from lumigraph.hdr import kang2003
from lumigraph.hdr.bench import recoverable
from lumigraph.hdr.kang2003 import (
    FALLBACK,
    WARPED,
    Radiometry,
    hdr_video,
    tonemap_video,
    unaligned_merge,
)
from lumigraph.hdr.merge import merge
from lumigraph.hdr.response import ResponseCurve

SIZE = (160, 120)
FRAMES = 5
NOISE = {"full_well_e": 20000.0, "read_noise_e": 4.0}  # the scene's sensor


def _video(**opts):
    s = render("bracket_video", size=SIZE, frames=FRAMES, seed=1, **opts)
    z = np.stack(s.images)
    t = np.array(s.stack["exposure_times_s"])
    truth = s.gt_arrays["radiance"].astype(np.float64) * s.gt["exposure_scale"]
    return s, z, t, truth, ResponseCurve("gt", 8, s.gt_arrays["g"])


def _log_err(est, truth, m):
    return np.log(np.maximum(est[m], 1e-12)) - np.log(truth[m])


def _true_motion(pan):
    """A ``_register`` that samples each neighbour at the scene's exact background
    motion (``pan`` px/frame to the right, ``bracket_video``'s ground truth), never
    occluded: the registration an oracle flow would give."""
    def register(i, x_all, t, rad, grid, flow_opts, *, bidirectional):
        maps, occ, unc = {}, {}, {}
        for j in (i - 1, i + 1):
            if 0 <= j < len(x_all):
                maps[j] = grid + np.array([pan * (j - i), 0.0], np.float32)
                occ[j] = np.zeros(grid.shape[:2], bool)
                unc[j] = np.zeros(grid.shape[:2], np.float32)
        return maps, occ, unc, {"mode": "true motion"}
    return register


def _neighbour_noise(truth, t, rad, i, m):
    """Relative shot + read noise of one neighbour's estimate at the truth
    (electrons = X * full well) over mask ``m``: the floor any fill-in carries."""
    j = i + 1 if i + 1 < FRAMES else i - 1
    x = truth[i][m] * t[j] / rad.x[np.nonzero(m)[2], -1]
    return np.sqrt(x * NOISE["full_well_e"] + NOISE["read_noise_e"] ** 2) / (x * NOISE["full_well_e"])


@pytest.fixture(scope="module")
def moving():
    s, z, t, truth, r = _video()
    return s, z, t, truth, r, hdr_video(z, t, r, **NOISE)


@pytest.fixture(scope="module")
def oracle(moving):
    """The same merge registered by the true motion instead of estimated flow."""
    s, z, t, _truth, r, _v = moving
    mp = pytest.MonkeyPatch()
    mp.setattr(kang2003, "_register", _true_motion(s.gt["pan_px"]))
    try:
        return hdr_video(z, t, r, **NOISE)
    finally:
        mp.undo()


def test_beats_single_frame_and_unaligned_merge(moving, oracle):
    _s, z, t, truth, r, v = moving
    rad = Radiometry(r, 3, clip_margin=0.02, **NOISE)
    e = {"ours": [], "naive": [], "single": [], "oracle": []}
    sig = []
    for i in range(FRAMES):
        m = recoverable(z, t, truth, rad, i)
        e["ours"].append(_log_err(v.radiance[i], truth[i], m))
        e["oracle"].append(_log_err(oracle.radiance[i], truth[i], m))
        e["naive"].append(_log_err(unaligned_merge(z, t, r, i, **NOISE), truth[i], m))
        e["single"].append(_log_err(merge(z[i:i + 1], t[i:i + 1], r).radiance, truth[i], m))
        sig.append(_neighbour_noise(truth, t, rad, i, m))
    rms = {k: float(np.sqrt(np.mean(np.concatenate(a) ** 2))) for k, a in e.items()}
    noise = float(np.sqrt(np.mean(np.concatenate(sig) ** 2)))
    # Lower bound: noise (and interpolation) cannot vanish; a copied truth would.
    assert 0.5 * noise < rms["ours"], (rms, noise)
    # Registration must win by more than three times the noise floor over both the
    # unaligned merge (ghosts of a 1.5 px/frame pan) and the frame's own bounds.
    assert rms["ours"] < rms["naive"] - 3 * noise, (rms, noise)
    assert rms["ours"] < rms["single"] - 3 * noise, (rms, noise)
    # Upper bound: estimated flow may cost at most three noise sigmas over the same
    # merge registered by the scene's true motion (which keeps the resampling and
    # fall-back error any registration has).
    assert rms["ours"] < rms["oracle"] + 3 * noise, (rms, noise)


def test_where_warped_is_not_ghosted(moving):
    _s, z, t, truth, r, v = moving
    rad = Radiometry(r, 3, clip_margin=0.02, **NOISE)
    ours, naive, sig = [], [], []
    for i in range(FRAMES):
        w = (v.flags[i] & WARPED) > 0
        w[:, :6] = w[:, -6:] = False
        ours.append(_log_err(v.radiance[i], truth[i], w))
        naive.append(_log_err(unaligned_merge(z, t, r, i, **NOISE), truth[i], w))
        sig.append(_neighbour_noise(truth, t, rad, i, w))
    o, n, noise = (float(np.sqrt(np.mean(np.concatenate(a) ** 2))) for a in (ours, naive, sig))
    # Exactly where neighbours were warped in, ours must beat the ghosted merge by
    # more than three noise sigmas of the fill-in itself.
    assert 0.0 < o < n - 3 * noise, (o, n, noise)
    for f in v.frames:
        s = f["sources"]
        assert abs(sum(s.values()) - 1.0) < 1e-6
        assert s["previous"] + s["next"] + s["both"] > 0.03, s


def test_static_equals_plain_merge_within_noise():
    _s, z, t, truth, r = _video(pan=0.0, light_speed=0.0)
    v = hdr_video(z, t, r, **NOISE)
    rad = Radiometry(r, 3, clip_margin=0.02, **NOISE)
    for i in (1, 2, 3):  # inner frames: both neighbours, bidirectional registration
        plain = unaligned_merge(z, t, r, i, **NOISE)
        rel = rad.lookup(rad.reliable.astype(np.float32), z[i]) > 0
        var_c = rad.lookup(rad.var, z[i]) / t[i] ** 2
        # Reliable in the current frame: ours is that frame, the plain merge the
        # inverse-variance mean of it and its neighbours, so Var(ours - plain) =
        # Var(cur) - Var(plain) <= Var(cur): RMS of the difference in units of the
        # current frame's sigma is at most 1 (+5 % for the noise model's rounding).
        d = (v.radiance[i] - plain)[rel] / np.sqrt(var_c[rel])
        assert float(np.sqrt(np.mean(d ** 2))) < 1.05
        # Clipped in the current frame: both are the neighbours' mean; only the
        # estimated (near-zero) flow's resampling separates them: within a tenth of
        # their noise sigma on average, and mostly identical.
        w = (v.flags[i] & WARPED) > 0
        var_n = np.mean([rad.lookup(rad.var, z[j]) / t[j] ** 2 for j in (i - 1, i + 1)], 0) / 2
        dn = (v.radiance[i] - plain)[w] / np.sqrt(var_n[w])
        assert float(np.sqrt(np.mean(dn ** 2))) < 0.5, float(np.sqrt(np.mean(dn ** 2)))
        # Fall-back only where every frame is clipped.
        fb = (v.flags[i] & FALLBACK) > 0
        all_clip = ~np.any([rad.lookup(rad.reliable.astype(np.float32), z[j]) > 0
                            for j in (i - 1, i, i + 1)], axis=0)
        assert (fb & ~all_clip).mean() < 0.002, (fb & ~all_clip).mean()
        assert v.frames[i]["flow"]["mean_motion_px"] < 0.1
    # End frames have one neighbour and no pair around them; they also register
    # through the flow to the frame two away (same exposure, no boost), halved.
    # Its round trip closes in flat dark areas where the boosted one-way pair's
    # does not, so fewer recoverable pixels fall back than with the one-way flow
    # alone: by more than three binomial standard errors of the difference.
    oneway = hdr_video(z, t, r, bidirectional=False, **NOISE)
    rad_rel = Radiometry(r, 3, clip_margin=0.02, **NOISE)
    for i in (0, FRAMES - 1):
        m = recoverable(z, t, truth, rad_rel, i)
        ours = float(((v.flags[i] & FALLBACK) > 0)[m].mean())
        one = float(((oneway.flags[i] & FALLBACK) > 0)[m].mean())
        assert v.frames[i]["flow"]["pair"] == [i, 2 if i == 0 else FRAMES - 3]
        se = np.sqrt((ours * (1 - ours) + one * (1 - one)) / m.sum())
        assert ours < one - 3 * se, (i, ours, one, se)


def test_tonemap_temporal_smoothing_reduces_flicker(moving):
    *_, v = moving
    a = tonemap_video(v.radiance, temporal=1)
    b = tonemap_video(v.radiance, temporal=5)
    assert b.images.shape == v.radiance.shape and b.images.dtype == np.uint8
    # The alternating fall-back bounds move the per-frame log-average; a 5-frame
    # window averages them out.
    assert 0.0 <= b.flicker < 0.5 * a.flicker, (a.flicker, b.flicker)


def test_bad_arguments():
    _s, z, t, _truth, r = _video()
    with pytest.raises(ValueError, match="at least 2 frames"):
        hdr_video(z[:1], t[:1], r)
    with pytest.raises(ValueError, match="same exposure"):
        hdr_video(z, np.full(FRAMES, t[0]), r)
    with pytest.raises(ValueError, match="exposure times for"):
        hdr_video(z, t[:3], r)
    with pytest.raises(ValueError, match="bit depth"):
        hdr_video(z.astype(np.uint16) * 16, t, ResponseCurve.linear(8))
    with pytest.raises(ValueError, match="temporal"):
        tonemap_video(np.ones((2, 4, 4, 3), np.float32), temporal=2)


# ----------------------------------------------------------------------- CLI
@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("video")
    s = render("bracket_video", size=SIZE, frames=4, seed=2)
    s.save(d / "vid")
    ResponseCurve("gt", 8, s.gt_arrays["g"]).save(d / "response.json")
    ResponseCurve.linear(12).save(d / "resp12.json")
    return d


def test_cli_video(folder, tmp_path):
    out = tmp_path / "o"
    r = lumigraph("hdr", "video", folder / "vid", "--response", folder / "response.json",
                  "--out", out, "--tonemap", "-q")
    assert r.returncode == 0, r.stderr
    for i in range(4):
        rad = read_exr(out / f"frame_{i:03d}.exr")
        assert rad.shape == (120, 160, 3) and np.isfinite(rad).all() and rad.min() >= 0
        assert (out / f"frame_{i:03d}.png").exists()
        meta = json.loads((out / f"frame_{i:03d}.exr.meta.json").read_text())
        assert set(meta["quality"]["sources"]) == {"current", "previous", "next", "both",
                                                   "fallback"}
    summary = json.loads((out / "video.meta.json").read_text())
    assert summary["quality"]["flicker"] is not None


def test_cli_bad_inputs_write_nothing(folder, tmp_path):
    import shutil

    from lumigraph.capture.io import read_image, write_image

    out = tmp_path / "o"
    vid = folder / "vid"
    frames = sorted(str(p) for p in vid.glob("frame_*.png"))
    resp = folder / "response.json"
    r = lumigraph("hdr", "video", frames[0], "--times", "0.002", "--response", resp, "--out", out)
    assert_clean_error(r, frames[0], "at least 2 frames")
    r = lumigraph("hdr", "video", *frames[:2], "--response", resp, "--out", out)
    assert_clean_error(r, "exposure time")
    small = tmp_path / "small.png"
    write_image(small, read_image(frames[1])[:60, :80])
    r = lumigraph("hdr", "video", frames[0], small, "--times", "0.002,0.016", "--response", resp,
                  "--out", out)
    assert_clean_error(r, "small.png")
    r = lumigraph("hdr", "video", vid, "--response", folder / "resp12.json", "--out", out)
    assert_clean_error(r, "resp12.json", "12-bit")
    r = lumigraph("hdr", "video", *frames[:3], "--times", "0.002,0.002,0.002", "--response", resp,
                  "--out", out)
    assert_clean_error(r, "--times", "same exposure")
    r = lumigraph("hdr", "video", vid, "--response", resp, "--out", out, "--temporal", "4")
    assert_clean_error(r, "--temporal")
    assert not out.exists()
    shutil.rmtree(tmp_path / "o", ignore_errors=True)


def test_grey_video_is_the_colour_path_on_one_channel():
    # OpenCV drops a single channel's axis; a grey (N, H, W, 1) video used to stop
    # with a broadcast error. Against three copies of the channel: every pixel
    # the grey run kept from its own frame (neither warped nor a fallback) is
    # the same number in every channel. Warped pixels follow the flow, which sees
    # a luminance one rounding away, so they are only required to be finite.
    from lumigraph.capture.render import render as render_scene
    from lumigraph.hdr.kang2003 import FALLBACK, WARPED
    from lumigraph.hdr.kang2003 import hdr_video as video
    from lumigraph.hdr.response import ResponseCurve as Curve

    s = render_scene("bracket_video", size=(64, 48), frames=4)
    z = np.stack(s.images)[..., :1]
    t = s.stack["exposure_times_s"]
    grey = video(z, t, Curve.linear(8, 1))
    colour = video(np.repeat(z, 3, axis=3), t, Curve.linear(8, 3))
    assert grey.radiance.shape == grey.flags.shape == (4, 48, 64, 1)
    assert np.isfinite(grey.radiance).all()
    own = (grey.flags[..., 0] & (WARPED | FALLBACK)) == 0
    assert 0 < own.mean() < 1
    for c in range(3):
        np.testing.assert_array_equal(grey.radiance[..., 0][own], colour.radiance[..., c][own])


def test_a_frame_from_its_neighbours_alone_is_the_whole_run_frame(folder):
    """Frame i reads the frames frames_used names only (its neighbours; an
    end frame also the frame two away): completed from those, its radiance
    and flags are the whole run's to the bit (what a batch item of ``hdr
    video`` computes)."""
    from lumigraph.capture.io import read_stack
    from lumigraph.hdr.kang2003 import frames_used, hdr_video

    stack = read_stack([folder / "vid"], need_times=True)
    curve = ResponseCurve.load(folder / "response.json")
    t = list(stack.effective_exposure_times_s)
    whole = hdr_video(stack.images, t, curve)
    n = len(t)
    for i in range(n):
        r = frames_used(i, n)
        lo, hi = r.start, r.stop
        part = hdr_video(stack.images[lo:hi], t[lo:hi], curve, only=[i - lo])
        assert np.array_equal(part.radiance[0], whole.radiance[i])
        assert np.array_equal(part.flags[0], whole.flags[i])
        assert part.frames[0]["sources"] == whole.frames[i]["sources"]
    assert n >= 4  # both ends read a frame two away, the inner frames their neighbours
