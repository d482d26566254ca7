"""Issue #15 (lighter daemons): when its pool goes cold, a daemon keeps no worker and no fork server either (the
fork server with the behaviors' modules and its resource tracker were about 40 MB of an idle host's 83 MB); the
next placement starts it again. Checked from the outside: the processes this one started."""

from __future__ import annotations

import time

import psutil

from drd.cluster.workers import WorkerPool


def forkservers() -> list[int]:
    """This process's children that are multiprocessing's fork server or resource tracker."""
    return [c.pid for c in psutil.Process().children(recursive=True)
            if any(("forkserver" in part or "resource_tracker" in part) for part in c.cmdline())]


def test_a_cold_pool_stops_the_fork_server_and_the_next_take_starts_it_again() -> None:
    pool = WorkerPool(1, preload=[], call_timeout=10.0, keep_warm=0.5, warm=False)
    try:
        pool.release(pool.take(60.0))
        assert forkservers(), "a take starts the fork server"
        deadline = time.monotonic() + 30.0
        while (pool.cooled == 0 or forkservers()) and time.monotonic() < deadline:  # a hang guard, not a measure
            time.sleep(0.05)
        assert pool.cooled >= 1 and forkservers() == [] and pool.pids() == []
        again = pool.take(60.0)  # a placement after the cold spell: the fork server comes back
        assert again.alive and forkservers()
        pool.release(again)
    finally:
        pool.close()
    assert forkservers() == []
