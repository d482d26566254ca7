"""Component manifests: the standard catalog, and one exact message per schema check."""

from __future__ import annotations

import os
import pickle
import re
import sys
from pathlib import Path

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

import components
from drd.manifests import (
    KEY_ORDER,
    ManifestError,
    ManifestProblem,
    default_dirs,
    load_catalog,
    parse_manifest,
)
from dsl.catalog import Catalog, ComponentType, Kind, Limit, NeedSpec, ParamSpec, Process, RecordSpec, Scheduling

STANDARD = Path(components.__file__).parent
DOCS = Path(__file__).resolve().parents[2] / "docs" / "components.md"

KINDS = {
    Kind.RC: ["Drive", "RangeSensor", "Camera", "Launcher", "Jump", "RadioChannel", "Sensor"],
    Kind.ARC: ["Ranger", "Scout", "Robot"],
    Kind.DATA: ["OccupancyMap", "DoorLog", "Door", "Goal"],
    Kind.BEHAVIOR: [
        "FollowCorridor", "AvoidObstacles", "DetectDoor", "AlignRanger", "LaunchScout", "LocateDarkCorner",
        "ServoToGoal", "TurnToWatch", "Watch", "Observe", "Calibrate", "ReturnToStart", "Wait",
    ],
}


@pytest.fixture(scope="module")
def standard() -> Catalog:
    return load_catalog([STANDARD])


# ---------------------------------------------------------------- the standard catalog


def test_standard_catalog_has_every_component_with_its_kind(standard: Catalog) -> None:
    assert {name: t.kind for name, t in standard.components.items()} == {
        name: kind for kind, names in KINDS.items() for name in names
    }


def test_every_behavior_parameter_has_a_default_and_a_description(standard: Catalog) -> None:
    for t in standard.components.values():
        for p in t.params:
            assert not p.required and p.default is not None, f"{t.name}.{p.name} has no default"
            assert p.description, f"{t.name}.{p.name} has no description"


def test_standard_components_are_described_and_point_where_agreed(standard: Catalog) -> None:
    for t in standard.components.values():
        assert t.description.endswith("."), t.name
        snake = re.sub(r"(?<!^)(?=[A-Z])", "_", t.name).lower()
        if t.kind is Kind.BEHAVIOR:
            assert t.entry_point == f"components.behaviors.{snake}:{t.name}"
            assert all(n.description for n in (*t.needs, *t.outputs, *t.events)), t.name
        elif t.kind is Kind.RC and not t.abstract:
            assert t.entry_point == f"components.sim.{snake}:Sim{t.name}"
            assert t.interfaces == (t.name,)


def test_standard_manifests_write_keys_in_canonical_order() -> None:
    for path in sorted(STANDARD.glob("*/manifest.yaml")):
        keys = list(yaml.safe_load(path.read_text(encoding="utf-8")))
        assert keys == sorted(keys, key=KEY_ORDER.index), path


def test_the_agreed_needs_and_records(standard: Catalog) -> None:
    servo, watch, door = (standard.components[n] for n in ("ServoToGoal", "Watch", "DetectDoor"))
    assert servo.needs[2] == NeedSpec("radio", "RadioChannel", ("Scout",), 1.0, servo.needs[2].description)
    duration = watch.params[0]
    assert duration == ParamSpec("duration", "duration", 60.0, False, duration.description,
                                 Limit(0.0, 86_400.0, duration=True))
    assert dict(door.outputs[0].fields) == {"width": "float", "x": "float", "y": "float", "side": "str"}
    assert standard.events["MotionDetected"].fields == {"area": "float", "x": "float", "y": "float"}
    assert standard.components["RadioChannel"].sharable and standard.components["RadioChannel"].capacity == 10
    assert standard.part_of("Scout", "Drive") == "wheels"
    assert standard.properties("Scout")["carrier"] == "Ranger"


