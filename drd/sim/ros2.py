"""The simulator served as ROS 2 robots over rmw_zenoh (docs/ros2.md): `drd sim --ros2`, and the dry-run's lockstep.

`ServedRobots` gives every simulated robot of a hosts file the topics of the mapping (`drd.hw.ros2`): it
publishes each robot's odometry, battery, scan, camera image and detections, magazine and radio links when
`publish()` is called, stamped with sim time (and `/clock`), and obeys `cmd_vel`, launch and jump requests. Two
ways to run it:

- `serve(...)`: real time (or `speed` times it), on a zenoh *router* session that ROS 2 tools and drd's `ros2`
  drivers connect to, until a stop event: what `drd sim --ros2` runs;
- `LockstepSimulation`: a `Simulation` whose every `step` waits for the commands drd's drivers sent, steps, serves
  every robot's state and waits until the drivers have it. The dry-run uses it for `driver: ros2` devices: every
  command and reading goes through rmw_zenoh messages, and the run is as reproducible as with `sim` drivers;
- `ServedSimulationService`: a cluster's simulator host with `simulator: {ros2: true, listen: ...}` in hosts.yaml.
  The world the controller resets and steps is served on that router: each step carries out the commands received
  since the last one, steps, and publishes the state, as a robot whose clock is the cluster's.

Robots a hosts file does not name, and devices it does not give them, are not served. A lost robot is silent (its
drivers' data go stale, as a real robot's would).
"""

from __future__ import annotations

import json
import logging
import math
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drd.bus import Bus
from drd.bus.base import BusError
from drd.bus.ros2 import Durability, MessageInfo, Publisher, QoS, Ros2Node, Ros2Session
from drd.hosts import Cluster, Device, Robot
from drd.hw import ros2 as mapping
from drd.hw.ros2 import Pose, Ros2Link, Ros2Options
from drd.sim.physics import MAX_LAUNCH, Simulation
from drd.sim.robots import SimError
from drd.sim.service import SimReply, SimRequest, SimulationService, world_dirs
from drd.sim.world import hosts_charges

log = logging.getLogger("drd.sim.ros2")

#: The transforms' type (/tf and /tf_static).
TF = "tf2_msgs/msg/TFMessage"
#: Seconds of sim time between two publications of every robot's state (10 Hz: the dry-run's control period).
PUBLISH_PERIOD = 0.1
#: The served camera image: this many columns, one row, `32FC1` (one pixel per region the behaviors look at).
IMAGE_WIDTH = 16
#: How long a lockstep waits for the other side before it says so and goes on.
LOCKSTEP_WAIT = 5.0
#: The zenoh settings of the lockstep's two sessions: a message that waits for room in a link's queue (its sending
#: thread starved of CPU on a loaded machine) waits up to `LOCKSTEP_WAIT` instead of rmw_zenoh's 1 ms, then is
#: dropped. A dropped reading would leave the lockstep one message short for the rest of the run (every step then
#: waits `LOCKSTEP_WAIT`). Local settings: nothing on the wire changes.
LOCKSTEP_ZENOH = {"scouting/delay": 0,
                  "transport/link/tx/queue/congestion_control/drop/wait_before_drop": int(LOCKSTEP_WAIT * 1e6)}
#: A served base stops once its `cmd_vel` has been quiet this many seconds of sim time, as ros2_control's
#: `diff_drive_controller` does by default (`cmd_vel_timeout`): the robot's own last line (docs/ros2.md "Safety").
CMD_VEL_TIMEOUT = 0.5

#: The battery and the radio links go out every this many publications (0.5 s of sim time: well within a driver's
#: `status_max_age`); the magazine too, and at once when a launch changes it.
STATUS_EVERY = 5


@dataclass
class _Served:
    """What one robot is served as: its node and its topics (name, type), for the CLI's report."""

    node: Ros2Node
    topics: list[tuple[str, str]] = field(default_factory=list)


