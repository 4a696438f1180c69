"""Every registered scene, generically: renders within the speed target at its
default test size, is deterministic under its seed, saves a folder every stage
accepts (stack.json through capture.io.read_stack), and reloads losslessly.
Each scene family's ground-truth checks live with its stage's tests."""

import time

import numpy as np
import pytest

from capture import io
from capture.render import RenderedScene, render, scenes

ALL = sorted(scenes())


@pytest.mark.parametrize("name", ALL)
def test_scene_renders_fast_deterministically_and_round_trips(name, tmp_path):
    t0, c0 = time.perf_counter(), time.process_time()
    a = render(name, seed=5, cache=False)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    # Target: <= 5 s on 2 cores. On a loaded machine wall time overstates the
    # cost and CPU time is the fair figure; multithreaded renderers make CPU
    # time exceed wall time on an idle one. The smaller of the two must meet it.
    assert min(wall, cpu) <= 5.0, f"{name}: {wall:.2f} s wall, {cpu:.2f} s CPU"
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

