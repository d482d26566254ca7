"""Live properties in the trader's offers (drd.daemon.load.live_robots, drd.daemon.view; pure): what the controller
reports (dependency changes, the drivers' pose and battery), merged over hosts.yaml, with ages, from a controller
only, and dropped when that controller goes or stops reporting."""

from __future__ import annotations

import math

import pytest
import yaml

from drd.daemon.load import MAX_TEXT, live_robots
from drd.daemon.messages import LiveReport
from drd.daemon.view import ClusterView
from drd.hosts import Cluster, parse_hosts
from drd.trader import Offer, compile_query
from dsl.catalog import Catalog

HOSTS = """
cluster: {name: lab, security: {mode: none}, lease: 1000ms}
hosts:
  controller: {endpoint: tcp/127.0.0.1:7447, roles: [controller]}
  ranger1:
    endpoint: tcp/127.0.0.1:7448
    roles: [worker]
    devices:
      drive: {type: Drive, driver: sim, options: {max_speed: 0.8}}
      ranges: {type: RangeSensor, driver: sim, options: {beams: 181, max_range: 8.0}}
      camera: {type: Camera, driver: sim, options: {resolution: 640, fov: 60.0}}
      launcher: {type: Launcher, driver: sim, options: {max_range: 6.0}}
      radio: {type: RadioChannel, driver: sim, capacity: 10, options: {range: 30.0}}
      scout1.wheels: {type: Drive, driver: sim, options: {max_speed: 0.3}}
      scout1.foot: {type: Jump, driver: sim, options: {max_height: 0.3}}
      scout1.camera: {type: Camera, driver: sim, options: {resolution: 320, fov: 90.0}}
    robots:
      ranger1:
        type: Ranger
        parts: {drive: drive, ranges: ranges, camera: camera, launcher: launcher}
        properties: {battery: 1.0, magazine: 1}
      scout1:
        type: Scout
        carrier: ranger1
        parts: {wheels: scout1.wheels, foot: scout1.foot, camera: scout1.camera, radio: radio}
        properties: {battery: 1.0}
"""


@pytest.fixture(scope="module")
def cluster(catalog: Catalog) -> Cluster:
    return parse_hosts(yaml.safe_load(HOSTS), "hosts.yaml", catalog)


def up_view(cluster: Cluster, me: str = "ranger1") -> ClusterView:
    view = ClusterView(cluster, me)
    for host in ("controller", "ranger1"):
        view.token(host, True, 0.0)
    return view


def offer(view: ClusterView, rid: str, now: float) -> Offer:
    return next(o for o in view.offers(now) if o.id == rid)


def test_the_controller_reports_dependency_changes_and_telemetry_only(cluster: Cluster) -> None:
    db = {"scout1": {"carrier": "", "battery": 1.0}, "ranger1": {"battery": 1.0, "magazine": 0}}
    telemetry = {"ranger1": {"x": 2.5, "y": -1.0, "heading": 0.5, "battery": 0.8, "colour": 3.0},
                 "scout1": {"x": math.nan}, "ghost": {"x": 1.0}}
    robots = live_robots(cluster.robots, lambda rid: db.get(rid, {}), telemetry)
    assert robots == {"ranger1": {"magazine": 0, "x": 2.5, "y": -1.0, "heading": 0.5, "battery": 0.8},
                      "scout1": {"carrier": ""}}  # unchanged values, unknown keys, NaN and other robots left out
    assert live_robots(cluster.robots, lambda rid: {}, {}) == {}  # nothing live: an empty report
    long = live_robots(cluster.robots, lambda rid: {"carrier": "r" * (MAX_TEXT + 1)}, {})
    assert long == {}


def test_live_values_override_hosts_yaml_with_their_age(cluster: Cluster, catalog: Catalog) -> None:
    view = up_view(cluster)
    query = compile_query('Scout where carrier == "ranger1"', catalog)
    assert [o.id for o in query.run(view.offers(1.0))] == ["scout1"]  # hosts.yaml's carrier
    assert view.live_report(LiveReport("controller", 0.0, {"scout1": {"carrier": ""},
                                                          "ranger1": {"x": 3.0, "y": 1.0, "heading": 0.1}}),
                            1.0, "controller") == []
    assert query.run(view.offers(1.2)) == []  # launched: no longer in ranger1's magazine
    scout = offer(view, "scout1", 1.25)
    assert scout.properties["carrier"] == "" and scout.live == {"carrier": pytest.approx(0.25)}
    ranger = offer(view, "ranger1", 1.5)
    assert (ranger.properties["x"], ranger.properties["magazine"]) == (3.0, 1)
    assert ranger.live == {"x": 0.5, "y": 0.5, "heading": 0.5}
    assert offer(view, "ranger1", 1.5).live and view.offers()[0].live == {}  # no `now`: hosts.yaml's alone
    moved = compile_query("Robot where x > 2", catalog)
    assert [o.id for o in moved.run(view.offers(1.5))] == ["ranger1"]


def test_live_values_go_with_the_controller_or_its_silence(cluster: Cluster) -> None:
    view = up_view(cluster)
    view.live_report(LiveReport("controller", 0.0, {"scout1": {"carrier": ""}}), 1.0)
    assert offer(view, "scout1", 1.9).properties["carrier"] == ""
    assert offer(view, "scout1", 2.1).properties["carrier"] == "ranger1"  # more than a lease old: hosts.yaml again
    view.live_report(LiveReport("controller", 0.0, {"scout1": {"carrier": ""}}), 3.0)
    view.token("controller", False, 3.1)
    assert offer(view, "scout1", 3.2).live == {}  # its controller is down


def test_only_a_controller_reports_and_only_configured_robots_and_keys(cluster: Cluster) -> None:
    view = up_view(cluster, "controller")
    [change] = view.live_report(LiveReport("ranger1", 0.0, {"scout1": {"carrier": ""}}), 1.0)
    assert (change.kind, change.detail) == ("rejected", "live properties from a host that is not a controller")
    [change] = view.live_report(LiveReport("controller", 0.0, {}), 1.0, key_host="ranger1")
    assert change.kind == "rejected"
    view.live_report(LiveReport("controller", 0.0, {"ghost": {"x": 1.0}, "scout1": {"carrier": ["a"], "x": 1.0,
                                                                                    "secret": "s"}}), 1.0)
    assert view.live == {"scout1": {"x": 1.0}}


def test_a_live_integer_the_bus_cannot_send_again_is_dropped_on_receipt(cluster: Cluster) -> None:
    """Wire audit 25, D3: a report of `battery: 2**70` was taken, and every daemon's trader reply holding it could
    not be encoded: `missionctl query` failed on every host."""
    view = up_view(cluster, "controller")
    view.live_report(LiveReport("controller", 0.0, {"ranger1": {"battery": 2**70, "magazine": 2**63 - 1},
                                                    "scout1": {"battery": -(2**63) - 1}}), 1.0)
    assert view.live == {"ranger1": {"magazine": 2**63 - 1}, "scout1": {}}
