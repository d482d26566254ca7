"""The controller's world loop paces a run at most `speed` times real time from where its loop (re)started: a world
resumed after a controller restart or failover at 112.7 s of mission time goes on at once (it used to wait 112.7 s
/ speed, paced as if the run had begun at 0, while `missionctl run` said "resumed")."""

from __future__ import annotations

import pytest

from drd.daemon.missions import pace


def test_a_resumed_world_is_paced_from_where_its_loop_started_not_from_zero() -> None:
    first = 112.7  # the instant the journal resumed it at
    after_one_cycle = first + 0.1
    assert pace(after_one_cycle - first, 1.0, 0.1) == pytest.approx(0.0)  # on time: no wait
    assert pace(after_one_cycle - first, 1.0, 0.05) == pytest.approx(0.05)  # ahead: the rest of its period
    assert pace(after_one_cycle - first, 5.0, 0.0) == pytest.approx(0.02)  # at 5x a cycle takes 20 ms of wall time


def test_a_world_behind_goes_on_at_once() -> None:
    assert pace(10.0, 20.0, 1.0) < 0  # 10 s at 20x is 0.5 s of wall time; 1 s went by: no wait
