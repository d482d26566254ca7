"""Failover benchmark, first part: what journaling a mission costs the executive (issue #16).

Run `python bench/failover.py [--repeat 3] [--json]` (never by pytest). The corridor surveillance mission runs in
the dry-run's executive twice in the same process, cycle by cycle: once plain, once saving after each cycle what
the cluster's controller saves (`drd.daemon.resume.Checkpoints`: the state tree of a mission whose records
changed it, `drd.runtime.snapshot.capture`, and the world's clock at most once a second, in the SQLite journal
`drd.journal`, WAL mode). It prints the executive's time per cycle both ways and the journaling's share. Goal:
journaling <= 10 % of the executive's time per step. The time from a controller's death to its mission running
again is measured by tests/test_controller_restart.py on real daemons (its log says when the mission was
resumed); it is not repeated here.
"""

from __future__ import annotations

import argparse
import functools
import json
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from rich.console import Console
from rich.table import Table

from drd.daemon.resume import Checkpoints
from drd.dryrun import team
from drd.hosts import load_hosts
from drd.journal import Journal, SqliteJournal
from drd.manifests import load_catalog
from drd.sim.world import load_world
from dsl import compile_file

ROOT = Path(__file__).resolve().parents[1]
GOAL = 0.10  # journaling's share of the executive's time, at most
CYCLE = 0.1


def one_run(journal: Journal | None) -> dict[str, float]:
    """The corridor mission to its end; seconds spent stepping the executive and saving, and saves made."""
    catalog = load_catalog()
    compiled = compile_file(ROOT / "missions" / "corridor_surveillance.mission", catalog)
    assert compiled.statechart is not None
    cluster = load_hosts(ROOT / "hosts.yaml", catalog)
    sim, executive = team(cluster, load_world(ROOT / "worlds" / "corridor.yaml"), catalog)
    checkpoints = Checkpoints(journal) if journal is not None else None
    listeners = [functools.partial(checkpoints.note, "M-1")] if checkpoints is not None else []
    executive.submit(compiled.statechart, "M-1", listeners=listeners)
    interp = executive.missions["M-1"]
    # what Checkpoints reads of the cluster's runner and world loop
    runner = SimpleNamespace(controller=SimpleNamespace(executive=executive), lock=threading.RLock(),
                             clock=SimpleNamespace(now=lambda: sim.time, base=0.0), cluster=cluster)
    world = SimpleNamespace(name="corridor", generation=1, missions=lambda: ["M-1"])
    stepping = saving = 0.0
    cycles = 0
    while not interp.finished and sim.time < 600:
        sim.step(CYCLE)
        t0 = time.perf_counter()
        executive.step()
        t1 = time.perf_counter()
        stepping += t1 - t0
        cycles += 1
        if checkpoints is not None:
            checkpoints.save(runner, world)
            saving += time.perf_counter() - t1
    assert interp.outcome == "success", interp.reason
    return {"stepping": stepping, "saving": saving, "cycles": cycles}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    plain, journaled = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeat):  # alternated, so a busy moment of the machine hits both
            plain.append(one_run(None))
            journal = SqliteJournal(Path(tmp) / f"journal-{i}.sqlite")
            journaled.append(one_run(journal))
            journal.close()
    per_cycle = statistics.median(r["stepping"] / r["cycles"] for r in plain)
    step = statistics.median(r["stepping"] / r["cycles"] for r in journaled)
    save = statistics.median(r["saving"] / r["cycles"] for r in journaled)
    share = save / step
    result: dict[str, Any] = {"executive_ms_per_cycle": round(per_cycle * 1e3, 4),
                              "journaled_executive_ms_per_cycle": round(step * 1e3, 4),
                              "journaling_ms_per_cycle": round(save * 1e3, 4), "journaling_share": round(share, 3),
                              "cycles": journaled[0]["cycles"], "goal": GOAL, "ok": share <= GOAL}
    if args.json:
        print(json.dumps(result))
    else:
        table = Table(title="journaling the corridor mission (dry-run executive, per control cycle)")
        for col in ("", "value"):
            table.add_column(col)
        for key, value in result.items():
            table.add_row(key, str(value))
        Console().print(table)
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
