"""The ROS 2 mapping (docs/ros2.md), shared by the `ros2` drivers (`components/ros2`) and the simulator served as
ROS 2 robots (`drd.sim.ros2`), so that the two sides cannot disagree: topic names and types, the QoS of each,
the conversions (poses, yaw, stamps, scans, images), the vision_msgs definitions, the drivers' options
(`Ros2Options`), and `Ros2Link`, what a host's `ros2` drivers share: one zenoh session per robot router, one node
per robot namespace, one clock and one thread that runs their watchdogs.
"""

from __future__ import annotations

import atexit
import functools
import logging
import math
import os
import threading
import time
import weakref
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drd.bus.ros2 import MessageCallback, MessageInfo, MessageTypes, Publisher, QoS, Ros2Node, Ros2Session
from drd.bus.ros2 import Subscription as Ros2Subscription
from drd.errors import ConfigurationError
from drd.hosts import Device
from drd.hw.interfaces import HardwareError

log = logging.getLogger("drd.hw.ros2")

TWIST = "geometry_msgs/msg/Twist"
ODOMETRY = "nav_msgs/msg/Odometry"
BATTERY = "sensor_msgs/msg/BatteryState"
LASER_SCAN = "sensor_msgs/msg/LaserScan"
IMAGE = "sensor_msgs/msg/Image"
DETECTIONS = "vision_msgs/msg/Detection2DArray"
STRING = "std_msgs/msg/String"
BOOL = "std_msgs/msg/Bool"
CLOCK = "rosgraph_msgs/msg/Clock"

#: rclcpp's default profile (reliable, keep last 10) and SensorDataQoS (best effort, keep last 5).
RELIABLE = QoS()
SENSOR = QoS.sensor_data()

#: Topic key -> (default topic, relative to the robot's namespace; type; QoS). docs/ros2.md's table.
TOPICS: dict[str, tuple[str, str, QoS]] = {
    "cmd_vel": ("cmd_vel", TWIST, RELIABLE),
    "odom": ("odom", ODOMETRY, RELIABLE),
    "battery": ("battery_state", BATTERY, RELIABLE),
    "scan": ("scan", LASER_SCAN, SENSOR),
    "image": ("camera/image_raw", IMAGE, SENSOR),
    "detections": ("camera/detections", DETECTIONS, SENSOR),
    "magazine": ("launcher/magazine", STRING, RELIABLE),
    "launch": ("launcher/launch", STRING, RELIABLE),
    "launch_result": ("launcher/result", STRING, RELIABLE),
    "jump": ("foot/jump", STRING, RELIABLE),
    "jump_result": ("foot/result", STRING, RELIABLE),
    "link": ("radio/link", BOOL, RELIABLE),  # one topic per peer: radio/link/<peer>
}
#: The topics that may be turned off (`topics: {battery: false}`).
OPTIONAL_TOPICS = frozenset({"battery", "detections"})

#: vision_msgs 4.1.1 (ROS 2 Jazzy's), the fields of each .msg file (github.com/ros-perception/vision_msgs, branch
#: ros2, vision_msgs/msg/): rosbags does not ship vision_msgs. In dependency order.
VISION_MSGS: dict[str, str] = {
    "vision_msgs/msg/Point2D": "float64 x\nfloat64 y\n",
    "vision_msgs/msg/Pose2D": "vision_msgs/Point2D position\nfloat64 theta\n",
    "vision_msgs/msg/BoundingBox2D": "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": "ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n",
    "vision_msgs/msg/Detection2D": "std_msgs/Header header\nObjectHypothesisWithPose[] results\nBoundingBox2D bbox\n"
                                   "string id\n",
    "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\nDetection2D[] detections\n",
}


@functools.cache
def message_types() -> MessageTypes:
    """A Jazzy type store with vision_msgs added: the one sessions of the mapping's topics are opened with (the
    shared `jazzy()` store stays rosbags' own)."""
    types = MessageTypes()
    for name, text in VISION_MSGS.items():
        types.register(name, text)
    return types


# -- conversions ----------------------------------------------------------------------------------------

Pose = tuple[float, float, float]


def compose(origin: Pose, pose: Pose) -> Pose:
    """`pose` (in the frame whose pose is `origin`) seen from `origin`'s own frame: origin ∘ pose."""
    ox, oy, oa = origin
    x, y, a = pose
    c, s = math.cos(oa), math.sin(oa)
    return ox + c * x - s * y, oy + s * x + c * y, wrap(oa + a)


