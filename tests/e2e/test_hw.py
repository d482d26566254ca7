"""Hardware abstraction: hosts.yaml picks each device's driver, imported lazily; the sim drivers work
through their interfaces, honour their device options, and refuse stale epochs."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from drd.hosts import Cluster, Device, load_hosts
from drd.hw import (
    INTERFACES,
    DriverError,
    HardwareError,
    HostDrivers,
    StaleCommand,
    driver_entry_point,
    drivers_for,
    load_driver,
)
from drd.hw.interfaces import Camera, Drive, Launcher, RadioChannel, RangeSensor
from drd.sim import Simulation, load_world
from drd.sim.sensors import walls_between
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parents[2]
CORRIDOR = load_world(ROOT / "worlds" / "corridor.yaml")


@pytest.fixture(scope="module", autouse=True)
def _forget_drivers() -> Iterator[None]:
    """Drivers imported here are dropped afterwards: other tests check what catalog loading imports."""
    before = set(sys.modules)
    yield
    for name in set(sys.modules) - before:
        if name.startswith("components.sim"):
            del sys.modules[name]


@pytest.fixture(scope="module")
def cluster(catalog: Catalog) -> Cluster:
    return load_hosts(ROOT / "hosts.yaml", catalog)


def build(cluster: Cluster, catalog: Catalog, world: object = CORRIDOR) -> tuple[Simulation, HostDrivers]:
    sim = Simulation(world, seed=1)  # type: ignore[arg-type]
    return sim, drivers_for(cluster, "ranger1", sim, catalog=catalog)


def test_every_device_of_ranger1_gets_a_driver_of_its_interface(cluster: Cluster, catalog: Catalog) -> None:
    _, hd = build(cluster, catalog)
    host = cluster.host("ranger1")
    assert set(hd.devices) == {d.id for d in host.devices}
    for d in host.devices:
        assert isinstance(hd.devices[d.id], INTERFACES[d.type]), d.id
    ranger = hd.robots["ranger1"]
    assert set(ranger) == {"drive", "ranges", "camera", "launcher"}
    assert ranger["drive"] is hd.devices["ranger1.drive"]
    assert hd.robots["scout3"]["radio"] is not hd.robots["scout4"]["radio"]  # a shared channel: one end each


def test_entry_points_follow_the_manifests_and_the_naming_rule(catalog: Catalog) -> None:
    assert driver_entry_point(Device("h.r", "h", "RangeSensor", "sim"), catalog) \
        == "components.sim.range_sensor:SimRangeSensor"
    assert driver_entry_point(Device("h.d", "h", "Drive", "serial")) == "components.serial.drive:SerialDrive"
    assert driver_entry_point(Device("h.c", "h", "RadioChannel", "my_radio")) \
        == "components.my_radio.radio_channel:MyRadioRadioChannel"


def test_a_users_own_device_type_simulates_with_the_class_its_manifest_names(catalog: Catalog) -> None:
    """New-user audit 8, D3: `driver: sim` took only entry points under drd's components.sim, so a user's own device
    type (a Tug, `entry_point: mykit.tug:SimTug`) could not be simulated without editing drd's tree."""
    from dataclasses import replace

    drive = catalog.get("Drive")
    assert drive is not None
    tug = replace(drive, name="Tug", entry_point="mykit.tug:SimTug")
    own = replace(catalog, components={**catalog.components, "Tug": tug})
    assert driver_entry_point(Device("h.tug", "h", "Tug", "sim"), own) == "mykit.tug:SimTug"


def test_drive_moves_the_ranger_clamped_to_max_speed(cluster: Cluster, catalog: Catalog) -> None:
    sim, hd = build(cluster, catalog)
    drive = hd.robots["ranger1"]["drive"]
    assert isinstance(drive, Drive) and drive.max_speed == 0.8
    x0, _, _ = drive.odometry()
    drive.set_velocity(5.0, 0.0)
    assert sim.command("ranger1")[0] == pytest.approx(0.8)
    sim.run_until(2.0)
    x1, y1, heading = drive.odometry()
    assert x1 - x0 == pytest.approx(1.6, abs=0.1) and abs(y1) < 0.05 and abs(heading) < 0.05
    drive.stop()
    assert sim.command("ranger1") == (0.0, 0.0)
    assert hd.robots["scout1"]["wheels"].max_speed == 0.3  # type: ignore[attr-defined]


def test_scan_sees_the_corridor_walls(cluster: Cluster, catalog: Catalog) -> None:
    _, hd = build(cluster, catalog)
    ranges = hd.robots["ranger1"]["ranges"]
    assert isinstance(ranges, RangeSensor)
    scan = ranges.scan()
    assert len(scan.ranges) == 181 and scan.max_range == 8.0
    assert scan.angle_min == pytest.approx(-math.pi / 2) and scan.angle(180) == pytest.approx(math.pi / 2)
    assert scan.ranges[0] == pytest.approx(1.25, abs=0.1)  # right: the south wall
    assert scan.ranges[180] == pytest.approx(1.25, abs=0.1)  # left: the north wall
    assert scan.ranges[90] == 8.0  # ahead: the corridor, longer than the laser


