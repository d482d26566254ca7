"""The Creator's freeze watch (drd.cluster.freeze): a gap between two looks longer than the limit is reported once,
by the look that sees it; the rest are quiet."""

from __future__ import annotations

import pytest

from drd.cluster.freeze import FreezeWatch


def test_a_gap_longer_than_the_limit_is_reported_once_by_the_look_that_sees_it() -> None:
    now = [10.0]
    watch = FreezeWatch(1.0, lambda: now[0])
    now[0] = 10.9
    assert watch.gap() == 0.0
    now[0] = 12.5
    assert watch.gap() == pytest.approx(1.6)  # 12.5 - 10.9: the time it stood still
    assert watch.gap() == 0.0  # reported once
    now[0] = 20.0
    watch.restart()
    now[0] = 20.5
    assert watch.gap() == 0.0  # counted from the restart