class ServedRobots:
    """Every robot of `cluster` that lives in `sim`, served on `session` in ROS domain `domain_id`."""

    def __init__(self, sim: Simulation, cluster: Cluster, session: Ros2Session, *, domain_id: int = 0,
                 lockstep: bool = False) -> None:
        self.sim, self.session, self.domain_id, self.lockstep = sim, session, domain_id, lockstep
        self.types = session.types
        if not self.types.known(mapping.DETECTIONS):
            raise ValueError("serve robots on a session opened with types=drd.hw.ros2.message_types() (vision_msgs)")
        self.lock = threading.RLock()  # the simulation: one caller at a time (zenoh's threads and the stepper)
        self.changed = threading.Condition()
        self.received: Counter[str] = Counter()  # commands received per key
        self.published: Counter[str] = Counter()  # messages published per key
        self._queue: list[Callable[[], None]] = []
        self._streams: list[tuple[Callable[[Any], None], bool]] = []  # (send, a status stream)
        self._publishers: dict[str, Publisher] = {}  # the streams' publishers by key
        self._count = 0  # publications so far
        self.commanded: dict[str, float] = {}  # robot -> sim time its last cmd_vel was carried out (while moving)
        self.timeouts = 0  # bases stopped by their cmd_vel timeout
        self.robots: dict[str, _Served] = {}
        self._nodes: dict[str, Ros2Node] = {}
        self.rangers = {r.id for r in sim.world.rangers}
        devices = {d.id: d for h in cluster.hosts for d in h.devices}
        root = Ros2Node(session, "drd_sim", "", domain_id)
        self._nodes[""] = root
        self._clock = root.publisher("/clock", mapping.CLOCK, QoS(depth=1))
        self._time, self._header = self.msg("builtin_interfaces/msg/Time"), self.msg("std_msgs/msg/Header")
        # tf2's broadcasters' QoS: /tf reliable, keep last 100; /tf_static also transient local, keep last 1 (a
        # late listener, rviz, gets the sensors' frames)
        self._tf = root.publisher("/tf", TF, QoS(depth=100))
        self._tf_static = root.publisher("/tf_static", TF, QoS(durability=Durability.TRANSIENT_LOCAL, depth=1))
        self.moving: list[Callable[[], tuple[str, str, Pose]]] = []  # per robot: (odom, base_link, pose in odom)
        self.fixed: list[tuple[str, str]] = []  # (base_link, sensor frame): the sensors sit at the robot's centre
        self.bases: dict[str, str] = {}  # robot -> its base frame
        try:
            for robot in cluster.robots:
                if robot.id in sim.robots:
                    self._serve(robot, devices)
        except BaseException:
            self.close()
            raise
        self._tf_static.publish_cdr(self.types.serialize(self._transforms(self.now(), [
            (parent, child, (0.0, 0.0, 0.0)) for parent, child in self.fixed]), TF))

    # -- building ----------------------------------------------------------------------------------------

    def _serve(self, robot: Robot, devices: Mapping[str, Device]) -> None:
        parts = [(d, Ros2Options.of(d, robot.id) if d.driver == "ros2" else Ros2Options(namespace=robot.id))
                 for device_id in robot.parts.values() if (d := devices.get(device_id)) is not None]
        # the frames the hosts file names (a real robot's, kept for its dry-run: ROS 2 audit 17, D3), else the robot's
        self.bases[robot.id] = next((o.frames["base_frame"] for _, o in parts if "base_frame" in o.frames),
                                    f"{robot.id}/base_link")
        for device, opts in parts:
            builder = _BUILDERS.get(device.type)
            if builder is not None:
                builder(self, robot.id, device, opts)

    def node(self, rid: str, opts: Ros2Options) -> Ros2Node:
        ns = opts.namespace or rid
        found = self._nodes.get(ns)
        if found is None:
            found = self._nodes[ns] = Ros2Node(self.session, "drd_sim", ns, self.domain_id)
        self.robots.setdefault(rid, _Served(found))
        return found

    def publisher(self, rid: str, opts: Ros2Options, key: str, suffix: str = "") -> Publisher | None:
        topic = opts.topic(key)
        if topic is None:
            return None
        _, type_name, qos = mapping.TOPICS[key]
        pub = self.node(rid, opts).publisher(topic + suffix, type_name, qos)
        self.robots[rid].topics.append((pub.topic.name, type_name))
        return pub

    def subscribe(self, rid: str, opts: Ros2Options, key: str, handle: Callable[[Any], None]) -> None:
        topic = opts.topic(key)
        if topic is None:
            return
        _, type_name, qos = mapping.TOPICS[key]

        def counted(msg: Any, info: MessageInfo) -> None:
            try:
                handle(msg)
            except Exception:
                log.exception("served %s: handling a message on %s", rid, info.key)
            finally:
                with self.changed:
                    self.received[info.key] += 1
                    self.changed.notify_all()

        sub = self.node(rid, opts).subscribe(topic, type_name, counted, qos)
        self.robots[rid].topics.append((sub.topic.name, type_name))

    def msg(self, type_name: str) -> Any:
        """The message class of `type_name` (built directly: `MessageTypes.make` is for the rare messages)."""
        return self.types.store.types[type_name]

    def header(self, st: Any, frame: str) -> Any:
        return self._header(stamp=st, frame_id=frame)

    def stream(self, pub: Publisher | None, make: Callable[[Any], Any], status: bool = False) -> Callable[[Any], None]:
        """Publish `make(stamp)` on `pub` at every `publish()` (every `STATUS_EVERY`th for a `status` stream; nothing
        when `make` raises SimError: a lost robot). Returns the sender, to publish at once."""
        types = self.types
        type_name = pub.topic.type_name if pub is not None else ""

        def send(st: Any) -> None:
            if pub is None:
                return
            try:
                message = make(st)
            except SimError:
                return
            pub.publish_cdr(types.serialize(message, type_name))
            with self.changed:
                self.published[pub.key] += 1

        if pub is not None:
            self._streams.append((send, status))
            self._publishers[pub.key] = pub
        return send

    def now(self) -> Any:
        """The stamp of the current sim time."""
        st = mapping.stamp(self.sim.time)
        return self._time(sec=st["sec"], nanosec=st["nanosec"])

    def command(self, fn: Callable[[], None]) -> None:
        """A setpoint from a subscriber: at once (real time) or at the next step (lockstep, in the stepper's thread)."""
        with self.lock:
            if self.lockstep:
                self._queue.append(fn)
            else:
                _quietly(fn)

    # -- running -----------------------------------------------------------------------------------------

    def apply(self) -> None:
        """Carry out the setpoints queued since the last step (lockstep)."""
        with self.lock:
            queue, self._queue = self._queue, []
            for fn in queue:
                _quietly(fn)

    def publish(self) -> None:
        """Every robot's state now, and `/clock`; first, a base whose `cmd_vel` went quiet is stopped (`quiet`)."""
        with self.lock:
            self._stop_quiet()
            st = self.now()
            status = self._count % STATUS_EVERY == 0
            self._count += 1
            for send, is_status in self._streams:
                if status or not is_status:
                    send(st)
            self._clock.publish_cdr(self.types.serialize(self.msg(mapping.CLOCK)(clock=st), mapping.CLOCK))
            if self.moving:
                self._tf.publish_cdr(self.types.serialize(self._transforms(st, _poses(self.moving)), TF))

    def _stop_quiet(self) -> None:
        """Stop each base whose last `cmd_vel` is `CMD_VEL_TIMEOUT` s of sim time old (called after every step, in
        each of the three ways the world is served): whoever drove it is gone, and a real base would stop too."""
        now = self.sim.time
        for rid, at in list(self.commanded.items()):
            if now - at < CMD_VEL_TIMEOUT - 1e-9:
                continue
            del self.commanded[rid]
            try:
                if self.sim.command(rid) == (0.0, 0.0):
                    continue
                self.sim.stop(rid)
            except SimError:  # lost meanwhile: nothing left to stop
                continue
            self.timeouts += 1
            log.info("served %s: no cmd_vel for %.2f s of sim time: stopped (cmd_vel timeout)", rid, now - at)

    def _transforms(self, st: Any, frames: Iterable[tuple[str, str, Pose]]) -> Any:
        """A tf2_msgs/TFMessage of (parent, child, pose of child in parent) transforms, stamped `st` (REP 105)."""
        stamped, transform, vector, rotation = (self.msg(t) for t in (
            "geometry_msgs/msg/TransformStamped", "geometry_msgs/msg/Transform", "geometry_msgs/msg/Vector3",
            "geometry_msgs/msg/Quaternion"))
        return self.msg(TF)(transforms=[
            stamped(header=self.header(st, parent), child_frame_id=child, transform=transform(
                translation=vector(x=x, y=y, z=0.0), rotation=rotation(**mapping.quaternion(a))))
            for parent, child, (x, y, a) in frames])

    def wait_matched(self, keys: Iterable[str], timeout: float) -> list[str]:
        """Wait (up to `timeout` s) until the session knows a subscription to each of these keys that a stream
        publishes (a subscription declared elsewhere reaches the router a moment later; a put before that is lost);
        the keys still unmatched."""
        pubs = [p for k in keys if (p := self._publishers.get(k)) is not None]
        deadline = time.monotonic() + timeout
        while True:
            unmatched = [p.key for p in pubs if not p.matched()]
            if not unmatched or time.monotonic() > deadline:
                return unmatched
            time.sleep(0.001)

    def wait_received(self, sent: Mapping[str, int], timeout: float) -> list[str]:
        """Wait (up to `timeout` s) until every command of `sent` (key -> count) has arrived; the keys still short."""
        deadline = time.monotonic() + timeout
        with self.changed:
            while True:
                short = [k for k, n in sent.items() if self.received[k] < n]
                left = deadline - time.monotonic()
                if not short or left <= 0:
                    return short
                self.changed.wait(left)

    def close(self) -> None:
        for node in self._nodes.values():
            node.close()
        self._nodes = {}


