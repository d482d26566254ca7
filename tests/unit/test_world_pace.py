"""The controller's world loop paces a run at most `speed` times real time from where its loop (re)started: a world
resumed after a controller restart or failover at 112.7 s of mission time goes on at once (it used to wait 112.7 s
/ speed, paced as if the run had begun at 0, while `missionctl run` said "resumed"); after a stall it goes on at
the asked pace, not faster to catch up (cluster audit 17, D2)."""

from __future__ import annotations

import pytest

from drd.daemon.missions import BEHIND, Pacer


def test_a_resumed_world_is_paced_from_where_its_loop_started_not_from_zero() -> None:
    first = 112.7  # the instant the journal resumed it at
    assert Pacer(1.0, first, 0.0).wait(first + 0.1, 0.1) == pytest.approx(0.0)  # on time: no wait
    assert Pacer(1.0, first, 0.0).wait(first + 0.1, 0.05) == pytest.approx(0.05)  # ahead: the rest of its period
    assert Pacer(5.0, first, 0.0).wait(first + 0.1, 0.0) == pytest.approx(0.02)  # at 5x a cycle is 20 ms of wall


def test_a_world_behind_goes_on_at_once_and_a_short_lag_is_made_up() -> None:
    pacer = Pacer(20.0, 0.0, 0.0)
    assert pacer.wait(10.0, 0.6) == 0.0  # 10 s at 20x is 0.5 s of wall time; 0.6 s went by: no wait
    assert pacer.wait(12.0, 0.6) == pytest.approx(0.0)  # 0.1 s behind was made up: on time again


def test_after_a_stall_the_world_goes_at_the_asked_pace_not_faster() -> None:
    """At 1x, a 5 s stall after 1 s: the next seconds of the world take a second of wall time each."""
    pacer = Pacer(1.0, 0.0, 0.0)
    assert pacer.wait(1.0, 1.0) == 0.0
    assert pacer.wait(1.1, 6.0) == 0.0  # stalled: 4.9 s behind, more than BEHIND: paced afresh from here
    assert 4.9 > BEHIND
    assert pacer.wait(1.2, 6.0) == pytest.approx(0.1)  # the next cycle waits its own period: no catching up
    wall = 6.0
    for k in range(3, 50):  # each cycle waits what the pacer says: 0.1 s of world per 0.1 s of wall
        wall += pacer.wait(1.0 + 0.1 * k, wall)
    assert wall == pytest.approx(6.0 + 0.1 * 48, abs=1e-9)
