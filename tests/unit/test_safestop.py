"""Which robots and cmd_vel topics a host's loss maps to (`drd.hw.safestop.ros2_drives`): the zero Twists the
controller and a restarted daemon send go exactly where that host's `ros2` Drives publish."""

from __future__ import annotations

import yaml

from drd.hosts import Cluster, parse_hosts
from drd.hw.safestop import DriveStop, has_drives, ros2_drives
from dsl.catalog import Catalog

HOSTS = """
cluster: {name: safe, security: {mode: none}, lease: 1000ms}
hosts:
  controller: {endpoint: tcp/127.0.0.1:7001, roles: [controller]}
  ranger1:
    endpoint: tcp/127.0.0.1:7002
    roles: [worker]
    drivers:
      ros2: {endpoint: tcp/10.0.0.5:7447, domain_id: 3}
    devices:
      drive: {type: Drive, driver: ros2, options: {max_speed: 0.8}}
      ranges: {type: RangeSensor, driver: ros2, options: {beams: 181, max_range: 8.0}}
      camera: {type: Camera, driver: ros2, options: {resolution: 640, fov: 60.0}}
      launcher: {type: Launcher, driver: ros2, options: {max_range: 6.0}}
      scout1.wheels:
        type: Drive
        driver: ros2
        options: {max_speed: 0.3}
        driver_options: {namespace: fleet/s1, topics: {cmd_vel: /s1/base/cmd_vel}, endpoint: tcp/10.0.0.6:7447}
      scout1.foot: {type: Jump, driver: ros2, options: {max_height: 0.3}}
      spare: {type: Drive, driver: ros2, options: {max_speed: 0.5}}
    robots:
      ranger1:
        type: Ranger
        parts: {drive: drive, ranges: ranges, camera: camera, launcher: launcher}
        properties: {battery: 1.0, magazine: 0}
  ranger2:
    endpoint: tcp/127.0.0.1:7003
    roles: [worker]
    devices:
      drive: {type: Drive, driver: sim, options: {max_speed: 0.8}}
      ranges: {type: RangeSensor, driver: sim, options: {beams: 181, max_range: 8.0}}
      camera: {type: Camera, driver: sim, options: {resolution: 640, fov: 60.0}}
      launcher: {type: Launcher, driver: sim, options: {max_range: 6.0}}
    robots:
      ranger2:
        type: Ranger
        parts: {drive: drive, ranges: ranges, camera: camera, launcher: launcher}
        properties: {battery: 1.0, magazine: 0}
"""


def cluster(catalog: Catalog) -> Cluster:
    return parse_hosts(yaml.safe_load(HOSTS), "hosts.yaml", catalog)


def test_a_host_loss_maps_to_each_ros2_drive_with_its_robot_router_namespace_and_topic(catalog: Catalog) -> None:
    stops, problems = ros2_drives(cluster(catalog), "ranger1")
    assert problems == []
    assert stops == [
        # the robot's namespace by default, the host's `drivers: ros2` endpoint and domain
        DriveStop("ranger1", "ranger1", "ranger1.drive", "tcp/10.0.0.5:7447", 3, "ranger1", "cmd_vel"),
        # a device's own options win: its router, its namespace, an absolute topic; no robot names it: the host's
        DriveStop("ranger1", "ranger1", "ranger1.scout1.wheels", "tcp/10.0.0.6:7447", 3, "fleet/s1",
                  "/s1/base/cmd_vel"),
        DriveStop("ranger1", "ranger1", "ranger1.spare", "tcp/10.0.0.5:7447", 3, "ranger1", "cmd_vel"),
    ]
    assert stops[0].describe() == "ranger1.drive (ranger1) /ranger1/cmd_vel at tcp/10.0.0.5:7447"
    assert stops[1].describe() == "ranger1.scout1.wheels (ranger1) /s1/base/cmd_vel at tcp/10.0.0.6:7447"


def test_sim_drives_and_other_ros2_devices_are_not_stopped(catalog: Catalog) -> None:
    """A `sim` Drive is the simulator's (its world stops with its host); a Jump or a sensor has no cmd_vel."""
    c = cluster(catalog)
    assert ros2_drives(c, "ranger2") == ([], [])
    assert ros2_drives(c, "controller") == ([], [])
    assert [has_drives(c, h) for h in ("controller", "ranger1", "ranger2")] == [False, True, False]


def test_a_drive_whose_options_are_refused_is_named_and_the_others_still_stopped(catalog: Catalog) -> None:
    """`drd start` refuses such a file (`check_driver_classes`); a controller reading it still stops what it can."""
    data = yaml.safe_load(HOSTS)
    data["hosts"]["ranger1"]["devices"]["spare"]["driver_options"] = {"watchdog": -1}
    stops, problems = ros2_drives(parse_hosts(data, "hosts.yaml", catalog), "ranger1")
    assert [s.device for s in stops] == ["ranger1.drive", "ranger1.scout1.wheels"]
    assert problems == ["ranger1.spare: driver_options.watchdog: expected a positive number of seconds, got -1"]