def _poses(moving: Iterable[Callable[[], tuple[str, str, Pose]]]) -> list[tuple[str, str, Pose]]:
    """Each robot's odom -> base_link transform now; a lost robot's is left out (silent, as its topics)."""
    out = []
    for pose in moving:
        try:
            out.append(pose())
        except SimError:
            continue
    return out


def _quietly(fn: Callable[[], None]) -> None:
    try:
        fn()
    except SimError as e:  # a lost robot, a Scout still in its magazine: a real base would ignore it too
        log.debug("served simulator: %s", e)


def _option(device: Device, key: str, default: float) -> float:
    value = device.options.get(key, default)
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else default


# -- one builder per RC type ----------------------------------------------------------------------------------

def _drive(s: ServedRobots, rid: str, device: Device, opts: Ros2Options) -> None:
    sim, types = s.sim, s.types
    if "max_speed" in device.options:
        sim.set_max_speed(rid, _option(device, "max_speed", math.inf))
    origin = sim.origin(rid)
    start = (origin.x, origin.y, origin.heading)
    odom_frame, base_frame = opts.frames.get("odom_frame", f"{rid}/odom"), opts.frames.get("base_frame", s.bases[rid])
    odometry_, pose_, point, quaternion = (s.msg(t) for t in (
        mapping.ODOMETRY, "geometry_msgs/msg/Pose", "geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"))
    with_cov, twist_cov, twist, vector = (s.msg(t) for t in ("geometry_msgs/msg/PoseWithCovariance",
                                                             "geometry_msgs/msg/TwistWithCovariance", mapping.TWIST,
                                                             "geometry_msgs/msg/Vector3"))
    zeros = np.zeros(36, dtype=np.float64)

    def where() -> tuple[str, str, Pose]:
        p = sim.odometry(rid)
        return odom_frame, base_frame, mapping.relative(start, (p.x, p.y, p.heading))

    def odometry(st: Any) -> Any:
        v, omega = sim.command(rid)
        _, _, (x, y, a) = where()
        pose = pose_(position=point(x=x, y=y, z=0.0),
                     orientation=quaternion(x=0.0, y=0.0, z=math.sin(a / 2), w=math.cos(a / 2)))
        moving = twist(linear=vector(x=v, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=omega))
        return odometry_(header=s.header(st, odom_frame), child_frame_id=base_frame,
                         pose=with_cov(pose=pose, covariance=zeros), twist=twist_cov(twist=moving, covariance=zeros))

    def battery(st: Any) -> Any:
        nan = math.nan  # what the model does not know ("if unmeasured NaN", says the message definition)
        return types.make(mapping.BATTERY, header=s.header(st, base_frame), percentage=sim.battery(rid),
                          voltage=PACK_VOLTAGE, temperature=nan, current=nan, charge=nan, capacity=nan,
                          design_capacity=nan, power_supply_status=2,  # DISCHARGING
                          power_supply_technology=PACK_TECHNOLOGY, present=True)

    s.stream(s.publisher(rid, opts, "odom"), odometry)
    s.moving.append(where)
    s.stream(s.publisher(rid, opts, "battery"), battery, status=True)

    def cmd_vel(m: Any) -> None:
        v, omega = float(m.linear.x), float(m.angular.z)
        if not (math.isfinite(v) and math.isfinite(omega)):  # a NaN pose would end the world (clients audit D1)
            log.warning("served %s: cmd_vel refused: linear.x %r and angular.z %r must be finite", rid, v, omega)
            return
        def carry_out() -> None:
            sim.set_velocity(rid, v, omega)
            if v or omega:
                s.commanded[rid] = sim.time  # the timeout runs from here (`ServedRobots._stop_quiet`)
            else:
                s.commanded.pop(rid, None)

        s.command(carry_out)

    s.subscribe(rid, opts, "cmd_vel", cmd_vel)