def test_camera_sees_nothing_through_walls(cluster: Cluster, catalog: Catalog) -> None:
    spawn = dataclasses.replace(CORRIDOR.rangers[0], x=16.0, y=0.0, heading=math.pi / 2)
    sim, hd = build(cluster, catalog, dataclasses.replace(CORRIDOR, rangers=(spawn,)))
    camera = hd.robots["ranger1"]["camera"]
    assert isinstance(camera, Camera) and camera.fov == pytest.approx(math.radians(60.0))
    person = sim.intruders()["intruder1"]  # in a north room, straight ahead, behind the corridor wall
    assert walls_between(sim.space, (16.0, 0.0), person) > 0
    assert camera.detections() == []
    assert len(camera.brightness(8)) == 8
    with pytest.raises(ValueError, match="n_regions"):
        camera.brightness(641)  # more regions than pixels


def test_camera_sees_a_person_in_the_corridor(cluster: Cluster, catalog: Catalog) -> None:
    spawn = dataclasses.replace(CORRIDOR.rangers[0], x=14.0, y=0.0, heading=0.0)
    sim, hd = build(cluster, catalog, dataclasses.replace(CORRIDOR, rangers=(spawn,)))
    sim.run_until(12.0)  # intruder1 walks down the corridor
    seen = hd.robots["ranger1"]["camera"].detections()  # type: ignore[attr-defined]
    assert [d.label for d in seen] == ["intruder1"] and 0 < seen[0].distance < 10


def test_launcher_respects_max_range_and_empties_the_magazine(cluster: Cluster, catalog: Catalog) -> None:
    sim, hd = build(cluster, catalog)
    launcher = hd.robots["ranger1"]["launcher"]
    assert isinstance(launcher, Launcher) and launcher.max_range == 6.0  # hosts.yaml, below the sim's 30 m
    radio = hd.robots["scout1"]["radio"]
    assert isinstance(radio, RadioChannel) and radio.link_ok()  # in the magazine
    landing = launcher.launch("scout1", 0.0, 20.0)
    assert landing.x == pytest.approx(1.0 + 6.0, abs=0.05) and landing.duration > 0
    assert "scout1" not in launcher.loaded() and launcher.loaded()[0] == "scout2"
    sim.run_until(3.0)
    assert math.dist((sim.pose("scout1").x, sim.pose("scout1").y), (1.0, 0.0)) < 6.5
    assert radio.link_ok() and hd.devices["ranger1.radio"].link_ok("scout1")  # type: ignore[attr-defined]
    with pytest.raises(HardwareError, match="not in ranger1's magazine"):
        launcher.launch("scout1", 0.0, 2.0)


def test_stale_epoch_is_refused(cluster: Cluster, catalog: Catalog) -> None:
    sim, hd = build(cluster, catalog)
    drive = hd.robots["ranger1"]["drive"]
    drive.set_velocity(0.5, 0.0, epoch=3)  # type: ignore[attr-defined]
    drive.set_velocity(0.4, 0.0, epoch=3)  # type: ignore[attr-defined]
    with pytest.raises(StaleCommand, match="epoch 2 refused"):
        drive.stop(epoch=2)  # type: ignore[attr-defined]
    assert sim.command("ranger1")[0] == pytest.approx(0.4)
    drive.stop(epoch=4)  # type: ignore[attr-defined]
    launcher = hd.robots["ranger1"]["launcher"]
    launcher.launch("scout1", 0.0, 1.0, epoch=1)  # type: ignore[attr-defined]  # each driver fences on its own
    with pytest.raises(StaleCommand):
        launcher.launch("scout2", 0.0, 1.0, epoch=0)  # type: ignore[attr-defined]
    assert "scout2" in launcher.loaded()  # type: ignore[attr-defined]


def test_drivers_are_imported_lazily() -> None:
    code = """
import sys
from pathlib import Path
from drd.hosts import Device
from drd.hw import load_driver
from drd.sim import Simulation, load_world
sim = Simulation(load_world(Path('worlds/corridor.yaml')), seed=1)
assert not [m for m in sys.modules if m.startswith('components.sim.')], sorted(sys.modules)
load_driver(Device('ranger1.drive', 'ranger1', 'Drive', 'sim', {'max_speed': 0.8}), 'ranger1', {'sim': sim})
loaded = sorted(m for m in sys.modules if m.startswith('components.sim.'))
assert loaded == ['components.sim.drive'], loaded
"""
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
                       check=False)
    assert r.returncode == 0, r.stdout + r.stderr


def test_an_unknown_driver_says_which_device_driver_and_module() -> None:
    device = Device("ranger1.drive", "ranger1", "Drive", "serial", {"port": "/dev/ttyUSB0"})
    with pytest.raises(DriverError) as e:
        load_driver(device, "ranger1", {})
    message = str(e.value)
    assert "ranger1.drive" in message and "'serial'" in message and "components.serial.drive" in message
    assert "components.serial" not in sys.modules


def test_sim_driver_needs_a_simulation(catalog: Catalog) -> None:
    device = Device("ranger1.drive", "ranger1", "Drive", "sim")
    with pytest.raises(DriverError, match=r"ranger1\.drive.*services\['sim'\]"):
        load_driver(device, "ranger1", {"catalog": catalog})
