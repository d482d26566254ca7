"""Placement benchmark: starting a component instance in a warm container, in a dedicated process, and a warm
forkserver spawn of a process as the peer, in the same run.

Run `python bench/placement.py [--repeat 200] [--json]` (never by pytest); `--policy HOSTS` times only the pure
policy (`drd.placement.place`) over HOSTS hosts. It builds a Component Creator
(`drd.cluster.creator.Creator`, no bus) for host ranger1 of a generated hosts file, with its own pool of
pre-started worker processes (fork server warm, behavior modules preloaded), and times with
`time.perf_counter`, `--repeat` times each (median and p90):

- **container**: `Creator.handle(start)` of a new instance whose manifest says `process: container`, placed
  in the mission's container that already runs (start -> first reply: placement, setup and `start` in the
  worker, the reply back);
- **dedicated**: the same for `process: dedicated`: a pre-started worker is taken from the pool (the pool is
  refilled between samples, so it is warm, as in a daemon that is not placing in a burst);
- **forkserver spawn** (the peer): starting a fresh worker process from the warm fork server until it says
  hello over its pipe, what placing would cost without pre-started workers;
- **step round trip**: one `step` call of a placed instance (one pipe round trip), for scale.

Goal: container placement <= 10 ms median. The component is `Calibrate` with no device bound (its `start`
only sets fields): what is measured is the placement machinery, not a component. Every worker started is
killed (by pid, reaped) in a `finally`.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

if TYPE_CHECKING:
    from drd.cluster.creator import Creator
    from drd.cluster.workers import WorkerPool

GOAL_MS = 10.0


def figures(samples: list[float]) -> dict[str, float]:
    ordered = sorted(samples)
    return {"median_ms": statistics.median(ordered) * 1000, "p90_ms": ordered[int(0.9 * (len(ordered) - 1))] * 1000,
            "min_ms": ordered[0] * 1000, "n": len(ordered)}


def timed(fn: Callable[[], Any]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def policy_samples(hosts: int, repeat: int) -> list[float]:
    """Seconds of each `place` of a movable component over `hosts` views (the decision record included)."""
    from drd.hosts import Placement
    from drd.placement import HostView, place
    from dsl.catalog import ComponentType, Kind

    views = [HostView(f"h{i:04d}", cpu=(i * 37) % 100, memory=(i * 11) % 100, instances=i % 7,
                      roles=frozenset() if i % 3 == 0 else frozenset({"worker"})) for i in range(hosts)]
    wait = ComponentType("Wait", Kind.BEHAVIOR)
    return [timed(lambda: place(wait, views, Placement(), role="worker", near={"h0001": 1.0}))
            for _ in range(repeat)]


def main() -> None:
    args = arguments()
    if args.policy:
        report = {"hosts": args.policy, **figures(policy_samples(args.policy, args.repeat))}
        print(json.dumps(report, indent=2) if args.json else
              f"place over {args.policy} hosts: median {report['median_ms']:.3f} ms, p90 {report['p90_ms']:.3f} ms")
        return
    creator, pool = bench_creator()
    try:
        if not pool.wait_ready(60.0):
            sys.exit("the worker pool did not start")
        samples = placement_samples(creator, pool, args.repeat)
    finally:
        creator.close()
        pool.close()
    report_placements({name: figures(values) for name, values in samples.items()}, args.repeat, args.json)


def arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=200, help="timed placements of each kind")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument("--policy", type=int, metavar="HOSTS", default=0,
                        help="time only the pure policy (drd.placement.place, filters then scores, with its Decision "
                             "record) over HOSTS hosts, a third without the worker role, with devices near one")
    return parser.parse_args()


def bench_creator() -> tuple[Creator, WorkerPool]:
    """A Creator for ranger1 with its own warm worker pool, over the catalog plus one container and one dedicated
    component (both `Calibrate`'s code): the imports are here so that `--policy` does not pay for them."""
    from drd.cluster.creator import Creator, behavior_modules
    from drd.cluster.workers import WorkerPool
    from drd.hosts import load_hosts
    from drd.hw.drivers import HostDrivers
    from drd.manifests import load_catalog
    from dsl.catalog import Catalog, ComponentType, Kind, Process
    from tests.cluster_support import hosts_yaml

    base = load_catalog()
    entry = base.components["Calibrate"].entry_point
    cat = Catalog.of([*base.components.values(),
                      ComponentType("BenchContainer", Kind.BEHAVIOR, entry_point=entry),
                      ComponentType("BenchDedicated", Kind.BEHAVIOR, entry_point=entry, process=Process.DEDICATED)])
    with tempfile.TemporaryDirectory() as tmp:
        hosts = Path(tmp) / "hosts.yaml"
        hosts.write_text(hosts_yaml("bench", ["controller", "ranger1"], [7001, 7002]))
        cluster = load_hosts(hosts, cat)
    pool = WorkerPool(2, preload=behavior_modules(cat))
    creator = Creator(None, cluster, "ranger1", cat, pool=pool)
    creator._drivers_for = lambda world, generation: HostDrivers()  # type: ignore[method-assign]  # no device bound
    return creator, pool


def placement_samples(creator: Creator, pool: WorkerPool, repeat: int) -> dict[str, list[float]]:
    """Seconds of each placement in a warm container, in a dedicated process, of each fork server spawn and of each
    step round trip, `repeat` of each."""
    from drd.cluster.remote import ComponentCall

    def start(path: str, component: str) -> None:
        reply = creator.handle(ComponentCall("start", "bench", path, component=component))
        if reply.error:
            sys.exit(f"start of {path} failed: {reply.error}")

    start("warm/first", "BenchContainer")  # the mission's container now runs
    container = [timed(lambda i=i: start(f"c/{i}", "BenchContainer")) for i in range(repeat)]
    steps = [timed(lambda: creator.handle(ComponentCall("step", "bench", "c/0", now=1.0))) for _ in range(repeat)]

    dedicated = []
    for i in range(repeat):
        pool.wait_ready(30.0)
        dedicated.append(timed(lambda i=i: start(f"d/{i}", "BenchDedicated")))
        with creator._lock:
            creator._forget(f"d/{i}")  # its process goes: the next sample takes a pre-started one again

    spawns = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        w = pool._spawn()  # a fresh worker from the warm fork server, up to its hello
        spawns.append(time.perf_counter() - t0)
        pool.release(w)
    return {"container": container, "dedicated": dedicated, "forkserver_spawn": spawns, "step_round_trip": steps}


def report_placements(out: dict[str, dict[str, float]], repeat: int, as_json: bool) -> None:
    """The figures as JSON or as a table, with the spawn/container ratio and the verdict on the goal."""
    ratio = out["forkserver_spawn"]["median_ms"] / out["container"]["median_ms"]
    verdict = "PASS" if out["container"]["median_ms"] <= GOAL_MS else "MISS"
    if as_json:
        print(json.dumps({**out, "spawn_over_container": ratio, "goal_ms": GOAL_MS, "verdict": verdict}, indent=2))
        return
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"Python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load {load}; {repeat} samples each")
    for name, label in (("container", "place in a warm container"), ("dedicated", "place in a dedicated process"),
                        ("forkserver_spawn", "warm forkserver spawn (peer)"), ("step_round_trip", "step round trip")):
        f = out[name]
        print(f"  {label:30} median {f['median_ms']:7.3f} ms   p90 {f['p90_ms']:7.3f} ms")
    print(f"  spawn / container placement  {ratio:7.1f}x")
    print(f"  goal: container placement <= {GOAL_MS:g} ms median: {verdict}")


if __name__ == "__main__":
    main()