#: `BatteryState.voltage`, which the message requires ("Mandatory"; only the other fields may be NaN): the world's
#: battery model (`drd.sim.model.Battery`) is a charge fraction with no electrical side, so this is the nominal
#: voltage of a 4-cell Li-ion pack (4 x 3.6 V, the pack of e.g. a TurtleBot 4), constant: it does not sag with
#: the charge, which `percentage` says.
PACK_VOLTAGE = 14.4
PACK_TECHNOLOGY = 2  # BatteryState.POWER_SUPPLY_TECHNOLOGY_LION, the chemistry that voltage is of


def _range_sensor(s: ServedRobots, rid: str, device: Device, opts: Ros2Options) -> None:
    sim = s.sim
    beams = int(_option(device, "beams", 181))
    max_range = _option(device, "max_range", 8.0)
    fov = math.radians(_option(device, "fov", 180.0))
    step = fov / (beams - 1) if beams > 1 else 0.0
    lo = -fov / 2 if beams > 1 else 0.0
    frame = opts.frames.get("scan_frame", f"{rid}/laser")
    s.fixed.append((s.bases[rid], frame))

    laser_scan, none = s.msg(mapping.LASER_SCAN), np.zeros(0, dtype=np.float32)

    def scan(st: Any) -> Any:
        r = np.asarray(sim.ranges(rid, beams, max_range, fov), dtype=np.float32)
        r[r >= np.float32(max_range)] = np.inf  # REP 117: nothing hit within range
        return laser_scan(header=s.header(st, frame), angle_min=lo, angle_max=lo + step * (beams - 1),
                          angle_increment=step, time_increment=0.0, scan_time=PUBLISH_PERIOD, range_min=0.0,
                          range_max=max_range, ranges=r, intensities=none)

    s.stream(s.publisher(rid, opts, "scan"), scan)


