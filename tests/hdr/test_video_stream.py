"""``hdr video`` on a cluster over videos of any length (issue 19): the
client learns the stack's times and bit depth one decoded frame at a time
(:func:`capture.io.scan_stack`), tone-maps one frame at a time
(:func:`hdr.kang2003.tonemap_frame`), writes what the in-process run writes,
and its memory does not grow with the number of frames."""

from __future__ import annotations

import json
import tracemalloc

import numpy as np
import pytest

from lumigraph.capture.errors import InputError
from lumigraph.capture.io import read_stack, scan_stack, write_exr, write_image, write_stack_json

# ----------------------------------------------------------- the header pass


def _codes(rng, top, shape=(5, 7, 3), dtype=np.uint16):
    z = rng.integers(0, top + 1, shape).astype(dtype)
    z.flat[0] = top  # the largest code present (a clipped pixel)
    return z


def _case(name, d, rng):
    """Files for a decision of decide_bit_depth, and read_stack's keywords."""
    paths = [d / f"f{i}.png" for i in range(3)]
    kw = {"times": [0.01, 0.02, 0.04]}
    if name == "8-bit":
        for p in paths:
            write_image(p, _codes(rng, 255, dtype=np.uint8))
    elif name == "12-bit plateau":
        for p, top in zip(paths, (900, 4095, 4095), strict=True):
            write_image(p, _codes(rng, top))
    elif name == "10-bit left-aligned":
        for p in paths:
            write_image(p, _codes(rng, 1023) << 6)
    elif name == "sBIT":
        for p in paths:
            write_image(p, _codes(rng, 4095), bit_depth=12)
    elif name == "given":
        for p in paths:
            write_image(p, _codes(rng, 3000))
        kw["bit_depth"] = 14
    elif name == "given too small":
        for p, top in zip(paths, (100, 200, 3000), strict=True):
            write_image(p, _codes(rng, top))
        kw["bit_depth"] = 10
    elif name == "stack.json":
        for p in paths:
            write_image(p, _codes(rng, 3000))
        write_stack_json(d, [p.name for p in paths], bit_depth=12, exposure_times_s=[1, 2, 4],
                         f_numbers=[4.0, 2.8, 2.0])
        return [d], {}
    elif name == "sizes differ":
        for i, p in enumerate(paths):
            write_image(p, _codes(rng, 255, shape=(5, 7 + (i == 2), 3), dtype=np.uint8))
    elif name == "float":
        paths = [d / f"f{i}.exr" for i in range(3)]
        for p in paths:
            write_exr(p, rng.random((5, 7, 3)).astype(np.float32))
    return paths, kw


CASES = ("8-bit", "12-bit plateau", "10-bit left-aligned", "sBIT", "given", "given too small",
         "stack.json", "sizes differ", "float")


@pytest.mark.parametrize("name", CASES)
def test_the_header_pass_decides_what_read_stack_decides(name, tmp_path):
    paths, kw = _case(name, tmp_path, np.random.default_rng(CASES.index(name)))
    try:
        full = read_stack(paths, need_times=True, **kw)
    except InputError as e:
        with pytest.raises(InputError) as got:
            scan_stack(paths, need_times=True, **kw)
        assert (got.value.where, got.value.problem) == (e.where, e.problem)
        return
    head = scan_stack(paths, need_times=True, **kw)
    for attr in ("paths", "bit_depth", "bit_depth_source", "exposure_times_s",
                 "effective_exposure_times_s", "linear", "info", "times_given"):
        assert getattr(head, attr) == getattr(full, attr), attr
    assert head.shape == full.images.shape[1:] and head.dtype == full.images.dtype


# ----------------------------------------------------- tone mapping by frames


