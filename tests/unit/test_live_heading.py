"""A robot's live `heading` (what `where`, `missionctl query` and `status` read) is an angle in [-pi, pi], as a ROS
yaw, however many turns the robot made; its driver's odometry keeps counting them (new-user audit 8: a Crawler
showed 7.374 rad after a spin)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from drd.rcm import Aggregate, ResourceManager, Unit
from drd.runtime.pool import ResourcePool
from drd.runtime.telemetry import DriverTelemetry


class Spun:
    """A Drive whose odometry counted one turn and a bit."""

    def __init__(self, heading: float) -> None:
        self.heading = heading

    def odometry(self) -> tuple[float, float, float]:
        return (1.0, 2.0, self.heading)


@pytest.mark.parametrize(("raw", "live"), [(7.374, 7.374 - math.tau), (-7.0, -7.0 + math.tau), (0.5, 0.5),
                                           (3 * math.pi + 0.1, -math.pi + 0.1)])
def test_the_live_heading_is_within_a_turn(raw: float, live: float) -> None:
    pool = ResourcePool(ResourceManager())
    pool.add([Unit("c.drive", "Drive", host="h"), Aggregate("c", "Crawler", {"drive": "c.drive"}, {}, host="h")], 0.0)
    drivers = SimpleNamespace(robots={"c": {"drive": Spun(raw)}}, devices={})
    data = DriverTelemetry(drivers, pool, lambda: 0.0)("c")
    assert data is not None and data["x"] == 1.0 and data["heading"] == pytest.approx(live)
    assert -math.pi <= data["heading"] <= math.pi


class Faulted:
    """A Drive whose odometry says NaN and whose battery reading fails (a stale topic, a NaN percentage)."""

    def odometry(self) -> tuple[float, float, float]:
        return (math.nan, 2.0, 0.0)

    def battery(self) -> float:
        raise RuntimeError("stale: older than 2 s")


def test_a_reading_the_driver_cannot_give_is_not_known_never_the_static_value() -> None:
    """ROS 2 audit 12: a NaN pose passed a geofence and a stale battery read as hosts.yaml's 1.0."""
    pool = ResourcePool(ResourceManager())
    pool.add([Unit("c.drive", "Drive", host="h"),
              Aggregate("c", "Crawler", {"drive": "c.drive"}, {"battery": 1.0}, host="h")], 0.0)
    pool.telemetry = DriverTelemetry(SimpleNamespace(robots={"c": {"drive": Faulted()}}, devices={}), pool,
                                     lambda: 0.0)
    assert pool.pose("c") is None
    view = pool.view("c")
    assert "battery" not in view and "x" not in view
    assert "battery" not in dict(view) and len(view) == len(dict(view))  # a mapping of what it answers (review)
    with pytest.raises(KeyError):
        view["battery"]


def test_on_a_cluster_a_reading_the_host_could_not_give_is_not_known_either() -> None:
    """Review of ROS 2 audit 12, D3: the host sends a battery it cannot read as null (JSON has no NaN), and the
    controller dropped it, so the pool fell back to hosts.yaml's 1.0."""
    from drd.cluster.telemetry import RemoteTelemetry

    pool = ResourcePool(ResourceManager())
    pool.add([Unit("c.drive", "Drive", host="h"),
              Aggregate("c", "Crawler", {"drive": "c.drive"}, {"battery": 1.0}, host="h")], 0.0)
    remote = RemoteTelemetry({"c": "h"}, fetch=lambda host: None, send=lambda host, op: None, now=lambda: 0.0)
    remote.seen("h", {"c": {"x": 1.0, "y": 2.0, "heading": 0.0, "battery": None}})
    pool.telemetry = remote
    assert pool.pose("c") == (1.0, 2.0, 0.0)
    with pytest.raises(KeyError):
        pool.view("c")["battery"]  # type: ignore[index]


def test_a_robot_on_another_host_is_not_known_until_its_host_has_read_it() -> None:
    """ROS 2 audit 18, #1: the controller's first read of a ROS 2 robot came before its first battery state, the
    value read as hosts.yaml's 1.0, and `where ranger.battery > 0.5` granted a robot at 30 %. The first read asks
    the host again until it has read the robot; a host that never does leaves it not known."""
    from drd.cluster import telemetry as remote

    asked: list[str] = []

    def fetch(host: str) -> None:  # the host reads its robot on the third ask (its driver's first message)
        asked.append(host)
        if len(asked) == 3:
            telemetry.seen(host, {"c": {"x": 1.0, "y": 2.0, "heading": 0.0, "battery": 0.3}})

    telemetry = remote.RemoteTelemetry({"c": "h", "d": "silent"}, fetch, lambda host, op: None, lambda: 0.0)
    pool = ResourcePool(ResourceManager())
    pool.add([Unit("c.drive", "Drive", host="h"), Aggregate("c", "Crawler", {"drive": "c.drive"}, {"battery": 1.0},
                                                           host="h"),
              Unit("d.drive", "Drive", host="silent"),
              Aggregate("d", "Crawler", {"drive": "d.drive"}, {"battery": 1.0}, host="silent")], 0.0)
    pool.telemetry = telemetry
    assert pool.view("c")["battery"] == 0.3 and asked == ["h"] * 3
    remote.FIRST_READ = 0.2  # a host that never reads it: given up on, and the robot's values are not known
    try:
        with pytest.raises(KeyError):
            pool.view("d")["battery"]
    finally:
        remote.FIRST_READ = 2.5


def test_a_host_back_after_it_was_down_has_its_robots_watched_and_read_again() -> None:
    """Cluster audit 19, #2: a restarted host's daemon watches nothing; the controller kept the x its robot had before
    the crash, and a `where ranger.x > 30` was granted on it. `forget` makes the next read watch and fetch anew."""
    from drd.cluster.telemetry import RemoteTelemetry

    sent: list[tuple[str, list[object]]] = []
    x = [35.0]

    def fetch(host: str) -> None:
        telemetry.seen(host, {"c": {"x": x[0], "y": 0.0, "heading": 0.0, "battery": 1.0}})

    telemetry = RemoteTelemetry({"c": "h"}, fetch, lambda host, op: sent.append((host, op)), lambda: 0.0)
    assert telemetry("c")["x"] == 35.0 and len(sent) == 1
    x[0] = 25.0  # driven after the restart; the host reports it only once it watches the robot again
    assert telemetry("c")["x"] == 35.0 and len(sent) == 1  # watched already: the last report
    telemetry.forget("h")
    assert telemetry("c")["x"] == 25.0 and sent[-1] == ("h", ["watch", ["c"], 0.0]) and len(sent) == 2


def test_the_first_read_of_a_robot_whose_host_is_down_is_not_waited_for() -> None:
    """Cluster audit 20, #2: each robot of a host that was down read first held the mission loop for FIRST_READ
    (2.5 s), and missions started in its lease stalled the world for 10 s. Asked once, not again while it is down."""
    from drd.cluster.telemetry import NOT_YET, RemoteTelemetry

    asked: list[str] = []
    down = {"h"}
    telemetry = RemoteTelemetry({"c": "h"}, asked.append, lambda host, op: None, lambda: 0.0,
                                down=lambda host: host in down)
    assert telemetry("c") is NOT_YET and asked == ["h"]