def _camera(s: ServedRobots, rid: str, device: Device, opts: Ros2Options) -> None:
    sim, types = s.sim, s.types
    fov = math.radians(_option(device, "fov", 60.0))
    resolution = int(_option(device, "resolution", 640))
    max_range = _option(device, "max_range", 10.0)
    min_light = _option(device, "min_light", 0.2)
    frame = opts.frames.get("camera_frame", f"{rid}/camera")
    s.fixed.append((s.bases[rid], frame))
    pixel = fov / resolution

    image_ = s.msg(mapping.IMAGE)

    def image(st: Any) -> Any:
        regions = sim.brightness(rid, fov, IMAGE_WIDTH, max_range)  # right to left; columns go left to right
        data = np.frombuffer(np.asarray(regions[::-1], dtype="<f4").tobytes(), np.uint8)
        return image_(header=s.header(st, frame), height=1, width=IMAGE_WIDTH, encoding="32FC1", is_bigendian=0,
                      step=4 * IMAGE_WIDTH, data=data)

    def detections(st: Any) -> Any:
        seen = []
        for d in sim.camera(rid, fov, max_range, min_light):
            bearing = round(d.bearing / pixel) * pixel  # to the pixel, as the sim camera reports it
            seen.append({"header": s.header(st, frame), "id": d.label, "results": [
                {"hypothesis": {"class_id": "person", "score": 1.0},
                 "pose": {"pose": {"position": {"x": d.distance * math.cos(bearing),
                                                "y": d.distance * math.sin(bearing)}}}}]})
        return types.make(mapping.DETECTIONS, header=s.header(st, frame), detections=seen)

    s.stream(s.publisher(rid, opts, "image"), image)
    s.stream(s.publisher(rid, opts, "detections"), detections)


