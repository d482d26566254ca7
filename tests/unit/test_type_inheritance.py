"""Type inheritance (`abstract`, `extends` in manifests): checked between manifests, flattened into the catalog, and
a trader query for a supertype matching its subtypes (drd.manifests, dsl.catalog, drd.trader; pure)."""

from __future__ import annotations

from typing import Any

import pytest

from drd.manifests import check_references, parse_manifest
from drd.trader import Offer, TraderError, compile_query, query
from dsl.catalog import Catalog, ComponentType, Kind, Limit, inherit

ROBOT = {"name": "Robot", "kind": "arc", "description": "Any robot.", "abstract": True,
         "properties": {"battery": "float"}, "limits": {"battery": {"min": 0, "max": 1}}}
CAM = {"name": "Cam", "kind": "rc", "description": "A camera.", "entry_point": "x.cam:Cam", "interfaces": ["Cam"],
       "properties": {"resolution": "int"}}


def arc(name: str, extends: Any = None, **more: Any) -> dict[str, Any]:
    data: dict[str, Any] = {"name": name, "kind": "arc", "description": f"A {name}.", "parts": {"camera": "Cam"}}
    if extends is not None:
        data["extends"] = extends
    return data | more


def types(*manifests: dict[str, Any]) -> list[ComponentType]:
    out = []
    for data in manifests:
        t, problems = parse_manifest(data, f"components/{data['name']}/manifest.yaml")
        assert problems == [] and t is not None, problems
        out.append(t)
    return out


def problems_of(*manifests: dict[str, Any]) -> list[tuple[str, str, str]]:
    return [(p.file, p.key, p.message) for p in check_references(types(*manifests))]


def test_a_subtype_gets_the_supertype_properties_and_limits_and_a_query_matches_it() -> None:
    found = types(ROBOT, CAM, arc("Rover", "Robot", properties={"magazine": "int"}),
                  arc("Drone", ["Robot"], properties={"battery": "float"}, limits={"battery": {"min": 0.2, "max": 1}}))
    assert problems_of(ROBOT, CAM, arc("Rover", "Robot"), arc("Drone", ["Robot"])) == []
    catalog = Catalog.of(inherit(found))
    rover, drone = catalog.get("Rover"), catalog.get("Drone")
    assert rover is not None and drone is not None
    assert dict(rover.properties) == {"battery": "float", "magazine": "int"}
    assert rover.limits["battery"] == Limit(0.0, 1.0)
    assert drone.limits["battery"] == Limit(0.2, 1.0)  # its own declaration wins
    assert catalog.subtypes("Robot") == ["Robot", "Rover", "Drone"]
    offers = [Offer("r1", "Rover", {"battery": 0.9, "magazine": 3}), Offer("d1", "Drone", {"battery": 0.4}),
              Offer("c1", "Cam", {"resolution": 640})]
    assert [o.id for o in query("Robot where battery > 0.3 prefer max(battery)", offers, catalog=catalog)] == \
        ["r1", "d1"]
    assert [o.id for o in query("Rover", offers, catalog=catalog)] == ["r1"]  # a subtype's query: itself only


def test_inheritance_is_transitive() -> None:
    machine = {"name": "Machine", "kind": "arc", "description": "Any machine.", "abstract": True,
               "properties": {"serial": "str"}}
    robot = ROBOT | {"extends": "Machine"}
    assert problems_of(machine, robot, CAM, arc("Rover", "Robot")) == []
    catalog = Catalog.of(inherit(types(machine, robot, CAM, arc("Rover", "Robot"))))
    assert catalog.supertypes("Rover") == ["Robot", "Machine"]
    assert catalog.subtypes("Machine") == ["Machine", "Robot", "Rover"]
    rover = catalog.get("Rover")
    assert rover is not None and set(rover.properties) == {"serial", "battery"}
    offers = [Offer("r1", "Rover", {"serial": "A7"})]
    assert [o.id for o in query('Machine where serial == "A7"', offers, catalog=catalog)] == ["r1"]


def test_the_queried_type_properties_only() -> None:
    catalog = Catalog.of(inherit(types(ROBOT, CAM, arc("Rover", "Robot", properties={"magazine": "int"}))))
    with pytest.raises(TraderError) as info:
        compile_query("Robot where magazine > 0", catalog)
    assert info.value.message.startswith("unknown property magazine (Robot has battery")
    assert compile_query("Robot where x > 1 and heading < 2", catalog).types == {"Robot", "Rover"}  # every robot's


def test_without_a_catalog_a_query_matches_its_exact_type() -> None:
    q = compile_query("Robot")
    assert not q.matches(Offer("r1", "Rover")) and q.matches(Offer("r0", "Robot"))


