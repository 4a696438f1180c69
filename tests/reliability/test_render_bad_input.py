"""``lumigraph render``: a scene option arrives unparsed and goes through the
scene's spec, so a NaN, an infinity or a value out of the spec's range is exit
2 naming the option, before anything is rendered or written; a re-render into
a folder commits as one set."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from reliability._inprocess_cli import assert_refused, cli, snapshot

from lumigraph.capture.errors import InputError

SIZE = ["--size", "48x36"]

BAD = [
    ("--stops", ["bracket", "--stops", "nan"]),
    ("--stops", ["bracket", "--stops", "inf"]),
    ("--stops", ["bracket", "--stops=-1"]),
    ("--min-time", ["bracket", "--min-time", "nan"]),
    ("--min-time", ["bracket", "--min-time", "1e308"]),  # its times overflowed to null
    ("--read-noise", ["bracket", "--read-noise", "1e308"]),  # an OverflowError
    ("--exposures", ["bracket", "--exposures", "2.5"]),
    ("--pan", ["bracket_video", "--pan", "inf"]),
    ("--pan", ["bracket_video", "--pan", "1e300"]),  # the texture lookup never returned
    ("--focus", ["lightfield-array", "--focus", "1,nan"]),
    ("--spacing", ["lightfield-array", "--spacing", "1e308"]),
    ("--square", ["boards", "--square", "1e308", "--size", "96x72"]),
    ("--baseline", ["boards-stereo", "--baseline", "1e-300", "--size", "96x72"]),
    ("--full-well", ["projector", "--full-well", "1e12", "--size", "32x24"]),  # numpy's Poisson
    # in range, but a refocus slope the scene's textures cannot serve: refused, not exit 1
    ("--disparity-near", ["lightfield-array", "--disparity-near", "8", "--size", "48x36",
                          "--grid", "3x3"]),
    ("--seed", ["bracket", "--seed=-1"]),
    ("--seed", ["bracket", "--seed", "1.5"]),
    ("--size", ["bracket", "--size", "3by2"]),
    ("--size", ["bracket", "--size", "3x2"]),
    ("SCENE", ["nosuch"]),
]


@pytest.mark.parametrize("where,argv", BAD, ids=[" ".join(a) for _, a in BAD])
def test_bad_scene_options_are_refused_naming_the_option(capsys, tmp_path, where, argv):
    out = tmp_path / "out"
    size = [] if "--size" in argv else SIZE
    r = cli(capsys, "render", *argv, *size, "--out", out, "--no-cache")
    assert_refused(r, where)
    assert not out.exists()


def test_the_scene_spec_refuses_non_finite_values_naming_the_option():
    from lumigraph.capture.render import get_scene, render

    spec = get_scene("bracket")
    for name, value in (("stops", "nan"), ("stops", math.inf), ("min_time", "-inf"),
                        ("noise", float("nan"))):
        with pytest.raises(InputError) as e:
            spec.parse_options({name: value})
        assert e.value.where == name
    with pytest.raises(InputError) as e:
        render("bracket", stops=float("nan"), cache=False)
    assert e.value.where == "stops"
    with pytest.raises(InputError) as e:
        get_scene("lightfield-array").parse_options({"novel": "0,inf,0"})
    assert e.value.where == "novel"


def _render(capsys, out, *opts):
    r = cli(capsys, "render", "bracket", *SIZE, "--out", out, "--no-cache", "-q", *opts)
    assert r.returncode == 0, r.stderr


def test_a_re_render_commits_one_consistent_set_and_writes_only_in_out(capsys, tmp_path):
    from lumigraph.capture.io import read_stack
    from lumigraph.capture.render import render

    d = tmp_path / "bracket"
    (tmp_path / "mine.txt").write_text("a user's file beside the output")
    _render(capsys, d, "--exposures", "5")
    beside = snapshot(*[p for p in tmp_path.iterdir() if p != d])
    old = snapshot(d)
    _render(capsys, d, "--exposures", "3", "--seed", "1")
    assert snapshot(*[p for p in tmp_path.iterdir() if p != d]) == beside  # nothing outside --out
    # stack.json names the new set; every file it names is the new render's,
    # the ground truth too; files it no longer names stay (a user's files are
    # never deleted) but no reader through stack.json sees them
    fresh = render("bracket", size=(48, 36), exposures=3, seed=1, cache=False)
    stack = read_stack([d])
    assert [p.rsplit("/", 1)[-1] for p in stack.paths] == list(fresh.image_names)
    for got, want in zip(stack.images, fresh.images, strict=True):
        assert np.array_equal(got.reshape(want.shape), want)
    assert json.loads((d / "gt.json").read_text())["params"]["exposures"] == 3
    assert np.array_equal(np.load(d / "gt" / "radiance.npy"), fresh.gt_arrays["radiance"])
    assert (d / "exposure_04.png").read_bytes() == old[str(d / "exposure_04.png")]
    r = cli(capsys, "hdr", "response", d, "--out", tmp_path / "r.json", "-q")
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "r.json.meta.json").read_text())
    assert len(meta["inputs"]) == 3


def test_a_re_render_that_fails_leaves_the_previous_set_untouched(capsys, tmp_path, monkeypatch):
    import lumigraph.capture.io as io

    d = tmp_path / "bracket"
    _render(capsys, d, "--exposures", "4")
    before = snapshot(d)

    def broken(*a, **k):  # the last file of the set fails after the images were written
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(io, "write_stack_json", broken)
    r = cli(capsys, "render", "bracket", *SIZE, "--out", d, "--no-cache", "--exposures", "2",
            "--seed", "5")
    assert r.returncode == 2, r.stderr
    assert snapshot(d) == before