def _result(s: ServedRobots, pub: Publisher | None, answer: dict[str, Any]) -> None:
    if pub is not None:
        pub.publish_cdr(s.types.serialize(s.types.make(mapping.STRING, data=json.dumps(answer)), mapping.STRING))


def _request(data: str, fields: Mapping[str, type]) -> dict[str, Any]:
    """A JSON request with these fields (and an `id`), or ValueError saying what is wrong."""
    request = json.loads(data)
    if not isinstance(request, dict) or "id" not in request:
        raise ValueError("a request is a JSON object with an id")
    for name, kind in fields.items():
        value = request.get(name)
        if not isinstance(value, kind) or isinstance(value, bool):
            raise ValueError(f"field {name}: expected a {kind.__name__ if isinstance(kind, type) else 'number'}")
    return request


def _launcher(s: ServedRobots, rid: str, device: Device, opts: Ros2Options) -> None:
    sim = s.sim
    max_range = min(MAX_LAUNCH, _option(device, "max_range", MAX_LAUNCH))
    origin = sim.origin(rid)
    start = (origin.x, origin.y, origin.heading)
    results = s.publisher(rid, opts, "launch_result")
    string = s.msg(mapping.STRING)
    magazine = s.stream(s.publisher(rid, opts, "magazine"),
                        lambda st: string(data=json.dumps(list(sim.magazine(rid)))), status=True)

    def launch(msg: Any) -> None:
        rid_ = None
        try:
            req = _request(msg.data, {"scout": str, "heading": (int, float), "distance": (int, float)})  # type: ignore[dict-item]
            rid_ = req["id"]
            distance = float(req["distance"])
            if distance <= 0:
                raise ValueError(f"launch distance must be positive, got {distance}")
            with s.lock:
                if req["scout"] not in sim.magazine(rid):
                    raise ValueError(f"{req['scout']} is not in {rid}'s magazine")
                distance = min(distance, max_range)
                p = sim.odometry(rid)
                flight = sim.launch(req["scout"], float(req["heading"]), distance)
                magazine(s.now())  # the magazine changed: said before the result
            a = p.heading + float(req["heading"])
            x, y, h = mapping.relative(start, (p.x + distance * math.cos(a), p.y + distance * math.sin(a), a))
            _result(s, results, {"id": rid_, "ok": True, "x": x, "y": y, "heading": h,
                                 "duration": flight.t1 - flight.t0})
        except (ValueError, SimError) as e:
            _result(s, results, {"id": rid_, "ok": False, "error": str(e)})

    s.subscribe(rid, opts, "launch", launch)


def _jump(s: ServedRobots, rid: str, device: Device, opts: Ros2Options) -> None:
    sim = s.sim
    max_distance = min(sim.max_jump, _option(device, "max_distance", sim.max_jump))
    results = s.publisher(rid, opts, "jump_result")

    def jump(msg: Any) -> None:
        rid_ = None
        try:
            req = _request(msg.data, {"dx": (int, float)})  # type: ignore[dict-item]
            rid_ = req["id"]
            dx = float(req["dx"])
            if not 0 < dx <= max_distance:
                raise ValueError(f"jump distance must be in (0, {max_distance:g}] m, got {dx}")
            with s.lock:
                sim.jump(rid, dx)
            _result(s, results, {"id": rid_, "ok": True})
        except (ValueError, SimError) as e:
            _result(s, results, {"id": rid_, "ok": False, "error": str(e)})

    s.subscribe(rid, opts, "jump", jump)