def relative(origin: Pose, pose: Pose) -> Pose:
    """The inverse of `compose`: `pose` seen from the frame whose pose is `origin`."""
    ox, oy, oa = origin
    dx, dy = pose[0] - ox, pose[1] - oy
    c, s = math.cos(oa), math.sin(oa)
    return c * dx + s * dy, -s * dx + c * dy, wrap(pose[2] - oa)


def wrap(angle: float) -> float:
    """The same angle in [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def quaternion(yaw: float) -> dict[str, float]:
    """A rotation of `yaw` about z, as geometry_msgs/Quaternion fields."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def yaw_of(q: Any) -> float:
    """The yaw of a geometry_msgs/Quaternion (the rotation about z; roll and pitch ignored)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def stamp(t: float) -> dict[str, int]:
    """builtin_interfaces/Time fields of `t` seconds: the nearest nanosecond, carried into the seconds (sim time
    adds up in floats, so 5 s is 4.999999999999998: that is {sec: 5, nanosec: 0}, not {4, 999999999})."""
    sec = math.floor(t)
    nanosec = round((t - sec) * 1e9)  # t - sec is exact; the product is within half an ulp of the true one
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return {"sec": int(sec), "nanosec": int(nanosec)}


def scan_ranges(ranges: Any, range_min: float, range_max: float) -> tuple[float, ...]:
    """A LaserScan's ranges as drd reads them (REP 117): +inf is `range_max` (nothing within range), -inf is 0 (too
    close), finite values are clipped to [0, range_max]. NaN is an invalid or missing reading, never free space: a
    NaN beam reads 0, as something at the sensor, so no behavior drives into what the laser could not see; a scan
    with most beams NaN is a faulted laser, refused as a stale one is (HardwareError: the reading fails, and the
    behavior with it, so its robot stops)."""
    r = np.asarray(ranges, dtype=np.float64)
    invalid = np.isnan(r)
    if r.size and 2 * int(invalid.sum()) > r.size:
        raise HardwareError(f"the laser gives no valid reading: {int(invalid.sum())} of {r.size} beams are NaN"
                            " (REP 117: invalid or missing)")
    r = np.clip(np.where(invalid, 0.0, r), 0.0, range_max)  # +inf -> range_max, -inf -> 0
    return tuple(r.tolist())


#: Bytes per pixel and the weights of the channels, per Image encoding drd reads.
_ENCODINGS: dict[str, tuple[type[np.generic], int, tuple[float, ...], float]] = {
    "mono8": (np.uint8, 1, (1.0,), 255.0),
    "8UC1": (np.uint8, 1, (1.0,), 255.0),
    "mono16": (np.uint16, 1, (1.0,), 65535.0),
    "16UC1": (np.uint16, 1, (1.0,), 65535.0),
    "rgb8": (np.uint8, 3, (0.299, 0.587, 0.114), 255.0),
    "bgr8": (np.uint8, 3, (0.114, 0.587, 0.299), 255.0),
    "rgba8": (np.uint8, 4, (0.299, 0.587, 0.114, 0.0), 255.0),
    "bgra8": (np.uint8, 4, (0.114, 0.587, 0.299, 0.0), 255.0),
    "32FC1": (np.float32, 1, (1.0,), 1.0),
}


def image_columns(msg: Any) -> np.ndarray[Any, np.dtype[np.float64]]:
    """The mean brightness (0..1) of each column of a sensor_msgs/Image, left to right; ValueError if unreadable."""
    spec = _ENCODINGS.get(msg.encoding)
    if spec is None:
        raise ValueError(f"image encoding {msg.encoding!r} is not read (use one of {', '.join(_ENCODINGS)})")
    dtype, channels, weights, scale = spec
    width, height, step = int(msg.width), int(msg.height), int(msg.step)
    item = np.dtype(dtype).itemsize
    if width < 1 or height < 1 or step < width * channels * item or len(msg.data) < step * height:
        raise ValueError(f"a {width}x{height} {msg.encoding} image with step {step} and {len(msg.data)} bytes")
    raw = np.asarray(msg.data, dtype=np.uint8)[: step * height].reshape(height, step)[:, : width * channels * item]
    kind = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<") if item > 1 else np.dtype(dtype)
    pixels = np.ascontiguousarray(raw).view(kind).reshape(height, width, channels).astype(np.float64)
    luma = pixels @ np.asarray(weights, dtype=np.float64)
    out: np.ndarray[Any, np.dtype[np.float64]] = np.clip(luma.mean(axis=0) / scale, 0.0, 1.0)
    return out


def strips(columns: Sequence[float] | np.ndarray[Any, Any], n: int) -> list[float]:
    """The mean of `n` equal vertical strips of an image's columns (left to right), RIGHT TO LEFT as drd orders
    regions (`Camera.brightness`)."""
    cols = np.asarray(columns, dtype=np.float64)
    if not 1 <= n <= len(cols):
        raise ValueError(f"n_regions must be in [1, {len(cols)}] (the image's width), got {n}")
    edges = np.linspace(0, len(cols), n + 1)
    bounds = [int(round(e)) for e in edges]
    out = [float(cols[a:max(b, a + 1)].mean()) for a, b in zip(bounds, bounds[1:], strict=False)]
    return out[::-1]


# -- options --------------------------------------------------------------------------------------------

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
#: Option -> (default, check, what it must be). Topics, origin and classes are checked on their own.
_NUMBERS: dict[str, tuple[float, str]] = {
    "watchdog": (0.5, "a positive number of seconds"),
    "max_rate": (20.0, "a positive number of messages a second"),
    "max_age": (0.5, "a positive number of seconds"),
    "status_max_age": (2.0, "a positive number of seconds"),
    "action_timeout": (2.0, "a positive number of seconds"),
}
_TEXTS = ("endpoint", "namespace", "odom_frame", "base_frame", "scan_frame", "camera_frame", "peer")
OPTION_KEYS = frozenset({*_NUMBERS, *_TEXTS, "domain_id", "topics", "origin", "classes"})


class OptionsError(ConfigurationError, ValueError):
    """`driver_options` a `ros2` driver refuses: every problem, each naming its key."""

    def __init__(self, device: str, problems: Sequence[str]) -> None:
        super().__init__(f"{device}: " + "; ".join(problems), where=device)
        self.problems = list(problems)


@dataclass(frozen=True)
class Ros2Options:
    """One `ros2` device's driver options, checked (docs/ros2.md)."""

    endpoint: str = DEFAULT_ENDPOINT
    domain_id: int = 0
    namespace: str = ""
    topics: Mapping[str, str | None] = field(default_factory=dict)
    origin: Pose = (0.0, 0.0, 0.0)
    frames: Mapping[str, str] = field(default_factory=dict)
    watchdog: float = 0.5
    max_rate: float = 20.0
    max_age: float = 0.5
    status_max_age: float = 2.0
    action_timeout: float = 2.0
    classes: tuple[str, ...] = ("person",)
    peer: str | None = None

    def topic(self, key: str) -> str | None:
        """The topic of `key` (relative to the namespace unless absolute), None when turned off."""
        return self.topics.get(key, TOPICS[key][0])

    @classmethod
    def of(cls, device: Device, robot_id: str) -> Ros2Options:
        """The device's options for robot `robot_id` (its namespace by default); OptionsError lists every problem."""
        problems = check_options(device.driver_options)
        if problems:
            raise OptionsError(device.id, problems)
        o = device.driver_options
        env_domain = os.environ.get("ROS_DOMAIN_ID", "")
        domain = o.get("domain_id", int(env_domain) if env_domain.isdigit() else 0)
        x, y, heading = (float(v) for v in o.get("origin", (0.0, 0.0, 0.0)))  # type: ignore[attr-defined]
        topics = {str(k): (None if v is False else str(v)) for k, v in dict(o.get("topics") or {}).items()}  # type: ignore[call-overload]
        return cls(
            endpoint=str(o.get("endpoint", DEFAULT_ENDPOINT)), domain_id=int(domain),  # type: ignore[call-overload]
            namespace=str(o.get("namespace", robot_id)), topics=topics,
            origin=(x, y, math.radians(heading)),
            frames={k: str(o[k]) for k in ("odom_frame", "base_frame", "scan_frame", "camera_frame") if k in o},
            **{k: float(o.get(k, d)) for k, (d, _) in _NUMBERS.items()},  # type: ignore[arg-type]
            classes=tuple(str(c) for c in o.get("classes", ("person",))),  # type: ignore[attr-defined]
            peer=str(o["peer"]) if "peer" in o else None,
        )


