"""Constraints on a cluster, piece by piece (`drd.cluster.guard`, `drd.cluster.telemetry`): what the controller
sends each device's host, how the host's gates judge a command with it, and how robots' live values travel.
The whole path on real daemons is in tests/e2e/test_cluster_multi.py."""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import pytest
import yaml

from drd.cluster import telemetry as telemetry_module
from drd.cluster.gates import deliver
from drd.cluster.guard import HostGuard, SharedGuard, decode_scope, encode_scope
from drd.cluster.telemetry import RemoteTelemetry
from drd.hosts import Cluster, parse_hosts
from drd.hw.interfaces import Fence
from drd.rcm import ResourceManager
from drd.runtime import records as rec
from drd.runtime.constraints import Active, Breach
from drd.runtime.ownership import NotHolder
from drd.runtime.pool import ResourcePool
from dsl.catalog import Catalog
from dsl.evaluate import Point
from dsl.parser import parse_expression
from tests.cluster_support import hosts_yaml


@pytest.fixture(scope="module")
def cluster(catalog: Catalog) -> Cluster:
    text = hosts_yaml("lab", ["controller", "ranger1", "ranger2"], [7447, 7448, 7449])
    return parse_hosts(yaml.safe_load(text), "hosts.yaml", catalog)


class Wheels:
    """A drive standing where the test puts it, recording what reached it."""

    READINGS = frozenset({"odometry", "battery", "max_speed"})
    SETPOINTS = ("set_velocity", "stop")
    STOP = "stop"
    max_speed = 0.8

    def __init__(self, x: float, y: float, heading: float = 0.0) -> None:
        self.pose = (x, y, heading)
        self.fence = Fence("wheels")
        self.moves: list[tuple[float, float]] = []

    def set_velocity(self, v: float, omega: float, epoch: int | None = None) -> None:
        self.fence.check(epoch)
        self.moves.append((v, omega))

    def stop(self, epoch: int | None = None) -> None:
        self.moves.append((0.0, 0.0))

    def odometry(self) -> tuple[float, float, float]:
        return self.pose

    def battery(self) -> float:
        return 0.75


class Drivers:
    """`drd.hw.HostDrivers` of one host with only a Ranger's drive."""

    def __init__(self, robot: str, wheels: Wheels) -> None:
        self.devices = {f"{robot}.drive": wheels}
        self.robots = {robot: {"drive": wheels}}


def pool_of(cluster: Cluster) -> ResourcePool:
    pool = ResourcePool(ResourceManager())
    pool.add(cluster.resources(), 0.0)
    return pool


def host_guard(cluster: Cluster, host: str, wheels: Wheels) -> tuple[HostGuard, Any, list[dict[str, Any]]]:
    from drd.runtime.ownership import LocalGates

    reports: list[dict[str, Any]] = []
    drivers = Drivers(host, wheels)
    gates = LocalGates.of(drivers.devices, drivers.robots)
    guard = HostGuard(cluster, host, drivers, gates, lambda: 1.0, reports.append)
    return guard, gates, reports


def guard_op(holder: str, text: str, robots: list[str], scope: dict[str, Any]) -> list[Any]:
    return ["guard", holder, holder.partition("/")[2], "near", text, robots, scope, {}, 1.0]


# --- what a host is sent of a behavior's scope -------------------------------------------------------


def test_the_scope_sent_holds_what_the_condition_reads_and_comes_back_the_same(cluster: Cluster) -> None:
    pool = pool_of(cluster)
    condition = parse_expression("distance(ranger, home) <= limit and tag == \"x\"")
    assert condition is not None
    names = {"ranger": pool.view("ranger1"), "home": Point(1.0, 2.0), "limit": 6, "tag": "x", "unused": 3,
             "records": [{"a": 1}]}
    scope = encode_scope(condition, names)
    assert scope == {"ranger": ["resource", "ranger1"], "home": ["point", 1.0, 2.0], "limit": ["value", 6],
                     "tag": ["value", "x"]}  # only what the condition reads, only what can be sent
    back = decode_scope(scope, pool)
    assert back["ranger"] == pool.view("ranger1") and back["home"] == Point(1.0, 2.0) and back["limit"] == 6
    assert decode_scope({"r": ["resource", "nosuch"], "p": ["point", "a", 1], "v": ["value", [1]]}, pool) == {}


