"""Dry-run benchmark: sim seconds per wall second (the real-time factor) of the corridor mission.

Run `python bench/dryrun.py [--repeat 3] [--cpu] [--json] [--profile] [--seed 0] [--no-record]` (never by pytest).
The corridor surveillance mission (missions/corridor_surveillance.mission) on worlds/corridor.yaml with
hosts.yaml, through `drd.dryrun.run`: the path `missionctl dry-run` takes (compiled chart, real executive,
resource manager, components and sim drivers, one process). Goal: >= 100x real time.

The recording column (issue #13): each round runs the mission a second time with a `drd.record.Recorder` (what
`--record run.mcap` does), right after the first; the best recorded round against the best plain one is the
recording's cost. Goals: at most 25 % of the dry-run's time, and a file of at most 20 MB.

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
import tempfile
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
from drd.record import Recorder
from drd.sim.world import World, load_world
from dsl import compile_file
from dsl.catalog import Catalog
from dsl.statechart import Statechart

GOAL = 100.0  # sim seconds per wall (or CPU) second, at least
RECORD_COST_GOAL = 0.25  # what recording adds to a dry-run's time, at most
RECORD_SIZE_GOAL = 20 * 1024 * 1024  # the corridor mission's recording, at most (bytes)
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
    recorded: float | None = None  # the same run with a recording (seconds), None when not measured
    size: int = 0  # the recording's bytes

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


def one(s: Setup, seed: int, clock: Callable[[], float], record: bool = True) -> Round:
    gc.collect()
    t0 = clock()
    r = run(s.chart, s.cluster, s.world, s.catalog, seed=seed)
    seconds = clock() - t0
    check(s, r)
    result = Round(r.sim_time, seconds, fingerprint(r))
    if record:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "run.mcap"
            gc.collect()
            t0 = clock()
            again = run(s.chart, s.cluster, s.world, s.catalog, seed=seed, recorder=Recorder(path))
            result.recorded, result.size = clock() - t0, path.stat().st_size
        if fingerprint(again) != result.fingerprint:
            raise SystemExit("recording changed the run")
    return result


def measure(s: Setup, seed: int, repeat: int, clock: Callable[[], float], record: bool = True) -> list[Round]:
    rounds = [one(s, seed, clock, record) for _ in range(repeat)]
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
    ap.add_argument("--no-record", action="store_true", help="skip the recording column")
    ap.add_argument("--mission", type=Path, default=MISSION, help=argparse.SUPPRESS)
    ap.add_argument("--world", type=Path, default=WORLD, help=argparse.SUPPRESS)
    ap.add_argument("--hosts", type=Path, default=HOSTS, help=argparse.SUPPRESS)
    args = ap.parse_args()
    repeat = max(1, args.repeat)
    setup = load(args.mission, args.world, args.hosts)
    rounds = measure(setup, args.seed, repeat, time.process_time if args.cpu else time.perf_counter,
                     not args.no_record)
    if args.json:
        print(json.dumps(figures(args, rounds), indent=2))
    else:
        show(args, rounds)
    if args.profile:  # on stderr with --json, so that stdout stays valid JSON
        profile(setup, args.seed, sys.stderr if args.json else sys.stdout)


def recording(rounds: list[Round]) -> tuple[float, int] | None:
    """What recording costs (the best recorded round over the best plain one, less 1) and the file's size."""
    recorded = [r.recorded for r in rounds if r.recorded is not None]
    if not recorded:
        return None
    return min(recorded) / min(r.seconds for r in rounds) - 1, max(r.size for r in rounds)


def figures(args: argparse.Namespace, rounds: list[Round]) -> dict[str, Any]:
    best = min(rounds, key=lambda r: r.seconds)
    out: dict[str, Any] = {
        "mission": args.mission.name, "world": args.world.name, "seed": args.seed, "repeat": len(rounds),
        "cpu": args.cpu, "sim_time": round(best.sim_time, 3), "seconds": round(best.seconds, 4),
        "real_time_factor": round(best.factor, 2), "all_seconds": [round(r.seconds, 4) for r in rounds],
        "fingerprint": best.fingerprint, "goal": GOAL, "pass": best.factor >= GOAL,
    }
    cost = recording(rounds)
    if cost is not None:
        out["recording"] = {"cost": round(cost[0], 4), "bytes": cost[1], "ratio": round(1 + cost[0], 4),
                            "all_seconds": [round(r.recorded or 0.0, 4) for r in rounds],
                            "goal_cost": RECORD_COST_GOAL, "goal_bytes": RECORD_SIZE_GOAL,
                            "pass": cost[0] <= RECORD_COST_GOAL and cost[1] <= RECORD_SIZE_GOAL}
    return out


def show(args: argparse.Namespace, rounds: list[Round]) -> None:
    best = min(rounds, key=lambda r: r.seconds)
    how = "CPU" if args.cpu else "wall"
    table = Table(title=f"{args.mission.name} on {args.world.name}, seed {args.seed} "
                        f"(best of {len(rounds)}, {'CPU time' if args.cpu else 'wall clock'})")
    cols = ["round", "sim s", f"{how} s", "x real time"]
    cols += [f"{how} s recorded", "recorded / not"] if rounds[0].recorded is not None else []
    for col in cols:
        table.add_column(col, justify="right")
    for i, r in enumerate(rounds, 1):
        cells = [str(i), f"{r.sim_time:.1f}", f"{r.seconds:.3f}", f"{r.factor:.1f}"]
        if r.recorded is not None:
            cells += [f"{r.recorded:.3f}", f"{r.recorded / r.seconds:.3f}"]
        table.add_row(*cells, style="bold" if r is best else None)
    console = Console()
    console.print(table)
    verdict = "[bold green]PASS[/]" if best.factor >= GOAL else "[bold red]MISS[/]"
    console.print(f"real-time factor = {best.factor:.1f}x (goal >= {GOAL:g}x): {verdict}"
                  f"  [dim]fingerprint {best.fingerprint}[/]")
    cost = recording(rounds)
    if cost is not None:
        ok = cost[0] <= RECORD_COST_GOAL and cost[1] <= RECORD_SIZE_GOAL
        verdict = "[bold green]PASS[/]" if ok else "[bold red]MISS[/]"
        console.print(f"recording: x{1 + cost[0]:.3f} the time (+{100 * cost[0]:.1f} %, goal <= "
                      f"{100 * RECORD_COST_GOAL:g} %), file {cost[1] / 1e6:.2f} MB (goal <= "
                      f"{RECORD_SIZE_GOAL / 1024 / 1024:g} MiB): {verdict}")


if __name__ == "__main__":
    main()
