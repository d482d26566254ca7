"""ROS 2 benchmark: the corridor mission through rmw_zenoh (`ros2` drivers against the served simulator) vs on `sim`
drivers, in the same run, and the latency a ROS 2 control cycle adds.

Run `python bench/ros2.py [--repeat 3] [--cycles 500] [--json]` (never by pytest). Goals (issue #19): the ROS 2 path
at >= 20x real time, and <= 2 ms added per control cycle on loopback.

- **Real-time factor**: `drd.dryrun.run` of missions/corridor_surveillance.mission on hosts.yaml (`sim` drivers)
  and on hosts.ros2.yaml (every device `ros2`: the dry-run serves the world as ROS 2 robots in its own process,
  drivers over TCP on loopback, in lockstep), best of `--repeat` each; every round must succeed. With it, the
  least CPU time a run took (all the process's threads): what a loaded machine changes least.
- **Added latency per control cycle**: one cycle is what the dry-run does for a Drive: `set_velocity`, a 0.1 s step
  of the world, `odometry()`. On `sim` drivers that is calls; on `ros2` it is a Twist published, received by the
  served simulator, the step, the whole team's state served (every robot's sensors computed, serialized and
  published: 28 messages), and the odometry received (`LockstepSimulation.step`). The median and 90th percentile of
  the difference, over `--cycles` cycles, and its parts: the transport (the command's and the state's trips on
  loopback, what the lockstep waits for) and the serving (what a robot's own ROS 2 drivers would do).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import statistics
import sys
import time
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from drd.dryrun import merged_drivers, run, simulation
from drd.hosts import Cluster, load_hosts
from drd.manifests import load_catalog
from drd.sim.world import World, load_world
from dsl import compile_file
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parent.parent
MISSION = ROOT / "missions" / "corridor_surveillance.mission"
WORLD = ROOT / "worlds" / "corridor.yaml"
GOAL_FACTOR = 20.0
GOAL_LATENCY_MS = 2.0


def factor(chart: Any, cluster: Cluster, world: World, catalog: Catalog, repeat: int) -> tuple[float, float, float]:
    """The best real-time factor of `repeat` runs, that run's wall time, and the least CPU time a run took (every
    thread of the process: zenoh's too), which a loaded machine changes far less than the wall time."""
    best, least_cpu = (0.0, 0.0), math.inf
    for _ in range(repeat):
        c0, t0 = _cpu(), time.perf_counter()
        report = run(chart, cluster, world, catalog)
        wall, cpu = time.perf_counter() - t0, _cpu() - c0
        if report.outcome != "success":
            sys.exit(f"the corridor mission did not succeed on {cluster.source}: {report.reason}")
        best, least_cpu = max(best, (report.sim_time / wall, wall)), min(least_cpu, cpu)
    return best[0], best[1], least_cpu


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def cycles(cluster: Cluster, world: World, catalog: Catalog, n: int,
           phases: list[tuple[float, float, float, float]] | None = None) -> list[float]:
    """Seconds per control cycle (command, 0.1 s step, odometry) of the Ranger's Drive, `n` times (the lockstep's
    phases of each step into `phases`, when served)."""
    sim = simulation(cluster, world)
    if phases is not None and hasattr(sim, "timings"):
        sim.timings = phases
    try:
        drivers = merged_drivers(cluster, sim, catalog, getattr(sim, "services", None))
        sync = getattr(sim, "sync", None)
        if callable(sync):
            sync()
        drive: Any = drivers.robots["ranger1"]["drive"]
        out = []
        for k in range(n):
            t0 = time.perf_counter()
            drive.set_velocity(0.3, 0.2 if k % 40 < 20 else -0.2)
            sim.step(0.1)
            drive.odometry()
            out.append(time.perf_counter() - t0)
        return out
    finally:
        close = getattr(sim, "close", None)
        if callable(close):
            close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs of the mission on each kind of driver (the best"
                        " real-time factor and the least CPU time are kept; default 3)")
    parser.add_argument("--cycles", type=int, default=500, help="control cycles timed on each (default 500)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args()
    catalog = load_catalog()
    compiled = compile_file(MISSION, catalog)
    assert compiled.statechart is not None
    world = load_world(WORLD)
    sim_hosts, ros2_hosts = load_hosts(ROOT / "hosts.yaml", catalog), load_hosts(ROOT / "hosts.ros2.yaml", catalog)
    sim_factor, sim_wall, sim_cpu = factor(compiled.statechart, sim_hosts, world, catalog, args.repeat)
    ros2_factor, ros2_wall, ros2_cpu = factor(compiled.statechart, ros2_hosts, world, catalog, args.repeat)
    plain = cycles(sim_hosts, world, catalog, args.cycles)
    phases: list[tuple[float, float, float, float]] = []
    served = cycles(ros2_hosts, world, catalog, args.cycles, phases)
    added = sorted(s - p for s, p in zip(sorted(served), sorted(plain), strict=True))  # quantile by quantile
    transport = sorted(p[0] + p[3] for p in phases)
    serving = sorted(p[2] for p in phases)
    result = {
        "sim": {"real_time_factor": round(sim_factor, 1), "wall_s": round(sim_wall, 2), "cpu_s": round(sim_cpu, 2)},
        "ros2": {"real_time_factor": round(ros2_factor, 1), "wall_s": round(ros2_wall, 2), "cpu_s": round(ros2_cpu, 2)},
        "cycle_ms": {"sim_median": round(statistics.median(plain) * 1e3, 3),
                     "ros2_median": round(statistics.median(served) * 1e3, 3),
                     "added_median": round(statistics.median(added) * 1e3, 3),
                     "added_p90": round(added[int(0.9 * (len(added) - 1))] * 1e3, 3),
                     "transport_median": round(statistics.median(transport) * 1e3, 3),
                     "transport_p90": round(transport[int(0.9 * (len(transport) - 1))] * 1e3, 3),
                     "serving_median": round(statistics.median(serving) * 1e3, 3)},
        "goals": {"ros2_factor": GOAL_FACTOR, "added_ms": GOAL_LATENCY_MS},
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    table = Table(title="corridor mission: ros2 drivers vs sim drivers", title_justify="left")
    for col in ("", "sim drivers", "ros2 drivers", "goal"):
        table.add_column(col)
    table.add_row("real-time factor", f"{sim_factor:.0f}x", f"{ros2_factor:.0f}x", f">= {GOAL_FACTOR:g}x")
    table.add_row("wall time of the mission", f"{sim_wall:.2f} s", f"{ros2_wall:.2f} s", "")
    table.add_row("CPU time of the mission (all threads)", f"{sim_cpu:.2f} s", f"{ros2_cpu:.2f} s", "")
    c = result["cycle_ms"]
    table.add_row("control cycle (median)", f"{c['sim_median']:.2f} ms", f"{c['ros2_median']:.2f} ms", "")
    table.add_row("added per cycle (median / p90)", "", f"{c['added_median']:.2f} / {c['added_p90']:.2f} ms", "")
    table.add_row("  of which transport on loopback", "",
                  f"{c['transport_median']:.2f} / {c['transport_p90']:.2f} ms", f"<= {GOAL_LATENCY_MS:g} ms")
    table.add_row("  of which serving the team's state", "", f"{c['serving_median']:.2f} ms", "")
    Console().print(table)


if __name__ == "__main__":
    main()