def _radio(s: ServedRobots, rid: str, device: Device, opts: Ros2Options) -> None:
    sim = s.sim
    reach = _option(device, "range", 30.0)
    peers = sorted(r for r in sim.robots if (r in s.rangers) != (rid in s.rangers))
    for peer in peers:
        scout, ranger = (rid, peer) if peer in s.rangers else (peer, rid)
        s.stream(s.publisher(rid, opts, "link", f"/{peer}"), _link(s, scout, ranger, reach), status=True)


def _link(s: ServedRobots, scout: str, ranger: str, reach: float) -> Callable[[Any], Any]:
    boolean = s.msg(mapping.BOOL)
    return lambda st: boolean(data=s.sim.radio_ok(scout, ranger, reach))


_BUILDERS: dict[str, Callable[[ServedRobots, str, Device, Ros2Options], None]] = {
    "Drive": _drive, "RangeSensor": _range_sensor, "Camera": _camera, "Launcher": _launcher, "Jump": _jump,
    "RadioChannel": _radio,
}


# -- real time ----------------------------------------------------------------------------------------------

def serve(served: ServedRobots, stop: threading.Event, *, speed: float = 1.0, period: float = PUBLISH_PERIOD,
          until: float | None = None) -> float:
    """Step the simulation `period` s of sim time at a time, at `speed` times real time, publishing after each step,
    until `stop` is set (or sim time reaches `until`); returns the sim time reached."""
    sim = served.sim
    served.publish()
    start, t0 = time.monotonic(), sim.time
    while not stop.is_set() and (until is None or sim.time < until - 1e-9):
        with served.lock:
            sim.step(period)
        served.publish()
        lag = (sim.time - t0) / speed - (time.monotonic() - start)
        if lag > 0:
            stop.wait(lag)
    return sim.time


