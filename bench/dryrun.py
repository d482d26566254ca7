"""Dry-run benchmark: sim seconds per wall second (the real-time factor) of the corridor mission.

Run `python bench/dryrun.py [--repeat 3] [--cpu] [--json] [--profile] [--seed 0]` (never by pytest).
The corridor surveillance mission (missions/corridor_surveillance.mission) on worlds/corridor.yaml with
hosts.yaml, through `drd.dryrun.run`: the path `missionctl dry-run` takes (compiled chart, real executive,
resource manager, components and sim drivers, one process). Goal: >= 100x real time.

The mission, hosts and world are loaded once, outside the timing; each round times one whole `run`
and the best of `--repeat` is kept. Every round must succeed, find every open door of the world and
launch a Scout through each, and every round with one seed must produce the same run (its fingerprint:
a hash of the timeline, doors, Scouts and detections), so nothing fast-but-wrong is measured.
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import hashlib
import json
import pstats
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from rich.console import Console
from rich.table import Table

from drd.dryrun import DryRun, run
from drd.hosts import Cluster, load_hosts
from drd.manifests import load_catalog
from drd.sim.world import World, load_world
from dsl import compile_file
from dsl.catalog import Catalog
from dsl.statechart import Statechart

GOAL = 100.0  # sim seconds per wall (or CPU) second, at least
ROOT = Path(__file__).resolve().parent.parent
MISSION = ROOT / "missions" / "corridor_surveillance.mission"
WORLD = ROOT / "worlds" / "corridor.yaml"
HOSTS = ROOT / "hosts.yaml"


@dataclass
class Setup:
    chart: Statechart
    cluster: Cluster
    world: World
    catalog: Catalog


@dataclass
class Round:
    sim_time: float
    seconds: float  # wall or CPU, as measured
    fingerprint: str

    @property
    def factor(self) -> float:
        return self.sim_time / self.seconds if self.seconds > 0 else float("inf")


def load(mission: Path, world: Path, hosts: Path) -> Setup:
    catalog = load_catalog()
    compiled = compile_file(mission, catalog)
    if not compiled.ok or compiled.statechart is None:
        raise SystemExit("\n".join(d.render(compiled.sources) for d in compiled.diagnostics) or "no mission")
    return Setup(compiled.statechart, load_hosts(hosts, catalog), load_world(world), catalog)


def fingerprint(r: DryRun) -> str:
    """A hash of what the run did (not of how long it took): same seed, same fingerprint."""
    facts = {"outcome": r.outcome, "reason": r.reason, "sim_time": r.sim_time, "timeline": r.timeline(),
             "doors": r.doors, "scouts": r.scouts, "detections": r.detections}
    return hashlib.sha256(json.dumps(facts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def check(s: Setup, r: DryRun) -> None:
    """The run did the mission's job; not an assert, so that it holds under python -O too."""
    if r.outcome != "success":
        raise SystemExit(f"the mission did not succeed: {r.outcome} {r.reason}")
    doors = sorted((round(d.center[0]), round(d.center[1])) for d in s.world.doors if d.state.value == "open")
    found = sorted((round(float(d["x"])), round(float(d["y"]))) for d in r.doors)
    if found != doors:
        raise SystemExit(f"doors found {found}, the open doors are {doors}")
    if len({sc["scout"] for sc in r.scouts}) != len(doors):
        raise SystemExit(f"{len(r.scouts)} Scouts launched for {len(doors)} open doors")


def one(s: Setup, seed: int, clock: Callable[[], float]) -> Round:
    gc.collect()
    t0 = clock()
    r = run(s.chart, s.cluster, s.world, s.catalog, seed=seed)
    seconds = clock() - t0
    check(s, r)
    return Round(r.sim_time, seconds, fingerprint(r))


def measure(s: Setup, seed: int, repeat: int, clock: Callable[[], float]) -> list[Round]:
    rounds = [one(s, seed, clock) for _ in range(repeat)]
    prints = {r.fingerprint for r in rounds}
    if len(prints) != 1:
        raise SystemExit(f"seed {seed} gave {len(prints)} different runs: {sorted(prints)}")
    return rounds


def profile(s: Setup, seed: int, out: TextIO, top: int = 25) -> None:
    prof = cProfile.Profile()
    prof.runcall(run, s.chart, s.cluster, s.world, s.catalog, seed=seed)
    stats = pstats.Stats(prof, stream=out)
    stats.sort_stats("tottime").print_stats(top)
    stats.sort_stats("cumulative").print_stats(top)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="whole runs; the best is kept")
    ap.add_argument("--seed", type=int, default=0, help="the simulation's seed (missionctl's default is 0)")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    ap.add_argument("--profile", action="store_true",
                    help="also cProfile one run (top 25 entries by own time, then by cumulative time)")
    ap.add_argument("--cpu", action="store_true", help="time process CPU time, steadier on a busy machine")
    ap.add_argument("--mission", type=Path, default=MISSION, help=argparse.SUPPRESS)
    ap.add_argument("--world", type=Path, default=WORLD, help=argparse.SUPPRESS)
    ap.add_argument("--hosts", type=Path, default=HOSTS, help=argparse.SUPPRESS)
    args = ap.parse_args()
    repeat = max(1, args.repeat)
    setup = load(args.mission, args.world, args.hosts)
    rounds = measure(setup, args.seed, repeat, time.process_time if args.cpu else time.perf_counter)
    best = min(rounds, key=lambda r: r.seconds)
    ok = best.factor >= GOAL
    how = "CPU time" if args.cpu else "wall clock"
    if args.json:
        out: dict[str, Any] = {
            "mission": args.mission.name, "world": args.world.name, "seed": args.seed, "repeat": repeat,
            "cpu": args.cpu, "sim_time": round(best.sim_time, 3), "seconds": round(best.seconds, 4),
            "real_time_factor": round(best.factor, 2), "all_seconds": [round(r.seconds, 4) for r in rounds],
            "fingerprint": best.fingerprint, "goal": GOAL, "pass": ok,
        }
        print(json.dumps(out, indent=2))
    else:
        table = Table(title=f"{args.mission.name} on {args.world.name}, seed {args.seed} "
                            f"(best of {repeat}, {how})")
        for col in ("round", "sim s", f"{'CPU' if args.cpu else 'wall'} s", "x real time"):
            table.add_column(col, justify="right")
        for i, r in enumerate(rounds, 1):
            table.add_row(str(i), f"{r.sim_time:.1f}", f"{r.seconds:.3f}", f"{r.factor:.1f}",
                          style="bold" if r is best else None)
        console = Console()
        console.print(table)
        verdict = "[bold green]PASS[/]" if ok else "[bold red]MISS[/]"
        console.print(f"real-time factor = {best.factor:.1f}x (goal >= {GOAL:g}x): {verdict}"
                      f"  [dim]fingerprint {best.fingerprint}[/]")
    if args.profile:  # on stderr with --json, so that stdout stays valid JSON
        profile(setup, args.seed, sys.stderr if args.json else sys.stdout)


if __name__ == "__main__":
    main()
