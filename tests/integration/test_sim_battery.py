"""The simulator's battery model (issue #11's battery floor): charge drains with time switched on and distance
driven, an empty robot stops for good, the Drive reports it, and a mission's battery floor fires as it drains.

Positions and charges are read on the simulated robot (ground truth); the mission's outcome from its report.
"""

from __future__ import annotations

import io
import json
import math
from pathlib import Path
from typing import cast

import pytest
import yaml

from components.sim.drive import SimDrive
from drd.dryrun import Mission, run, run_many
from drd.hosts import load_hosts
from drd.hw.interfaces import HardwareError
from drd.sim import SimError
from drd.sim.model import Battery
from drd.sim.physics import Simulation
from drd.sim.service import RemoteSimulation, SimulationService
from drd.sim.world import WorldError, load_world
from dsl import compile_text
from dsl.catalog import Catalog
from tests.conftest import ROOT


def world_with(tmp_path: Path, battery: object) -> Path:
    data = yaml.safe_load((ROOT / "worlds" / "corridor.yaml").read_text())
    data["battery"] = battery
    path = tmp_path / "drained.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def drive(sim: Simulation, seconds: float, v: float = 0.5) -> None:
    sim.set_velocity("ranger1", v, 0.0)
    sim.run_until(sim.time + seconds)


def test_charge_drains_with_time_and_distance_as_the_world_says(tmp_path: Path) -> None:
    sim = Simulation(load_world(world_with(tmp_path, {"idle": 0.001, "per_meter": 0.02, "start": {"ranger1": 0.8}})))
    assert sim.battery("ranger1") == 0.8 and sim.battery("scout1") == 1.0
    x0 = sim.pose("ranger1").x
    drive(sim, 6.0)
    moved = sim.pose("ranger1").x - x0
    assert moved > 2.0
    expected = 0.8 - 0.001 * 6.0 - 0.02 * moved
    assert math.isclose(sim.battery("ranger1"), expected, abs_tol=0.002), (sim.battery("ranger1"), expected)


def test_an_empty_robot_stops_for_good_and_never_reads_below_zero(tmp_path: Path) -> None:
    sim = Simulation(load_world(world_with(tmp_path, {"per_meter": 0.5})))  # 2 m of charge
    drive(sim, 10.0)
    assert sim.battery("ranger1") == 0.0
    x = sim.pose("ranger1").x
    assert 2.5 < x < 3.3, x  # started at 1.0: 2 m, and no farther
    drive(sim, 3.0)  # commands to an empty robot turn no wheel
    assert sim.pose("ranger1").x == pytest.approx(x, abs=1e-6) and sim.battery("ranger1") == 0.0


def test_standing_still_drains_with_time_only_and_the_magazine_not_at_all(tmp_path: Path) -> None:
    sim = Simulation(load_world(world_with(tmp_path, {"idle": 0.002, "per_meter": 1.0})))
    sim.run_until(50.0)
    assert sim.pose("ranger1").x == 1.0  # it never moved: nothing per metre
    assert sim.battery("ranger1") == pytest.approx(1.0 - 0.002 * 50.0)
    assert sim.battery("scout1") == 1.0  # in the magazine, off the floor: switched off


def test_an_empty_robot_takes_commands_and_does_nothing(tmp_path: Path) -> None:
    sim = Simulation(load_world(world_with(tmp_path, {"start": {"ranger1": 0.0, "scout2": 0.0}})))
    drive(sim, 2.0)
    assert sim.pose("ranger1").x == 1.0 and sim.command("ranger1") == (0.0, 0.0)
    with pytest.raises(SimError, match="ranger1's battery is empty: it cannot launch"):
        sim.launch("scout1", 0.0, 3.0)  # the launcher runs on the Ranger's battery
    assert sim.magazine("ranger1")[0] == "scout1"  # still loaded


def test_an_empty_scout_cannot_hop(tmp_path: Path) -> None:
    data = yaml.safe_load((ROOT / "worlds" / "corridor.yaml").read_text())
    data["scouts"] = [{"id": "walker", "at": [5, 0]}]
    data["battery"] = {"start": {"walker": 0.0}}
    path = tmp_path / "walker.yaml"
    path.write_text(yaml.safe_dump(data))
    sim = Simulation(load_world(path))
    with pytest.raises(SimError, match="walker's battery is empty: it cannot jump"):
        sim.jump("walker", 0.5)
    assert sim.pose("walker").x == 5.0


@pytest.mark.parametrize("name", ["corridor", "two_rangers"])
def test_the_shipped_worlds_never_drain(name: str) -> None:
    world = load_world(ROOT / "worlds" / f"{name}.yaml")
    assert world.battery == Battery()  # no section: no drain, everyone full
    sim = Simulation(world, dt=0.5)  # coarse steps: only the charge is looked at
    drive(sim, 20.0)
    sim.run_until(1800.0)  # a 30-minute mission keeps its charge
    assert {r: sim.battery(r) for r in sim.robots} == dict.fromkeys(sim.robots, 1.0)


def test_a_bad_battery_section_names_the_key(tmp_path: Path) -> None:
    with pytest.raises(WorldError) as e:
        load_world(world_with(tmp_path, {"idle": -1, "start": {"ranger9": 0.5, "scout1": 2}}))
    text = "\n".join(map(str, e.value.problems))
    assert "battery.idle: expected a non-negative number" in text
    assert "battery.start.ranger9: no robot 'ranger9'" in text
    assert "battery.start.scout1: expected a charge from 0 (empty) to 1 (full)" in text