def test_loading_never_imports_an_entry_point(standard: Catalog) -> None:
    """In a fresh interpreter: loading the catalog must not import any component's implementation."""
    import subprocess

    code = ("import sys; from drd.manifests import load_catalog; load_catalog(); "
            "print([m for m in sys.modules if m.startswith(('components.behaviors', 'components.sim'))])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "[]"


def test_docs_list_every_standard_component_and_manifest_key(standard: Catalog) -> None:
    text = DOCS.read_text(encoding="utf-8")
    assert [n for n in standard.components if f"`{n}`" not in text] == []
    assert [k for k in KEY_ORDER if f"`{k}`" not in text] == []


def test_the_docs_behavior_table_names_each_behaviors_needs(standard: Catalog) -> None:
    """The table of docs/components.md lists each standard behavior's needs as its manifest declares them (docs
    audit 1: five rows had lost a need, so a user binding a behavior by hand missed one)."""
    rows = {}
    for line in DOCS.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 4 and cells[0].startswith("`") and cells[0].strip("`") in KINDS[Kind.BEHAVIOR]:
            rows[cells[0].strip("`")] = cells[2]
    assert sorted(rows) == sorted(KINDS[Kind.BEHAVIOR])
    for name, cell in rows.items():
        ct = standard.get(name)
        assert ct is not None
        wanted = [f"`{n.name}: {n.type}" for n in ct.needs]  # `drive: Drive of [...]`, `scout: Scout`
        assert [w for w in wanted if w not in cell] == [], (name, cell)


# ---------------------------------------------------------------- parsing one manifest


def test_parse_manifest_converts_to_catalog_types() -> None:
    data = {
        "name": "Patrol", "kind": "behavior", "description": "Walks a beat.",
        "entry_point": "x.patrol:Patrol", "process": "dedicated", "multiplicity": 2,
        "scheduling": {"cores": [0, 1], "nice": 5},
        "params": {
            "speed": {"type": "float", "default": 1},
            "pause": {"type": "duration", "default": "250ms"},
            "label": {"type": "str"},
        },
        "needs": {"radio": {"type": "RadioChannel", "of": ["Scout"], "quantity": 2}},
        "events": {"Seen": {"fields": {"area": "float"}}},
        "interfaces": ["RadioChannel"],
    }
    t, problems = parse_manifest(data, "p.yaml")
    assert problems == []
    assert t == ComponentType(
        "Patrol", Kind.BEHAVIOR, "Walks a beat.",
        params=(ParamSpec("speed", "float", 1.0), ParamSpec("pause", "duration", 0.25),
                ParamSpec("label", "str", None, required=True)),
        needs=(NeedSpec("radio", "RadioChannel", ("Scout",), 2.0),),
        events=(RecordSpec("Seen", {"area": "float"}),), interfaces=("RadioChannel",), multiplicity=2,
        entry_point="x.patrol:Patrol", process=Process.DEDICATED, scheduling=Scheduling((0, 1), 5),
        source="p.yaml",
    )
    assert isinstance(t.params[0].default, float)


_keys = st.sampled_from([*KEY_ORDER, "type", "default", "of", "quantity", "fields"]) | st.text(max_size=6)
_json = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(_keys, inner, max_size=4),
    max_leaves=12,
)


@given(st.dictionaries(st.sampled_from(KEY_ORDER), _json) | _json)
def test_parse_manifest_reports_rather_than_crashes(data: object) -> None:
    t, problems = parse_manifest(data, "fuzz.yaml")
    assert t is not None or problems
    assert all(isinstance(p, ManifestProblem) for p in problems)


def test_problem_and_error_render_and_pickle() -> None:
    p = ManifestProblem("m.yaml", "params.speed.type", "unknown type 'flaot' (did you mean float?)")
    assert str(p) == "m.yaml: params.speed.type: unknown type 'flaot' (did you mean float?)"
    assert str(ManifestProblem("m.yaml", "", "invalid YAML: oops", line=3)) == "m.yaml:3: invalid YAML: oops"
    err = ManifestError([p, p])
    assert str(err) == f"{p}\n{p}"
    assert pickle.loads(pickle.dumps(err)).problems == (p, p)


# ---------------------------------------------------------------- every check, with its message

F = "components/Bad/manifest.yaml"
DROP = object()
_BASES = {
    "behavior": {"entry_point": "components.behaviors.bad:Bad"},
    "rc": {"entry_point": "components.sim.bad:SimBad", "interfaces": ["Bad"]},
    "arc": {"parts": {"drive": "Drive"}},
    "data": {},
}


def manifest(base: str = "behavior", **changes: object) -> dict[str, object]:
    """A valid manifest of kind `base` named Bad, with `changes` (DROP removes a key)."""
    data = {"name": "Bad", "kind": base, "description": "A test component.", **_BASES[base], **changes}
    return {k: v for k, v in data.items() if v is not DROP}


def need(type_: str, *of: str, **more: object) -> dict[str, object]:
    return {"type": type_, **({"of": list(of)} if of else {}), **more}


class Folders(dict[str, object]):
    """Several manifest folders for one case; any other case content is the folder Bad."""


