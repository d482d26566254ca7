"""Only the holder drives, whatever the mission (issue #11): random missions and failures, checked from the trace.

Hypothesis writes missions in the mission language (nested behaviors, `parallel` blocks and concurrent plans,
multiplicities `W[2]` / `W[1..*]`, `needs` with priorities and `for 2s` slices, radio quantities, `release(x)` on
transitions, `after 3s` timeouts, preallocation, components that fail or that command after losing their grant)
and failures (a host killed, a robot lost, a host joining late, a mission stopped), runs each in the real dry-run
on the two-Ranger team (executive, Resource Controller Manager, gates, `sim` drivers, pymunk) and checks the
trace alone:

- `drd.tracecheck.check`, the invariant of `docs/trace.md`: no accepted command from a non-holder (or at
  another epoch), no exclusive unit held twice at once, nothing held when a mission has finished;
- here, more strictly, by `released` records only: every unit of every `granted` gets its own `released` (with
  one of the documented reasons) before its mission's `finished`, never a second grant to the same holder before
  that, never a grant of an exclusive unit another holder has not released, and the quantities held on a
  sharable unit never exceed its capacity (quantities read from the compiled charts).

A failing example is printed as a corpus entry (YAML); `tests/ownership_corpus/README.md` says how to keep it.
"""

from __future__ import annotations

import io
import json
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

from drd.dryrun import Mission, run_many
from drd.executive import EntryPoints
from drd.hosts import Cluster, load_hosts
from drd.hw.interfaces import HardwareError
from drd.inject import parse_all
from drd.rcm import Unit
from drd.runtime.component import Component, Status
from drd.runtime.ownership import NotHolder
from drd.runtime.records import END_REASONS
from drd.sim.world import World, load_world
from drd.tracecheck import check
from dsl import ast, compile_text
from dsl.catalog import Catalog, ComponentType, Kind, NeedSpec, ParamSpec
from dsl.statechart import Statechart
from tests.conftest import ROOT

CORPUS = Path(__file__).resolve().parents[1] / "ownership_corpus"
HOSTS = ROOT / "hosts.two_rangers.yaml"
WORLD = ROOT / "worlds" / "two_rangers.yaml"


# ---------------------------------------------------------------- test components


class _Timed(Component):
    """Runs for `duration` seconds of un-suspended time; fails once it has run `fail_after` seconds (0: never)."""

    def start(self) -> None:
        assert self.ctx is not None
        self.ran = 0.0
        self.last = self.ctx.now()

    def tick(self, now: float) -> Status:
        assert self.ctx is not None
        self.ran += now - self.last
        self.last = now
        fail_after = float(self.ctx.params.get("fail_after") or 0.0)
        if fail_after > 0 and self.ran >= fail_after - 1e-9:
            return Status.FAILURE
        return Status.SUCCESS if self.ran >= float(self.ctx.params["duration"]) - 1e-9 else Status.RUNNING

    def resume(self) -> None:
        assert self.ctx is not None
        self.last = self.ctx.now()


class Pusher(_Timed):
    """Drives its Drive at `v` m/s every cycle, bound or not (after a `release` of the need it is bound through,
    it keeps trying: the gate refuses). A `rogue` one also commands from `suspend` and `terminate`, its last words
    as its authority ends: let through only while it still holds."""

    def step(self, now: float) -> Status:
        assert self.ctx is not None
        status = self.tick(now)
        self.device("drive").set_velocity(float(self.ctx.params["v"]), 0.0)
        return status

    def _last_gasp(self) -> None:
        assert self.ctx is not None
        if self.ctx.params.get("rogue"):
            try:
                self.device("drive").set_velocity(float(self.ctx.params["v"]), 0.3)
            except Exception:  # refused (NotHolder) or the robot is gone: what the gate decides is in the trace
                pass

    def suspend(self) -> None:
        self._last_gasp()

    def terminate(self, status: Status) -> None:
        self._last_gasp()


