"""Issue #15 (lighter daemons): when its pool goes cold, a daemon keeps no worker and no fork server either (the
fork server with the behaviors' modules and its resource tracker were about 40 MB of an idle host's 83 MB); the
next placement starts it again. Checked from the outside: the processes the pool started.

The fork server is one per process, and a pool stops it only when it is the process's one pool: so the pool runs
in a process of its own here, not beside whatever pools other tests of this pytest worker left open."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.conftest import ROOT

CHILD = """
import json, time
import psutil
from drd.cluster.workers import WorkerPool


def forkservers():
    return [c.pid for c in psutil.Process().children(recursive=True)
            if any(("forkserver" in part or "resource_tracker" in part) for part in c.cmdline())]


seen = {}
pool = WorkerPool(1, preload=[], call_timeout=10.0, keep_warm=0.5, warm=False)
try:
    pool.release(pool.take(60.0))
    seen["after_take"] = len(forkservers())
    deadline = time.monotonic() + 30.0
    while (pool.cooled == 0 or forkservers()) and time.monotonic() < deadline:  # a hang guard, not a measure
        time.sleep(0.05)
    seen.update(cooled=pool.cooled, cold_forkservers=len(forkservers()), cold_workers=len(pool.pids()))
    again = pool.take(60.0)  # a placement after the cold spell: the fork server comes back
    seen.update(again_alive=again.alive, again_forkservers=len(forkservers()))
    pool.release(again)
finally:
    pool.close()
seen["closed_forkservers"] = len(forkservers())
print(json.dumps(seen))
"""


def test_a_cold_pool_stops_the_fork_server_and_the_next_take_starts_it_again() -> None:
    done = subprocess.run([sys.executable, "-c", CHILD], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["after_take"] > 0, "a take starts the fork server"
    assert seen["cooled"] >= 1 and seen["cold_forkservers"] == 0 and seen["cold_workers"] == 0, seen
    assert seen["again_alive"] and seen["again_forkservers"] > 0, seen
    assert seen["closed_forkservers"] == 0, seen