def case(id: str, content: object, *expected: str) -> object:
    """A table row; a message not naming its file is about components/Bad/manifest.yaml."""
    files = content if isinstance(content, Folders) else {"Bad": content}
    return pytest.param(files, [m if m.startswith("components/") else f"{F}: {m}" for m in expected], id=id)


NAME_RULE = "(letters, digits and _, not starting with a digit)"
B2 = "components/Bad2/manifest.yaml"
RADIO = {"interfaces": ["RadioChannel"]}
CASES = [
    # files and YAML
    case("yaml-syntax", "name: Bad\n  kind: behavior\n",
         f"{F}:2: invalid YAML: mapping values are not allowed here"),
    case("yaml-duplicate-key", "name: Bad\nkind: data\nname: Bad\n",
         f"{F}:3: invalid YAML: duplicate key 'name'"),
    case("top-level-list", "- name: Bad\n", "expected a mapping of manifest keys, got a list"),
    case("empty-file", "", "expected a mapping of manifest keys, got null"),
    case("folder-name", manifest(name="Good"), "name: Good does not match its folder Bad"),
    case("duplicate", Folders(Bad=manifest(), Bad2=manifest()),
         f"{B2}: name: Bad does not match its folder Bad2",
         f"{B2}: name: duplicate component Bad, also in {F}"),
    case("all-files-reported",
         Folders(Bad=manifest("data", description=DROP), Bad2=manifest(name=DROP, kind=DROP)),
         "description: required key missing",
         f"{B2}: name: required key missing",
         f"{B2}: kind: required key missing"),
    # top-level keys and values
    case("required-behavior", manifest(entry_point=DROP), "entry_point: required key missing"),
    case("required-rc", manifest("rc", interfaces=DROP), "interfaces: required key missing"),
    case("required-arc", manifest("arc", parts=DROP), "parts: required key missing"),
    case("unknown-key", manifest(parmas={}), "parmas: unknown key (did you mean params?)"),
    case("key-of-another-kind", manifest(parts={}), "parts: does not apply to a behavior manifest"),
    case("kind-typo", manifest(kind="behaviour"), "kind: unknown kind 'behaviour' (did you mean behavior?)"),
    # the rest of a misspelt kind's manifest is checked as that kind (users audit 15, D8: its unknown types were not)
    case("kind-typo-and-types", manifest(kind="behaviour", params={"rpm": {"type": "flaot", "default": 3}}),
         "kind: unknown kind 'behaviour' (did you mean behavior?)",
         "params.rpm.type: unknown type 'flaot' (did you mean float?)"),
    case("kind-unknown", manifest(kind="robot"),
         "kind: unknown kind 'robot' (expected one of behavior, rc, arc, data)"),
    case("name-syntax", manifest(name="3d"), f"name: '3d' is not a name {NAME_RULE}"),
    case("name-builtin", Folders(int=manifest(name="int")),
         "components/int/manifest.yaml: name: int is a built-in type"),
    case("description-type", manifest(description=3), "description: expected a string, got int 3"),
    case("entry-point-format", manifest(entry_point="components.behaviors.bad"),
         "entry_point: expected 'package.module:Class', got 'components.behaviors.bad'"),
    case("process", manifest(process="dedicate"),
         "process: unknown process 'dedicate' (did you mean dedicated?)"),
    case("multiplicity", manifest(multiplicity=0), "multiplicity: expected a positive integer, got int 0"),
    case("scheduling", manifest(scheduling={"core": [1], "cores": [-1], "nice": 40}),
         "scheduling.core: unknown key (did you mean cores?)",
         "scheduling.cores: expected a list of core numbers or null, got a list",
         "scheduling.nice: expected an integer from -20 to 19, got int 40"),
    # params
    case("params-not-mapping", manifest(params=["speed"]), "params: expected a mapping, got a list"),
    case("param-not-mapping", manifest(params={"speed": "float"}),
         "params.speed: expected a mapping, got str 'float'"),
    case("param-keyword", manifest(params={"for": {"type": "float", "default": 1.0}}),
         "params.for: 'for' is a reserved word of the mission language; choose another name"),
    case("param-name", manifest(params={"max-speed": {"type": "float", "default": 1.0}}),
         f"params.max-speed: 'max-speed' is not a name {NAME_RULE}"),
    case("param-type-missing", manifest(params={"speed": {"default": 0.4}}),
         "params.speed.type: required key missing"),
    case("param-unknown-key", manifest(params={"speed": {"type": "float", "defualt": 0.4}}),
         "params.speed.defualt: unknown key (did you mean default?)"),
    case("param-type-typo", manifest(params={"speed": {"type": "flaot", "default": 0.4}}),
         "params.speed.type: unknown type 'flaot' (did you mean float?)"),
    case("default-float", manifest(params={"speed": {"type": "float", "default": "fast"}}),
         "params.speed.default: expects float, got str 'fast'"),
    case("default-bool-is-not-int", manifest(params={"n": {"type": "int", "default": True}}),
         "params.n.default: expects int, got bool True"),
    case("default-bool", manifest(params={"enabled": {"type": "bool", "default": 1}}),
         "params.enabled.default: expects bool, got int 1"),
    case("default-duration-text", manifest(params={"d": {"type": "duration", "default": "60 seconds"}}),
         "params.d.default: expects a duration such as 60s or 250ms, got str '60 seconds'"),
    case("default-duration-unitless", manifest(params={"d": {"type": "duration", "default": 60}}),
         "params.d.default: expects a duration such as 60s or 250ms, got int 60"),
    case("default-component", manifest(params={"who": {"type": "Ranger", "default": 3}}),
         "params.who.default: expects a Ranger id, got int 3"),
    case("param-description", manifest(params={"speed": {"type": "float", "default": 1.0, "description": 2}}),
         "params.speed.description: expected a string, got int 2"),
    # needs
    case("need-type-typo", manifest(needs={"drive": need("Drvie")}),
         "needs.drive.type: unknown type 'Drvie' (did you mean Drive?)"),
    case("need-type-scalar", manifest(needs={"x": need("float")}),
         "needs.x.type: float is a value type, expected an rc or an arc"),
    case("need-type-data", manifest(needs={"map": need("OccupancyMap")}),
         "needs.map.type: OccupancyMap is a data type, expected an rc or an arc"),
    case("need-unknown-key", manifest(needs={"drive": {"type": "Drive", "count": 2}}, interfaces=["Drive"]),
         "needs.drive.count: unknown key"),
    case("of-typo", manifest(needs={"drive": need("Drive", "Rangr")}, interfaces=["Drive"]),
         "needs.drive.of: unknown type 'Rangr' (did you mean Ranger?)"),
    case("of-not-arc", manifest(needs={"drive": need("Drive", "Camera")}, interfaces=["Drive"]),
         "needs.drive.of: Camera is an rc, expected an arc"),
    case("of-not-list", manifest(needs={"drive": {"type": "Drive", "of": "Ranger"}}, interfaces=["Drive"]),
         "needs.drive.of: expected a list of names, got str 'Ranger'"),
    case("of-without-part", manifest(needs={"foot": need("Jump", "Ranger")}, interfaces=["Jump"]),
         "needs.foot.of: Ranger has no Jump part"),
    case("of-ambiguous-part",
         Folders(Bad=manifest(needs={"drive": need("Drive", "Twin")}, interfaces=["Drive"]),
                 Twin=manifest("arc", name="Twin", parts={"left": "Drive", "right": "Drive"})),
         "needs.drive.of: Twin has several Drive parts (left, right)"),
    case("quantity-exclusive", manifest(needs={"drive": need("Drive", quantity=1)}, interfaces=["Drive"]),
         "needs.drive.quantity: Drive is not sharable; only a sharable rc has a quantity"),
    case("quantity-zero", manifest(needs={"radio": need("RadioChannel", quantity=0)}, **RADIO),
         "needs.radio.quantity: expected a positive number, got int 0"),
    case("quantity-over-capacity", manifest(needs={"radio": need("RadioChannel", quantity=20)}, **RADIO),
         "needs.radio.quantity: 20 exceeds the capacity of RadioChannel (10)"),
    # outputs, events, interfaces
    case("output-field-type", manifest(outputs={"door": {"fields": {"width": "flaot"}}}),
         "outputs.door.fields.width: unknown type 'flaot' (did you mean float?)"),
    case("output-unknown-key", manifest(outputs={"door": {"field": {}}}),
         "outputs.door.field: unknown key (did you mean fields?)"),
    case("event-conflict", Folders(Bad=manifest(events={"Moved": {"fields": {"area": "float"}}}),
                                   Bad2=manifest(name="Bad2", events={"Moved": {"fields": {"area": "int"}}})),
         f"{B2}: events.Moved: fields differ from Moved in Bad ({F})"),
    case("interface-not-rc", manifest(interfaces=["Ranger"]), "interfaces: Ranger is an arc, expected an rc"),
    case("interface-missing", manifest(needs={"drive": need("Drive", "Ranger")}),
         "interfaces: does not list Drive, used by needs.drive"),
    # rc and arc
    case("rc-one-interface", manifest("rc", interfaces=["Bad", "Drive"]),
         "interfaces: an rc implements exactly one interface, got 2"),
    case("sharable-needs-capacity", manifest("rc", sharable=True),
         "capacity: required when sharable is true"),
    case("capacity-positive", manifest("rc", sharable=True, capacity=0),
         "capacity: expected a positive number, got int 0"),
    case("capacity-needs-sharable", manifest("rc", capacity=4),
         "capacity: only a sharable rc has a capacity"),
    case("sharable-type", manifest("rc", sharable="yes"), "sharable: expected true or false, got str 'yes'"),
    case("property-builtin", manifest("rc", properties={"id": "str"}),
         "properties.id: id is built in: every resource has id and host"),
    case("property-type", manifest("arc", properties={"carrier": "Rangr"}),
         "properties.carrier: unknown type 'Rangr' (did you mean Ranger?)"),
    case("property-is-part", manifest("arc", properties={"drive": "int"}),
         "properties.drive: also the name of a part"),
    case("part-not-rc", manifest("arc", parts={"base": "Ranger", "n": "int"}),
         "parts.base: Ranger is an arc, expected an rc", "parts.n: int is a value type, expected an rc"),
    case("part-type-not-text", manifest("arc", parts={"base": 3}),
         "parts.base: expected a type name, got int 3"),
]