@pytest.mark.parametrize(("manifests", "expected"), [
    ((arc("Rover", "Robt"), CAM, ROBOT), ("Rover", "extends", "unknown type 'Robt' (did you mean Robot?)")),
    ((arc("Rover", "Cam"), CAM), ("Rover", "extends", "Cam is an rc, not an arc: a type extends abstract types of "
                                                      "its own kind (abstract: true)")),
    ((arc("Rover", "Scout"), arc("Scout"), CAM), ("Rover", "extends", "Scout is not abstract: a type extends"
                                                                       " abstract types of its own kind (abstract:"
                                                                       " true)")),
    ((arc("Rover", "Robot", properties={"battery": "int"}), ROBOT, CAM),
     ("Rover", "properties.battery", "battery is int in Rover but float in Robot")),
])
def test_bad_supertypes_are_refused_naming_the_manifest_and_key(manifests: tuple[dict[str, Any], ...],
                                                                expected: tuple[str, str, str]) -> None:
    name, key, message = expected
    assert (f"components/{name}/manifest.yaml", key, message) in problems_of(*manifests)


def test_a_cycle_is_refused_in_each_manifest_on_it() -> None:
    a = {"name": "A", "kind": "arc", "description": "A.", "abstract": True, "extends": ["B"]}
    b = {"name": "B", "kind": "arc", "description": "B.", "abstract": True, "extends": "A"}
    found = problems_of(a, b)
    assert ("components/A/manifest.yaml", "extends", "a cycle: A -> B -> A") in found
    assert ("components/B/manifest.yaml", "extends", "a cycle: B -> A -> B") in found
    assert Catalog.of(inherit(types(a, b))).supertypes("A") == ["B"]  # the walk ends, loading stops on the problem


def test_an_abstract_type_declares_properties_only_and_is_no_resource() -> None:
    t, problems = parse_manifest(ROBOT | {"parts": {"camera": "Cam"}, "entry_point": "x.y:Z"}, "robot.yaml")
    assert {(p.key, p.message) for p in problems} == {("parts", "does not apply to an abstract manifest"),
                                                      ("entry_point", "does not apply to an abstract manifest")}
    t, problems = parse_manifest(ROBOT, "robot.yaml")
    assert problems == [] and t is not None and t.abstract and not t.is_resource and t.kind is Kind.ARC
    _, problems = parse_manifest({"name": "W", "kind": "behavior", "description": "W.", "entry_point": "x.y:W",
                                  "extends": ["Robot"]}, "w.yaml")
    assert [(p.key, p.message) for p in problems] == [("extends", "does not apply to a behavior manifest")]
    catalog = Catalog.of(types(ROBOT, CAM))
    assert "Robot" not in catalog.names(Kind.ARC) and "Robot" in catalog.names()


def test_a_need_or_a_part_of_an_abstract_type_is_refused() -> None:
    sensor = {"name": "Sense", "kind": "rc", "description": "Any sensor.", "abstract": True}
    watcher = {"name": "Watcher", "kind": "behavior", "description": "W.", "entry_point": "x.y:Watcher",
               "needs": {"robot": {"type": "Robot"}}}
    found = problems_of(ROBOT, sensor, CAM, watcher, arc("Rover", "Robot", parts={"eye": "Sense"}))
    assert ("components/Watcher/manifest.yaml", "needs.robot.type", "Robot is abstract: name one of its subtypes") \
        in found
    assert ("components/Rover/manifest.yaml", "parts.eye", "Sense is abstract: name one of its subtypes") in found


def test_hosts_yaml_names_concrete_types(catalog: Catalog) -> None:
    from drd.config import ConfigError
    from drd.hosts import parse_hosts

    data = {"cluster": {"name": "lab", "security": {"mode": "none"}, "lease": "1000ms"},
            "hosts": {"controller": {"endpoint": "tcp/127.0.0.1:7447", "roles": ["controller"]},
                      "r1": {"endpoint": "tcp/127.0.0.1:7448", "roles": ["worker"],
                             "devices": {"s": {"type": "Sensor", "driver": "sim"}},
                             "robots": {"bot": {"type": "Robot", "parts": {}}}}}}
    with pytest.raises(ConfigError) as info:
        parse_hosts(data, "hosts.yaml", catalog)
    text = str(info.value)
    assert "hosts.r1.devices.s.type: Sensor is abstract: name one of its types (Camera, RangeSensor)" in text
    assert "hosts.r1.robots.bot.type: Robot is abstract: name one of its types (Ranger, Scout)" in text


def test_a_device_is_queried_by_its_driver_in_the_trader_and_in_a_mission(catalog: Catalog) -> None:
    """`missionctl query` lists `driver=sim` among a device's properties; it is queryable (docs audit 8: refused as
    an unknown property), for a device only."""
    from dsl import compile_text

    own = Catalog.of(inherit(types(ROBOT, CAM, arc("Rover", "Robot"))))
    offers = [Offer("r1.camera", "Cam", {"driver": "sim"}), Offer("r2.camera", "Cam", {"driver": "ros2"})]
    assert [o.id for o in query('Cam where driver != "sim"', offers, catalog=own)] == ["r2.camera"]
    with pytest.raises(TraderError, match="unknown property driver"):
        compile_query('Rover where driver == "sim"', own)
    text = 'mission M {\n    needs c: Camera where c.driver == "ros2"\n    Wait(duration: 1s)\n}\n'
    assert compile_text(text, catalog, "m.mission").ok