class Hopper(_Timed):
    """Hops its Scout's foot forward once a second of running time (an action, not a setpoint)."""

    def start(self) -> None:
        super().start()
        self.next_hop = 0.0

    def step(self, now: float) -> Status:
        status = self.tick(now)
        if self.ran >= self.next_hop - 1e-9:
            self.next_hop += 1.0
            try:
                self.device("foot").jump(0.05)
            except NotHolder:
                raise  # refused by the gate: the component fails, as a real one would
            except HardwareError:
                pass  # the simulator's refusal (a Scout in its magazine cannot jump): the gate accepted it
        return status


class Looker(_Timed):
    """Reads its camera every cycle (no actuator: a hold with no command)."""

    def step(self, now: float) -> Status:
        self.device("camera").brightness(3)
        return self.tick(now)


_TIMED = (ParamSpec("duration", "duration", 3.0), ParamSpec("fail_after", "duration", 0.0))
PUSH = ComponentType("Push", Kind.BEHAVIOR, "drives forward every cycle",
                     entry_point="tests.test_ownership_properties:Pusher",
                     params=(ParamSpec("v", "float", 0.3), *_TIMED, ParamSpec("rogue", "bool", False)),
                     needs=(NeedSpec("drive", "Drive", ("Ranger", "Scout")),), interfaces=("Drive",))
HOP = ComponentType("Hop", Kind.BEHAVIOR, "hops once a second", entry_point="tests.test_ownership_properties:Hopper",
                    params=_TIMED, needs=(NeedSpec("foot", "Jump", ("Scout",)),), interfaces=("Jump",))
LOOK = ComponentType("Look", Kind.BEHAVIOR, "reads the camera", entry_point="tests.test_ownership_properties:Looker",
                     params=_TIMED, needs=(NeedSpec("camera", "Camera", ("Ranger", "Scout")),),
                     interfaces=("Camera",))
REGISTRY = {"Push": Pusher, "Hop": Hopper, "Look": Looker}


@pytest.fixture(scope="module")
def cat(catalog: Catalog) -> Catalog:
    return Catalog.of([*catalog.components.values(), PUSH, HOP, LOOK])


@pytest.fixture(scope="module")
def team(cat: Catalog) -> tuple[Cluster, World]:
    return load_hosts(HOSTS, cat), load_world(WORLD)


# ---------------------------------------------------------------- a scenario: missions, failures, a time limit


@dataclass(frozen=True)
class Scenario:
    """What one example runs: mission texts (each with an optional priority against the others), failures in the
    `--inject` syntax plus `stop MISSION-ID at T` (the operator stops one mission), and the sim-time limit."""

    missions: tuple[tuple[str, int | None], ...]
    injections: tuple[str, ...] = ()
    until: float = 30.0
    description: str = ""
    xfail: str = ""

    def to_yaml(self) -> str:
        data: dict[str, Any] = {}
        if self.description:
            data["description"] = self.description
        if self.xfail:
            data["xfail"] = self.xfail
        data["until"] = self.until
        data["injections"] = list(self.injections)
        data["missions"] = [{"priority": p, "text": t} if p is not None else {"text": t} for t, p in self.missions]
        return yaml.dump(data, Dumper=_BlockDumper, sort_keys=False, allow_unicode=True, width=120)

    @classmethod
    def from_yaml(cls, text: str) -> Scenario:
        data = yaml.safe_load(text)
        return cls(tuple((m["text"], m.get("priority")) for m in data["missions"]),
                   tuple(data.get("injections") or ()), float(data.get("until", 30.0)),
                   str(data.get("description", "")), str(data.get("xfail", "")))


class _BlockDumper(yaml.SafeDumper):
    """Mission texts as `|` blocks, so a corpus entry reads like a mission file."""


def _str(dumper: yaml.SafeDumper, value: str) -> yaml.Node:
    return dumper.represent_scalar("tag:yaml.org,2002:str", value, style="|" if "\n" in value else None)


_BlockDumper.add_representer(str, _str)

_STOP = re.compile(r"^\s*stop\s+(?P<mission>\S+)\s+at\s+(?P<at>\S+)\s*$")


