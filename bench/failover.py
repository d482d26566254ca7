"""Failover benchmark: what journaling a mission costs the executive, and how long a mission waits for a controller
(issue #16).

Run `python bench/failover.py [--repeat 3] [--json] [--failover N]` (never by pytest). The corridor surveillance
mission runs in the dry-run's executive twice in the same process, cycle by cycle: once plain, once saving after
each cycle what the cluster's controller saves (`drd.daemon.resume.Checkpoints`: the state tree of a mission whose
records changed it, `drd.runtime.snapshot.capture`, and the world's clock at most once a second, in the SQLite
journal `drd.journal`, WAL mode). It prints the executive's time per cycle both ways and the journaling's share.
Goal: journaling <= 10 % of the executive's time per step.

With `--failover N` it also measures, N times each on real processes on loopback (the corridor mission at `--speed
20`, kill -9 of the acting controller once 30 s of it ran), the time until the mission runs again (the executive's
`status` shows its time past what it was at the kill):

- **restart on the same host**: controller + ranger1, the SQLite journal; `drd start --host controller` again at
  once; timed from that command. Goal: <= 2 s.
- **takeover by a standby**: a 3-member etcd cluster, controller + controller2 + ranger1 (`cluster.store`); nothing
  is started again; timed from the kill, with the moment the standby was elected (its log). Goal: <= the election's
  lease + 2 s.
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

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the tests' cluster and etcd fixtures
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ... imported as `tests.*`

from drd.daemon.resume import Checkpoints
from drd.dryrun import team
from drd.hosts import load_hosts
from drd.journal import DeferredJournal, Journal, SqliteJournal
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
    out = {"stepping": stepping, "saving": saving, "cycles": cycles}
    if isinstance(journal, DeferredJournal):  # what is still queued when the mission ends, and how much was merged
        t0 = time.perf_counter()
        journal.flush()
        out |= {"flush": time.perf_counter() - t0, "written": journal.written, "merged": journal.merged}
    return out


def _mission_time(client: Any, mission: str) -> float | None:
    from drd.errors import BusFailure

    try:
        missions = client.missions(mission)  # that one only (`drd.paging`)
    except BusFailure:
        return None
    return next((float(m["time"]) for m in missions if m.get("id") == mission and m.get("outcome") is None
                 and isinstance(m.get("time"), int | float)), None)


def _log_time(line: str) -> float:
    """The wall time of a daemon's log line (its `asctime`, local time)."""
    import datetime

    stamp = " ".join(line.split(" ", 2)[:2])
    return datetime.datetime.strptime(stamp, "%Y-%m-%d %H:%M:%S,%f").timestamp()


def _kill_and_wait(cluster: Any, victim: str, restart: bool, standby: str | None) -> dict[str, float]:
    """Run the corridor mission, kill -9 `victim` after 30 s of it, start it again if `restart`; the seconds until
    the mission runs again (and until `standby` was elected, if given)."""
    import signal

    from tests.cluster_support import corridor_run, eventually

    with tempfile.TemporaryDirectory() as tmp:
        trace = Path(tmp) / "run.jsonl"
        with corridor_run(cluster, trace) as (run, mission):
            client = cluster.client(timeout=0.5)
            eventually(lambda: (_mission_time(client, mission) or 0.0) > 30.0, "30 s of the mission", 60, poll=0.1)
            last = _mission_time(client, mission) or 0.0
            cluster.procs[victim].send_signal(signal.SIGKILL)
            killed, killed_wall = time.monotonic(), time.time()
            cluster.procs[victim].wait(timeout=10)
            if restart:
                cluster.start(victim)
            started = time.monotonic()
            eventually(lambda: (_mission_time(client, mission) or 0.0) > last, "the mission running again", 120,
                       poll=0.02)
            back = time.monotonic()
            out, _err = run.communicate(timeout=300)
        assert run.returncode == 0 and json.loads(out)["outcome"] == "success", out[-1000:]
    result = {"from_kill_s": back - killed, "from_restart_s": back - started}
    if standby is not None:
        line = next(li for li in cluster.log(standby).splitlines() if "elected the acting controller" in li)
        result["elected_s"] = _log_time(line) - killed_wall
    return result


