"""Scale benchmark: the real-time factor of a 1,000-robot dry-run, and the cost per robot from 10 to 1,000.

Run `python bench/scale.py [--until 120] [--cpu] [--json] [--profile] [--sizes 10,100,1000]` (never by pytest).
Each size is a generated building (`drd.sim.building`, what `missionctl world generate` writes): 10 robots are
one wing of a Ranger and 9 Scouts, 100 are 5 wings and 1,000 are 50 wings of a Ranger and 19 Scouts. The corridor
mission (missions/corridor_surveillance.mission, unchanged) runs on each through `drd.dryrun.run`, the path
`missionctl dry-run` takes, for `--until` seconds of sim time (the same for every size, so the costs compare;
setting up the team and submitting the mission are inside the timing, as for a user). Cost per robot = wall
(or CPU) seconds per sim second per robot; the ratio column is each size's cost per robot against the 10-robot
run of the same invocation, so a busy machine slows both sides alike.

Every run must launch a Scout from every wing's Ranger and lose no RoomSurveillance instance on the way (no
`degraded`, no failure), so nothing fast-but-wrong is measured. Goals: 1,000 robots >= 10x real time; cost per
robot at 1,000 within 1.5x of that at 100 (roughly flat).
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import json
import pstats
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from drd.dryrun import DryRun, run
from drd.hosts import parse_hosts
from drd.manifests import load_catalog
from drd.sim.building import Building, hosts, world
from drd.sim.world import parse_world
from dsl import compile_file

GOAL = 10.0  # the 1,000-robot run's real-time factor, at least
FLAT = 1.5  # cost per robot at 1,000 against 100, at most
ROOT = Path(__file__).resolve().parent.parent
MISSION = ROOT / "missions" / "corridor_surveillance.mission"
#: robots -> (wings, Scouts per wing)
SHAPES = {10: (1, 9), 100: (5, 19), 1000: (50, 19)}


@dataclass
class Point:
    robots: int
    wings: int
    sim_time: float
    seconds: float
    launched: int

    @property
    def factor(self) -> float:
        return self.sim_time / self.seconds if self.seconds > 0 else float("inf")

    @property
    def per_robot_ms(self) -> float:
        """Milliseconds of wall (or CPU) time per sim second per robot."""
        return 1000 * self.seconds / self.sim_time / self.robots


def shape(robots: int) -> tuple[int, int]:
    if robots in SHAPES:
        return SHAPES[robots]
    if robots % 20:
        raise SystemExit(f"--sizes {robots}: give 10, 100, 1000 or a multiple of 20 (wings of 1 Ranger + 19 Scouts)")
    return robots // 20, 19


def measure(robots: int, until: float, cpu: bool, profile: cProfile.Profile | None) -> Point:
    catalog = load_catalog()
    compiled = compile_file(MISSION, catalog)
    if compiled.statechart is None:
        raise SystemExit(f"{MISSION} does not compile")
    wings, scouts = shape(robots)
    b = Building(wings, scouts)
    sim_world = parse_world(world(b), b.name)
    cluster = parse_hosts(hosts(b), b.name, catalog)
    clock = time.process_time if cpu else time.perf_counter
    gc.collect()
    t0 = clock()
    if profile is not None:
        profile.enable()
    report = run(compiled.statechart, cluster, sim_world, catalog, until=until)
    if profile is not None:
        profile.disable()
    seconds = clock() - t0
    check(report, b)
    return Point(b.robots, wings, report.sim_time, seconds, len(report.scouts))


def check(report: DryRun, b: Building) -> None:
    """The run did the mission's job so far: each wing's Ranger launched, no instance failed."""
    wing_of = {s: w for w in range(b.wings) for s in b.scout_ids(w)}
    wings = {wing_of[str(s["scout"])] for s in report.scouts}
    problems = []
    if wings != set(range(b.wings)):
        problems.append(f"{b.wings - len(wings)} wings launched no Scout")
    if report.outcome == "failure" or report.degraded():
        problems.append(f"outcome {report.outcome}: {report.reason}")
    if problems:
        raise SystemExit(f"{b.robots} robots: " + "; ".join(problems))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="10,100,1000", help="robot counts (10, 100, 1000 or multiples of 20)")
    ap.add_argument("--until", type=float, default=120.0, help="sim seconds per run (the same for every size)")
    ap.add_argument("--cpu", action="store_true", help="time process CPU time, steadier on a busy machine")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    ap.add_argument("--profile", action="store_true", help="also the top 25 cProfile entries of the largest run")
    args = ap.parse_args()
    sizes = sorted({int(s) for s in args.sizes.split(",") if s.strip()})
    if not sizes or min(sizes) < 1:
        raise SystemExit("--sizes: robot counts, e.g. 10,100,1000")
    profile = cProfile.Profile() if args.profile else None
    points = [measure(n, args.until, args.cpu, profile if n == sizes[-1] else None) for n in sizes]
    figures = summary(points, args)
    if args.json:
        print(json.dumps(figures, indent=2))
    else:
        show(figures)
    if profile is not None:
        stats = pstats.Stats(profile, stream=sys.stderr)
        stats.sort_stats("tottime").print_stats(25)


def summary(points: list[Point], args: argparse.Namespace) -> dict[str, Any]:
    peer = points[0]
    by = {p.robots: p for p in points}
    out: dict[str, Any] = {
        "clock": "cpu" if args.cpu else "wall", "until": args.until, "peer_robots": peer.robots,
        "sizes": [{"robots": p.robots, "wings": p.wings, "sim_time": round(p.sim_time, 1),
                   "seconds": round(p.seconds, 3), "real_time_factor": round(p.factor, 2),
                   "per_robot_ms": round(p.per_robot_ms, 4), "vs_peer": round(p.per_robot_ms / peer.per_robot_ms, 2),
                   "scouts_launched": p.launched} for p in points],
        "goals": {},
    }
    if 1000 in by:
        out["goals"]["rtf_1000"] = {"value": round(by[1000].factor, 2), "goal": GOAL, "met": by[1000].factor >= GOAL}
    if 100 in by and 1000 in by:
        flat = by[1000].per_robot_ms / by[100].per_robot_ms
        out["goals"]["flat_100_1000"] = {"value": round(flat, 2), "goal": FLAT, "met": flat <= FLAT}
    return out


def show(figures: dict[str, Any]) -> None:
    console = Console()
    table = Table(title=f"corridor mission on generated buildings, {figures['until']:g} s of sim time "
                        f"({figures['clock']} clock)")
    for col in ("robots", "wings", "sim s", "seconds", "x real time", "ms / robot / sim s",
                f"vs {figures['peer_robots']} robots", "Scouts launched"):
        table.add_column(col, justify="right")
    for s in figures["sizes"]:
        table.add_row(str(s["robots"]), str(s["wings"]), f"{s['sim_time']:.1f}", f"{s['seconds']:.2f}",
                      f"{s['real_time_factor']:.1f}", f"{s['per_robot_ms']:.4f}", f"{s['vs_peer']:.2f}x",
                      str(s["scouts_launched"]))
    console.print(table)
    for name, g in figures["goals"].items():
        mark = "PASS" if g["met"] else "MISS"
        what = ("1,000 robots, x real time >=" if name == "rtf_1000" else "cost per robot 1,000 / 100 <=")
        console.print(f"{mark}: {what} {g['goal']:g} (measured {g['value']:g})")


if __name__ == "__main__":
    main()
