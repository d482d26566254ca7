"""The `ros2` drivers: one module per RC type, each implementing its `drd.hw.interfaces` protocol on a ROS 2 robot
through rmw_zenoh (docs/ros2.md), with the mapping of `drd.hw.ros2`. Imported lazily by `drd.hw.drivers.load_driver`;
only the shared `Ros2Driver` base lives here.

A driver's backend (`services["ros2"]`) is a `drd.hw.ros2.Ros2Link` (the dry-run's, whose clock is sim time); with
none, the process's own link is used (`default_link()`: a client session per robot router, the monotonic clock).
"""

from __future__ import annotations

import json
import logging
import threading
import weakref
from collections.abc import Callable, Mapping
from typing import Any

from drd.bus.ros2 import MessageInfo, Publisher, Subscription
from drd.hosts import Device
from drd.hw.interfaces import Fence, HardwareError
from drd.hw.ros2 import TOPICS, OptionsError, Ros2Link, Ros2Options, check_options, default_link

log = logging.getLogger("drd.ros2")


class Latest:
    """The latest message of one subscription, when it arrived (on the link's clock), and how many came."""

    def __init__(self, driver: Ros2Driver, key: str, topic: str, max_age: float, frame: str | None = None,
                 child: str | None = None) -> None:
        self.key, self.topic, self.max_age, self.frame, self.child = key, topic, max_age, frame, child
        self.what = driver.describe()
        self.endpoint = driver.opts.endpoint
        self.link = driver.link
        self.message: Any = None
        self.at = 0.0
        self.count = 0
        self.wrong_frame = 0
        self.seen_frame: tuple[str, str | None] = ("", None)  # the last frame (and child) dropped
        self.arrived = threading.Condition()
        self.since = self.link.now()  # the first message is waited for until `max_age` after this, once

    def receive(self, message: Any, _info: MessageInfo) -> None:
        frame = message.header.frame_id if self.frame is not None else None
        child = message.child_frame_id if self.child is not None else None
        if frame != self.frame or child != self.child:
            self.wrong_frame += 1
            self.seen_frame = (message.header.frame_id, child)
            if self.wrong_frame == 1:
                log.warning("%s: %s in frame %r (child %r), not %r (child %r): dropped", self.what, self.topic, frame,
                            child, self.frame, self.child)
            return
        with self.arrived:
            self.message, self.at = message, self.link.now()
            self.count += 1
            self.arrived.notify_all()

    def get(self) -> Any:
        """The latest message, fresh enough; HardwareError when stale, or when none came within `max_age` of the
        subscription. Only that first wait blocks: a topic nobody publishes answers every later call at once (each
        call waited `max_age` again, and a battery topic's 2 s held every control step past its 1 s deadline, so a
        healthy host was reported as not answering: ROS 2 audit 12, D4)."""
        with self.arrived:
            left = self.since + self.max_age - self.link.now()
            if self.message is None and left > 0:
                self.arrived.wait_for(lambda: self.message is not None, left)
            message, at = self.message, self.at
        if message is None and self.wrong_frame:  # the router is up: the frames disagree
            want, got = _frames(self.frame, self.child), _frames(*self.seen_frame)
            raise HardwareError(f"{self.what}: no message on {self.topic} in {want} within {self.max_age:g} s: "
                                f"{self.wrong_frame} came in {got}; the driver's frame options must name the frames "
                                "the robot publishes")
        if message is None:
            raise HardwareError(f"{self.what}: no message on {self.topic} (none within {self.max_age:g} s; is "
                                f"{self.link.source(self.endpoint)} up and publishing it?)")
        age = self.link.now() - at
        if age > self.max_age:
            raise HardwareError(f"{self.what}: the latest message on {self.topic} is {age:.2f} s old (stale: older "
                                f"than {self.max_age:g} s)")
        return message


def _frames(frame: str | None, child: str | None) -> str:
    return f"frame {frame!r}" + (f" (child {child!r})" if child is not None else "")