@dataclass
class Outcome:
    charts: dict[str, Statechart]  # mission id -> chart
    records: list[dict[str, Any]]
    outcomes: list[str | None] = field(default_factory=list)


def compile_mission(text: str, cat: Catalog) -> Statechart:
    r = compile_text(text, cat, "generated.mission")
    assert r.ok and r.statechart is not None, ([str(d.message) for d in r.diagnostics], text)
    return r.statechart


def run_scenario(s: Scenario, cat: Catalog, team: tuple[Cluster, World]) -> Outcome:
    """Dry-run the scenario's missions together on the two-Ranger team; the trace's records, as dicts."""
    cluster, world = team
    charts = [compile_mission(text, cat) for text, _ in s.missions]
    ids = [f"{c.name}-{n}" for n, c in enumerate(charts, 1)]
    stops: list[tuple[float, str]] = []
    failures: list[str] = []
    for text in s.injections:
        m = _STOP.match(text)
        if m is None:
            failures.append(text)
            continue
        at = ast.parse_duration(m["at"])
        assert at is not None and m["mission"] in ids, (text, ids)
        stops.append((at, m["mission"]))
    injections = parse_all(failures, hosts={h.name for h in cluster.hosts}, robots={r.id for r in cluster.robots},
                           doors={d.id for d in world.doors})

    def progress(sim: Any, executive: Any) -> None:  # after each control cycle: the operator's stops due
        while stops and min(stops)[0] <= sim.time + 1e-9:
            stops.remove(due := min(stops))
            executive.stop(due[1], "stopped by the operator (test)")

    trace = io.StringIO()
    reports = run_many([Mission(c, p) for c, (_, p) in zip(charts, s.missions, strict=True)], cluster, world, cat,
                       until=s.until, trace=trace, registry=EntryPoints(cat, REGISTRY), injections=injections,
                       progress=progress, progress_every=0.0)
    records = [json.loads(line) for line in trace.getvalue().splitlines()]
    return Outcome(dict(zip(ids, charts, strict=True)), records, [r.outcome for r in reports])


# ---------------------------------------------------------------- the properties, from the trace alone


def _state_of(path: str) -> str:
    """The statechart state of an instance path (`M/W[1]/Push` -> `M/W[*]/Push`)."""
    return re.sub(r"\[\d+\]", "[*]", path)


def _quantity(q: object) -> float:
    if isinstance(q, ast.Literal) and isinstance(q.value, int | float) and not isinstance(q.value, bool):
        return float(q.value)
    if isinstance(q, int | float):
        return float(q)
    assert q is None, f"a generated quantity is a literal, got {q!r}"
    return 1.0


def held_quantities(chart: Statechart | None, record: Mapping[str, Any], sharable: Iterable[str]) -> dict[str, float]:
    """How much of each sharable unit a `granted` record takes: the quantities of the needs (or of the aggregates
    whose part it is) that the grant maps to it, as the chart declares them."""
    resources: Mapping[str, str] = {**(record.get("resources") or {}), **(record.get("shares") or {})}
    state = chart.states.get(_state_of(str(record["path"]))) if chart is not None else None
    quantities = {n.name: _quantity(n.quantity) for n in state.needs} if state is not None else {}
    out: dict[str, float] = {}
    for unit in set(sharable) & set(record.get("epochs") or {}):
        for key, rid in resources.items():
            if rid == unit:
                out[unit] = out.get(unit, 0.0) + quantities.get(key.split(".")[0], 1.0)
    return out


