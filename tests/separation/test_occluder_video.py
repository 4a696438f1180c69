"""``lumigraph separate VIDEO --method occluder``: the video form and the still-frame
form give the same result on the same frames; a synthetic sweep with exact
ground truth; Nayar et al.'s real videos; bad video inputs."""

import json
import shutil

import numpy as np
import pytest
from conftest import ROOT, assert_clean_error, lumigraph, need_shared

from lumigraph.capture import io
from lumigraph.capture.video import bt709_to_linear, linear_to_bt709, read_video, write_video
from lumigraph.separation.video import video_response

FIX = ROOT / "fixtures" / "projector"
OCC = [FIX / f"occluder_{k:02d}.png" for k in range(4)]


def _read(out):
    return [io.read_exr(out / n) for n in ("direct.exr", "global.exr")]


def _meta(out):
    return json.loads((out / "direct.exr.meta.json").read_text())["params"]


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """The projector fixture's shadow sweep (4 frames, 16-bit linear), BT.709-encoded
    to 8 bits: as a lossless FFV1 video (twice over, 8 frames) and as PNGs."""
    d = tmp_path_factory.mktemp("sweep")
    lin = np.stack([io.read_image(p) for p in OCC]).astype(np.float64) / 65535.0
    codes = np.round(255.0 * linear_to_bt709(lin)).astype(np.uint8)
    codes = np.repeat(codes[..., None], 3, axis=-1)
    video = write_video(d / "sweep.avi", np.concatenate([codes, codes]))
    assert np.array_equal(read_video(video).frames[:4], codes)  # FFV1 is lossless
    pngs = []
    for k, c in enumerate(codes):
        pngs.append(d / f"frame_{k}.png")
        io.write_image(pngs[-1], c)
    for k, p in enumerate(OCC):
        shutil.copy(p, d / f"lin_{k}.png")  # the 16-bit linear originals
    video_response(3).save(d / "bt709.json")
    return d, video, pngs, codes


def test_video_and_frames_agree_and_match_the_linear_sweep(sweep, tmp_path):
    d, video, pngs, codes = sweep
    r = lumigraph("separate", video, "--method", "occluder", "--max-frames", "4",
                  "--out", tmp_path / "v", "-q")
    assert r.returncode == 0, r.stderr
    assert "BT.709" in r.stderr  # the assumed curve is said
    r = lumigraph("separate", *pngs, "--method", "occluder", "--response", d / "bt709.json",
                  "--out", tmp_path / "f", "-q")
    assert r.returncode == 0, r.stderr
    (vd, vg), (fd, fg) = _read(tmp_path / "v"), _read(tmp_path / "f")
    assert np.array_equal(vd, fd) and np.array_equal(vg, fg)
    mv, mf = _meta(tmp_path / "v"), _meta(tmp_path / "f")
    assert mv["video"]["frames"] == [0, 1, 2, 3] and mv["images"] == mf["images"] == 4
    assert mv["alpha"] == mf["alpha"] and mv["alpha_source"] == "measured"
    # one bar in four is dark: alpha = 3/4. A pixel wholly inside a projector
    # cell votes lit in exactly 3 frames; one straddling a bar edge is partly lit
    # in two frames, and its vote may be off by one frame in four
    lin = np.stack([io.read_image(p) for p in OCC]).astype(np.float64) / 65535.0
    hi, lo = lin.max(axis=0), lin.min(axis=0)
    c = hi - lo
    sel = c >= 0.5 * np.percentile(c, 90)  # the pixels the estimate counts
    partial = ((lin > lo + 0.1 * c) & (lin < hi - 0.1 * c)).any(axis=0)[sel].mean()
    assert abs(mv["alpha"] - 0.75) <= 0.25 * partial

    # against the same sweep in 16-bit linear codes: the only difference is the
    # 8-bit BT.709 quantisation, at most one code step of the curve at each extreme
    r = lumigraph("separate", *sorted(d.glob("lin_*.png")), "--method", "occluder",
                  "--out", tmp_path / "l", "-q")
    assert r.returncode == 0, r.stderr
    ld, lg = (x[..., None] if x.ndim == 2 else x for x in _read(tmp_path / "l"))
    lin = codes[..., :1].astype(np.int64)
    step = bt709_to_linear(np.minimum(lin + 1, 255)) - bt709_to_linear(np.maximum(lin - 1, 0))
    step_max = np.take_along_axis(step, lin.argmax(axis=0)[None], 0)[0]
    step_min = np.take_along_axis(step, lin.argmin(axis=0)[None], 0)[0]
    tol16 = 2.0 / 65535
    assert np.all(np.abs(vd[..., :1] - ld) <= 0.5 * (step_max + step_min) + tol16)
    assert np.all(np.abs(vg[..., :1] - lg) <= 0.5 * step_min / 0.75 + tol16)