class Ros2Driver:
    """Base of every `ros2` driver: the device, its robot, its options, the link, the node and the fence."""

    READINGS: frozenset[str] = frozenset()
    SETPOINTS: tuple[str, ...] = ()
    ACTIONS: tuple[str, ...] = ()
    STOP: str | None = None

    def __init__(self, device: Device, robot_id: str, backend: object = None) -> None:
        self.device, self.robot_id = device, robot_id
        try:
            self.opts = Ros2Options.of(device, robot_id)
        except OptionsError as e:
            raise HardwareError(str(e)) from None
        self.link: Ros2Link = backend if isinstance(backend, Ros2Link) else default_link()
        self.fence = Fence(f"{device.id} ({robot_id})")
        self.node = self.link.node(self.opts.endpoint, self.opts.domain_id, self.opts.namespace)
        self._entities: list[Publisher | Subscription] = []
        self._finalizer = weakref.finalize(self, _close_entities, self.link, self._entities)

    @classmethod
    def check_options(cls, device: Device) -> list[str]:
        """What `drd start` refuses before it starts: the problems of the device's `driver_options`."""
        return check_options(device.driver_options)

    def describe(self) -> str:
        return f"{self.device.id} ({self.robot_id}, ros2)"

    def option(self, key: str, default: float) -> float:
        """A numeric device option (a manifest property: `max_speed`, `fov`...), or `default`."""
        value = self.device.options.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise HardwareError(f"{self.device.id}: option {key} has a bad value {value!r}")
        return float(value)

    def publisher(self, key: str, suffix: str = "") -> Publisher:
        topic = self.opts.topic(key)
        assert topic is not None, key
        _, type_name, qos = TOPICS[key]
        pub = self.link.publisher(self.node, topic + suffix, type_name, qos)
        self._entities.append(pub)
        return pub

    def subscribe(self, key: str, max_age: float, frame: str | None = None, suffix: str = "",
                  child: str | None = None) -> Latest | None:
        """The latest message of topic `key` (None when the options turn it off), kept fresh by a subscription; with
        `frame` (and `child`), only messages in that frame (an Odometry's child frame) count."""
        topic = self.opts.topic(key)
        if topic is None:
            return None
        _, type_name, qos = TOPICS[key]
        latest = Latest(self, key, topic + suffix, max_age, frame, child)
        sub = self.link.subscribe(self.node, topic + suffix, type_name, qos, _weak(latest.receive))
        latest.topic = sub.topic.name
        self._entities.append(sub)
        return latest

    def publish(self, pub: Publisher, message: object) -> None:
        self.link.publish(pub, message)

    def close(self) -> None:
        """Undeclare this driver's publishers and subscriptions (the node and the session are the link's)."""
        self._finalizer()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.device.id!r}, robot={self.robot_id!r})"


def _weak(method: Callable[[Any, MessageInfo], None]) -> Callable[[Any, MessageInfo], None]:
    """A callback that does not keep its object alive (a dropped driver's subscriptions then close)."""
    ref = weakref.WeakMethod(method)

    def call(message: Any, info: MessageInfo) -> None:
        target = ref()
        if target is not None:
            target(message, info)
    return call


def _close_entities(link: Ros2Link, entities: list[Publisher | Subscription]) -> None:
    for entity in entities:
        entity.close()
        if isinstance(entity, Subscription):
            link.unsubscribed(entity.key)
    entities.clear()


class Actions:
    """Request/result pairs on two JSON `std_msgs/msg/String` topics (launch, jump): a request with a fresh `id`,
    then wait for the result with that id (docs/ros2.md)."""

    def __init__(self, driver: Ros2Driver, request: str, result: str) -> None:
        self.driver = driver
        self.requests = driver.publisher(request)
        self.results: dict[Any, Mapping[str, Any]] = {}
        self.answered = threading.Condition()
        self.next_id = 1
        topic = driver.opts.topic(result)
        assert topic is not None
        _, type_name, qos = TOPICS[result]
        self.topic = topic
        driver._entities.append(driver.link.subscribe(driver.node, topic, type_name, qos, _weak(self.receive)))

    def receive(self, message: Any, _info: MessageInfo) -> None:
        try:
            answer = json.loads(message.data)
        except ValueError:
            log.warning("%s: a result that is not JSON on %s", self.driver.describe(), self.topic)
            return
        if isinstance(answer, dict) and "id" in answer:
            with self.answered:
                self.results[answer["id"]] = answer
                self.answered.notify_all()

    def call(self, **fields: Any) -> Mapping[str, Any]:
        """Send a request, wait (`action_timeout`) for its result; HardwareError on a timeout or `"ok": false`."""
        with self.answered:
            rid = self.next_id
            self.next_id += 1
        self.driver.publish(self.requests, {"data": json.dumps({"id": rid, **fields})})
        timeout = self.driver.opts.action_timeout
        with self.answered:
            self.answered.wait_for(lambda: rid in self.results, timeout)
            answer = self.results.pop(rid, None)
        what = self.driver.describe()
        if answer is None:
            raise HardwareError(f"{what}: no result on {self.topic} within {timeout:g} s")
        if answer.get("ok") is not True:
            raise HardwareError(f"{what}: {answer.get('error') or 'refused'}")
        return answer