def ownership_problems(records: Sequence[Mapping[str, Any]], capacity: Mapping[str, float],
                       charts: Mapping[str, Statechart] | None = None) -> list[str]:
    """Every breach of the ownership invariant in a trace: `check`'s, then the stricter ones of this file.

    `capacity`: the sharable units and their capacities; `charts`: mission id -> chart, for the quantities."""
    charts = charts or {}
    problems = [f"{b.kind} at {b.at:g}: {b.detail}" for b in check(records, sharable=set(capacity)).breaches]
    held: dict[str, dict[tuple[str, str], float]] = {}  # unit -> {(mission, holder): quantity}
    finished: set[str] = set()
    for n, r in enumerate(records):
        kind, mission, path = r.get("kind"), str(r.get("mission", "")), str(r.get("path", ""))
        where = f"record {n} ({kind} {path} at {r.get('at')})"
        if mission in finished and kind in ("granted", "command") and r.get("accepted", True):
            problems.append(f"{where}: after {mission} finished")
        if kind == "granted":
            quantities = held_quantities(charts.get(mission), r, capacity)
            for unit in r.get("epochs") or {}:
                holders = held.setdefault(unit, {})
                if (mission, path) in holders:
                    problems.append(f"{where}: {unit} granted again to its holder, with no released between")
                others = [f"{m}:{h}" for (m, h) in holders if (m, h) != (mission, path)]
                if unit not in capacity and others:
                    problems.append(f"{where}: exclusive {unit} granted while {', '.join(others)} never released it")
                holders[(mission, path)] = quantities.get(unit, 0.0)
                if unit in capacity and sum(holders.values()) > capacity[unit] + 1e-9:
                    problems.append(f"{where}: {unit} over its capacity {capacity[unit]:g}: "
                                    f"{sorted(holders.items())}")
        elif kind == "released":
            if r.get("reason") not in END_REASONS:
                problems.append(f"{where}: released for no documented reason ({r.get('reason')!r})")
            for unit in r.get("resources") or ():
                held.get(str(unit), {}).pop((mission, path), None)
        elif kind == "finished":
            finished.add(mission)
            for unit, holders in held.items():
                problems += [f"{where}: {h} finished holding {unit} without a released record"
                             for (m, h) in holders if m == mission]
    problems += [f"end of trace: {m} never finished" for m in {str(r.get("mission", "")) for r in records} - finished]
    problems += [f"end of trace: {m}:{h} still holds {unit}, no released"
                 for unit, holders in held.items() for (m, h) in holders if m not in finished]
    return problems


#: Real breaches the property found, both fixed (their shrunk examples stay in tests/ownership_corpus/):
#:
#: - a preallocation never used was not cancelled when the state that made it failed and the failure propagated
#:   (to the mission's root, or out of an instance of a multiplicity): `preallocation_leak_*_fails*.yaml`;
#: - a preallocated state that failed as it was entered kept the preallocated grant:
#:   `preallocation_leak_at_failed_entry*.yaml`.


def sharable_capacities(cluster: Cluster) -> dict[str, float]:
    return {u.id: u.capacity for u in cluster.resources() if isinstance(u, Unit) and u.sharable}


def assert_owned(s: Scenario, cat: Catalog, team: tuple[Cluster, World]) -> Outcome:
    out = run_scenario(s, cat, team)
    problems = ownership_problems(out.records, sharable_capacities(team[0]), out.charts)
    assert not problems, "\n".join(problems[:10])
    return out


# ---------------------------------------------------------------- the generator


DRIVES = ('drv.id == "ranger1.drive"', 'drv.id == "ranger1.drive"', 'drv.id == "ranger2.drive"', None)
NEEDS: dict[str, tuple[str, tuple[str | None, ...]]] = {  # need name -> (type, the `where`s it may have)
    "drv": ("Drive", DRIVES),
    "cam": ("Camera", ('cam.id == "ranger1.camera"', 'cam.id == "ranger1.camera"', None)),
    "ranger": ("Ranger", ('ranger.id == "ranger1"', 'ranger.id == "ranger2"', None)),
    "scout": ("Scout", ('scout.id == "scout1"', None, None)),
    "radio": ("RadioChannel", ('radio.id == "ranger1.radio"', None)),
    "foot": ("Jump", ('foot.id == "ranger1.scout1.foot"', None)),
}
MULTIPLICITIES = ("[2]", "[2]", "[1..2]", "[0..2]", "[1..*]", "[2..3]")
#: A behavior's own needs, drawn from these: what a Push below can drive through, most often.
OWN = ("drv", "drv", "ranger", "scout", "cam", "radio", "foot")