@pytest.mark.parametrize(("files", "expected"), CASES)
def test_bad_manifests(files: dict[str, object], expected: list[str], tmp_path: Path,
                       monkeypatch: pytest.MonkeyPatch) -> None:
    """Each check, with the standard components in scope so that references resolve."""
    for folder, content in files.items():
        (tmp_path / "components" / folder).mkdir(parents=True)
        text = content if isinstance(content, str) else yaml.safe_dump(content, sort_keys=False)
        (tmp_path / "components" / folder / "manifest.yaml").write_text(text, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ManifestError) as info:
        load_catalog([STANDARD, Path("components")])
    assert [str(p) for p in info.value.problems] == expected


def test_a_standard_manifest_broken_by_a_users_type_names_the_users_file(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """A user's folder that replaces the data type Door with a behavior breaks the standard manifests that use
    Door: their errors say where that Door comes from, or nothing in them points at the user's file."""
    write(tmp_path / "mine", manifest("behavior", name="Door"))
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ManifestError) as info:
        load_catalog([STANDARD, Path("mine")])
    broken = [str(p) for p in info.value.problems if "Door is a behavior" in str(p)]
    assert broken and all("(defined in mine/Door/manifest.yaml), expected a data type" in p for p in broken), broken
    assert any("AlignRanger" in p for p in broken)