# --- the host's guard ------------------------------------------------------------------------------


def test_a_host_refuses_a_command_that_would_take_its_robot_out_of_range_of_a_robot_elsewhere(
        cluster: Cluster) -> None:
    wheels = Wheels(4.9, 0.0)  # ranger2, 4.9 m east of ranger1 (which stands on another host)
    guard, gates, reports = host_guard(cluster, "ranger2", wheels)
    holder = "M-1/Keep"
    gates.grant("ranger2.drive", holder, 3, 1.0)
    guard.apply(guard_op(holder, "distance(r2, r1) <= 5", ["ranger2", "ranger1"],
                         {"r1": ["resource", "ranger1"], "r2": ["resource", "ranger2"]}))
    gate = gates.get("ranger2.drive")
    # ranger1's pose is unknown: the condition cannot be read here, and the gate does not guess
    gate.execute(wheels, "M-1/Keep/Go", 3, "set_velocity", (0.8, 0.0), {}, 1.0)
    guard.apply(["seen", {"ranger1": {"x": 0.0, "y": 0.0, "heading": 0.0}}, 1.0])
    with pytest.raises(NotHolder, match="constraint near"):
        gate.execute(wheels, "M-1/Keep/Go", 3, "set_velocity", (0.8, 0.0), {}, 1.1)
    gate.execute(wheels, "M-1/Keep/Go", 3, "set_velocity", (-0.5, 0.0), {}, 1.2)  # back towards ranger1: fine
    assert wheels.moves == [(0.8, 0.0), (0.0, 0.0), (-0.5, 0.0)]  # the refusal also stopped the robot
    [breach] = [r for r in reports if r["kind"] == "breach"]
    assert breach["mission"] == "M-1" and breach["holder"] == holder and breach["name"] == "near"
    assert not breach["holds"] and breach["value"] > 5
    # another behavior's commands are not its constraint's business; an unguarded holder drives freely
    guard.apply(["unguard", holder, 1.3])
    gate.execute(wheels, "M-1/Keep/Go", 3, "set_velocity", (0.8, 0.0), {}, 1.4)


class FirstBattery(Wheels):
    """A ROS 2 drive before the robot's first battery state: the reading waits for it (`Latest.get`)."""

    def __init__(self, x: float, y: float) -> None:
        super().__init__(x, y)
        self.arrived = threading.Event()

    def battery(self) -> float:
        assert self.arrived.wait(30), "the test never sent the battery state"
        return 0.5


def test_a_reading_that_waits_for_its_first_message_does_not_hold_a_guarded_command(cluster: Cluster) -> None:
    """A constraint on the ROS 2 cluster: the guard read the drive's battery on the command's thread, under the
    Creator's lock, and waited for its first message (2 s), which the world the host serves could not publish
    without stepping: the behavior's scans went stale and the mission failed (found with hosts.ros2.yaml)."""
    wheels = FirstBattery(1.0, 0.0)
    guard, gates, _reports = host_guard(cluster, "ranger1", wheels)
    gates.grant("ranger1.drive", "M-1/Keep", 3, 1.0)
    guard.apply(guard_op("M-1/Keep", "distance(r, point(1, 0)) <= 1", ["ranger1"], {"r": ["resource", "ranger1"]}))
    command = threading.Thread(target=gates.get("ranger1.drive").execute,
                               args=(wheels, "M-1/Keep/Go", 3, "set_velocity", (0.8, 0.0), {}, 1.0))
    command.start()
    command.join(10)
    done = not command.is_alive()
    wheels.arrived.set()  # the battery state arrives: the read under way returns
    command.join(10)
    assert done and wheels.moves == [(0.8, 0.0)], "the command waited for a reading (or did not reach the drive)"
    # read by then: the next command is checked against the robot's pose (1 m out, beyond the fence: refused)
    wheels.pose = (2.5, 0.0, 0.0)
    guard.local.clock = lambda: 1.1  # the next instant: read again
    assert eventually_read(guard, "ranger1", 2.5)
    with pytest.raises(NotHolder, match="constraint near"):
        gates.get("ranger1.drive").execute(wheels, "M-1/Keep/Go", 3, "set_velocity", (0.8, 0.0), {}, 1.1)