@dataclass
class _File:
    """What one mission file under construction has: its behaviors, and counters for fresh names."""

    prefix: str
    decls: list[str] = field(default_factory=list)
    behaviors: int = 0
    aliases: int = 0


@st.composite
def _need(draw: st.DrawFn, name: str) -> str:
    typ, wheres = NEEDS[name]
    text = f"needs {name}: {typ}"
    where = draw(st.sampled_from(wheres))
    if where:
        text += f" where {where}"
    if typ == "RadioChannel":
        text += f" quantity {draw(st.integers(1, 10))}"
    elif draw(st.integers(0, 2)):
        text += f" for {draw(st.integers(1, 4))}s"
    return text


@st.composite
def _leaf(draw: st.DrawFn) -> tuple[str, str]:
    name = draw(st.sampled_from(["Push", "Push", "Push", "Look", "Hop"]))
    duration = draw(st.integers(1, 6))
    args = [f"duration: {duration}s"]
    if name == "Push":
        args.insert(0, f"v: {draw(st.sampled_from(['0.3', '0.5', '-0.2']))}")
        if draw(st.integers(0, 2)) == 0:
            args.append("rogue: true")
    if draw(st.integers(0, 5)) == 0:
        args.append(f"fail_after: {draw(st.integers(1, duration))}s")
    return name, f"{name}({', '.join(args)})"


@st.composite
def _child(draw: st.DrawFn, f: _File, depth: int) -> tuple[str, str]:
    """One child item (a component call or a behavior of this file), with maybe a multiplicity and a priority."""
    if depth < 3 and draw(st.integers(0, 2)) == 0:
        name = draw(_behavior(f, depth + 1))
        text = name
        several = draw(st.integers(0, 2)) == 0  # instances of a behavior queue on its needs: slices, revocations
    else:
        name, text = draw(_leaf())
        several = draw(st.integers(0, 5)) == 0
    if several:
        text += draw(st.sampled_from(MULTIPLICITIES))
    return name, text


@st.composite
def _actions(draw: st.DrawFn, own: list[str]) -> str:
    """A transition's actions, if any: a `release` of one of the behavior's own needs, a log line."""
    acts = []
    release = draw(st.booleans())
    if own and release:
        acts.append(f"release({draw(st.sampled_from(own))})")
    if draw(st.integers(0, 5)) == 0:
        acts.append('log "passing"')
    return f" / {'; '.join(acts)}" if acts else ""


@st.composite
def _body(draw: st.DrawFn, f: _File, depth: int, own: list[str]) -> list[str]:
    """Needs, children and how they run: one child, a sequence with transitions, a parallel block or a concurrent
    plan; timeouts, error transitions and `release` of the behavior's own needs on the way."""
    lines = [draw(_need(n)) for n in own]
    n_children = draw(st.integers(1, 3))
    names: list[str] = []
    for _ in range(n_children):
        name, text = draw(_child(f, depth))
        if name in names or draw(st.integers(0, 5)) == 0:
            f.aliases += 1
            name = f"{f.prefix}{f.aliases}"
            text += f" as {name}"
        if draw(st.integers(0, 4)) == 0:
            text += f" priority {draw(st.integers(1, 3))}"
        names.append(name)
        lines.append(text)

    def actions() -> str:
        return draw(_actions(own))

    form = "single" if n_children == 1 else draw(st.sampled_from(["sequence", "parallel", "parallel", "plan"]))
    transitions: list[str] = []
    if form == "parallel" and own and draw(st.booleans()):
        # a watcher whose timeout gives a need back while its siblings still run (and drive through it)
        f.aliases += 1
        watcher = f"{f.prefix}{f.aliases}"
        lines.append(f"Look(duration: 8s) as {watcher}")
        transitions.append(f"{watcher} -> {watcher} after {draw(st.integers(1, 4))}s / "
                           f"release({draw(st.sampled_from(own))})")
    if form == "parallel":
        policy = draw(st.sampled_from(["", "all ", "any ", f"until {draw(st.sampled_from(names))} "]))
        lines[len(own):] = [f"parallel {policy}{{ {'; '.join(lines[len(own):])} }}"]
    if form == "plan":
        *first, last = names
        lines.append(f"plan concurrent {{ {'; '.join(f'{a} < {last}' for a in first)} }}")
    if form == "sequence":
        lines.append(f"start -> {names[0]}")
        for a, b in zip(names, names[1:], strict=False):
            lines.append(f"{a} -> {b}{' preallocate' if draw(st.integers(0, 4)) == 0 else ''}{actions()}")
    lines += transitions
    for i, name in enumerate(names):  # timeouts and error handling
        later = names[i + 1:] if form in ("sequence", "single") else []
        if draw(st.integers(0, 2)) == 0:
            target = draw(st.sampled_from(["done", "fail", *later, name, name]))  # back to itself: a restart
            lines.append(f"{name} -> {target} after {draw(st.integers(1, 6))}s{actions()}")
        if draw(st.integers(0, 2)) == 0:
            lines.append(f"{name} -> {draw(st.sampled_from(['done', *later]))} on error{actions()}")
    return lines


