"""How drd reads a LaserScan's ranges (REP 117), `drd.hw.ros2.scan_ranges`: clients audit D2, a laser giving NaN on
every beam read as free space in front of a moving robot (NaN was `range_max`), and FollowCorridor drove on blind."""

from __future__ import annotations

import math

import pytest

from drd.hw.interfaces import HardwareError
from drd.hw.ros2 import scan_ranges


def test_inf_is_nothing_in_range_minus_inf_too_close_and_finite_values_are_clipped() -> None:
    assert scan_ranges([math.inf, -math.inf, 2.5, 9.0, -1.0], 0.1, 4.0) == (4.0, 0.0, 2.5, 4.0, 0.0)


def test_a_nan_beam_is_never_free_space() -> None:
    got = scan_ranges([2.0, math.nan, 3.0, math.inf], 0.1, 4.0)
    assert got == (2.0, 0.0, 3.0, 4.0), "an invalid reading reads as something at the sensor"


@pytest.mark.parametrize("nan", [3, 4])
def test_a_scan_of_mostly_nan_beams_is_a_faulted_laser(nan: int) -> None:
    with pytest.raises(HardwareError, match=f"{nan} of 4 beams are NaN"):
        scan_ranges([math.nan] * nan + [1.0] * (4 - nan), 0.1, 4.0)
    assert scan_ranges([math.nan, math.nan, 1.0, 1.0], 0.1, 4.0) == (0.0, 0.0, 1.0, 1.0)  # half: still a scan
