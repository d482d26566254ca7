"""Runtime benchmark: events per second through our statechart interpreter, against sismic and transitions.

Run `python bench/runtime.py [--events 20000] [--repeat 3] [--json] [--profile]` (never by pytest).
Two charts, each built for every implementation and driven by the same N events, best of `--repeat`:

- compound: a parallel state with two regions, each cycling a -> b -> c -> a on one event
  (our runtime vs sismic). Goal: ours >= 10x sismic.
- flat: two states toggling on one event (ours vs sismic vs `transitions.Machine`).
  Goal: ours >= transitions.

Our side is a compiled mission run by `drd.runtime.interpreter.Interpreter`, its leaves trivial
components that always return RUNNING (so states change only on events); one event is
`emit("MotionDetected", ...)` then `step()`. Sismic's is `queue(...)` then `execute()`, transitions'
is `machine.go()`. The clock stands still (no slice, lease or timeout work), each round starts
from a freshly started chart, and the final configurations of all implementations are checked
to be the expected one (and one more event must move them all) so that nothing is measured idling.
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import json
import pstats
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TextIO

from rich.console import Console
from rich.table import Table
from sismic.interpreter import Interpreter as SismicInterpreter
from sismic.io import import_from_yaml
from transitions import Machine

from drd.manifests import load_catalog
from drd.rcm import Aggregate, ResourceManager, Unit
from drd.runtime.clock import SimClock
from drd.runtime.component import Component, Status
from drd.runtime.interpreter import Interpreter
from drd.runtime.pool import ResourcePool
from dsl import compile_text
from dsl.statechart import Statechart, StateKind

COMPOUND_GOAL = 10.0  # ours / sismic on the compound chart, at least
FLAT_GOAL = 1.0  # ours / transitions on the flat chart, at least
EVENT = "MotionDetected"
FIELDS = {"area": 0.5, "x": 1.0, "y": 2.0}
CYCLE = ("a", "b", "c")
REGIONS = ("r1", "r2")

# Both regions are the same behavior R, aliased; the mission's Ranger serves every Watch's camera, so
# the only request to the resource manager is the root's, granted on start.
COMPOUND_MISSION = """\
mission Compound {
    needs ranger: Ranger
    parallel { R as r1; R as r2 }
}

behavior R {
    Watch as a
    Watch as b
    Watch as c
    start -> a
    a -> b on MotionDetected
    b -> c on MotionDetected
    c -> a on MotionDetected
}
"""

FLAT_MISSION = """\
mission Flat {
    needs ranger: Ranger
    Watch as a
    Watch as b
    start -> a
    a -> b on MotionDetected
    b -> a on MotionDetected
}
"""

COMPOUND_YAML = """\
statechart:
  name: Compound
  root state:
    name: Compound
    parallel states:
""" + "".join(f"""\
      - name: {r}
        initial: {r}/a
        states:
          - name: {r}/a
            transitions: [{{target: {r}/b, event: {EVENT}}}]
          - name: {r}/b
            transitions: [{{target: {r}/c, event: {EVENT}}}]
          - name: {r}/c
            transitions: [{{target: {r}/a, event: {EVENT}}}]
""" for r in REGIONS)

FLAT_YAML = f"""\
statechart:
  name: Flat
  root state:
    name: Flat
    initial: a
    states:
      - name: a
        transitions: [{{target: b, event: {EVENT}}}]
      - name: b
        transitions: [{{target: a, event: {EVENT}}}]