def eventually_read(guard: HostGuard, robot: str, x: float) -> bool:
    """Whether the guard's background read sees `robot` at `x` within 10 s (it reads when asked)."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        data = guard.pool.telemetry(robot) if guard.pool.telemetry is not None else None
        if data is not None and data.get("x") == x:
            return True
        time.sleep(0.01)
    return False


def test_a_host_reports_the_robots_it_is_asked_to_watch_and_only_its_own(cluster: Cluster) -> None:
    guard, _gates, _reports = host_guard(cluster, "ranger1", Wheels(2.0, 3.0, 0.5))
    assert guard.telemetry() is None  # nobody asked
    guard.apply(["watch", ["ranger1", "ranger2"], 1.0])
    assert guard.telemetry() == {"kind": "telemetry", "mission": "", "host": "ranger1",
                                 "robots": {"ranger1": {"x": 2.0, "y": 3.0, "heading": 0.5, "battery": 0.75}}}


def test_malformed_operations_are_ignored_and_the_guard_keeps_what_it_had(cluster: Cluster) -> None:
    wheels = Wheels(0.0, 0.0)
    guard, gates, _reports = host_guard(cluster, "ranger1", wheels)
    for op in (["guard", "x"], ["seen", "nope", 1.0], ["watch", "ranger1", 1.0], ["unguard"], ["bogus"],
               guard_op("M-1/A", "distance(r, ", ["ranger1"], {})):
        guard.apply(op)
    assert guard.guard.active == [] and guard.watched == [] and guard.shipped == {}


# --- the controller's side -------------------------------------------------------------------------


def test_the_controller_tells_the_hosts_of_the_robots_a_constraint_names(cluster: Cluster) -> None:
    pool = pool_of(cluster)
    pool.places = {"n1": (0.0, -1.0, 4.0, 1.0)}
    sent: list[tuple[str, list[Any]]] = []
    hosts = {u.id: u.host for u in cluster.resources() if u.host and type(u).__name__ == "Unit"}
    shared = SharedGuard(pool, hosts, lambda host, op: sent.append((host, op)), lambda: 2.0)
    condition = parse_expression("distance(r1, r2) <= 5")
    assert condition is not None
    names = {"r1": pool.view("ranger1"), "r2": pool.view("ranger2")}
    shared.add(Active("M-1/Keep", "Keep", "near", condition, ("ranger1", "ranger2"), lambda: None,  # type: ignore
                      names=lambda: names))
    assert sorted(h for h, _ in sent) == ["ranger1", "ranger2"]
    op = sent[0][1]
    assert op[:6] == ["guard", "M-1/Keep", "Keep", "near", "distance(r1, r2) <= 5", ["ranger1", "ranger2"]]
    assert op[6] == {"r1": ["resource", "ranger1"], "r2": ["resource", "ranger2"]}
    assert op[7] == {"n1": [0.0, -1.0, 4.0, 1.0]}
    sent.clear()
    latest = {"ranger1": {"x": 1.0, "y": 0.0}, "ranger2": {"x": 3.0, "y": 0.0}}
    shared.share(latest.get)  # each host gets the other's robot
    assert sorted(sent) == [("ranger1", ["seen", {"ranger2": {"x": 3.0, "y": 0.0}}, 2.0]),
                            ("ranger2", ["seen", {"ranger1": {"x": 1.0, "y": 0.0}}, 2.0])]
    sent.clear()
    shared.remove("M-1/Keep")
    assert sorted(sent) == [("ranger1", ["unguard", "M-1/Keep", 2.0]), ("ranger2", ["unguard", "M-1/Keep", 2.0])]


def test_a_breach_sent_back_reaches_the_behavior_that_declared_the_constraint(cluster: Cluster) -> None:
    heard: list[Any] = []
    pool = pool_of(cluster)
    shared = SharedGuard(pool, {}, lambda host, op: None, lambda: 0.0)
    condition = parse_expression("ranger.x < 4")
    assert condition is not None
    a = Active("M-1/Out", "Out", "fence", condition, ("ranger1",), lambda: None)  # type: ignore[arg-type, return-value]
    a.refused = heard.append
    shared.add(a)
    got: list[tuple[str, Any]] = []
    deliver([{"kind": "breach", "mission": "M-1", "holder": "M-1/Out", "name": "fence", "holds": False,
              "margin": -0.1, "value": 4.1, "limit": 4},
             {"kind": "breach", "mission": "M-1", "holder": "M-1/Out"},  # malformed: dropped
             {"kind": "command", "mission": "M-1", "at": 1.0, "path": "Out", "device": "ranger1.drive",
              "method": "stop", "epoch": 1, "accepted": True, "reason": ""}],
            lambda mission, r: got.append((mission, r)))
    assert [type(r) for _m, r in got] == [Breach, rec.Command]
    shared.breached(got[0][1])
    assert len(heard) == 1 and heard[0].value == 4.1 and not heard[0].holds


def test_the_controller_reads_a_robot_first_at_once_then_from_every_reply(cluster: Cluster,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(telemetry_module, "FIRST_READ", 0.3)  # how long the first read asks a silent host again
    sent: list[tuple[str, list[Any]]] = []
    fetched: list[str] = []
    telemetry: RemoteTelemetry

    def fetch(host: str) -> None:  # ranger1 answers with its robot (and a foreign one, ignored); ranger2 is silent
        fetched.append(host)
        if host == "ranger1":
            deliver([{"kind": "telemetry", "mission": "", "host": host,
                      "robots": {"ranger1": {"x": 1.0, "y": 2.0, "heading": 0.0, "battery": 0.5, "evil": 1},
                                 "ranger2": {"x": 99.0}}}], lambda m, r: None, telemetry.seen)

    telemetry = RemoteTelemetry({"ranger1": "ranger1", "ranger2": "ranger2"}, fetch,
                                lambda host, op: sent.append((host, op)), lambda: 3.0)
    assert telemetry("ranger1") == {"x": 1.0, "y": 2.0, "heading": 0.0, "battery": 0.5}
    assert sent == [("ranger1", ["watch", ["ranger1"], 3.0])] and fetched == ["ranger1"]
    # ranger1 may not speak for ranger2, and ranger2 has not answered, asked again for FIRST_READ: not known, never
    # hosts.yaml's static values (ros2 audit 18, #1)
    assert all(math.isnan(v) for v in telemetry("ranger2").values())
    assert sent[-1] == ("ranger2", ["watch", ["ranger2"], 3.0]) and fetched.count("ranger2") > 1
    assert telemetry("ranger1") is not None and fetched.count("ranger1") == 1  # no second fetch
    assert telemetry.due() == ["ranger2"]  # ranger1 answered since; ranger2 did not say anything of its own
    assert telemetry.due() == ["ranger1", "ranger2"]  # nothing since the last call
    telemetry.reset()
    assert telemetry.latest == {} and telemetry.due() == []
    assert telemetry("nosuch") is None
