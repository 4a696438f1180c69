"""The one check of exposure times and the one aperture-bracket rule (capture.exposure)."""

import numpy as np
import pytest

from lumigraph.capture import io
from lumigraph.capture.errors import InputError
from lumigraph.capture.exposure import check_exposure_times, effective_exposure_times


@pytest.mark.parametrize("times,count,fragment", [
    (None, 2, "needed"), ([1.0], 2, "1 exposure times for 2 images"),
    ([1.0, 0.0], 2, "positive"), ([1.0, np.nan], 2, "finite"), (["a", 1.0], 2, "seconds")])
def test_bad_times_name_the_argument(times, count, fragment):
    with pytest.raises(InputError, match=fragment) as e:
        check_exposure_times(times, count)
    assert e.value.where == "exposure_times_s"


def test_distinct_is_asked_for_and_where_can_be_a_file():
    assert check_exposure_times([0.1, 0.1], 2).tolist() == [0.1, 0.1]
    with pytest.raises(InputError, match="duplicated") as e:
        check_exposure_times([0.1, 0.1], 2, where="stack.json", distinct=True)
    assert e.value.where == "stack.json"


def test_effective_exposure_is_time_times_relative_aperture_area():
    assert effective_exposure_times([0.5, 0.5]) == (0.5, 0.5)
    e = effective_exposure_times([0.01, 0.01], [2.0, 4.0], f_number_ref=4.0)
    assert e == pytest.approx((0.04, 0.01), rel=1e-15)
    with pytest.raises(InputError, match="2 f-numbers for 3 images"):
        effective_exposure_times([1.0, 1.0, 1.0], [2.0, 4.0])


def test_stack_applies_f_numbers_unless_times_are_given(tmp_path):
    a = np.full((4, 6, 3), 100, np.uint8)
    for i in range(2):
        io.write_image(tmp_path / f"i{i}.png", a)
    io.write_stack_json(tmp_path, ["i0.png", "i1.png"], exposure_times_s=[0.01, 0.01],
                        f_numbers=[4.0, 2.0])
    st = io.read_stack([tmp_path])
    assert st.exposure_times_s == (0.01, 0.01)
    assert st.effective_exposure_times_s == pytest.approx((0.0025, 0.01), rel=1e-15)
    given = io.read_stack([tmp_path], times=[1.0, 2.0])
    assert given.effective_exposure_times_s == (1.0, 2.0)
    io.write_stack_json(tmp_path, ["i0.png", "i1.png"], exposure_times_s=[0.01, 0.01],
                        f_numbers=[4.0])
    with pytest.raises(InputError, match="1 f-numbers for 2 images") as e:
        io.read_stack([tmp_path])
    assert e.value.where.endswith("stack.json")
    with pytest.raises(InputError, match="exposure times") as e:
        io.Stack(np.zeros((2, 4, 6, 3), np.uint8), ("a", "b"), 8, (1.0,))
