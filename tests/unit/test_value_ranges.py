"""Every value checked where it is written (issue #18): a behavior parameter's range and unit live beside it in its
manifest, a constant argument outside is a located compile error, an evaluated one fails the state as it is
entered; every number of hosts.yaml has a declared range, refused at load with the file, the line and the key."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from drd.hosts import RANGES, HostsError, load_hosts
from drd.manifests import ManifestError, load_catalog, parse_manifest
from drd.runtime import records as rec
from dsl import compile_text
from dsl.catalog import Catalog, Kind, Limit
from dsl.params import apply_params, parse_assignments
from dsl.statechart import Statechart
from tests.conftest import ROOT
from tests.runtime_support import Harness, Timed, ranger_world

NUMERIC = ("int", "float", "duration")

# ---------------------------------------------------------------- the standard manifests


def test_every_numeric_parameter_of_every_standard_behavior_declares_a_range(catalog: Catalog) -> None:
    """A parameter a mission may set is bounded at both ends, with its default inside (durations carry their unit;
    a dimensionless one, a fraction, may have none)."""
    numeric = [(t.name, p) for t in catalog.components.values() for p in t.params if p.type in NUMERIC]
    assert len(numeric) >= 16  # the enumeration saw the catalog
    assert [f"{name}.{p.name}" for name, p in numeric if p.limit is None or not p.limit.bounded] == []
    assert [f"{name}.{p.name}" for name, p in numeric
            if p.limit is not None and isinstance(p.default, int | float) and p.limit.refuses(p.default)] == []
    assert [f"{name}.{p.name}" for name, p in numeric if p.limit is not None and p.limit.duration != (
        p.type == "duration")] == []


def test_every_numeric_property_of_every_standard_resource_declares_a_range(catalog: Catalog) -> None:
    """What hosts.yaml may set on a device (`options`) or a robot (`properties`) is bounded too."""
    numeric = [(t.name, name) for t in catalog.components.values() if t.kind in (Kind.RC, Kind.ARC)
               for name, type_ in t.properties.items() if type_ in NUMERIC]
    assert ("RangeSensor", "beams") in numeric and ("Ranger", "battery") in numeric
    assert [f"{t}.{n}" for t, n in numeric if not (limit := catalog.components[t].limits.get(n)) or
            not limit.bounded] == []


def test_the_agreed_ranges(catalog: Catalog) -> None:
    speed = catalog.components["FollowCorridor"].param("speed")
    wait = catalog.components["Wait"].param("duration")
    assert speed is not None and speed.limit == Limit(0.0, 2.0, "m/s")
    assert wait is not None and wait.limit == Limit(0.0, 86_400.0, duration=True) and wait.limit.text == "0s..24h"


# ---------------------------------------------------------------- a mission's constant arguments


def diagnostics(text: str, catalog: Catalog) -> list[str]:
    result = compile_text(text, catalog, "speed.mission")
    return [d.render(result.sources) for d in result.diagnostics]


def test_a_constant_argument_outside_its_range_is_a_located_error_naming_range_unit_and_manifest(
        catalog: Catalog) -> None:
    text = "mission M {\n    needs ranger: Ranger\n    FollowCorridor(speed: 50)\n}\n"
    [error] = diagnostics(text, catalog)
    lines = error.splitlines()
    assert lines[0] == ("speed.mission:3:27: error: speed 50 is out of range: 0..2 m/s (FollowCorridor's manifest, "
                        "components/FollowCorridor/manifest.yaml)")
    assert lines[1].endswith("FollowCorridor(speed: 50)") and lines[2].endswith("^^")
    assert lines[2].index("^") == lines[1].index("50")
    assert "hint: give speed a value within 0..2 m/s, or leave it out for the default 0.4 m/s" in error


@pytest.mark.parametrize(("argument", "message"), [
    ("Wait(duration: 25h)", "duration 25h is out of range: 0s..24h (Wait's manifest"),
    ("Calibrate(samples: 0)", "samples 0 is out of range: 1..1000 scans (Calibrate's manifest"),
    ("AvoidObstacles(margin: -0.5)", "margin -0.5 is out of range: 0..5 m (AvoidObstacles' manifest"),
    ("DetectDoor(min_width: 12)", "min_width 12 is out of range: 0.1..5 m (DetectDoor's manifest"),
    ("Watch(threshold: 1.5)", "threshold 1.5 is out of range: 0..1 (Watch's manifest"),
])
def test_each_standard_range_is_checked_where_written(argument: str, message: str, catalog: Catalog) -> None:
    [error] = diagnostics(f"mission M {{\n    needs ranger: Ranger\n    {argument}\n}}\n", catalog)
    assert message in error and error.startswith("speed.mission:3:")


def test_arguments_inside_their_range_and_at_its_ends_compile(catalog: Catalog) -> None:
    text = ("mission M {\n    needs ranger: Ranger\n    parallel all {\n        FollowCorridor(speed: 2)\n"
            "        AvoidObstacles(margin: 0)\n        Wait(duration: 24h)\n    }\n}\n")
    assert diagnostics(text, catalog) == []


def test_a_negative_duration_is_reported_once(catalog: Catalog) -> None:
    """`Wait(duration: -1s)` was an error before ranges; the range does not repeat it."""
    errors = diagnostics("mission M {\n    Wait(duration: -1s)\n}\n", catalog)
    assert len(errors) == 1 and "a duration cannot be negative" in errors[0]


# ---------------------------------------------------------------- evaluated arguments, at run time

EVALUATED = """mission M {
    var s: float = 0.1
    Go(v: s * 10)
}
behavior Go(v: float) {
    needs ranger: Ranger
    FollowCorridor(speed: v)
}
"""


def compiled(text: str, catalog: Catalog) -> Statechart:
    result = compile_text(text, catalog, "evaluated.mission")
    assert result.ok and result.statechart is not None, [d.render(result.sources) for d in result.diagnostics]
    return result.statechart


def run(chart: Statechart) -> Harness:
    h = Harness(chart, {"FollowCorridor": Timed}, ranger_world())
    h.run(until=20.0)
    return h


def test_an_evaluated_argument_outside_its_range_fails_the_state_naming_parameter_and_range(catalog: Catalog) -> None:
    """`--param s=5` makes `speed: v` 50 when Go enters FollowCorridor: the state is refused, with the reason."""
    chart = compiled(EVALUATED, catalog)
    assert run(chart).interp.outcome == "success"  # s * 10 = 1 m/s
    h = run(apply_params(chart, parse_assignments(["s=5"])))
    assert h.interp.outcome == "failure"
    why = "FollowCorridor: speed 50 is out of range: 0..2 m/s (FollowCorridor's manifest)"
    assert any(isinstance(r, rec.Log) and r.text == f"cannot enter: {why}" for r in h.records)
    assert not any(isinstance(r, rec.Entered) and r.path.endswith("/FollowCorridor") for r in h.records)


def test_a_constant_argument_is_not_checked_again_at_run_time(catalog: Catalog) -> None:
    chart = compiled(EVALUATED, catalog)
    leaf = next(s for s in chart.states.values() if s.component == "FollowCorridor")
    assert [name for name, _ in leaf.ranges] == ["speed"]
    plain = compiled("mission M {\n    needs ranger: Ranger\n    FollowCorridor(speed: 1)\n}\n", catalog)
    assert all(not s.ranges for s in plain.states.values())


# ---------------------------------------------------------------- manifests that declare ranges

BEHAVIOR: dict[str, Any] = {"name": "Roll", "kind": "behavior", "description": "Rolls.",
                            "entry_point": "x.y:Roll"}


def problems(params: dict[str, Any]) -> list[str]:
    _t, found = parse_manifest(BEHAVIOR | {"params": params}, "roll.yaml")
    return [str(p) for p in found]


def test_a_range_is_declared_beside_the_parameter() -> None:
    t, found = parse_manifest(BEHAVIOR | {"params": {
        "speed": {"type": "float", "default": 0.4, "min": 0, "max": 2, "unit": "m/s"},
        "pause": {"type": "duration", "default": "1s", "min": "100ms", "max": "1h"},
        "open": {"type": "int", "default": 1, "min": 0}}}, "roll.yaml")
    assert found == [] and t is not None
    assert [p.limit for p in t.params] == [Limit(0.0, 2.0, "m/s"), Limit(0.1, 3600.0, duration=True),
                                           Limit(0.0, None)]


@pytest.mark.parametrize(("params", "expected"), [
    ({"speed": {"type": "float", "default": 5.0, "min": 0, "max": 2, "unit": "m/s"}},
     "roll.yaml: params.speed.default: 5 is out of range: 0..2 m/s: a default must lie in its own range"),
    ({"pause": {"type": "duration", "default": "2h", "max": "1h"}},
     "roll.yaml: params.pause.default: 2h is out of range: ..1h: a default must lie in its own range"),
    ({"speed": {"type": "float", "default": 1.0, "min": 2, "max": 0}}, "roll.yaml: params.speed: min 2 is above max 0"),
    ({"label": {"type": "str", "default": "a", "max": 3}},
     "roll.yaml: params.label.max: a range applies to a numeric parameter (int, float or duration), not str"),
    ({"speed": {"type": "float", "default": 1.0, "max": float("inf")}},
     "roll.yaml: params.speed.max: expected a finite number, got float inf"),
    ({"speed": {"type": "float", "default": 1.0, "max": "fast"}},
     "roll.yaml: params.speed.max: expected a finite number, got str 'fast'"),
    ({"pause": {"type": "duration", "default": "1s", "max": 60}},
     "roll.yaml: params.pause.max: expected a duration such as 0s or 24h, got int 60"),
    ({"pause": {"type": "duration", "default": "1s", "max": "1h", "unit": "s"}},
     "roll.yaml: params.pause.unit: a duration's unit is written in its bounds (min: 0s, max: 24h)"),
    ({"speed": {"type": "float", "default": float("nan")}},
     "roll.yaml: params.speed.default: expects a finite float, got float nan"),
    ({"speed": {"type": "float", "default": 1.0, "maxi": 2}},
     "roll.yaml: params.speed.maxi: unknown key (did you mean max?)"),
])
def test_a_bad_range_is_a_manifest_problem(params: dict[str, Any], expected: str) -> None:
    assert problems(params) == [expected]


def test_a_default_outside_its_range_stops_the_catalog_loading(tmp_path: Path) -> None:
    folder = tmp_path / "Roll"
    folder.mkdir()
    (folder / "manifest.yaml").write_text(
        "name: Roll\nkind: behavior\ndescription: Rolls.\nentry_point: x.y:Roll\n"
        "params:\n  speed: {type: float, default: 50, min: 0, max: 2, unit: m/s}\n", encoding="utf-8")
    with pytest.raises(ManifestError, match=r"params\.speed\.default: 50 is out of range: 0\.\.2 m/s"):
        load_catalog([tmp_path])


# ---------------------------------------------------------------- Limit itself


def test_a_limit_refuses_nan_and_infinities_and_shows_its_range() -> None:
    speed = Limit(0, 2, "m/s")
    assert (speed.refuses(2), speed.refuses(0), speed.refuses(2.5)) == ("", "", "2.5 is out of range: 0..2 m/s")
    assert speed.refuses(math.nan) == "nan is not a finite number (expected 0..2 m/s)"
    assert speed.refuses(-math.inf) == "-inf is not a finite number (expected 0..2 m/s)"
    assert Limit().refuses(math.inf) == "inf is not a finite number" and Limit().refuses(1e300) == ""
    assert Limit(1, 10).refuses(10**400) == "an integer of 401 digits is out of range: 1..10"
    assert Limit(0.25, 5400, duration=True).text == "250ms..90min"


# ---------------------------------------------------------------- hosts.yaml


def bad_hosts(tmp_path: Path, *changes: tuple[str, str]) -> Path:
    text = (ROOT / "hosts.yaml").read_text(encoding="utf-8")
    for old, new in changes:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp_path / "hosts.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def line_of(path: Path, text: str) -> int:
    return next(i for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if text in line)


def test_hosts_values_outside_their_ranges_are_refused_with_file_line_and_key(tmp_path: Path,
                                                                              catalog: Catalog) -> None:
    path = bad_hosts(tmp_path, ("lease: 3s", "lease: 0s"), ("capacity: 10", "capacity: 0"),
                     ("battery: 1.0, magazine: 6", "battery: 3, magazine: 6"), ("slice: 60s", "slice: -1s"),
                     ("cores: 2", "cores: .nan"))
    with pytest.raises(HostsError) as refused:
        load_hosts(path, catalog)
    got = {p.key: (p.file, p.line, p.message) for p in refused.value.problems}
    file = path.as_posix()
    assert got["cluster.lease"] == (file, line_of(path, "lease: 0s"), "0s is out of range: 100ms..10min")
    assert got["hosts.controller.cores"] == (file, line_of(path, "cores: .nan"),
                                             "expected an integer (1..4096 cores), got float nan")
    assert got["hosts.ranger1.devices.radio.capacity"] == (file, line_of(path, "capacity: 0"),
                                                           "0 is out of range: 1..1000000")
    assert got["hosts.ranger1.devices.drive.slice"][:2] == (file, line_of(path, "slice: -1s"))
    assert "(200ms..24h), got str '-1s'" in got["hosts.ranger1.devices.drive.slice"][2]
    assert got["hosts.ranger1.robots.ranger1.properties.battery"] == (
        file, line_of(path, "battery: 3,"),
        "3 is out of range: 0..1 (Ranger's manifest, components/Ranger/manifest.yaml)")
    assert len(got) == 5
    assert str(refused.value).splitlines()[0] == f"{file}:{line_of(path, 'lease: 0s')}: cluster.lease: 0s is out of" \
                                                 " range: 100ms..10min"


def test_a_missing_key_points_at_its_parents_line(tmp_path: Path, catalog: Catalog) -> None:
    path = bad_hosts(tmp_path, ("drive: {type: Drive, driver: sim, slice: 60s", "drive: {type: Drive, slice: 60s"))
    with pytest.raises(HostsError) as refused:
        load_hosts(path, catalog)
    [problem] = refused.value.problems
    assert (problem.key, problem.line) == ("hosts.ranger1.devices.drive.driver", line_of(path, "drive: {type: Drive"))


def test_every_number_hosts_yaml_defines_has_a_declared_range() -> None:
    assert set(RANGES) == {"lease", "slice", "capacity", "cores", "history", "placement", "instances", "compile",
                           "domain_id"}
    assert all(limit.bounded for limit in RANGES.values())
    assert (ROOT / "docs" / "hosts.md").read_text(encoding="utf-8").count("100ms..10min") >= 1


def test_a_huge_value_is_echoed_cut_with_its_length_separated(tmp_path: Path, catalog: Catalog) -> None:
    path = bad_hosts(tmp_path, ("slice: 60s", "slice: " + "x" * 100_000))
    with pytest.raises(HostsError) as refused:
        load_hosts(path, catalog)
    [problem] = [str(p) for p in refused.value.problems]
    assert "… (100,000 characters)" in problem and len(problem) < 300  # the value's own length