def test_stride_keeps_every_nth_frame(sweep, tmp_path):
    d, video, pngs, _ = sweep
    # 8 frames = the sweep twice; stride 2 keeps 0, 2, 4, 6 = frames 0, 2, 0, 2 of the sweep
    r = lumigraph("separate", video, "--method", "occluder", "--stride", "2", "--alpha", "0.5",
                  "--out", tmp_path / "v", "-q")
    assert r.returncode == 0, r.stderr
    r = lumigraph("separate", pngs[0], pngs[2], pngs[0], pngs[2], "--method", "occluder",
                  "--alpha", "0.5", "--response", d / "bt709.json", "--out", tmp_path / "f", "-q")
    assert r.returncode == 0, r.stderr
    (vd, vg), (fd, fg) = _read(tmp_path / "v"), _read(tmp_path / "f")
    assert np.array_equal(vd, fd) and np.array_equal(vg, fg)
    assert _meta(tmp_path / "v")["video"]["frames"] == [0, 2, 4, 6]


def test_bad_video_inputs_exit_2(sweep, tmp_path, monkeypatch):
    d, video, pngs, _ = sweep
    junk = tmp_path / "junk.mpg"
    junk.write_bytes(b"\x00\x00\x01\xb3" + bytes(range(256)) * 8)
    assert_clean_error(lumigraph("separate", junk, "--method", "occluder", "--out",
                                 tmp_path / "o"), "junk.mpg")
    assert_clean_error(lumigraph("separate", *pngs[:3], "--method", "occluder", "--stride", "2",
                                 "--out", tmp_path / "o"), "--stride", "video")
    assert_clean_error(lumigraph("separate", video, pngs[0], "--method", "occluder",
                                 "--out", tmp_path / "o"), "sweep.avi", "alone")
    assert_clean_error(lumigraph("separate", video, "--method", "occluder", "--stride", "0",
                                 "--out", tmp_path / "o"), "--stride")
    monkeypatch.setenv("LUMIGRAPH_MAX_PIXELS", "1000")  # 48x36 = 1728 pixels a frame
    assert_clean_error(lumigraph("separate", video, "--method", "occluder", "--out",
                                 tmp_path / "o"), "sweep.avi", "1728")
    monkeypatch.setenv("LUMIGRAPH_MAX_PIXELS", "6000")  # three frames fit, not four
    assert_clean_error(lumigraph("separate", video, "--method", "occluder", "--out",
                                 tmp_path / "o"), "sweep.avi", "max_frames")
    assert not (tmp_path / "o").exists()


def test_real_video_both_forms(tmp_path):
    """Red_Leaves.mpg (CAVE): a pole's shadow swept over leaves; 20 frames, every 4th."""
    src = need_shared("data", "separation-cave-occluder", "Red_Leaves.mpg")
    r = lumigraph("separate", src, "--method", "occluder", "--stride", "4", "--max-frames", "20",
                  "--out", tmp_path / "v", "-q")
    assert r.returncode == 0, r.stderr
    v = read_video(src, stride=4, max_frames=20)
    pngs = []
    for i, f in zip(v.indices, v.frames, strict=True):
        pngs.append(tmp_path / f"frame_{i:03d}.png")
        io.write_image(pngs[-1], f)
    video_response(3).save(tmp_path / "bt709.json")
    r = lumigraph("separate", *pngs, "--method", "occluder", "--response", tmp_path / "bt709.json",
                  "--out", tmp_path / "f", "-q")
    assert r.returncode == 0, r.stderr
    (vd, vg), (fd, fg) = _read(tmp_path / "v"), _read(tmp_path / "f")
    assert vd.shape == (472, 424, 3) and np.array_equal(vd, fd) and np.array_equal(vg, fg)
    m = _meta(tmp_path / "v")
    assert m["video"]["frames"] == list(range(0, 80, 4)) and not m["video"]["complete"]
    # a pole's shadow covers a few percent of the frame (PROVENANCE: thin occluder),
    # a mesh would leave alpha far below 1
    assert 0.85 < m["alpha"] < 0.99