def etcd_journaling(repeat: int, step: float, plain: float) -> dict[str, Any]:
    """The same journaled runs with the etcd backend (3 members on loopback, each write a transaction that a quorum
    writes to disk), written by the loop itself and then, alternated, by `DeferredJournal` (as a controller does):
    each one's cost per cycle and share of the executive's time per step (`step`, SQLite runs'); for the deferred
    writes also the whole cycle against a plain run's (`plain`: the writer thread takes the interpreter's lock
    too), the saves written and merged, and the flush at the end."""
    from drd.cluster.election import leader_key
    from drd.etcd import Etcd, created_at, put
    from drd.journal import EtcdJournal
    from tests.etcd_support import ETCD, etcd_cluster

    if ETCD is None:
        return {"etcd": "skipped: etcd is not installed (Debian package etcd-server)"}
    runs: list[dict[str, float]] = []
    deferred: list[dict[str, float]] = []
    with tempfile.TemporaryDirectory() as tmp, etcd_cluster(Path(tmp), 3) as etcd:
        client = Etcd(etcd.urls)
        for i in range(2 * repeat):
            name = f"bench{i}"
            _ok, term, _ = client.txn([created_at(leader_key(name), 0)], [put(leader_key(name), "bench")])
            journal = EtcdJournal(client, name, term, leader=leader_key(name))
            if i % 2:
                later = DeferredJournal(journal)
                deferred.append(one_run(later))
                later.close()
            else:
                runs.append(one_run(journal))
    save = statistics.median(r["saving"] / r["cycles"] for r in runs)
    later_save = statistics.median(r["saving"] / r["cycles"] for r in deferred)
    cycle = statistics.median((r["stepping"] + r["saving"]) / r["cycles"] for r in deferred)
    return {"etcd_journaling_ms_per_cycle": round(save * 1e3, 4), "etcd_journaling_share": round(save / step, 3),
            "etcd_deferred_journaling_ms_per_cycle": round(later_save * 1e3, 4),
            "etcd_deferred_journaling_share": round(later_save / step, 3),
            "etcd_deferred_cycle_vs_plain": round(cycle / plain, 3),
            "etcd_deferred_written": int(statistics.median(r["written"] for r in deferred)),
            "etcd_deferred_merged": int(statistics.median(r["merged"] for r in deferred)),
            "etcd_deferred_flush_ms": round(1e3 * max(r["flush"] for r in deferred), 2),
            "etcd_ok": later_save / step <= GOAL}


def failover(rounds: int) -> dict[str, Any]:
    """The restart and takeover times (see the module), `rounds` of each, medians and worst."""
    from tests.cluster_support import corridor_hosts, eventually, running_cluster, serving_cluster
    from tests.etcd_support import ETCD, etcd_cluster

    out: dict[str, Any] = {}
    restarts, takeovers = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(rounds):
            (Path(tmp) / f"restart{i}").mkdir()
            with serving_cluster(Path(tmp) / f"restart{i}", ["controller", "ranger1"], corridor_hosts) as cluster:
                restarts.append(_kill_and_wait(cluster, "controller", True, None))
        if ETCD is None:
            out["takeover"] = "skipped: etcd is not installed (Debian package etcd-server)"
        for i in range(rounds if ETCD is not None else 0):
            (Path(tmp) / f"takeover{i}").mkdir()
            with etcd_cluster(Path(tmp) / f"etcd{i}", 3) as etcd, \
                    running_cluster(Path(tmp) / f"takeover{i}", ["controller", "ranger1", "controller2"]) as cluster:
                text = corridor_hosts(cluster).replace(
                    "  world: corridor", f"  world: corridor\n  store: {{etcd: [{', '.join(etcd.urls)}]}}", 1)
                port = cluster.ports[2]
                cluster.hosts_file.write_text(text + f"\n  controller2:\n    endpoint: tcp/127.0.0.1:{port}\n"
                                              "    roles: [controller]\n")
                cluster.start("controller")

                def elected(c: Any = cluster) -> bool:
                    return "elected the acting" in c.log("controller")

                eventually(elected, "an election", 60)
                cluster.start("ranger1")
                cluster.start("controller2")
                cluster.wait_ready()
                cluster.wait_up()
                takeovers.append(_kill_and_wait(cluster, "controller", False, "controller2"))
    lease = 2.0  # the election's lease in these clusters: max(2, ceil(cluster.lease = 1 s))
    if restarts:
        worst = max(r["from_restart_s"] for r in restarts)
        out |= {"restart_from_command_s": round(statistics.median(r["from_restart_s"] for r in restarts), 2),
                "restart_from_command_worst_s": round(worst, 2),
                "restart_from_kill_s": round(statistics.median(r["from_kill_s"] for r in restarts), 2),
                "restart_ok": worst <= 2.0}
    if takeovers:
        worst = max(r["from_kill_s"] for r in takeovers)
        out |= {"takeover_from_kill_s": round(statistics.median(r["from_kill_s"] for r in takeovers), 2),
                "takeover_from_kill_worst_s": round(worst, 2),
                "elected_from_kill_s": round(statistics.median(r["elected_s"] for r in takeovers), 2),
                "election_lease_s": lease, "takeover_goal_s": lease + 2.0, "takeover_ok": worst <= lease + 2.0}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--etcd", action="store_true",
                        help="also journal into a 3-member etcd cluster on loopback (the replicated backend)")
    parser.add_argument("--failover", type=int, default=0, metavar="N",
                        help="also time N restarts and N standby takeovers on real processes (minutes each)")
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
    if args.etcd:
        result |= etcd_journaling(args.repeat, step, per_cycle)
    if args.failover > 0:
        result |= failover(args.failover)
    if args.json:
        print(json.dumps(result))
    else:
        table = Table(title="journaling the corridor mission (dry-run executive, per control cycle)")
        for col in ("", "value"):
            table.add_column(col)
        for key, value in result.items():
            table.add_row(key, str(value))
        Console().print(table)
    goals = ("ok", "etcd_ok", "restart_ok", "takeover_ok")
    return 0 if all(result.get(goal, True) for goal in goals) else 1


if __name__ == "__main__":
    sys.exit(main())
