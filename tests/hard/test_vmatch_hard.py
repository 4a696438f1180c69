"""Hard cases of video matching (issue 15): textureless regions, added and
removed objects, frames of different sizes or empty. Each meets its bound
or says why not."""

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture import io
from lumigraph.capture.scenes.flow_lighting import VARIANTS, render_lighting
from lumigraph.stereo.sand2004 import video_matching

SIZE = (160, 120)


def _err(flow, gt):
    return np.hypot(*(flow - gt).transpose(2, 0, 1))


def test_textureless_regions_low_probability_not_garbage():
    # The cartoon kind: flat colour regions whose radiance has no gradient at
    # all (ground truth's textureless mask), under a gain/offset change.
    p = render_lighting("cartoon", size=SIZE, seed=1, **VARIANTS["gain"])
    flat = p.textureless & p.valid
    assert flat.mean() > 0.2
    r = video_matching(*p.frames)
    # Low: the texture term of the probability sees only noise there.
    assert r.confidence[flat].mean() < 0.25
    # Not garbage: finite, and filled from the surrounding edges by the
    # regression to within half the true motion on average (flat areas
    # carry no evidence of their own; a zero field would be 100 % off).
    assert np.isfinite(r.flow).all()
    motion = np.hypot(*p.flow[flat].T).mean()
    assert _err(r.flow, p.flow)[flat].mean() < 0.5 * motion
    # ...and a flat pixel is not reported as a failed match.
    assert r.occluded[flat].mean() < 0.05


@pytest.mark.parametrize("change", ["added", "removed"])
def test_added_or_removed_object_gets_low_probability(change):
    p = render_lighting("layers", size=SIZE, seed=2, change=change, gain=0.7, offset=0.05)
    r = video_matching(*p.frames)
    assert p.changed.mean() > 0.02
    # Pixels of the reference whose counterpart the object covers (added) or
    # that show the object (removed) match nothing: under even odds, and
    # lower than the matched pixels'.
    assert r.confidence[p.changed].mean() < 0.5
    assert r.confidence[p.changed].mean() < 0.5 * r.confidence[p.valid].mean()


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    d = tmp_path_factory.mktemp("takes")
    p = render_lighting("natural", size=(96, 72), seed=0, **VARIANTS["gain"])
    io.write_image(d / "take1.png", p.frames[0])
    io.write_image(d / "take2.png", p.frames[1])
    return d


def test_frames_of_different_sizes_exit_2_one_line(takes, tmp_path):
    small = tmp_path / "small.png"
    io.write_image(small, np.zeros((40, 50, 3), np.uint8))
    r = lumigraph("flow", takes / "take1.png", small, "--method", "video-matching",
                  "--out", tmp_path / "m.flo")
    assert_clean_error(r, "small.png", "50x40")
    assert not (tmp_path / "m.flo").exists()


def test_empty_frame_exit_2_one_line(takes, tmp_path):
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    r = lumigraph("flow", takes / "take1.png", empty, "--method", "video-matching",
                  "--out", tmp_path / "m.flo")
    assert_clean_error(r, "empty.png")
    assert not (tmp_path / "m.flo").exists()


def test_the_command_writes_the_probability_of_a_second_take(takes, tmp_path):
    r = lumigraph("flow", takes / "take1.png", takes / "take2.png", "--method", "video-matching",
                  "--out", tmp_path / "m.flo", "-q")
    assert r.returncode == 0, r.stderr
    prob = io.read_exr(tmp_path / "m.prob.exr")
    assert prob.shape == (72, 96) and 0 <= prob.min() and prob.max() <= 1
