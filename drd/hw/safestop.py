"""Zero Twists sent from outside a `ros2` Drive's own driver (docs/ros2.md "Safety"; docs/design.md "A robot left
driving by a dead host"): a Drive's watchdog and every stop run in the daemon that hosts the driver, so when that
process dies (kill -9) or freezes, nothing in it can stop the robot. Two others can:

- the same host's daemon when it starts again (`Daemon.start`): its hosts-file robots may have been left on their
  last command by the process it replaces;
- the acting controller when it marks a host down (its lease lapsed), for that host's robots: it has the hosts file,
  so it knows each robot's router, ROS domain, namespace and cmd_vel topic.

`ros2_drives` is the pure part (which robots and topics a host's loss maps to); `send_zeros` and `stop_drives`
publish through a `Ros2Link` of their own (the drivers' way of opening a session, a node and a publisher), best
effort, on threads of their own, so neither a daemon's start nor the controller's loop waits on a robot's router.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from drd.hosts import Cluster
from drd.hw.interfaces import HardwareError
from drd.hw.ros2 import RELIABLE, TWIST, OptionsError, Ros2Link, Ros2Options

log = logging.getLogger("drd.hw.safestop")

#: The driver and the device type whose driver publishes cmd_vel (`components.ros2.drive.Ros2Drive`).
DRIVER, DRIVE = "ros2", "Drive"
#: A zero Twist is sent this many times, this far apart: a zenoh put right after a session opens may reach the
#: router before the robot's subscription is matched, and a zero repeated is still a zero.
REPEAT, GAP = 3, 0.1
ZERO = {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


@dataclass(frozen=True, slots=True)
class DriveStop:
    """Where one robot's `ros2` Drive listens: what a zero Twist for it is published on."""

    host: str
    robot: str
    device: str
    endpoint: str
    domain_id: int
    namespace: str
    topic: str

    def describe(self) -> str:
        where = self.topic if self.topic.startswith("/") else f"/{self.namespace.strip('/')}/{self.topic}"
        return f"{self.device} ({self.robot}) {where} at {self.endpoint}"


def ros2_drives(cluster: Cluster, host: str) -> tuple[list[DriveStop], list[str]]:
    """Every `ros2` Drive `host`'s daemon drives, for the robot that names it (a Drive is exclusive: one at most; a
    device no robot names is driven for the host itself, as `drd.hw.drivers.drivers_for` does), and the problems (a
    device whose options `drd start` would refuse: its topic is not known). Pure: the hosts file only."""
    h = cluster.host(host)
    owners = {device_id: robot.id for robot in reversed(h.robots) for device_id in robot.parts.values()}
    stops: list[DriveStop] = []
    problems: list[str] = []
    for device in h.devices:
        if device.driver != DRIVER or device.type != DRIVE:
            continue
        robot = owners.get(device.id, h.name)
        try:
            opts = Ros2Options.of(device, robot)
        except OptionsError as e:
            problems.append(str(e))
            continue
        topic = opts.topic("cmd_vel")
        assert topic is not None  # cmd_vel cannot be turned off
        stops.append(DriveStop(host, robot, device.id, opts.endpoint, opts.domain_id, opts.namespace, topic))
    return stops, problems


class StandbyLinks:
    """Sessions to the `ros2` robots' routers, opened ahead by the controller (`warm`, on a thread), so a host's loss
    publishes its zeros without first opening a session, most of the time between a loss seen and the first zero
    (ROS 2 audit 17, D4: 0.15-0.21 s). A stop that fails on them is sent again through sessions of its own."""

    def __init__(self) -> None:
        self.link = Ros2Link(period=None)  # no watchdog thread: nothing here commands the robot again

    def warm(self, cluster: Cluster) -> threading.Thread:
        """Open a session to every router a `ros2` Drive of `cluster` listens on (best effort, on a thread)."""
        endpoints = sorted({stop.endpoint for h in cluster.hosts for stop in ros2_drives(cluster, h.name)[0]})

        def open_all() -> None:
            for endpoint in endpoints:
                try:
                    self.link.session(endpoint)
                except Exception as e:  # a router down now: a loss opens its own session, as before
                    log.info("no standby session to the robots' router at %s yet: %s", endpoint, e)

        thread = threading.Thread(target=open_all, name="drd safe stop sessions", daemon=True)
        thread.start()
        return thread

    def close(self) -> None:
        self.link.close()


