"""The driving behaviors' progress check (`components.behaviors.progress`), nav2's in one number."""

from __future__ import annotations

import math

from components.behaviors.progress import PROGRESS, STUCK, Progress, allowance


def test_it_stalls_only_after_the_allowance_without_a_step_beyond_its_best() -> None:
    p = Progress()
    assert not p.stalled(0.0, 0.0)
    assert not p.stalled(STUCK - 0.1, PROGRESS - 0.01)  # not a whole step yet, and not the whole allowance
    assert p.stalled(STUCK, PROGRESS - 0.01)
    assert not p.stalled(STUCK + 1, PROGRESS)  # a step: the clock starts again
    assert not p.stalled(STUCK + 2, 0.0)  # back and forth below the best is no progress...
    assert p.stalled(2 * STUCK + 1, PROGRESS + 0.4)  # ...and stalls once the allowance ran out
    p.reset()  # resumed: the time suspended does not count
    assert not p.stalled(1000.0, 0.0)


def test_a_slow_robot_gets_the_time_its_speed_needs() -> None:
    """Reverify audit 14, D2: at 0.016 m/s (within FollowCorridor's range) an empty corridor failed at 30 s."""
    assert allowance(0.5) == STUCK
    assert allowance(0.016) == 3 * PROGRESS / 0.016 > STUCK
    assert allowance(0.0) == math.inf
    assert Progress(allowance=allowance(0.016)).says() == f"no progress: got no more than 0.5 m farther in " \
                                                          f"{3 * PROGRESS / 0.016:g} s"
