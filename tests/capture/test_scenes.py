"""Every registered scene, generically: renders within the speed target at its
default test size, is deterministic under its seed, saves a folder every stage
accepts (stack.json through capture.io.read_stack), and reloads losslessly
(its JSON parts in the same order).
Each scene family's ground-truth checks live with its stage's tests."""

import time

import numpy as np
import pytest

from lumigraph.capture import io
from lumigraph.capture.render import RenderedScene, render, scenes

ALL = sorted(scenes())


@pytest.mark.parametrize("name", ALL)
def test_scene_renders_fast_deterministically_and_round_trips(name, tmp_path):
    t0, c0 = time.perf_counter(), time.process_time()
    a = render(name, seed=5, cache=False)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    # The target (<= 5 s on 2 idle cores) is measured by `lumigraph bench
    # render`, with nothing beside it. Here two xdist workers share the two
    # cores, so a scene gets one core on average: a renderer that uses both
    # cores (Mitsuba, OpenCV) may take up to twice its idle wall time, and its
    # CPU time is up to twice its wall time. This guard catches regressions
    # beyond that: the smaller of the two figures within 2 x 5 s.
    assert min(wall, cpu) <= 2 * 5.0, f"{name}: {wall:.2f} s wall, {cpu:.2f} s CPU"
    b = render(name, seed=5, cache=False)
    assert len(a.images) == len(b.images) > 0
    assert all(np.array_equal(x, y) for x, y in zip(a.images, b.images, strict=True))
    a.save(tmp_path)
    st = io.read_stack([tmp_path])
    assert st.images.shape[0] == len(a.images)
    assert st.bit_depth == a.bit_depth
    back = RenderedScene.load(tmp_path)
    assert all(np.array_equal(x, y.reshape(x.shape)) for x, y in zip(a.images, back.images, strict=True))
    assert sorted(back.gt_arrays) == sorted(a.gt_arrays)
    for k, v in a.gt_arrays.items():
        assert np.array_equal(np.asarray(v), back.gt_arrays[k], equal_nan=True)
    # the JSON parts come back equal and in the same order (a block model's
    # parameters follow its file's order, and results may depend on it)
    import json
    for part in ("files", "gt", "stack"):
        assert json.dumps(getattr(back, part)) == json.dumps(getattr(a, part)), part



def test_boards_can_share_the_stereo_pair_rig():
    """``boards-stereo --rig stereo-pair-*`` renders its boards with the very
    cameras and pose the ``stereo-pair`` scene renders with."""
    from lumigraph.capture.errors import InputError

    for layout in ("rectified", "unrectified"):
        b = render("boards-stereo", size=(160, 120), views=2, rig=f"stereo-pair-{layout}",
                   distortion="none", square=0.05, baseline=0.18, cache=False)
        p = render("stereo-pair", size=(160, 120), layout=layout, supersample=1, cache=False)
        for key in ("R", "T"):
            np.testing.assert_array_equal(b.gt["rig"][key], p.gt["rig"][key])
        for cam in ("left", "right"):
            np.testing.assert_array_equal(b.gt["rig"][cam]["K"], p.gt["rig"][cam]["K"])
            assert b.gt["rig"][cam]["dist"] == p.gt["rig"][cam]["dist"] == [0.0] * 5
    with pytest.raises(InputError, match="^distortion: .*no lens distortion"):
        render("boards-stereo", size=(160, 120), views=2, rig="stereo-pair-rectified", cache=False)
