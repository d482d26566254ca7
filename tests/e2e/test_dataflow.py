"""Declared data flow (issue #12): inputs bound by name, else by type, else explicitly; ports between concurrent
siblings, producers stepped first; a user's patrol works whatever its names.

The mission-level tests run the real dry-run with the standard components and read the trace (which door each
Scout went through); the binding rules are checked through the compiler's located errors; ports through test
components that say what they read each cycle.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from drd.manifests import check_references, parse_manifest
from drd.runtime import records as rec
from drd.runtime.component import Component, Status
from dsl import compile_text
from dsl.catalog import Catalog, ComponentType, InputSpec, Kind, NeedSpec, RecordSpec
from dsl.statechart import Statechart
from tests.conftest import ROOT
from tests.runtime_support import Harness, ranger_world

MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]

PATROL = """\
mission {mission} {{
    shared {log}: DoorLog
    {lookout}[2] as {alias}
}}

behavior {lookout} {{
    needs ranger: Ranger
    needs scout: Scout where scout.carrier == ranger
    start -> {find}
    {find} -> {aim}
    AlignRanger as {aim}
    {aim} -> {throw}
    LaunchScout as {throw}
    {throw} -> done / release(ranger)
    {find} -> fail on error
}}

behavior {find} {{
    parallel until {spotter} {{
        FollowCorridor(speed: 0.5)
        DetectDoor(min_width: 0.7) as {spotter}
    }}
}}
"""


@pytest.mark.parametrize("names", [
    {"mission": "Patrol", "log": "doors", "lookout": "Lookout", "alias": "lookouts", "find": "FindDoor",
     "aim": "Aim", "throw": "Throw", "spotter": "spotter"},
    {"mission": "Rondas", "log": "puertas", "lookout": "Vigia", "alias": "vigias", "find": "Buscar",
     "aim": "Apuntar", "throw": "Lanzar", "spotter": "ojo"},
])
def test_a_users_two_scout_patrol_launches_one_scout_per_distinct_door_whatever_its_names(
        names: dict[str, str], tmp_path: Path) -> None:
    mission = tmp_path / "patrol.mission"
    mission.write_text(PATROL.format(**names))
    trace = tmp_path / "trace.jsonl"
    r = subprocess.run([*MISSIONCTL, "dry-run", str(mission), "--json", "--trace", str(trace), "--until", "300"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads(r.stdout)["outcome"] == "success"
    records = [json.loads(line) for line in trace.read_text().splitlines()]
    events = [x for x in records if x["kind"] == "event"]
    launched = [e for e in events if e["name"] == "ScoutLaunched"]
    doors = [e for e in events if e["name"] == "DoorDetected"]
    assert len(launched) == 2 and len({e["fields"]["scout"] for e in launched}) == 2
    assert len(doors) == 2
    (x1, y1), (x2, y2) = ((d["fields"]["x"], d["fields"]["y"]) for d in doors)
    assert abs(x1 - x2) + abs(y1 - y2) > 1.0, "two distinct doors, one Scout each"
    # each instance launched through the door its own search found: its launch follows its own detection
    for d in doors:
        instance = d["path"].split("/")[1]
        assert any(e["path"].split("/")[1] == instance for e in launched)


def errors(text: str, catalog: Catalog) -> list[Any]:
    return [d for d in compile_text(text, catalog, "t.mission").diagnostics if d.severity.value == "error"]


def test_a_missing_input_is_a_located_error_with_a_hint(catalog: Catalog) -> None:
    [d] = errors("mission M {\n    needs ranger: Ranger\n    AlignRanger\n}\n", catalog)
    assert d.code == "missing-input" and (d.span.line, d.span.column) == (3, 5)
    assert "AlignRanger needs input door (Door)" in d.message
    assert d.hint is not None and "AlignRanger(door: ...)" in d.hint


TWO_DOORS = """\
mission M {{
    needs ranger: Ranger
    plan {{ first < second < AlignRanger }}
    DetectDoor as first
    DetectDoor as second
    {align}
}}
"""


def test_two_candidates_of_the_inputs_type_are_ambiguous_and_an_explicit_binding_chooses(catalog: Catalog) -> None:
    [d] = errors(TWO_DOORS.format(align=""), catalog)
    assert d.code == "ambiguous-input" and "first.door" in d.message and "second.door" in d.message
    assert d.hint is not None and "AlignRanger(door: first.door)" in d.hint
    r = compile_text(TWO_DOORS.format(align="AlignRanger(door: second.door)"), catalog, "t.mission")
    assert r.ok and r.statechart is not None
    [binding] = r.statechart.states["M/AlignRanger"].inputs
    assert (binding.state, binding.field, binding.shared) == ("M/second", "door", False)
    assert not r.statechart.states["M/AlignRanger"].args, "an input binding is not a parameter"
    [d] = errors(TWO_DOORS.format(align="AlignRanger(door: secnd.door)"), catalog)
    assert d.code == "unknown-input-source" and d.span.line == 6 and "first, second" in (d.hint or "")


WRAPPED = """\
mission M {{
    needs ranger: Ranger
    plan {{ first < second < Aim }}
    DetectDoor as first
    DetectDoor as second
    Aim
}}