@st.composite
def _behavior(draw: st.DrawFn, f: _File, depth: int) -> str:
    f.behaviors += 1
    name = f"{f.prefix.upper()}{f.behaviors}"
    own = draw(st.lists(st.sampled_from(OWN), max_size=2, unique=True))
    lines = draw(_body(f, depth, own))
    priority = f" priority {draw(st.integers(1, 3))}" if draw(st.integers(0, 2)) == 0 else ""
    f.decls.append(f"behavior {name}{priority} {{\n" + "".join(f"    {line}\n" for line in lines) + "}\n")
    return name


@st.composite
def mission_texts(draw: st.DrawFn, name: str) -> str:
    f = _File(name.lower())
    own = draw(st.lists(st.sampled_from(OWN), max_size=1))
    lines = draw(_body(f, 0, own))
    root = f"mission {name} {{\n" + "".join(f"    {line}\n" for line in lines) + "}\n"
    return "\n".join([root, *reversed(f.decls)])


HOST_NAMES = ("ranger1", "ranger2")
ROBOT_NAMES = ("ranger1", "ranger1", "ranger2", "scout1", "scout4")  # those the generated needs name, most often


@st.composite
def scenarios(draw: st.DrawFn) -> Scenario:
    """One or two missions (the second with its own priority against the first) and up to two failures."""
    until = float(draw(st.integers(12, 30)))
    missions: list[tuple[str, int | None]] = [(draw(mission_texts("M")), None)]
    if draw(st.integers(0, 2)) == 0:
        missions.append((draw(mission_texts("N")), draw(st.integers(1, 3))))
    ids = [f"{name}-{n}" for n, name in enumerate("MN"[: len(missions)], 1)]
    # while the missions run (most are done within 8 s), on slice boundaries often
    at = st.integers(1, 16).map(lambda half: f"{half / 2:g}s")
    failure = st.one_of(
        st.builds("kill {} at {}".format, st.sampled_from(HOST_NAMES), at),
        st.builds("lose {} at {}".format, st.sampled_from(ROBOT_NAMES), at),
        st.builds("stop {} at {}".format, st.sampled_from(ids), at),
    )
    injections = draw(st.lists(failure, max_size=2))
    if draw(st.integers(0, 5)) == 0:  # ranger2's daemon starts late: its resources join, multiplicities grow
        injections = [i for i in injections if "ranger2" not in i and "scout4" not in i]
        injections.append(f"join ranger2 at {draw(at)}")
    return Scenario(tuple(missions), tuple(injections), until)


# ---------------------------------------------------------------- the tests