def _number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def check_options(options: Mapping[str, object]) -> list[str]:
    """What is wrong with a `ros2` device's `driver_options` (empty: nothing), each problem naming its key."""
    problems = [f"driver_options.{k}: unknown option (known: {', '.join(sorted(OPTION_KEYS))})"
                for k in options if k not in OPTION_KEYS]
    for k, (_default, what) in _NUMBERS.items():
        if k in options and not (_number(options[k]) and float(options[k]) > 0):  # type: ignore[arg-type]
            problems.append(f"driver_options.{k}: expected {what}, got {options[k]!r}")
    for k in _TEXTS:
        if k in options and not (isinstance(options[k], str) and options[k]):
            problems.append(f"driver_options.{k}: expected a non-empty string, got {options[k]!r}")
    domain = options.get("domain_id", 0)
    if isinstance(domain, bool) or not isinstance(domain, int) or not 0 <= domain <= 232:
        problems.append(f"driver_options.domain_id: expected a ROS domain id, 0 to 232, got {domain!r}")
    origin = options.get("origin", (0, 0, 0))
    if not isinstance(origin, list | tuple) or len(origin) != 3 or not all(_number(v) for v in origin):
        problems.append(f"driver_options.origin: expected [x, y, heading] (m, m, degrees), got {origin!r}")
    classes = options.get("classes", ["person"])
    if not isinstance(classes, list | tuple) or not all(isinstance(c, str) and c for c in classes):
        problems.append(f"driver_options.classes: expected a list of class ids, got {classes!r}")
    problems += _check_topics(options.get("topics", {}))
    return problems