# ---------------------------------------------------------------- loading


def write(folder: Path, data: dict[str, object]) -> None:
    (folder / str(data["name"])).mkdir(parents=True)
    (folder / str(data["name"]) / "manifest.yaml").write_text(yaml.safe_dump(data), encoding="utf-8")


def test_drd_components_folders_override_in_order(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    first, second = tmp_path / "first", tmp_path / "second"
    write(first, manifest("rc", name="Drive", interfaces=["Drive"], properties={"wheels": "int"}))
    write(second, manifest("rc", name="Drive", interfaces=["Drive"], properties={"tracks": "int"}))
    write(second, manifest("data", name="Notebook"))
    monkeypatch.setenv("DRD_COMPONENTS", os.pathsep.join([str(first), "", str(second)]))
    monkeypatch.chdir(tmp_path)
    assert default_dirs() == [STANDARD, first, second]
    catalog = load_catalog()
    assert catalog.components["Drive"].properties == {"tracks": "int"}
    assert catalog.components["Drive"].source == "second/Drive/manifest.yaml"
    assert catalog.components["Notebook"].kind is Kind.DATA
    assert catalog.components["FollowCorridor"].needs[0].type == "Drive"


def test_a_missing_component_folder_is_a_problem(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ManifestError, match="^nowhere: no such component directory$"):
        load_catalog([STANDARD, Path("nowhere")])


def test_yaml_syntax_error_names_file_and_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "Broken").mkdir()
    (tmp_path / "Broken" / "manifest.yaml").write_text("name: Broken\nkind: data\ndescription: a: b\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ManifestError) as info:
        load_catalog([tmp_path])
    message = "invalid YAML: mapping values are not allowed here"
    assert info.value.problems == (ManifestProblem("Broken/manifest.yaml", "", message, line=3),)
    assert str(info.value) == "Broken/manifest.yaml:3: invalid YAML: mapping values are not allowed here"