EXAMPLES = 200
PROPERTY = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None, print_blob=False,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def test_random_missions_and_failures_keep_ownership(cat: Catalog, team: tuple[Cluster, World]) -> None:
    seen: dict[str, int] = {}  # what the examples exercised: a generator gone blind must fail loudly

    def count(key: str, n: int = 1) -> None:
        seen[key] = seen.get(key, 0) + n

    @PROPERTY
    @given(scenario=scenarios())
    def holds(scenario: Scenario) -> None:
        note("the example as a corpus entry (tests/ownership_corpus/NAME.yaml):\n" + scenario.to_yaml())
        out = run_scenario(scenario, cat, team)
        problems = ownership_problems(out.records, sharable_capacities(team[0]), out.charts)
        assert not problems, "\n".join(problems[:10])
        report = check(out.records, sharable=set(sharable_capacities(team[0])))
        count("examples")
        count("driven", report.accepted > 0)
        count("refused", report.refused > 0)
        for r in out.records:
            if r["kind"] == "released":
                count(f"released: {r['reason']}")
            elif r["kind"] in ("revoked", "suspended", "resumed", "halted"):
                count(r["kind"])
        for o in out.outcomes:
            count(f"outcome: {o}")

    holds()
    # the examples reached what the invariant is about: drives driven, slices taken, holds ended every way
    assert seen["examples"] >= EXAMPLES // 2, seen
    assert seen["driven"] >= EXAMPLES // 2, seen
    # refused commands came mostly from a killed host's components, whose last words followed their lost grant: they
    # now die with it, as on a cluster, and say nothing; the gate refusing is shown for sure by
    # `test_the_gate_refuses_the_last_words_of_a_lost_robots_holder`
    assert seen.get("revoked", 0) > 0, seen
    reasons = {k for k in seen if k.startswith("released: ")}
    assert {"released: exit", "released: revoked", "released: release"} <= reasons, seen
    assert reasons & {"released: host lost", "released: resource lost"}, seen


def _corpus() -> list[Path]:
    return sorted(CORPUS.glob("*.yaml"))


@pytest.mark.parametrize("entry", _corpus(), ids=lambda p: p.stem)
def test_corpus_entry_keeps_ownership(entry: Path, cat: Catalog, team: tuple[Cluster, World]) -> None:
    """Each example kept in `tests/ownership_corpus/` (a shrunk failure, now fixed, or a hand-picked hard case),
    replayed: its trace must hold."""
    scenario = Scenario.from_yaml(entry.read_text(encoding="utf-8"))
    assert not scenario.xfail, f"{entry.name}: a known breach; fix drd, then drop its xfail"
    out = run_scenario(scenario, cat, team)
    caps = sharable_capacities(team[0])
    problems = ownership_problems(out.records, caps, out.charts)
    assert not problems, "\n".join(problems[:10])
    assert check(out.records, sharable=set(caps)).accepted > 0 or "leak" in entry.stem, \
        "the entry drives nothing: it proves nothing"


def test_the_gate_refuses_the_last_words_of_a_lost_robots_holder(cat: Catalog, team: tuple[Cluster, World]) -> None:
    """The refusal the random examples must show, shown for sure: scout1 is lost under a rogue pusher, whose last
    words as it is terminated come after its grant went."""
    entry = CORPUS / "last_words_of_a_lost_robots_holder.yaml"
    out = run_scenario(Scenario.from_yaml(entry.read_text(encoding="utf-8")), cat, team)
    refused = [r for r in out.records if r["kind"] == "command" and not r.get("accepted")]
    assert refused, [r for r in out.records if r["kind"] in ("command", "released", "finished")][-8:]
    assert {r["device"] for r in refused} == {"ranger1.scout1.wheels"}, refused


def test_the_corpus_is_there() -> None:
    assert (CORPUS / "README.md").is_file()
    assert len(_corpus()) >= 2


# ---------------------------------------------------------------- the checks can fail


def _base(cat: Catalog, team: tuple[Cluster, World]) -> Outcome:
    """A run of a corpus entry that holds: a trace to break by hand."""
    entry = CORPUS / "rotation_release_loss_and_kill_at_a_slice_boundary.yaml"
    return run_scenario(Scenario.from_yaml(entry.read_text(encoding="utf-8")), cat, team)