def _check_topics(topics: object) -> list[str]:
    if not isinstance(topics, Mapping):
        return [f"driver_options.topics: expected a mapping of topic keys to names, got {topics!r}"]
    problems = []
    for k, v in topics.items():
        if k not in TOPICS:
            problems.append(f"driver_options.topics.{k}: unknown topic key (known: {', '.join(sorted(TOPICS))})")
        elif v is False and k in OPTIONAL_TOPICS:
            continue
        elif not isinstance(v, str) or not v:
            off = " or false" if k in OPTIONAL_TOPICS else ""
            problems.append(f"driver_options.topics.{k}: expected a topic name{off}, got {v!r}")
    return problems


# -- the link -------------------------------------------------------------------------------------------

class Ros2Link:
    """What the `ros2` drivers of one process share: sessions, nodes, a clock, and the watchdogs' thread.

    - `session(endpoint)`: one zenoh client session per robot router (or, when built with `session=`, that one
      session for every endpoint: the dry-run's, served in the same process);
    - `node(endpoint, domain, namespace)`: one ROS 2 node, `/<namespace>/drd`, per robot namespace;
    - `now()`: the clock drivers measure data age and silences with (the monotonic clock; the dry-run's sim time);
    - `watch(check)`: `check()` runs every `period` s on the link's thread (`period=None`: only when someone
      calls `tick()`, as the dry-run's lockstep does after each step); held weakly, so a dropped driver stops;
    - counts of what the drivers sent and received per key, for a lockstep to wait on (`sent`, `received`).
    """

    def __init__(self, *, clock: Callable[[], float] = time.monotonic, session: Ros2Session | None = None,
                 period: float | None = 0.02, types: MessageTypes | None = None) -> None:
        self.now = clock
        self.types = types or message_types()
        self.period = period
        self._shared = session
        self._sessions: dict[str, Ros2Session] = {}
        self._nodes: dict[tuple[str, int, str], Ros2Node] = {}
        self._lock = threading.Lock()
        self._checks: list[weakref.WeakMethod[Callable[[], None]]] = []
        self.changed = threading.Condition()
        self.sent: Counter[str] = Counter()
        self.received: Counter[str] = Counter()
        self.listeners: Counter[str] = Counter()  # subscriptions per key
        self._total = 0  # messages received in all
        self._target = 0  # the total a waiter waits for (0: wake at every message)
        self._closed = threading.Event()
        self._thread: threading.Thread | None = None

    def session(self, endpoint: str) -> Ros2Session:
        if self._shared is not None:
            return self._shared
        with self._lock:
            if self._closed.is_set():
                raise RuntimeError("the ROS 2 link is closed")
            found = self._sessions.get(endpoint)
            if found is None:
                found = self._sessions[endpoint] = Ros2Session.connect(endpoint, types=self.types)
            return found

    def connected(self, endpoint: str) -> bool:
        """Whether this link has a session to `endpoint` open now and linked to its router (a client session whose
        router went away drops what it puts, silently)."""
        with self._lock:
            found = self._shared or self._sessions.get(endpoint)
        if found is None:
            return False
        try:
            return bool(list(found.bus.session.info.routers_zid()))
        except Exception:  # closed meanwhile
            return False

    def source(self, endpoint: str) -> str:
        """Where a robot's messages come from, in words: its router, or the dry-run's simulator (one session)."""
        return "the dry-run's simulated robot" if self._shared is not None else f"the robot's router at {endpoint}"

    def node(self, endpoint: str, domain_id: int, namespace: str) -> Ros2Node:
        session = self.session(endpoint)
        with self._lock:
            key = (endpoint if self._shared is None else "", domain_id, namespace)
            found = self._nodes.get(key)
            if found is None:
                found = self._nodes[key] = Ros2Node(session, "drd", namespace, domain_id)
            return found

    def publisher(self, node: Ros2Node, topic: str, type_name: str, qos: QoS) -> Publisher:
        return node.publisher(topic, type_name, qos)

    def publish(self, publisher: Publisher, message: object) -> None:
        publisher.publish(message)
        with self.changed:
            self.sent[publisher.key] += 1

    def subscribe(self, node: Ros2Node, topic: str, type_name: str, qos: QoS,
                  callback: MessageCallback) -> Ros2Subscription:
        def counted(message: Any, info: MessageInfo) -> None:
            try:
                callback(message, info)
            finally:
                with self.changed:
                    self.received[info.key] += 1
                    self._total += 1
                    if self._total >= self._target:  # wake a lockstep's wait once, not at every message
                        self.changed.notify_all()

        sub = node.subscribe(topic, type_name, counted, qos)
        with self.changed:
            self.listeners[sub.key] += 1
        return sub

    def unsubscribed(self, key: str) -> None:
        with self.changed:
            self.listeners[key] -= 1

    def wait_received(self, published: Mapping[str, int], timeout: float) -> list[str]:
        """Wait (up to `timeout` s) until every subscription here has received as many messages of its key as
        `published` says were sent; the keys still short (empty when all arrived)."""
        deadline = time.monotonic() + timeout
        with self.changed:
            wanted = {k: n * published.get(k, 0) for k, n in self.listeners.items() if n > 0}
            self._target = self._total + sum(max(0, w - self.received[k]) for k, w in wanted.items())
            try:
                while True:
                    short = [k for k, w in wanted.items() if self.received[k] < w]
                    left = deadline - time.monotonic()
                    if not short or left <= 0:
                        return short
                    self.changed.wait(left)
            finally:
                self._target = 0

    def watch(self, check: Callable[[], None]) -> None:
        """Run `check` (a bound method: held weakly) periodically, or at each `tick()`."""
        with self._lock:
            self._checks.append(weakref.WeakMethod(check))
            if self.period is not None and self._thread is None and not self._closed.is_set():
                self._thread = threading.Thread(target=self._run, name="drd ros2 watchdog", daemon=True)
                self._thread.start()

    def tick(self) -> None:
        """Run every live check once, now (a check that raises is logged, never stops the others)."""
        with self._lock:
            refs = list(self._checks)
        dead = []
        for ref in refs:
            check = ref()
            if check is None:
                dead.append(ref)
                continue
            try:
                check()
            except Exception:
                log.exception("a ros2 driver's watchdog raised")
        if dead:
            with self._lock:
                self._checks = [r for r in self._checks if r not in dead]

    def _run(self) -> None:
        while not self._closed.wait(self.period):
            self.tick()

    def close(self) -> None:
        """Close the nodes and the sessions this link opened (not a shared session), stop the thread."""
        self._closed.set()
        with self._lock:
            nodes, self._nodes = list(self._nodes.values()), {}
            sessions, self._sessions = list(self._sessions.values()), {}
            thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)
        for node in nodes:
            node.close()
        for session in sessions:
            session.close()


_DEFAULT: Ros2Link | None = None
_DEFAULT_LOCK = threading.Lock()


def default_link() -> Ros2Link:
    """The process's own link, for `ros2` drivers built with no backend (a daemon's): closed at exit."""
    global _DEFAULT
    with _DEFAULT_LOCK:
        if _DEFAULT is None:
            _DEFAULT = Ros2Link()
            atexit.register(_DEFAULT.close)
        return _DEFAULT