@pytest.mark.parametrize(("temporal", "bit_depth"), [(1, 8), (5, 8), (3, 16)])
def test_tonemapping_frame_by_frame_is_tonemap_video_to_the_bit(temporal, bit_depth):
    from lumigraph.hdr.kang2003 import frame_log_stats, tonemap_frame, tonemap_video, video_exposure

    rng = np.random.default_rng(temporal)
    v = np.exp(rng.normal(0, 2, (7, 9, 11, 3))).astype(np.float32)
    v[2, :3] = -0.5  # below zero (noise in the dark): clipped at 0 either way
    v[4, 4:] *= 300.0
    whole = tonemap_video(v, temporal=temporal, bit_depth=bit_depth)
    e = video_exposure([frame_log_stats(f) for f in v], temporal=temporal, bit_depth=bit_depth)
    frames = np.stack([tonemap_frame(f, e, i) for i, f in enumerate(v)])
    assert frames.dtype == whole.images.dtype and (frames == whole.images).all()
    assert (e.log_average == whole.log_average).all()
    assert (e.log_average_used == whole.log_average_used).all()
    assert e.flicker == whole.flicker and e.params == whole.params


# ------------------------------------------------------------- the command


@pytest.fixture(scope="module")
def videos(tmp_path_factory):
    """Rendered alternating-exposure videos (3, 4 and 16 frames) and their
    true response curve."""
    from lumigraph.capture.render import render
    from lumigraph.hdr.response import ResponseCurve

    d = tmp_path_factory.mktemp("videos")
    for n in (3, 4, 16):
        s = render("bracket_video", size=(160, 120), frames=n, seed=2)
        s.save(d / f"v{n}")
    ResponseCurve("gt", 8, s.gt_arrays["g"]).save(d / "response.json")
    return d


def _batch(monkeypatch, argv):
    """The cluster path of ``hdr video`` with its items run in this process
    (the in-process engine; outside the command's staged result set, as a
    worker writes them), so the client's own work is measurable here."""
    from lumigraph.hdr import cli

    monkeypatch.setattr(cli, "batch_requested", lambda args: True)
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)  # in this process, always
    args = cli.build_parser().parse_args(["video", *map(str, argv)])
    return args.func(args)


def _untimed(d):
    """A sidecar's section without its timings (``time_s``), which differ per run."""
    if isinstance(d, dict):
        return {k: _untimed(v) for k, v in d.items() if k != "time_s"}
    return [_untimed(v) for v in d] if isinstance(d, list) else d


def test_the_batch_path_writes_what_the_in_process_run_writes(videos, tmp_path, monkeypatch):
    from lumigraph.hdr.cli import main

    argv = [videos / "v4", "--response", videos / "response.json", "--tonemap", "-q"]
    assert main(["video", *map(str, argv), "--out", str(tmp_path / "plain")]) == 0
    assert _batch(monkeypatch, [*argv, "--out", tmp_path / "batch"]) == 0
    names = [f"frame_{i:03d}.{ext}" for i in range(4) for ext in ("exr", "png")]
    for name in names:
        assert (tmp_path / "plain" / name).read_bytes() == (tmp_path / "batch" / name).read_bytes()
        plain, batch = (json.loads((tmp_path / w / f"{name}.meta.json").read_text())
                        for w in ("plain", "batch"))
        assert plain["params"] == batch["params"]
        assert _untimed(plain["quality"]) == _untimed(batch["quality"])
    plain, batch = (json.loads((tmp_path / w / "video.meta.json").read_text())
                    for w in ("plain", "batch"))
    assert plain["params"] == batch["params"]
    # the frames' diagnostics and the flicker
    assert _untimed(plain["quality"]) == _untimed(batch["quality"])


def test_the_clients_memory_does_not_grow_with_the_frames(videos, tmp_path, monkeypatch):
    """Peak traced memory of the client (the items run in it too, three frames
    each): 16 frames against 4. Keeping any frame's pixels, even as its 8-bit
    codes, would cost H·W·C bytes per frame (the old client kept every frame's
    codes and, with --tonemap, every radiance frame in float64: ~80x that); what
    may grow is the per-frame metadata (times, hashes, diagnostics), bounded
    here by half a frame's codes per frame."""
    frame_bytes = 120 * 160 * 3  # one frame's uint8 codes
    argv = ["--response", videos / "response.json", "--tonemap", "-q"]
    _batch(monkeypatch, [videos / "v3", *argv, "--out", tmp_path / "warm"])  # imports, caches
    peaks = {}
    for n in (4, 16):
        tracemalloc.start()
        try:
            assert _batch(monkeypatch, [videos / f"v{n}", *argv, "--out", tmp_path / f"o{n}"]) == 0
            peaks[n] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert peaks[16] - peaks[4] < (16 - 4) * frame_bytes / 2, peaks