behavior Aim {{ {align} }}
"""


def test_the_ambiguous_inputs_hint_binds_an_enclosing_behaviors_sibling_and_works(catalog: Catalog) -> None:
    """Users audit 12, D3: the hint proposed `first.door` for an input whose candidates were siblings of its
    enclosing behavior, then refused that binding ("not an output of a sibling", and an empty list)."""
    [d] = errors(WRAPPED.format(align="AlignRanger"), catalog)
    assert d.code == "ambiguous-input" and d.hint is not None
    bound = d.hint.removeprefix("bind it: ")
    r = compile_text(WRAPPED.format(align=bound), catalog, "t.mission")
    assert r.ok, [x.message for x in r.diagnostics]
    assert r.statechart is not None
    [binding] = r.statechart.states["M/Aim/AlignRanger"].inputs
    assert (binding.state, binding.field) == ("M/first", "door")
    [d] = errors(WRAPPED.format(align="AlignRanger(door: frist.door)"), catalog)
    assert d.code == "unknown-input-source" and "first, second" in (d.hint or "")


def test_shared_data_binds_by_type_whatever_its_name_and_an_optional_input_may_stay_unbound(
        catalog: Catalog) -> None:
    text = "mission M {{\n    needs ranger: Ranger\n    {shared}\n    DetectDoor\n}}\n"
    r = compile_text(text.format(shared="shared anything: DoorLog"), catalog, "t.mission")
    assert r.ok and r.statechart is not None
    [b] = r.statechart.states["M/DetectDoor"].inputs
    assert (b.name, b.state, b.field, b.shared) == ("visited", "M", "anything", True)
    r = compile_text(text.format(shared=""), catalog, "t.mission")
    assert r.ok and r.statechart is not None and r.statechart.states["M/DetectDoor"].inputs == ()


def test_an_input_is_not_bound_to_a_datum_of_another_type_even_by_name(catalog: Catalog) -> None:
    [d] = errors("mission M {\n    needs ranger: Ranger\n    shared door: DoorLog\n    AlignRanger\n}\n", catalog)
    assert d.code == "missing-input"
    [d] = errors("mission M {\n    needs ranger: Ranger\n    shared seen: DoorLog\n    AlignRanger(door: seen)\n}\n",
                 catalog)
    assert d.code == "type" and "is a Door" in d.message and "DoorLog" in d.message


# --- ports: concurrent siblings, producers first --------------------------------------------------------------

COUNT = ComponentType("Count", Kind.DATA, "a number")
TICK = ComponentType("Tick", Kind.BEHAVIOR, "counts its steps", entry_point="x:Tick",
                     outputs=(RecordSpec("n", {}, "Count"),))
SEE = ComponentType("See", Kind.BEHAVIOR, "reads a count each step", entry_point="x:See",
                    inputs=(InputSpec("n", "Count"),), outputs=(RecordSpec("m", {}, "Count"),))
LOOP = ComponentType("Loop", Kind.BEHAVIOR, "reads a count, outputs one", entry_point="x:Loop",
                     inputs=(InputSpec("m", "Count"),), outputs=(RecordSpec("n2", {}, "Count"),),
                     needs=(NeedSpec("drive", "Drive", ("Ranger",)),))


@pytest.fixture(scope="module")
def ports(catalog: Catalog) -> Catalog:
    return Catalog.of([*catalog.components.values(), COUNT, TICK, SEE, LOOP])


class Tick(Component):
    def start(self) -> None:
        self.n = 0

    def step(self, now: float) -> Status:
        assert self.ctx is not None
        self.n += 1
        self.ctx.outputs["n"] = self.n
        return Status.SUCCESS if self.n >= 5 else Status.RUNNING


class See(Component):
    def step(self, now: float) -> Status:
        assert self.ctx is not None
        self.ctx.log(f"saw {self.input('n')}")
        self.ctx.outputs["m"] = self.input("n")
        return Status.RUNNING


def chart(text: str, catalog: Catalog) -> Statechart:
    r = compile_text(text, catalog, "t.mission")
    assert r.ok and r.statechart is not None, [d.render() for d in r.diagnostics]
    return r.statechart


def seen(h: Harness) -> list[str]:
    return [r.text for r in h.of(rec.Log) if r.text.startswith("saw")]


def test_a_running_producer_feeds_a_concurrent_consumer_in_the_same_cycle_whatever_the_declaration_order(
        ports: Catalog) -> None:
    text = "mission M {\n    parallel until Tick {\n        See\n        Tick\n    }\n}\n"
    sc = chart(text, ports)
    assert sc.states["M"].entry == ("M/Tick", "M/See"), "the producer is entered, and stepped, first"
    h = Harness(sc, {"Tick": Tick, "See": See}, ranger_world())
    assert h.run() == "success"
    assert seen(h)[:4] == ["saw 1", "saw 2", "saw 3", "saw 4"], "each cycle's value, not the previous one"


def test_last_reads_the_previous_cycle(ports: Catalog) -> None:
    text = "mission M {\n    parallel until Tick {\n        See(n: last(Tick.n))\n        Tick\n    }\n}\n"
    sc = chart(text, ports)
    assert sc.states["M"].entry == (), "no feed this cycle: declaration order"
    h = Harness(sc, {"Tick": Tick, "See": See}, ranger_world())
    assert h.run() == "success"
    assert seen(h)[:4] == ["saw None", "saw 1", "saw 2", "saw 3"]


def test_concurrent_siblings_feeding_each_other_are_an_error_unless_one_reads_last(ports: Catalog) -> None:
    text = "mission M {{\n    needs ranger: Ranger\n    parallel {{\n        See(n: Loop.n2)\n        Loop(m: {m})\n" \
           "    }}\n}}\n"
    [d] = errors(text.format(m="See.m"), ports)
    assert d.code == "input-cycle" and "See" in d.message and "Loop" in d.message and "last(" in (d.hint or "")
    assert not errors(text.format(m="last(See.m)"), ports)


def test_manifests_declare_inputs_of_known_data_types_and_never_a_parameter_of_the_same_name() -> None:
    good, problems = parse_manifest({"name": "Aim", "kind": "behavior", "entry_point": "m:Aim", "description": "x",
                                     "inputs": {"door": {"type": "Door", "optional": True}}}, "aim.yaml")
    assert not problems and good is not None and good.inputs == (InputSpec("door", "Door", True),)
    door = ComponentType("Door", Kind.DATA, fields={"x": "float"})
    assert not check_references([good, door])
    bad, problems = parse_manifest({"name": "Aim", "kind": "behavior", "entry_point": "m:Aim", "description": "x",
                                    "params": {"door": {"type": "float", "default": 1.0}},
                                    "inputs": {"door": {"type": "Dor"}, "x": {"optional": True}}}, "aim.yaml")
    assert any(p.key == "inputs.x.type" for p in problems), problems
    assert bad is not None
    found = {(p.key, p.message) for p in check_references([bad, door])}
    assert any(k == "inputs.door.type" and "unknown type 'Dor'" in m for k, m in found), found
    assert any(k == "inputs.door" and "parameter too" in m for k, m in found), found


def test_no_standard_component_reads_data_by_a_hidden_name() -> None:
    """The coupling the issue found: components looked siblings and shared data up by name."""
    for path in (ROOT / "components" / "behaviors").glob("*.py"):
        text = path.read_text()
        for hidden in ("sibling_output", ".shared(", 'services.get("shared")', 'services.get("siblings")'):
            assert hidden not in text, f"{path.name} uses {hidden}"


def test_plan_shows_each_inputs_binding_and_dot_draws_the_connections() -> None:
    mission = "missions/corridor_surveillance.mission"
    r = subprocess.run([*MISSIONCTL, "plan", mission], cwd=ROOT, capture_output=True, text=True, timeout=60,
                       check=False)
    assert r.returncode == 0, r.stderr
    assert "door ← FindNewDoor.door" in r.stdout and "goal ← LocateDarkCorner.goal" in r.stdout
    assert "visited ← shared visited (CorridorSurveillance)" in r.stdout
    r = subprocess.run([*MISSIONCTL, "plan", mission, "-f", "dot"], cwd=ROOT, capture_output=True, text=True,
                       timeout=60, check=False)
    assert r.returncode == 0, r.stderr
    assert 'label="door", style=dotted' in r.stdout and 'label="goal", style=dotted' in r.stdout
