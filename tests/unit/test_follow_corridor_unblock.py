"""FollowCorridor's way out of a lasting block (`unblock_turn`) and the side it turns to (`scan.open_side`)."""

from __future__ import annotations

import math

from components.behaviors.follow_corridor import FREE, WAIT, unblock_turn
from components.behaviors.scan import open_side
from drd.hw.interfaces import Scan


def _scan(left: float, right: float, far_left: float | None = None) -> Scan:
    """A 181-beam scan over 180 degrees: `right` on the right half, `left` on the left, and one beam at 45 degrees
    left reading `far_left` if given."""
    ranges = [right if i < 90 else left for i in range(181)]
    if far_left is not None:
        ranges[135] = far_left
    return Scan(tuple(ranges), -math.pi / 2, math.pi / 180, 8.0)


def test_a_short_block_is_waited_out_a_lasting_one_is_turned_out_of() -> None:
    assert unblock_turn(WAIT - 0.1, 0.8, None, 1) is None  # a person crossing: wait
    assert unblock_turn(WAIT, 0.8, None, -1) == -1
    assert unblock_turn(WAIT + 10, 0.8, None, 1) == 1


def test_a_turn_under_way_keeps_its_side_until_the_way_is_free() -> None:
    assert unblock_turn(0.0, FREE - 0.01, 1, -1) == 1  # the side of this scan does not flip the turn
    assert unblock_turn(100.0, FREE, -1, 1) is None


def test_the_side_that_reads_farthest_wins_over_the_one_more_open_on_the_whole() -> None:
    # the right looks into a room (every beam 5 m), the left along the corridor (short but for one far beam)
    assert open_side(_scan(left=1.0, right=5.0, far_left=8.0)) == 1
    assert open_side(_scan(left=5.0, right=1.0)) == 1
    assert open_side(_scan(left=1.0, right=5.0)) == -1
    assert open_side(_scan(left=2.0, right=2.0)) == 1  # a tie: left