def _first(records: list[dict[str, Any]], kind: str, **match: Any) -> int:
    return next(i for i, r in enumerate(records) if r["kind"] == kind and all(r.get(k) == v for k, v in match.items()))


def test_the_checks_catch_a_broken_trace(cat: Catalog, team: tuple[Cluster, World]) -> None:
    out = _base(cat, team)
    caps = sharable_capacities(team[0])
    assert ownership_problems(out.records, caps, out.charts) == []

    def broken(records: Sequence[Mapping[str, Any]]) -> list[str]:
        return ownership_problems(records, caps, out.charts)

    # an accepted command from a path that holds nothing (a component outside the holder's subtree)
    i = _first(out.records, "command", accepted=True)
    forged = dict(out.records[i], path="Stranger/Push")
    assert any("non-holder command" in p for p in broken([*out.records[: i + 1], forged, *out.records[i + 1:]]))
    # the same command at another epoch than its grant's
    stale = dict(out.records[i], epoch=(out.records[i]["epoch"] or 0) + 7)
    assert any("non-holder command" in p for p in broken([*out.records[:i], stale, *out.records[i + 1:]]))
    # a hold that never gets its `released` (the holder exits, the unit is silently free)
    j = max(k for k, r in enumerate(out.records) if r["kind"] == "released")  # the last: never granted again
    unreleased = [r for k, r in enumerate(out.records) if k != j]
    assert any("without a released" in p for p in broken(unreleased))
    # a second holder granted an exclusive unit before the first released it
    g = _first(out.records, "granted")
    unit = next(iter(out.records[g]["epochs"]))
    twin = dict(out.records[g], path="Other/Holder", epochs={unit: 99}, resources={"x": unit})
    assert any("double hold" in p for p in broken([*out.records[: g + 1], twin, *out.records[g + 1:]]))
    # a released with an undocumented reason
    assert any("no documented reason" in p
               for p in broken([dict(r, reason="gone") if k == j else r for k, r in enumerate(out.records)]))


def test_the_checks_catch_a_capacity_overrun(cat: Catalog, team: tuple[Cluster, World]) -> None:
    text = ("mission Radio {\n    parallel all { A; B }\n}\n"
            "behavior A {\n    needs radio: RadioChannel where radio.id == \"ranger1.radio\" quantity 6\n"
            "    Push(duration: 2s)\n}\n"
            "behavior B {\n    needs radio: RadioChannel where radio.id == \"ranger1.radio\" quantity 6\n"
            "    Push(duration: 2s)\n}\n")
    out = run_scenario(Scenario(((text, None),), until=10.0), cat, team)
    caps = sharable_capacities(team[0])
    assert ownership_problems(out.records, caps, out.charts) == []
    grants = [r for r in out.records if r["kind"] == "granted" and "ranger1.radio" in r["epochs"]]
    assert len(grants) == 2 and grants[0]["at"] < grants[1]["at"], "6 + 6 of a 10 channel: the second waits"
    # the second grant moved before the first's release: 12 of 10
    i, j = (out.records.index(g) for g in grants)
    early = [*out.records[: i + 1], out.records[j], *(r for k, r in enumerate(out.records) if k > i and k != j)]
    assert any("over its capacity" in p for p in ownership_problems(early, caps, out.charts))


def test_the_generator_writes_valid_missions(cat: Catalog) -> None:
    """Every generated mission compiles (a generator that writes nonsense would test nothing)."""

    @settings(max_examples=60, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(text=mission_texts("M"))
    def compiles(text: str) -> None:
        compile_mission(text, cat)

    compiles()


def test_a_scenario_survives_its_yaml() -> None:
    s = Scenario((("mission M {\n    Push\n}\n", None), ("mission N {\n    Look\n}\n", 2)),
                 ("kill ranger2 at 3s", "stop M-1 at 4.5s"), 12.0, "two", "")
    assert Scenario.from_yaml(s.to_yaml()) == s
    assert replace(s, description="") != s