def test_the_drive_reports_the_charge(tmp_path: Path, catalog: Catalog) -> None:
    sim = Simulation(load_world(world_with(tmp_path, {"start": {"ranger1": 0.42}})))
    cluster = load_hosts(ROOT / "hosts.yaml", catalog)
    device = next(d for d in cluster.devices if d.id == "ranger1.drive")
    assert SimDrive(device, "ranger1", sim).battery() == 0.42


def test_the_drive_reads_the_charge_through_the_simulator_service(tmp_path: Path, catalog: Catalog) -> None:
    (tmp_path / "worlds").mkdir()
    world_with(tmp_path, {"per_meter": 0.1}).rename(tmp_path / "worlds" / "drained.yaml")
    service = SimulationService(None, "test", root=tmp_path)  # no bus: requests go straight to `handle`
    service.reset("drained")
    remote = cast(Simulation, RemoteSimulation(service.handle, "drained", root=tmp_path))  # duck-typed
    cluster = load_hosts(ROOT / "hosts.yaml", catalog)
    device = next(d for d in cluster.devices if d.id == "ranger1.drive")
    over_bus = SimDrive(device, "ranger1", remote)
    assert over_bus.battery() == 1.0
    over_bus.set_velocity(0.5, 0.0)
    proxy = cast(RemoteSimulation, remote)
    proxy.flush()  # as the Creator does before the controller steps the physics
    service.sim.run_until(4.0)
    proxy.sync(service.sim.time, service.sim.version)
    assert over_bus.battery() == service.sim.battery("ranger1") < 0.9
    with pytest.raises(HardwareError, match="no robot 'ranger9'"):
        SimDrive(device, "ranger9", remote).battery()  # refused by the simulator, reported as by any driver
    with pytest.raises(ValueError, match="battery takes 1..1 arguments"):
        service._call(service.sim, "battery", [])  # the allow-list still checks what a remote driver sends


def test_a_battery_floor_fires_as_the_battery_drains(tmp_path: Path, catalog: Catalog) -> None:
    text = """
mission Charged {
    needs ranger: Ranger
    constraint charged: ranger.battery >= 0.9
    FollowCorridor(speed: 0.5)
}
"""
    r = compile_text(text, catalog, "c.mission")
    assert r.ok and r.statechart is not None
    trace = io.StringIO()
    world = load_world(world_with(tmp_path, {"per_meter": 0.05}))  # 0.1 of charge = 2 m
    (report,) = run_many([Mission(r.statechart)], load_hosts(ROOT / "hosts.yaml", catalog), world, catalog,
                         until=40.0, trace=trace)
    assert report.outcome == "failure" and "constraint charged violated" in report.reason
    records = [json.loads(line) for line in trace.getvalue().splitlines()]
    [violation] = [x for x in records if x["kind"] == "event" and x["name"] == "violation"][:1]
    assert violation["fields"]["name"] == "charged" and violation["fields"]["value"] < 0.9
    x = report.tracks["ranger1"][-1][1]
    assert 2.5 < x < 3.5, x  # stopped about 2 m from its start (1.0), with charge still left


def test_a_drained_robot_with_no_floor_just_stops_where_it_ran_out(tmp_path: Path, catalog: Catalog) -> None:
    text = "mission Drained {\n    needs ranger: Ranger\n    FollowCorridor(speed: 0.5)\n}\n"
    r = compile_text(text, catalog, "d.mission")
    assert r.ok and r.statechart is not None
    world = load_world(world_with(tmp_path, {"per_meter": 0.25}))  # 4 m of charge
    report = run(r.statechart, load_hosts(ROOT / "hosts.yaml", catalog), world, catalog, until=30.0)
    x = report.tracks["ranger1"][-1][1]
    assert 4.5 < x < 5.5, x  # 4 m from its start (1.0), and no farther: nothing failed, the wheels just stopped


def hosts_with_scout3_at(tmp_path: Path, charge: float) -> Path:
    text = (ROOT / "hosts.yaml").read_text()
    scout3 = ("parts: {wheels: scout3.wheels, foot: scout3.foot, camera: scout3.camera, radio: radio}\n"
              "        properties: {battery: 1.0}")
    assert scout3 in text
    path = tmp_path / "hosts.yaml"
    path.write_text(text.replace(scout3, scout3.replace("1.0", str(charge))))
    return path


def test_hosts_yaml_battery_is_the_start_charge_where_the_world_gives_none(tmp_path: Path, catalog: Catalog) -> None:
    """Semantics audit 7: every simulated robot started full whatever hosts.yaml said, so `where s.battery < 0.7`
    found no Scout (and `> 0.7` took the one hosts.yaml said was half empty)."""
    text = "mission Low {\n    needs s: Scout where s.battery < 0.7\n    Wait(duration: 1s)\n}\n"
    r = compile_text(text, catalog, "low.mission")
    assert r.ok and r.statechart is not None
    hosts = load_hosts(hosts_with_scout3_at(tmp_path, 0.4), catalog)
    report = run(r.statechart, hosts, load_world(ROOT / "worlds" / "corridor.yaml"), catalog, until=10.0)
    assert report.outcome == "success", report.reason
    assert [h for h in report.holds() if h["path"] == "Low"][0]["resources"]["s"] == "scout3"
    (tmp_path / "worlds").mkdir()
    world_with(tmp_path, {"start": {"ranger1": 0.3}}).rename(tmp_path / "worlds" / "half.yaml")
    service = SimulationService(None, "c", root=tmp_path, charges={"scout3": 0.4, "ranger1": 0.9})
    service.reset("half")
    assert (service.sim.battery("scout3"), service.sim.battery("ranger1"), service.sim.battery("scout1")) == (
        0.4, 0.3, 1.0)  # the world's own start charge wins; a robot neither names starts full