def free_endpoint() -> str:
    """A loopback endpoint no one listens on now (the dry-run's private router)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{sock.getsockname()[1]}"


# -- lockstep (the dry-run) ------------------------------------------------------------------------------------

class LockstepSimulation(Simulation):
    """A `Simulation` whose robots are served over rmw_zenoh to the `ros2` drivers of this very process, in lockstep.

    `serve(cluster)` starts a private router on a free loopback port and returns the drivers' services
    (`{"ros2": Ros2Link}`: every `ros2` device, whatever its `endpoint`, reaches this router; its clock is sim
    time). Each `step` then: waits until the server got every command the drivers sent, carries them out, steps,
    publishes every robot's state, waits until every driver subscription has it, and runs the drivers' watchdogs.
    """

    served: ServedRobots | None = None
    link: Ros2Link | None = None
    services: dict[str, Any] | None = None  # the drivers' backends: {"ros2": link}
    #: Set to a list to get each step's phases: (commands' wait, physics, serving the state, readings' wait), s.
    timings: list[tuple[float, float, float, float]] | None = None
    _sessions: tuple[Ros2Session, ...] = ()

    def serve(self, cluster: Cluster, *, domain_id: int = 0, loopback: bool = True) -> dict[str, Any]:
        """Serve the robots of `cluster`; the services for their drivers. `loopback`: the drivers' session is a
        client of the router over TCP on loopback, as on a real robot (else they share the router's session)."""
        router, endpoint = None, ""
        for _attempt in range(3):  # a free port may be taken between the look and the listen
            endpoint = free_endpoint()
            try:
                router = Ros2Session.listen(endpoint, options=LOCKSTEP_ZENOH, types=mapping.message_types(),
                                            one_thread=True)
                break
            except BusError:
                continue
        if router is None:
            raise BusError("the dry-run's ROS 2 router could not listen on a loopback port")
        sessions = [router]
        try:
            client = Ros2Session.connect(endpoint, options=LOCKSTEP_ZENOH, types=router.types, one_thread=True) \
                if loopback else Ros2Session(router.bus, types=router.types, one_thread=True)
            sessions.insert(0, client)
            self.served = ServedRobots(self, cluster, router, domain_id=domain_id, lockstep=True)
        except BaseException:
            for session in sessions:
                session.close()
            raise
        self._sessions = tuple(sessions)
        self.link = Ros2Link(clock=lambda: self.time, session=client, period=None)
        self.services = {"ros2": self.link}
        return self.services

    def sync(self) -> None:
        """Publish the state now and wait until the drivers have it (before the first cycle)."""
        if self.served is None or self.link is None:
            return
        unmatched = self.served.wait_matched([k for k, n in self.link.listeners.items() if n > 0], LOCKSTEP_WAIT)
        if unmatched:
            log.warning("lockstep: the subscriptions to %s did not reach the served simulator", ", ".join(unmatched))
        self.served.publish()
        self._wait_readings()

    def step(self, dt: float | None = None) -> None:
        served, link = self.served, self.link
        if served is None or link is None:
            super().step(dt)
            return
        t0 = time.perf_counter()
        short = served.wait_received(dict(link.sent), LOCKSTEP_WAIT)
        if short:
            log.warning("lockstep: commands on %s did not reach the served simulator", ", ".join(short))
        t1 = time.perf_counter()
        served.apply()
        with served.lock:
            super().step(dt)
        t2 = time.perf_counter()
        served.publish()
        t3 = time.perf_counter()
        self._wait_readings()
        link.tick()
        if self.timings is not None:  # (commands' wait, physics, serving the state, readings' wait) in seconds
            self.timings.append((t1 - t0, t2 - t1, t3 - t2, time.perf_counter() - t3))

    def _wait_readings(self) -> None:
        assert self.served is not None and self.link is not None
        short = self.link.wait_received(dict(self.served.published), LOCKSTEP_WAIT)
        if short:
            log.warning("lockstep: %s did not reach the ros2 drivers", ", ".join(short))

    def close(self) -> None:
        if self.link is not None:
            self.link.close()
        if self.served is not None:
            self.served.close()
        for session in self._sessions:
            session.close()
        self.served, self.link, self._sessions = None, None, ()


# -- a cluster's simulator host (hosts.yaml `simulator: {ros2: true}`) ---------------------------------------------

class ServedSimulationService(SimulationService):
    """The simulator service of a cluster whose simulator host serves its world as ROS 2 robots.

    The controller resets and steps the world as on any simulator host (`SimulationService`); each reset also serves
    the new world's robots on this host's router (`listen`), and each step carries out the commands that arrived
    since the previous one (queued: zenoh's threads never touch the physics), steps, and publishes every robot's
    state. Nothing waits for the drivers: they may run on any host, as a real robot's nodes do not wait for drd. The
    served robots and the service share one lock, so a launch or a jump (carried out on arrival) and the `sim`
    drivers of this host never run beside a step.
    """

    def __init__(self, bus: Bus | None, cluster: Cluster, *, listen: str, domain_id: int = 0) -> None:
        self.team, self.domain_id = cluster, domain_id
        self.served: ServedRobots | None = None
        try:
            self.session = Ros2Session.listen(listen, types=mapping.message_types())
        except BusError as e:
            raise BusError(f"the simulator's ROS 2 router cannot listen on {listen} (hosts.yaml simulator.listen):"
                           f" {e}") from None
        try:
            super().__init__(bus, cluster.name, beside=world_dirs(cluster), charges=hosts_charges(cluster))
        except BaseException:
            self.session.close()
            raise
        self._shared = threading.RLock()  # the service's lock, shared with the served robots (re-entered)
        self._lock = self._shared  # type: ignore[assignment]

    def reset(self, world: str, seed: int = 0) -> SimReply:
        with self._lock:
            reply = super().reset(world, seed)
            old, self.served = self.served, None
            if old is not None:
                old.close()
            served = ServedRobots(self.sim, self.team, self.session, domain_id=self.domain_id, lockstep=True)
            served.lock = self._shared
            self.served = served
            served.publish()  # the start pose, before the first step
            return reply

    def handle(self, req: SimRequest) -> SimReply:
        if req.op != "step":
            return super().handle(req)
        with self._lock:
            served = self.served
            if served is not None and served.sim is self.sim:
                served.apply()
            reply = super().handle(req)
            if served is not None and served.sim is self.sim:
                served.publish()
            return reply

    def close(self) -> None:
        super().close()
        with self._lock:
            served, self.served = self.served, None
        if served is not None:
            served.close()
        self.session.close()
