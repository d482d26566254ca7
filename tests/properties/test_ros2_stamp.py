"""`drd.hw.ros2.stamp`: a ROS 2 builtin_interfaces/Time is the nearest nanosecond of the sim time, its nanoseconds
always below a second (a whole second carries into `sec`, as an independent ROS 2 client reads it)."""

from __future__ import annotations

from fractions import Fraction

from hypothesis import given
from hypothesis import strategies as st

from drd.hw.ros2 import stamp

BILLION = 10**9


@given(st.floats(min_value=0.0, max_value=1e7, allow_nan=False, allow_infinity=False))
def test_a_stamp_is_the_nearest_nanosecond(t: float) -> None:
    s = stamp(t)
    assert 0 <= s["nanosec"] < BILLION
    assert abs(Fraction(s["sec"]) * BILLION + s["nanosec"] - Fraction(t) * BILLION) <= Fraction(1, 2)


def test_time_added_up_in_steps_stamps_each_step_exactly() -> None:
    t = 0.0
    for steps in range(1, 10_001):  # as the simulator counts its time, 0.1 s at a time, for 1000 s (the sum
        t += 0.1  # drifts by under a nanosecond until about 1750 s)
        s = stamp(t)
        assert (s["sec"], s["nanosec"]) == (steps // 10, steps % 10 * 100_000_000), steps


def test_five_seconds_is_five_seconds() -> None:
    assert stamp(4.999999999999998) == {"sec": 5, "nanosec": 0}
    assert stamp(0.9999999999999999) == {"sec": 1, "nanosec": 0}