def send_zeros(stops: Sequence[DriveStop], why: str, *, still: Callable[[], bool] = lambda: True,
               repeat: int = REPEAT, gap: float = GAP, standby: StandbyLinks | None = None) -> list[str]:
    """Publish a zero Twist `repeat` times on each Drive of `stops` (all of one robot router: one session), unless
    `still()` turns false meanwhile (the host came back: its own drivers command again); each failure, logged.
    Through `standby`'s sessions when given (the publishers made are closed after), else through its own; a stop
    that fails on the standby sessions is sent again through its own."""
    if standby is not None and all(standby.link.connected(stop.endpoint) for stop in stops):
        try:
            return _send(stops, why, still, repeat, gap, standby.link, own=False)
        except _StandbyFailed:
            pass
    return _send(stops, why, still, repeat, gap, Ros2Link(period=None), own=True)


class _StandbyFailed(HardwareError):
    """A publisher could not be made on a standby session (closed meanwhile, its router restarted)."""


def _send(stops: Sequence[DriveStop], why: str, still: Callable[[], bool], repeat: int, gap: float, link: Ros2Link,
          own: bool) -> list[str]:
    failures: list[str] = []
    publishers: list[tuple[DriveStop, Any]] = []
    try:
        for stop in stops:
            try:
                node = link.node(stop.endpoint, stop.domain_id, stop.namespace)
                publishers.append((stop, link.publisher(node, stop.topic, TWIST, RELIABLE)))
            except Exception as e:  # best effort: the robot's router may be down or unreachable
                if not own:
                    raise _StandbyFailed(str(e)) from e
                failures.append(f"{stop.describe()}: {e}")
                log.warning("could not stop %s (%s): %s", stop.describe(), why, e)
        sent = 0
        for k in range(repeat if publishers else 0):
            if k and not still():
                break
            for stop, pub in publishers:
                try:
                    link.publish(pub, ZERO)
                except Exception as e:
                    failures.append(f"{stop.describe()}: {e}")
                    log.warning("could not stop %s (%s): %s", stop.describe(), why, e)
            sent += 1
            if sent < repeat:
                time.sleep(gap)
        if publishers:
            log.warning("zero Twist (%d times) to %s: %s", sent, ", ".join(s.describe() for s, _ in publishers), why)
    finally:
        if own:
            link.close()
        else:  # the sessions and nodes stay for the next loss; the publishers go (the graph forgets them)
            for _, pub in publishers:
                pub.close()
    return failures


def stop_drives(stops: Sequence[DriveStop], why: str, *, still: Callable[[], bool] = lambda: True,
                wait: float = 0.0, standby: StandbyLinks | None = None) -> list[threading.Thread]:
    """`send_zeros` on a thread per robot router (a dead one holds up no other), waiting up to `wait` s for them
    all (0: not at all); the threads, still running or not."""
    by_endpoint: dict[str, list[DriveStop]] = {}
    for stop in stops:
        by_endpoint.setdefault(stop.endpoint, []).append(stop)
    threads = [threading.Thread(target=send_zeros, args=(group, why), kwargs={"still": still, "standby": standby},
                                name=f"drd safe stop {endpoint}", daemon=True)
               for endpoint, group in by_endpoint.items()]
    for thread in threads:
        thread.start()
    deadline = time.monotonic() + wait
    for thread in threads:
        thread.join(max(0.0, deadline - time.monotonic()))
    return threads


def has_drives(cluster: Cluster, host: str) -> bool:
    """Whether `host` has a `ros2` Drive (before importing anything of ROS 2)."""
    return any(d.driver == DRIVER and d.type == DRIVE for d in cluster.host(host).devices)


def stop_host_robots(cluster: Cluster, host: str, why: str, *, still: Callable[[], bool] = lambda: True,
                     wait: float = 0.0, standby: StandbyLinks | None = None) -> list[threading.Thread]:
    """A zero Twist to every `ros2` Drive of `host`'s robots (`ros2_drives`, `stop_drives`); logs what it cannot."""
    stops, problems = ros2_drives(cluster, host)
    for problem in problems:
        log.warning("cannot stop a robot of host %s (%s): %s", host, why, problem)
    return stop_drives(stops, why, still=still, wait=wait, standby=standby)