"""


class Idle(Component):
    """An elementary behavior that never finishes by itself."""

    def step(self, now: float) -> Status:
        return Status.RUNNING


def ranger() -> list[Any]:
    parts = {p: f"ranger1.{p}" for p in ("drive", "ranges", "camera", "launcher")}
    types = {"drive": "Drive", "ranges": "RangeSensor", "camera": "Camera", "launcher": "Launcher"}
    units: list[Any] = [Unit(rid, types[p], host="ranger1") for p, rid in parts.items()]
    return [*units, Aggregate("ranger1", "Ranger", parts, {"battery": 1.0}, host="ranger1")]


# ---------------------------------------------------------------- the three implementations
class Runner:
    """One implementation of one chart: `fresh()` builds and starts it, `fire()` delivers one event."""

    name = ""

    def fresh(self) -> None:
        raise NotImplementedError

    def fire(self) -> None:
        raise NotImplementedError

    def config(self) -> tuple[str, ...]:
        """Active leaf states, as sorted paths relative to the root ("r1/a", or "a")."""
        raise NotImplementedError


class Ours(Runner):
    name = "drd (ours)"

    def __init__(self, chart: Statechart):
        self.chart = chart
        self.fresh()

    def fresh(self) -> None:
        clock = SimClock(1.0)
        rcm = ResourceManager()
        pool = ResourcePool(rcm)
        pool.add(ranger(), clock.now())
        self.interp = Interpreter(self.chart, {"Watch": Idle}, rcm, clock, pool=pool)
        self.interp.start()
        self.interp.step()
        if self.interp.outcome is not None:
            raise SystemExit(f"the mission ended at start: {self.interp.outcome} {self.interp.reason}")
        self.emit, self.step = self.interp.emit, self.interp.step

    def fire(self) -> None:
        self.emit(EVENT, **FIELDS)
        self.step()

    def config(self) -> tuple[str, ...]:
        if self.interp.outcome is not None:
            raise SystemExit(f"the mission ended: {self.interp.outcome} {self.interp.reason}")
        root = f"{self.chart.root}/"
        return tuple(sorted(n.path.removeprefix(root) for n in self.interp.active()
                            if n.state.kind is StateKind.LEAF))


class Sismic(Runner):
    name = "sismic"

    def __init__(self, yaml: str):
        self.statechart = import_from_yaml(yaml)
        self.fresh()

    def fresh(self) -> None:
        self.interp = SismicInterpreter(self.statechart)
        self.interp.execute()  # enter the initial configuration
        self.queue, self.execute = self.interp.queue, self.interp.execute

    def fire(self) -> None:
        self.queue(EVENT, **FIELDS)
        self.execute()

    def config(self) -> tuple[str, ...]:
        return tuple(sorted(s for s in self.interp.configuration if not self.statechart.children_for(s)))


class Transitions(Runner):
    name = "transitions"

    def __init__(self) -> None:
        self.fresh()

    def fresh(self) -> None:
        self.machine = Machine(states=["a", "b"], initial="a", auto_transitions=False,
                               transitions=[{"trigger": "go", "source": "a", "dest": "b"},
                                            {"trigger": "go", "source": "b", "dest": "a"}])
        self.fire = self.machine.go  # type: ignore[method-assign]

    def config(self) -> tuple[str, ...]:
        return (str(self.machine.state),)


# ---------------------------------------------------------------- measuring
@dataclass
class Figure:
    chart: str
    impl: str
    events: int
    seconds: float

    @property
    def rate(self) -> float:
        return self.events / self.seconds


def expected(chart: str, n: int) -> tuple[str, ...]:
    if chart == "compound":
        return tuple(f"{r}/{CYCLE[n % 3]}" for r in REGIONS)
    return (("a", "b")[n % 2],)


def measure(chart: str, runners: list[Runner], events: int, repeat: int,
            clock: Callable[[], float]) -> list[Figure]:
    best = {r.name: float("inf") for r in runners}
    for _ in range(repeat):  # rounds interleave the implementations, so a busy moment hits them all alike
        for r in runners:
            r.fresh()
            fire = r.fire
            gc.collect()
            t0 = clock()
            for _ in range(events):
                fire()
            best[r.name] = min(best[r.name], clock() - t0)
            got, want = r.config(), expected(chart, events)
            if got != want:  # not an assert: it must hold under python -O too
                raise SystemExit(f"{chart}/{r.name}: after {events} events the configuration is {got}, not {want}")
            r.fire()
            if r.config() != expected(chart, events + 1):
                raise SystemExit(f"{chart}/{r.name}: one more event did not move the configuration")
    return [Figure(chart, r.name, events, best[r.name]) for r in runners]


def compiled(text: str) -> Statechart:
    r = compile_text(text, load_catalog(), "bench.mission")
    if not r.ok or r.statechart is None:
        raise SystemExit("\n".join(d.render(r.sources) for d in r.diagnostics))
    return r.statechart


def profile(chart: Statechart, events: int, out: TextIO) -> None:
    ours = Ours(chart)
    prof = cProfile.Profile()
    prof.runcall(lambda: [ours.fire() for _ in range(events)])
    pstats.Stats(prof, stream=out).sort_stats("cumulative").print_stats(25)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--events", type=int, default=20_000, help="events delivered per run")
    ap.add_argument("--repeat", type=int, default=3, help="runs per implementation; the best is kept")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    ap.add_argument("--profile", action="store_true",
                    help="also cProfile our runtime on the compound chart (top 25 cumulative entries)")
    ap.add_argument("--cpu", action="store_true", help="time process CPU time, steadier on a busy machine")
    args = ap.parse_args()
    events, repeat = max(1, args.events), max(1, args.repeat)
    clock = time.process_time if args.cpu else time.perf_counter
    compound = compiled(COMPOUND_MISSION)
    figures = measure("compound", [Ours(compound), Sismic(COMPOUND_YAML)], events, repeat, clock)
    figures += measure("flat", [Ours(compiled(FLAT_MISSION)), Sismic(FLAT_YAML), Transitions()], events, repeat, clock)
    rate = {(f.chart, f.impl): f.rate for f in figures}
    goals = [
        ("compound: ours / sismic", rate["compound", Ours.name] / rate["compound", Sismic.name], COMPOUND_GOAL),
        ("flat: ours / transitions", rate["flat", Ours.name] / rate["flat", Transitions.name], FLAT_GOAL),
    ]
    flat_sismic = rate["flat", Ours.name] / rate["flat", Sismic.name]
    if args.json:
        print(json.dumps({
            "events": events, "repeat": repeat, "cpu": args.cpu,
            "figures": [{"chart": f.chart, "impl": f.impl, "seconds": round(f.seconds, 6),
                         "events_per_s": round(f.rate), "us_per_event": round(f.seconds / f.events * 1e6, 3)}
                        for f in figures],
            "ratios": {"compound_ours_over_sismic": round(goals[0][1], 3),
                       "flat_ours_over_sismic": round(flat_sismic, 3),
                       "flat_ours_over_transitions": round(goals[1][1], 3)},
            "goals": [{"goal": name, "ratio": round(ratio, 3), "at_least": goal, "pass": ratio >= goal}
                      for name, ratio, goal in goals],
        }, indent=2))
    else:
        how = "CPU time" if args.cpu else "wall clock"
        table = Table(title=f"{events:,} events per run (best of {repeat}, {how})")
        for col in ("chart", "implementation", "events/s", "µs/event", "ours ÷ this"):
            table.add_column(col, justify="left" if col in ("chart", "implementation") else "right")
        for f in figures:
            table.add_row(f.chart, f.impl, f"{f.rate:,.0f}", f"{f.seconds / f.events * 1e6:.2f}",
                          f"{rate[f.chart, Ours.name] / f.rate:.2f}x", style="bold" if f.impl == Ours.name else None)
        console = Console()
        console.print(table)
        for name, ratio, goal in goals:
            verdict = "[bold green]PASS[/]" if ratio >= goal else "[bold red]MISS[/]"
            console.print(f"{name} = {ratio:.2f}x (goal >= {goal:g}x): {verdict}")
    if args.profile:  # on stderr with --json, so that stdout stays valid JSON
        profile(compound, events, sys.stderr if args.json else sys.stdout)


if __name__ == "__main__":
    main()
