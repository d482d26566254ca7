"""A run as an MCAP file, and served live to Foxglove (issue #13): what the mission did, where the robots were,
what their sensors read, and its ending.

Written with the Foxglove SDK (its MCAP writer, its WebSocket server and its standard schemas), read back with
`mcap`, so any MCAP tool (Foxglove, `ros2 bag`, PlotJuggler, the `mcap` CLI) opens it. Message log times are sim
time, in the mission's seconds. `docs/recording.md` says what each channel holds; in short:

- `/drd/records`: every trace record, JSON (`docs/trace.md`: `kind`, `at`, `path`, its fields, `mission`);
- `/drd/active`: each mission's active configuration at each instant it changed (JSON: the active leaves and their
  state, what each behavior holds, who waits behind whom), kept from the records as they are written;
- `/drd/log`: the records' `log` lines as `foxglove.Log` (the Log panel);
- `/drd/world`: `foxglove.SceneUpdate`: the walls, doors (their colour their state, changed when an injection
  changes one), rooms, obstacles, and a body for each robot and intruder, locked to its frame; a camera's field of
  view once it is first read;
- `/drd/tf`: `foxglove.FrameTransforms` each control cycle: every robot's and intruder's pose that changed since
  the cycle before (all of them every second, so a viewer that joins late has them all within a second);
- `/drd/trails`: `foxglove.SceneUpdate`: each robot's path, one piece per second of sim time;
- `/drd/scan/<robot>`: `foxglove.LaserScan`, each scan a behavior read (at most one per robot per control cycle);
- `/drd/camera`, `/drd/light`: JSON: what each camera saw (people: bearing, distance, light) and its region
  brightness; `/drd/seen`: `foxglove.SceneUpdate`: a line from the camera to each person it sees, for 0.3 s;
- `/drd/flights`: JSON: each launch and jump, then its landing;
- `/drd/hosts`, `/drd/hosts/load`, `/drd/placements`: JSON, a cluster run's hosts (up or down), their load
  reports, and where each component instance runs;
- `/drd/runs`: one JSON message per mission when the run ends: what the records cannot say (its id, priority,
  speed, wall time, the injections, where each placed Scout ended), so `replay` rebuilds the same report.

The sensors are recorded as the drivers read them, by tapping the simulation's sensor calls (`Recorder.watch`): no
second ray cast, and no reading changed (a reading is a function of the instant: `drd.sim.physics`). The MCAP writer
indexes the file as it goes (chunks, flushed each second of sim time), so a file cut short by a crash is still
readable up to its last chunk.
"""

from __future__ import annotations

import atexit
import bisect
import json
import logging
import math
import re
import shutil
import struct
import threading
import time
import weakref
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import orjson

from drd import outputs
from drd.errors import ConfigurationError
from drd.explain import Waiters, within
from drd.runtime import records as rec
from drd.sim.model import INTRUDER_RADIUS, RANGER_RADIUS, SCOUT_RADIUS, DoorState, World
from drd.sim.observe import SCAN_EVERY, SensorTap
from drd.tracecheck import record_problem

RECORDS, TF, RUNS, WORLD = "/drd/records", "/drd/tf", "/drd/runs", "/drd/world"
ACTIVE, LOG, TRAILS = "/drd/active", "/drd/log", "/drd/trails"
SCAN, CAMERA, LIGHT, SEEN, FLIGHTS = "/drd/scan/", "/drd/camera", "/drd/light", "/drd/seen", "/drd/flights"
HOSTS, LOADS, PLACEMENTS = "/drd/hosts", "/drd/hosts/load", "/drd/placements"
WORLD_ATTACHMENT = "world.yaml"
#: Chunks of this size (uncompressed), and a flush every this many seconds of sim time.
CHUNK_BYTES, FLUSH_EVERY = 64 * 1024, 1.0
#: Every pose, changed or not, at least this often (s of sim time): a late viewer has every frame within it.
KEYFRAME_EVERY = 1.0
#: How long a camera's sighting stays drawn in the 3D view (s): a little more than two control cycles.
SEEN_FOR = 0.3
#: A trail gets a point when its robot moved this far (m) from the last one.
TRAIL_STEP = 0.1
#: The frame of an intruder (a person walking through the world, not a robot): `intruder/<id>`.
INTRUDER = "intruder/"
#: The id prefix of a camera's field of view in the world's scene (`fov/<robot>`).
FOV = "fov/"
#: The version of this layout, in the file's metadata (`drd` record `format`).
FORMAT = "drd-run-1"
#: Where `--foxglove` serves when given no address: loopback only.
LIVE_DEFAULT = ("127.0.0.1", 8765)
#: How long (s) the live view stays up after the run's last message when a viewer is subscribed: the server drops
#: what it has not sent yet when it stops (a viewer missed `/drd/runs`, readers audit 16, D2).
LINGER = 1.0
#: How long (s) a dry-run served live waits at its start for a first viewer (`Recorder.wait_for_viewer`): its first
#: messages are at 0, and one logged before a viewer subscribed never reaches it (records audit 23, #1).
FIRST_VIEWER = 3.0
#: How long (s) after a viewer's first subscription its others are given (a viewer subscribes channel by channel).
SUBSCRIBING = 0.3


class RecordingError(ConfigurationError):
    """A recording cannot be written or read (the message names the file)."""


#: The recorders with a file open: closed at exit if a command ended without (the SDK's writer must be closed while
#: the interpreter lives, else its drop panics in Rust).
_OPEN: weakref.WeakSet[Recorder] = weakref.WeakSet()
#: The SDK's own logger of a message it could not write to a sink (its first message holds the OS error).
SINK_LOGGER = "foxglove.log_sink_set"


class _SinkErrors(logging.Filter):
    """Keeps the SDK's "error logging message" lines (one per message once a write failed) off stderr, and the
    first one's OS error (`No space left on device`) for the recording's one-line error."""

    def __init__(self) -> None:
        super().__init__()
        self.first: str | None = None
        self.count = 0

    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        if "error logging message" not in text:
            return True
        self.count += 1
        if self.first is None or "AttemptedWriteAfterFailure" in self.first:
            found = re.search(r'message: "([^"]+)"', text)
            self.first = found.group(1) if found else text.removeprefix("error logging message: ")
        return False


_SINK = _SinkErrors()


def _close_all() -> None:
    for recorder in list(_OPEN):
        recorder.close()


atexit.register(_close_all)


def _ns(seconds: float) -> int:
    return max(0, int(round(seconds * 1e9)))


def _default(value: Any) -> Any:
    """Resources and other objects appear by their id or text (as in a trace: `drd.runtime.trace`)."""
    return getattr(value, "id", None) or str(value)


_JSON_OPTIONS = orjson.OPT_NON_STR_KEYS | orjson.OPT_PASSTHROUGH_DATACLASS | orjson.OPT_PASSTHROUGH_DATETIME


def _json(value: Any) -> bytes:
    """JSON as a trace line has it (`json.dumps` with `_default`), at a third of its cost."""
    return orjson.dumps(value, default=_default, option=_JSON_OPTIONS)


def _color(hex_: str, alpha: float = 1.0) -> Any:
    from foxglove.messages import Color

    return Color(r=int(hex_[1:3], 16) / 255, g=int(hex_[3:5], 16) / 255, b=int(hex_[5:7], 16) / 255, a=alpha)


def _pose(x: float = 0.0, y: float = 0.0, heading: float = 0.0, z: float = 0.0) -> Any:
    from foxglove.messages import Pose, Quaternion, Vector3

    return Pose(position=Vector3(x=x, y=y, z=z),
                orientation=Quaternion(x=0.0, y=0.0, z=math.sin(heading / 2), w=math.cos(heading / 2)))


def _stamp(at: float) -> Any:
    from foxglove.messages import Timestamp

    ns = _ns(at)
    return Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def _line(points: Sequence[tuple[float, float]], color: Any, width: float, strip: bool = False) -> Any:
    from foxglove.messages import LinePrimitive, LinePrimitiveLineType, Point3

    kind = LinePrimitiveLineType.LineStrip if strip else LinePrimitiveLineType.LineList
    return LinePrimitive(type=kind, thickness=width, scale_invariant=False,
                         points=[Point3(x=x, y=y, z=0.0) for x, y in points], color=color)


#: Colours of the 3D view, as the picture's (`drd.render`): doors green open, red closed, brown blocked.
DOOR_COLOURS = {DoorState.OPEN: "#2e9e44", DoorState.CLOSED: "#d32f2f", DoorState.BLOCKED: "#8e3b00"}
RANGER_COLOUR, SCOUT_COLOUR, INTRUDER_COLOUR, WALL_COLOUR = "#1f4e9c", "#f28e2b", "#c2185b", "#1d2330"


class Twins:
    """One channel in two contexts, the file's and the live view's: what is logged goes to both (`live` alone: what
    a late viewer is sent again)."""

    def __init__(self, file: Any, live: Any) -> None:
        self.file, self.live = file, live

    def log(self, message: Any, *, log_time: int) -> None:
        self.file.log(message, log_time=log_time)
        self.live.log(message, log_time=log_time)


class Recorder:
    """Writes one run into `path` (None: no file) and serves it live on `serve` (host, port; None: not served):
    `scene` and `watch` once, `record` for each trace record, `poses` each control cycle, `end` once."""

    def __init__(self, path: Path | None, *, serve: tuple[str, int] | None = None, robots: Sequence[str] = ()) -> None:
        import foxglove
        from foxglove.channels import FrameTransformsChannel, LogChannel, SceneUpdateChannel
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        self.path, self.context = path, foxglove.Context()  # this run's own: several recorders may coexist
        # the live view's own when there is a file too: what is sent again to a viewer that joins late must not go
        # into the file (the SDK logs to every sink of a context, and its Python API gives no sink's id)
        self.live_context = foxglove.Context() if path is not None and serve is not None else self.context
        self.writer: Any = None
        self.server: Any = None
        if path is not None:
            # small chunks, flushed each second of sim time: a run cut short keeps all but its last second. LZ4: on
            # the corridor mission its flushes cost 14 ms, zstd's 24 ms (level 1) to 57 ms (the default, threaded),
            # for a file 15 % larger (2.1 MB, not 1.8)
            try:
                self.writer = foxglove.open_mcap(str(path), allow_overwrite=True, context=self.context,
                                                 writer_options=MCAPWriteOptions(
                                                     chunk_size=CHUNK_BYTES, compression=MCAPCompression.Lz4))
            except Exception as e:  # the SDK's own errors: a folder that does not exist, no permission
                raise RecordingError(f"{path}: cannot write the recording: {e}") from e
            sink = logging.getLogger(SINK_LOGGER)
            if _SINK not in sink.filters:
                sink.addFilter(_SINK)
            _OPEN.add(self)
        self.error: str | None = None  # why the file stopped being written (the run went on without it)
        self.sink_errors = _SINK.count
        # Every channel is made before the live view starts (each of `robots`' lasers too; another robot's when the
        # world is drawn, or at its first scan): a channel made mid-run is advertised with its first message, which
        # a viewer then never gets, and a viewer subscribing at once may be refused it as unknown for the whole run
        # (readers audits 13 and 16). A channel with no message is not written into the file.
        self.channels: dict[str, Any] = {topic: self._json_channel(topic) for topic in JSON_SCHEMAS}
        self.lock = threading.Lock()
        self.viewers = 0  # subscriptions of the live view's clients (`close` lets them have the last messages)
        self.subscribed = threading.Event()  # a viewer subscribed to something (`wait_for_viewer`)
        self.tf = self._made(lambda context: FrameTransformsChannel(TF, context=context))
        self.world = self._made(lambda context: SceneUpdateChannel(WORLD, context=context))
        self.trails = self._made(lambda context: SceneUpdateChannel(TRAILS, context=context))
        self.seen = self._made(lambda context: SceneUpdateChannel(SEEN, context=context))
        self.log = self._made(lambda context: LogChannel(LOG, context=context))
        self.scans: dict[str, Any] = {}
        for robot in robots:  # `robots`: whose laser channels to make now, before the live view starts
            self._scan_channel(robot)
        self.views: dict[str, ActiveView] = {}
        self.frames = _Frames()
        self.sensors = SensorTap(self)  # a dry-run's simulation reports its readings here (`watch`)
        self.fovs: set[str] = set()  # cameras whose field of view is drawn
        self.doors: dict[str, tuple[tuple[float, float], tuple[float, float]]] = {}  # the scene's, by id
        self.flying: list[tuple[float, str, str, tuple[float, float]]] = []  # (t1, robot, kind, end), landings due
        self.entities: dict[str, Any] = {}  # the world's entities as they are now, for a viewer that joins late
        self.gone: set[str] = set()  # the lost robots whose body (and view) left the scene (`cycle`)
        self.closed, self.flushed, self.now = False, 0.0, 0.0  # `now`: the latest sim time logged
        self.kept = 0.0  # the sim time up to which the file's chunks were written (the last flush that succeeded)
        if serve is not None:
            self._serve(*serve)

    def _made(self, make: Callable[[Any], Any]) -> Any:
        """The channel `make(context)` makes, in the file's context and, when the live view has its own, in that
        too (`Twins`)."""
        if self.live_context is self.context:
            return make(self.context)
        return Twins(make(self.context), make(self.live_context))

    def _json_channel(self, topic: str) -> Any:
        import foxglove

        name, schema = JSON_SCHEMAS[topic]
        return self._made(lambda context: foxglove.Channel(
            topic, message_encoding="json", context=context,
            schema=foxglove.Schema(name=name, encoding="jsonschema", data=json.dumps(schema).encode())))

    def _serve(self, host: str, port: int) -> None:
        """The live view: the Foxglove WebSocket server on `host:port` only, serving this recorder's channels."""
        import foxglove

        try:
            self.server = foxglove.start_server(name="drd", host=host, port=port, context=self.live_context,
                                                server_listener=_late_viewers(self))
        except Exception as e:  # the SDK's own errors: the port is taken, the address is not this machine's
            self.close()
            raise RecordingError(f"cannot serve the live view on {host}:{port}: {e}") from e

    def wait_for_viewer(self, limit: float = FIRST_VIEWER) -> bool:
        """Before a dry-run's first message: wait up to `limit` seconds for a viewer, and then `SUBSCRIBING` for
        the rest of its subscriptions, so a viewer there from the start gets every message; whether one came (none
        is waited for when the run is not served)."""
        if self.server is None or not self.subscribed.wait(limit):
            return False
        time.sleep(SUBSCRIBING)
        return True

    @property
    def port(self) -> int | None:
        """The port the live view is served on (None when it is not served)."""
        return None if self.server is None else int(self.server.port)

    def json(self, topic: str, at: float, value: Any) -> None:
        """One message on a JSON channel (`JSON_SCHEMAS`) at sim time `at`."""
        self._channel(topic).log(_json(value), log_time=_ns(at))

    def _channel(self, topic: str) -> Any:
        return self.channels[topic]

    def resend(self, topic: str, at: float, message: Any) -> None:
        """`message` again on `topic`'s channel (`/drd/world`, or a JSON one) for a viewer that joined late: to the
        live view only, not into the file, which has it already."""
        channel = self.world if topic == WORLD else self._channel(topic)
        live = channel.live if isinstance(channel, Twins) else channel
        live.log(message if topic == WORLD else _json(message), log_time=_ns(at))

    def scene(self, world: World, starts: bool = False) -> None:
        """The world as a scene at time 0, and its file as the attachment `world.yaml`, so a replay can draw the
        run without it; `starts`: the run starts the world, so every robot is where the world file puts it at 0 (a
        dry-run; not a cluster's mission, which may join a world that has run for a while)."""
        source = Path(world.source)
        if self.writer is not None and source.is_file():
            data = source.read_bytes()
            self._write(lambda w: w.attach(log_time=0, create_time=0, name=WORLD_ATTACHMENT,
                                           media_type="application/yaml", data=data))
        self.doors = {d.id: (d.a, d.b) for d in world.doors}
        self.frames.scouts = frozenset(world.scout_ids)
        if starts:  # where every robot starts, at 0 (the first cycle's poses are at 0.1 s: `replay --at 0` showed
            self._starts(world)  # no robot, readers audit 16, D8)
        for robot in (*(r.id for r in world.rangers), *world.scout_ids):
            self._scan_channel(robot)
        self.update_world(0.0, [*_building(world), *_bodies(world)])

    def _starts(self, world: World) -> None:
        """Every robot's start pose on `/drd/tf` at 0 (a Scout in a magazine as its Ranger's frame), and every
        intruder's: the scene at 0 locks their bodies to their frames (records audit 18, #3: they came at 0.1 s)."""
        spawned = {r.id: (r.x, r.y, r.heading) for r in world.rangers}
        spawned.update({s.id: (s.x, s.y, s.heading) for s in world.scouts})
        spawned.update({INTRUDER + i.id: (*i.position(0.0), 0.0) for i in world.intruders})
        start = self.frames.transforms(0.0, spawned, {sid: r.id for r in world.rangers for sid in r.magazine})
        if start is not None:
            self.tf.log(start, log_time=0)

    def update_world(self, at: float, entities: list[tuple[str, Any]]) -> None:
        """Add or replace entities (id, entity) of the world's scene at sim time `at`."""
        from foxglove.messages import SceneUpdate

        self.entities.update(entities)
        self.world.log(SceneUpdate(entities=[e for _, e in entities]), log_time=_ns(at))

    def delete_robots(self, at: float, robots: list[str]) -> None:
        """Lost robots leave the world's scene at sim time `at`: a deletion of each one's body and camera view, as
        Foxglove's SceneUpdate deletes (records audit 18, #2: a lost Scout's body stayed, drawn at its last pose)."""
        from foxglove.messages import SceneEntityDeletion, SceneEntityDeletionType, SceneUpdate

        self.gone.update(robots)
        ids = [e for rid in robots for e in (f"body/{rid}", f"{FOV}{rid}") if e in self.entities]
        for entity in ids:
            del self.entities[entity]
        if ids:
            self.world.log(SceneUpdate(deletions=[SceneEntityDeletion(
                timestamp=_stamp(at), type=SceneEntityDeletionType.MatchingId, id=e) for e in ids]), log_time=_ns(at))

    def scene_now(self) -> Any:
        """The world's scene as it is now (None before `scene`)."""
        from foxglove.messages import SceneUpdate

        return SceneUpdate(entities=list(self.entities.values())) if self.entities else None

    def watch(self, sim: Any) -> None:
        """Record what `sim`'s sensors read from now on (`drd.sim.observe.SensorTap`), its launches, jumps and door
        changes."""
        self.sensors.tap(sim)

    # -- the sensors, as their drivers read them (a `drd.sim.observe.SensorSink`; times are sim times)

    def _scan_channel(self, robot: str) -> Any:
        from foxglove.channels import LaserScanChannel

        channel = self.scans.get(robot)
        if channel is None:
            with self.lock:  # a cluster run writes from several threads (`drd.cli.cluster._ClusterView`)
                channel = self.scans.get(robot) or self.scans.setdefault(
                    robot, self._made(lambda context: LaserScanChannel(SCAN + robot, context=context)))
        return channel

    def scan(self, robot: str, at: float, ranges: list[float], max_range: float, fov: float) -> None:
        from foxglove.messages import LaserScan

        channel = self._scan_channel(robot)
        inf = math.inf  # a beam that hit nothing: +inf (REP 117), not a point at the laser's reach
        half = fov / 2 if len(ranges) > 1 else 0.0
        channel.log(LaserScan(timestamp=_stamp(at), frame_id=robot, pose=_pose(), start_angle=-half, end_angle=half,
                              ranges=[d if d < max_range else inf for d in ranges]), log_time=_ns(at))

    def camera(self, robot: str, at: float, fov: float, max_range: float, people: list[dict[str, float]]) -> None:
        self.view(robot, at, fov, max_range)  # a simulator host older than `view` says it with the first frame
        self.json(CAMERA, at, {"robot": robot, "at": at, "fov": fov, "max_range": max_range, "detections": people})
        if people:
            self._seen(robot, at, people)

    def _seen(self, robot: str, at: float, people: list[dict[str, float]]) -> None:
        from foxglove.messages import Duration, SceneEntity, SceneUpdate

        ends = [(p["distance"] * math.cos(p["bearing"]), p["distance"] * math.sin(p["bearing"])) for p in people]
        line = _line([p for end in ends for p in ((0.0, 0.0), end)], _color("#ffc107"), 0.05)
        self.seen.log(SceneUpdate(entities=[SceneEntity(
            timestamp=_stamp(at), frame_id=robot, id=f"seen/{robot}", frame_locked=True, lines=[line],
            lifetime=Duration(sec=0, nsec=int(SEEN_FOR * 1e9)))]), log_time=_ns(at))

    def view(self, robot: str, at: float, fov: float, max_range: float) -> None:
        """A camera's field of view, drawn once (when it is first read), locked to its robot's frame (as long as
        the view's reach, at most 3 m: a wedge as long as a 10 m camera's would cover the building)."""
        if robot in self.fovs:
            return
        self.fovs.add(robot)
        from foxglove.messages import KeyValuePair, SceneEntity

        reach = min(max_range, 3.0)
        arc = [(reach * math.cos(a), reach * math.sin(a)) for a in (-fov / 2 + fov * k / 8 for k in range(9))]
        entity = SceneEntity(timestamp=_stamp(at), frame_id=robot, id=f"{FOV}{robot}", frame_locked=True,
                             metadata=[KeyValuePair(key="fov", value=repr(float(fov)))],  # radians, for `read`
                             lines=[_line([(0.0, 0.0), *arc, (0.0, 0.0)], _color(SCOUT_COLOUR, 0.6), 0.02, True)])
        self.update_world(at, [(f"{FOV}{robot}", entity)])

    def light(self, robot: str, at: float, fov: float, regions: list[float]) -> None:
        self.json(LIGHT, at, {"robot": robot, "at": at, "fov": fov, "regions": regions})

    def flight(self, flight: dict[str, Any]) -> None:
        """A launch or a jump, and its landing when it is due (`land`)."""
        at = float(flight["at"])
        self.land(at)  # the landings before it first: the channel's times never go back
        self.json(FLIGHTS, at, {k: flight[k] for k in ("robot", "kind", "at", "from", "to", "lands_at", "heading",
                                                       "blocked")})
        bisect.insort(self.flying, (float(flight["lands_at"]), str(flight["robot"]), str(flight["kind"]),
                                    (float(flight["to"][0]), float(flight["to"][1]))))

    def land(self, at: float) -> None:
        """The landings due by `at` (the simulation lands a flight in the step that reaches its end time)."""
        while self.flying and self.flying[0][0] <= at + 1e-9:
            t1, robot, kind, end = self.flying.pop(0)
            self.json(FLIGHTS, max(t1, 0.0), {"robot": robot, "kind": "landing", "of": kind, "at": t1,
                                              "to": list(end)})

    def door(self, door: str, at: float, state: str) -> None:
        ends = self.doors.get(door)
        if ends is not None:
            self.update_world(at, [_door(door, ends[0], ends[1], DoorState(state), at)])

    def record(self, mission: str, r: rec.Record, seq: int | None = None) -> None:
        """One trace record of `mission`: on `/drd/records`, and into its active configuration (`/drd/active`).
        `seq`: the executive's sequence number, which a cluster run's trace line carries (missions that ran
        together merge by it: `check-trace --together`), so the recorded record carries it too."""
        view = self.views.get(mission)
        if view is None:
            view = self.views[mission] = ActiveView(mission)
        if view.changed_at is not None and r.at > view.changed_at + 1e-9:
            self._active(view)  # the instant before is complete
        view.take(r)
        data = r.to_dict()
        data["mission"] = mission
        if seq is not None:
            data["seq"] = seq
        self._channel(RECORDS).log(_json(data), log_time=_ns(r.at))
        if isinstance(r, rec.Log):
            self._log_line(r)
        self.now = max(self.now, r.at)

    def _log_line(self, r: rec.Log) -> None:
        from foxglove.messages import Log, LogLevel

        self.log.log(Log(timestamp=_stamp(r.at), level=LogLevel.Info, message=r.text, name=r.path),
                     log_time=_ns(r.at))

    def _active(self, view: ActiveView) -> None:
        at = view.changed_at or 0.0
        self.json(ACTIVE, at, view.state(at))
        view.changed_at = None

    def cycle(self, sim: Any) -> None:
        """The end of a control cycle of `sim`: where every robot and intruder is (`poses`); a robot lost in this
        cycle leaves the scene."""
        carried = {scout: r.id for r in sim.world.rangers for scout in sim.magazine(r.id)}
        lost = [rid for rid in sim.robots if sim.state(rid) == "lost"]
        if len(lost) > len(self.gone):
            self.delete_robots(sim.time, [rid for rid in lost if rid not in self.gone])
        poses = {rid: (p.x, p.y, p.heading) for rid in sim.robots  # a lost robot is gone: no pose (worlds audit 17)
                 if rid not in carried and rid not in self.gone and (p := sim.pose(rid))}
        for iid, (x, y) in sim.intruders().items():
            poses[INTRUDER + iid] = (x, y, 0.0)
        self.poses(sim.time, poses, carried)

    def poses(self, at: float, poses: dict[str, tuple[float, float, float]],
              carried: dict[str, str] | None = None) -> None:
        """The end of a control cycle at sim time `at`: each robot's (x, y, heading) as frame transforms from
        `world` (those that changed), each Scout in a magazine (`carried`: Scout -> Ranger) as its Ranger's frame,
        the trails, the landings due, and the active configurations that changed."""
        for view in self.views.values():
            if view.changed_at is not None:
                self._active(view)
        self.transforms(at, poses, carried or {})
        self.land(at)
        self.now = max(self.now, at)
        self.flush(at)

    def transforms(self, at: float, poses: dict[str, tuple[float, float, float]], carried: dict[str, str]) -> None:
        """The poses at sim time `at` on `/drd/tf` (those that changed) and the trails they leave."""
        message = self.frames.transforms(at, poses, carried)
        if message is not None:
            self.tf.log(message, log_time=_ns(at))
        trails = self.frames.trails(at)
        if trails is not None:
            self.trails.log(trails, log_time=_ns(at))

    def flush(self, at: float) -> None:
        """Write the chunk so far to the file when a second of sim time has passed since the last time."""
        if at - self.flushed >= FLUSH_EVERY:
            self.flushed = at
            if self.writer is not None and not self.closed:
                self._write(lambda w: w.flush())
                if self.writer is not None:  # the flush went through
                    self.kept = at

    def _write(self, op: Callable[[Any], object]) -> None:
        """`op(writer)`; on a write error (disk full) the file is closed as it is and the run goes on without it
        (`failed`): a recording is a by-product, the mission is what runs."""
        try:
            op(self.writer)
        except RuntimeError as e:  # the SDK's FoxgloveError: the file system refused a write
            self.failed(e)

    def failed(self, e: BaseException) -> None:
        """Stop writing the file (closed as it is: its complete chunks stay readable), and keep one line saying
        why and where the readable file ends, naming it (`error`, `drd.outputs.failures`)."""
        writer, self.writer = self.writer, None
        _OPEN.discard(self)
        for _ in range(2 if writer is not None else 0):  # after a failed write it refuses once, then lets go
            try:
                writer.close()
                break
            except RuntimeError:
                continue
        if self.error is None:
            why = _SINK.first if _SINK.count > self.sink_errors and _SINK.first else str(e).removeprefix(
                "FoxgloveError: ")
            if "space" not in why and self.path is not None and _full(self.path):
                why = f"No space left on device ({why})"
            # where an independent reader's messages end (a chunk written between flushes may hold more than the
            # last flush that went through, and what was logged after the last good chunk is lost: readers audit
            # 13, D5 said a second too late)
            end = _readable_until(self.path) if self.path is not None else None
            self.error = (f"{self.path}: cannot write the recording: {why}; it stops at "
                          f"{self.kept if end is None else end:.1f} s of sim time (its complete chunks are readable)")
            outputs.failed(self.error)

    def where(self, robot: str) -> tuple[float, float] | None:
        """Where `robot` was last written on `/drd/tf` (its Ranger's place while carried), or None if never."""
        last = self.frames.last.get(robot)
        if isinstance(last, str):
            last = self.frames.last.get(last)
        return None if last is None or isinstance(last, str) else (last[0], last[1])

    def end(self, runs: Sequence[dict[str, Any]], at: float) -> None:
        """Each mission's run summary (`summary`), then close the file and the live view."""
        for view in self.views.values():
            if view.changed_at is not None:
                self._active(view)
        # each at its mission's end (readers audit 13, D9), with its place in the run's report (`order`: a replay
        # lists them so, not by when they ended: readers audit 16, D3)
        ordered = sorted(enumerate(runs), key=lambda item: _ended(item[1], at))
        for i, run in ordered:
            self._channel(RUNS).log(json.dumps({"format": FORMAT, **run, "order": i}, default=_default),
                                    log_time=_ns(_ended(run, at)))
        self.close()

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            if self.writer is not None:
                self._write(lambda w: w.close())
                _OPEN.discard(self)
            if self.server is not None:
                if self.viewers:  # the last messages (`/drd/runs`) are queued for the viewers: stopping drops them
                    time.sleep(LINGER)
                self.server.stop()


def _readable_until(path: Path) -> float | None:
    """The sim time of the last message a reader gets from `path` in file order (None: none, or no file)."""
    from mcap.reader import NonSeekingReader

    last: int | None = None
    try:
        with path.open("rb") as fh:
            try:
                for _schema, _channel, message in NonSeekingReader(fh).iter_messages(log_time_order=False):
                    last = message.log_time if last is None else max(last, message.log_time)
            except _damaged():  # where the failed write left it
                pass
    except OSError:
        return None
    return None if last is None else last / 1e9


def _full(path: Path) -> bool:
    """Whether the file system holding `path` has no room left for another chunk."""
    try:
        return shutil.disk_usage(path.parent).free < CHUNK_BYTES
    except OSError:
        return False


def _ended(run: Mapping[str, Any], at: float) -> float:
    """When a run's mission ended (its summary's `sim_time`), at most `at` (the run's end)."""
    ended = run.get("sim_time")
    return min(float(ended), at) if isinstance(ended, (int, float)) and ended >= 0 else at


def _late_viewers(r: Recorder) -> Any:
    """The live view's listener: a viewer that subscribes after the start gets what was sent once (the world as it
    is now, each mission's active configuration)."""
    from foxglove.websocket import ChannelView, Client, ServerListener

    class LateViewers(ServerListener):
        def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
            with r.lock:  # the server's threads
                r.viewers -= 1

        def on_subscribe(self, client: Client, channel: ChannelView) -> None:
            with r.lock:
                r.viewers += 1
            r.subscribed.set()
            scene = r.scene_now() if channel.topic == WORLD else None
            if scene is not None:
                r.resend(WORLD, r.now, scene)
            elif channel.topic == ACTIVE:
                for view in list(r.views.values()):
                    try:
                        state = view.state(r.now)
                    except RuntimeError:  # the run changed it meanwhile (this is the server's thread): it sends
                        continue  # the next change anyway
                    r.resend(ACTIVE, r.now, state)

    return LateViewers()


def _building(world: World) -> list[tuple[str, Any]]:
    """Walls, doors (coloured by state), obstacles and room names, in the `world` frame."""
    from foxglove.messages import CubePrimitive, SceneEntity, TextPrimitive, Vector3

    walls = [p for w in world.walls for p in ((w.a[0], w.a[1]), (w.b[0], w.b[1]))]
    out = [SceneEntity(frame_id="world", id="walls", lines=[_line(walls, _color(WALL_COLOUR), 0.08)])]
    out += [_door(d.id, d.a, d.b, d.state)[1] for d in world.doors]
    out += [SceneEntity(frame_id="world", id=f"obstacle/{i}", cubes=[CubePrimitive(
        pose=_pose((o.x0 + o.x1) / 2, (o.y0 + o.y1) / 2, z=o.height / 2),
        size=Vector3(x=o.x1 - o.x0, y=o.y1 - o.y0, z=o.height), color=_color("#8d6e63", 0.8))])
        for i, o in enumerate(world.obstacles)]
    out += [SceneEntity(frame_id="world", id=f"room/{r.id}", texts=[TextPrimitive(
        pose=_pose((r.x0 + r.x1) / 2, (r.y0 + r.y1) / 2), billboard=True, font_size=0.4, scale_invariant=False,
        color=_color("#3a4256"), text=r.id)]) for r in world.rooms]
    ids = ["walls", *(f"door/{d.id}" for d in world.doors), *(f"obstacle/{i}" for i in range(len(world.obstacles))),
           *(f"room/{r.id}" for r in world.rooms)]
    return list(zip(ids, out, strict=True))


def _door(door_id: str, a: tuple[float, float], b: tuple[float, float], state: DoorState,
          at: float = 0.0) -> tuple[str, Any]:
    """A door's entity as it is from sim time `at` (its timestamp, as the message's log time)."""
    from foxglove.messages import SceneEntity

    return f"door/{door_id}", SceneEntity(timestamp=_stamp(at), frame_id="world", id=f"door/{door_id}",
                                          lines=[_line([a, b], _color(DOOR_COLOURS[DoorState(state)]), 0.12)])


def _bodies(world: World) -> list[tuple[str, Any]]:
    """A body for each robot and intruder, locked to its frame (so it moves with `/drd/tf`): a disc to scale, a
    heading line for robots, and its name."""
    from foxglove.messages import CylinderPrimitive, SceneEntity, TextPrimitive, Vector3

    def body(frame: str, radius: float, colour: str, heading: bool) -> tuple[str, Any]:
        lines = [_line([(0.0, 0.0), (radius * 2.2, 0.0)], _color("#ffffff"), 0.03)] if heading else []
        disc = CylinderPrimitive(pose=_pose(z=0.05), size=Vector3(x=2 * radius, y=2 * radius, z=0.1),
                                 bottom_scale=1.0, top_scale=1.0, color=_color(colour, 0.9))
        name = TextPrimitive(pose=_pose(z=0.3), billboard=True, font_size=12.0, scale_invariant=True,
                             color=_color(colour), text=frame.removeprefix(INTRUDER))
        return f"body/{frame}", SceneEntity(frame_id=frame, id=f"body/{frame}", frame_locked=True, lines=lines,
                                            cylinders=[disc], texts=[name])

    return ([body(r.id, RANGER_RADIUS, RANGER_COLOUR, True) for r in world.rangers]
            + [body(s, SCOUT_RADIUS, SCOUT_COLOUR, True) for s in world.scout_ids]
            + [body(INTRUDER + i.id, i.radius or INTRUDER_RADIUS, INTRUDER_COLOUR, False) for i in world.intruders])


class _Frames:
    """The poses of each control cycle as frame transforms (only those that changed, all every second), and the
    trails they leave (a point every `TRAIL_STEP` metres, sent as one piece per second)."""

    def __init__(self) -> None:
        self.last: dict[str, tuple[float, float, float] | str] = {}  # a pose, or the Ranger carrying it
        self.keyframe = -math.inf
        self.trail_end: dict[str, tuple[float, float]] = {}
        self.trail_new: dict[str, list[tuple[float, float]]] = {}
        self.pieces = 0
        self.trail_sent = 0.0
        self.scouts: frozenset[str] = frozenset()  # the robots with a Scout's body (the world's), whatever their ids

    def transforms(self, at: float, poses: dict[str, tuple[float, float, float]], carried: dict[str, str]) -> Any:
        """This cycle's `FrameTransforms` (None when nothing moved and no keyframe is due): a Scout in a magazine is
        its Ranger's frame (sent once, not every cycle it is carried)."""
        from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Vector3

        every = at - self.keyframe >= KEYFRAME_EVERY - 1e-9
        if every:
            self.keyframe = at
        last, stamp, out = self.last, _stamp(at), []
        for rid, ranger in carried.items():
            if every or last.get(rid) != ranger:
                last[rid] = ranger
                out.append(FrameTransform(timestamp=stamp, parent_frame_id=ranger, child_frame_id=rid,
                                          translation=Vector3(x=0.0, y=0.0, z=0.0),
                                          rotation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)))
                self.trail_end.pop(rid, None)
        for rid, pose in poses.items():
            if every or last.get(rid) != pose:
                last[rid] = pose
                x, y, h = pose
                out.append(FrameTransform(timestamp=stamp, parent_frame_id="world", child_frame_id=rid,
                                          translation=Vector3(x=x, y=y, z=0.0),
                                          rotation=Quaternion(x=0.0, y=0.0, z=math.sin(h / 2), w=math.cos(h / 2))))
                self._trail(rid, x, y)
        return FrameTransforms(transforms=out) if out else None

    def _trail(self, rid: str, x: float, y: float) -> None:
        end = self.trail_end.get(rid)
        if end is None or math.hypot(x - end[0], y - end[1]) >= TRAIL_STEP:
            self.trail_new.setdefault(rid, [end] if end is not None else []).append((x, y))
            self.trail_end[rid] = (x, y)

    def trails(self, at: float) -> Any:
        """The trails' new pieces, once a second (None otherwise, or when nobody moved)."""
        if at - self.trail_sent < 1.0 - 1e-9:
            return None
        self.trail_sent = at
        from foxglove.messages import SceneEntity, SceneUpdate

        pieces = []
        for rid, points in self.trail_new.items():
            if len(points) > 1:
                self.pieces += 1
                colour = INTRUDER_COLOUR if rid.startswith(INTRUDER) else (
                    SCOUT_COLOUR if rid in self.scouts else RANGER_COLOUR)  # as the body (users audit 12, D5)
                pieces.append(SceneEntity(frame_id="world", id=f"trail/{rid}/{self.pieces}", timestamp=_stamp(at),
                                          lines=[_line(points, _color(colour, 0.7), 0.04, strip=True)]))
        self.trail_new = {}
        return SceneUpdate(entities=pieces) if pieces else None


class ActiveView:
    """One mission's active configuration, kept from its records as they come: what `state_at` reads from every
    record up to an instant (`drd.explain`: the active leaves, each running, waiting or suspended; what each
    behavior holds; who waits behind whom), without reading them all again at each change."""

    def __init__(self, mission: str) -> None:
        self.mission = mission
        self.name = ""  # the mission's name: its root state's
        self.active: dict[str, float] = {}  # path -> since, in the order entered
        self.below: dict[str, int] = {}  # path -> how many active paths are under it (0: a leaf)
        self.suspended: set[str] = set()
        self.holds: dict[str, dict[str, str]] = {}  # path -> need -> unit (aggregates' parts too)
        self.waiters = Waiters()  # who waits, behind whom
        self.outcome: str | None = None
        self.changed_at: float | None = None

    def take(self, r: rec.Record) -> None:
        """Apply one record; `changed_at` is its time when it changed the configuration."""
        self.waiters.take(r)
        if isinstance(r, rec.Entered):
            self._enter(r)
        elif isinstance(r, rec.Exited):
            self._exit(r.path)
        elif isinstance(r, rec.Suspended):
            self.suspended.add(r.path)
        elif isinstance(r, rec.Resumed):
            self.suspended.discard(r.path)
        elif isinstance(r, rec.Waiting):
            pass  # `waiters` took it: a change all the same
        elif isinstance(r, rec.Granted):
            self.holds[r.path] = r.named
        elif isinstance(r, rec.Released):
            gone = set(r.resources)
            self.holds[r.path] = {k: v for k, v in self.holds.get(r.path, {}).items() if v not in gone}
        elif isinstance(r, rec.Finished):
            self.outcome = r.outcome
        elif isinstance(r, rec.Restored):  # its states are entered again: those in force as the journal saved them
            for path in [p for p in self.active if within(p, r.path)]:
                self._exit(path)
            self.outcome = None
        else:
            return
        self.changed_at = r.at

    def _enter(self, r: rec.Entered) -> None:
        if not self.name:
            self.name = r.path.split("/", 1)[0]
        if r.path not in self.active:
            for prefix in _prefixes(r.path):
                self.below[prefix] = self.below.get(prefix, 0) + 1
        self.active[r.path] = r.at

    def _exit(self, path: str) -> None:
        if self.active.pop(path, None) is not None:
            for prefix in _prefixes(path):
                self.below[prefix] -= 1
        self.suspended.discard(path)
        self.holds.pop(path, None)

    def state(self, at: float) -> dict[str, Any]:
        """The configuration now: as `state_at` gives a mission at `at` (`mission`, `id`, `outcome`, `active`,
        `holds`, `waiting`), with `at`."""
        def state(path: str) -> str:
            if path in self.waiters.waits:
                return "waiting"
            frozen = any(path == s or path.startswith((s + "/", s + "[")) for s in self.suspended)
            return "suspended" if frozen else "running"

        active = sorted(({"path": p, "since": round(t, 6), "state": state(p)} for p, t in self.active.items()
                         if not self.below.get(p)), key=lambda row: (row["since"], row["path"]))  # as `explain`'s
        waiting = self.waiters.waiting()
        return {"mission": self.name, "id": self.mission, "at": at, "outcome": self.outcome, "active": active,
                "holds": {p: held for p, held in self.holds.items() if held}, "waiting": waiting}


def _prefixes(path: str) -> list[str]:
    """The paths a path is under: `A/B[2]/C` is under `A`, `A/B` and `A/B[2]` (as `drd.explain` reads them: a path
    `q` is under `p` when it starts with `p/` or `p[`)."""
    return [path[:i] for i, c in enumerate(path) if c in "/[" and i > 0]


#: A waiter in `/drd/active`: its first `explain.BLOCKERS_SHOWN` blockers now, with what each holds, and how many.
_WAITER = {"type": "object", "required": ["path", "since", "needs", "blocked_by", "blockers"], "properties": {
    "path": {"type": "string"}, "since": {"type": "number"}, "needs": {"type": "array", "items": {"type": "string"}},
    "blocked_by": {"type": "array", "items": {"type": "object", "required": ["path", "holds"], "properties": {
        "path": {"type": "string"}, "mission": {"type": "string"}, "holds": {"type": "object"}}}},
    "blockers": {"type": "integer", "minimum": 0}}}

#: The JSON channels: their schema's name and JSON schema (named, so a viewer lists `drd.Record`, not anonymous).
_NUM, _STR, _INT = {"type": "number"}, {"type": "string"}, {"type": "integer"}
JSON_SCHEMAS: dict[str, tuple[str, dict[str, Any]]] = {
    RECORDS: ("drd.Record", {"type": "object", "required": ["kind", "at", "path", "mission"], "properties": {
        "kind": _STR, "at": _NUM, "path": _STR, "mission": _STR}}),
    RUNS: ("drd.Run", {"type": "object", "required": ["format", "mission", "records", "sim_time"], "properties": {
        "format": _STR, "mission": _STR, "records": _STR, "sim_time": _NUM, "wall_time": _NUM, "order": _INT,
        "controller_away": _NUM, "id": _STR, "priority": _INT, "speed": _NUM, "on_cluster": {"type": "boolean"},
        "injections": {"type": "array", "items": {"type": "object"}},
        "scouts": {"type": "array", "items": {"type": "object"}}}}),
    ACTIVE: ("drd.Active", {"type": "object", "required": ["mission", "id", "at", "active", "holds", "waiting"],
                            "properties": {"mission": _STR, "id": _STR, "at": _NUM, "outcome": {
                                "type": ["string", "null"]}, "active": {"type": "array", "items": {
                                    "type": "object", "properties": {"path": _STR, "since": _NUM, "state": _STR}}},
                                "holds": {"type": "object"}, "waiting": {"type": "array", "items": _WAITER}}}),
    CAMERA: ("drd.CameraFrame", {"type": "object", "required": ["robot", "at", "fov", "detections"], "properties": {
        "robot": _STR, "at": _NUM, "fov": _NUM, "max_range": _NUM, "detections": {"type": "array", "items": {
            "type": "object", "properties": {"label": _STR, "bearing": _NUM, "distance": _NUM, "light": _NUM}}}}}),
    LIGHT: ("drd.Brightness", {"type": "object", "required": ["robot", "at", "fov", "regions"], "properties": {
        "robot": _STR, "at": _NUM, "fov": _NUM, "regions": {"type": "array", "items": _NUM}}}),
    FLIGHTS: ("drd.Flight", {"type": "object", "required": ["robot", "kind", "at", "to"], "properties": {
        "robot": _STR, "kind": _STR, "at": _NUM, "from": {"type": "array"}, "to": {"type": "array"},
        "lands_at": _NUM, "blocked": {"type": "boolean"}}}),
    HOSTS: ("drd.Hosts", {"type": "object", "required": ["at", "hosts"], "properties": {
        "at": _NUM, "hosts": {"type": "array"}, "events": {"type": "array"}}}),
    LOADS: ("drd.LoadReport", {"type": "object", "required": ["host", "cpu", "memory"], "properties": {
        "host": _STR, "cpu": _NUM, "memory": _NUM, "load1": _NUM, "instances": {"type": "integer"}}}),
    PLACEMENTS: ("drd.Placements", {"type": "object", "required": ["at", "instances"], "properties": {
        "at": _NUM, "instances": {"type": "array"}}}),
}
#: What older code imports (the first part's names).
RECORD_SCHEMA, RUN_SCHEMA = JSON_SCHEMAS[RECORDS][1], JSON_SCHEMAS[RUNS][1]


@dataclass
class Recording:
    """What a recording holds, read back: each mission's records, its run summary, and each robot's track
    (sim time, x, y, heading), decoded from the Foxglove transforms with `mcap_protobuf`."""

    records: dict[str, list[rec.Record]] = field(default_factory=dict)
    #: Each record's `seq` (None when it has none: a dry-run's), in the order of `records`.
    seqs: dict[str, list[int | None]] = field(default_factory=dict)
    #: The missions of the records in file order (the trace's causal order, across missions: docs/trace.md).
    order: list[str] = field(default_factory=list)
    runs: list[dict[str, Any]] = field(default_factory=list)
    tracks: dict[str, list[tuple[float, float, float, float]]] = field(default_factory=dict)
    #: A Scout in a magazine: from when, carried by which Ranger (its frame's parent is the Ranger's).
    carried: dict[str, list[tuple[float, str]]] = field(default_factory=dict)
    fovs: dict[str, float] = field(default_factory=dict)  # each camera's field of view (radians), by robot
    #: A lost robot: when its body left the world's scene (a deletion on `/drd/world`); `state_at` has it no more.
    gone: dict[str, float] = field(default_factory=dict)
    world: bytes | None = None  # the world file the run used (`world.yaml` attachment), if it was a file
    cut: bool = False  # the file ends before the run did (a crash): what its complete chunks held
    #: Why the reading stopped early (a cut or a damaged chunk: where in the file, and the reader's error), or None.
    damage: str | None = None

    def trace_lines(self) -> Iterator[str]:
        """The recorded records as the run's `--trace` wrote them, in the file's order (a trace of several missions
        interleaves them in causal order: one mission's `released` before another's `granted` of what it freed),
        with `seq` where the run's lines had it."""
        from drd.runtime.trace import trace_line

        order = self.order
        if len(order) != sum(map(len, self.records.values())):  # records put together by hand: mission by mission
            order = [mission for mission, records in self.records.items() for _ in records]
        taken = dict.fromkeys(self.records, 0)  # records of each mission written so far
        for mission in order:
            i = taken[mission]
            taken[mission] = i + 1
            seqs = self.seqs.get(mission, [])
            line = trace_line(self.records[mission][i], mission)
            seq = seqs[i] if i < len(seqs) else None
            yield line if seq is None else f'{line[:-1]},"seq":{seq}}}'

    def load_world(self, name: str) -> World | None:
        """The recorded world (its problems name `name`), or None when the recording has none."""
        from drd.config import load_yaml
        from drd.sim.world import parse_world

        return None if self.world is None else parse_world(load_yaml(self.world.decode("utf-8")), name)

    def pose(self, robot: str, at: float) -> tuple[float, float, float] | None:
        """Where `robot` was at sim time `at` (its last recorded pose then, its Ranger's while it was carried), or
        None before its first."""
        track, carried = self.tracks.get(robot, []), self.carried.get(robot, [])
        i = bisect.bisect_right([t for t, *_ in track], at + 1e-9)
        j = bisect.bisect_right([t for t, _ in carried], at + 1e-9)
        if j and (i == 0 or carried[j - 1][0] >= track[i - 1][0]):
            return self.pose(carried[j - 1][1], at)
        return None if i == 0 else track[i - 1][1:]

    def last_place(self, robot: str) -> tuple[float, float] | None:
        """Where `robot` was when the recording ends (its Ranger's place while carried), or None if never."""
        pose = self.pose(robot, math.inf)
        return None if pose is None else (pose[0], pose[1])

    def robots(self) -> list[str]:
        """Every robot and intruder (`intruder/<id>`) the recording has a pose of."""
        return sorted({*self.tracks, *self.carried})


def read(path: Path | str) -> Recording:
    """Read a recording written by `Recorder` (`path` a Path or a str, as docs/recording.md calls it), in one
    streaming pass: a file cut short (a crash) gives what its complete chunks hold, with `cut` set and a summary
    made up from the records (RecordingError naming the file when it holds no drd run at all)."""
    path = Path(path)
    damaged = _damaged()
    from mcap.reader import NonSeekingReader
    from mcap_protobuf.decoder import DecoderFactory

    out = Recording()
    factory = DecoderFactory()
    decoders: dict[int, Any] = {}  # a decoder per schema (by id), made from the schema in the file
    try:
        with path.open("rb") as fh:
            try:
                for schema, channel, message in NonSeekingReader(fh).iter_messages(log_time_order=False):
                    if channel.topic in (TF, WORLD) and schema is not None:
                        decoder = decoders.get(schema.id) or decoders.setdefault(
                            schema.id, factory.decoder_for(channel.message_encoding, schema))
                        if decoder is not None and channel.topic == TF:
                            _take_poses(out, _decoded(channel.topic, decoder, message.data), message.log_time)
                        elif decoder is not None:  # each camera's view, drawn when it is first read
                            _take_views(out, _decoded(channel.topic, decoder, message.data), message.log_time)
                    elif channel.message_encoding != "json":  # not drd's (a ROS 2 bag's CDR of the same topics)
                        continue
                    elif channel.topic in (RECORDS, RUNS):
                        _take(out, channel.topic, message.data)
                    elif channel.topic in (CAMERA, LIGHT) and len(out.fovs) < 64:
                        robot, fov = _camera_fov(channel.topic, message.data)
                        out.fovs.setdefault(robot, fov)
            except damaged as e:  # a file cut short, or a damaged chunk: keep what the chunks before it held
                if not out.records:
                    raise
                out.cut = True
                out.damage = f"stopped reading at byte {fh.tell():,} of {path.stat().st_size:,}: {_reason(e)}"
            fh.seek(0)
            try:
                out.world = next((a.data for a in NonSeekingReader(fh).iter_attachments()
                                  if a.name == WORLD_ATTACHMENT), None)
            except damaged:  # a damaged summary section (a name not UTF-8: readers audit 16, D4): no world
                pass
    except (OSError, ValueError) + damaged as e:
        raise RecordingError(f"{path}: cannot read it as a drd recording: {_unreadable(path, e)}") from e
    out.runs.sort(key=lambda run: int(run["order"]) if isinstance(run.get("order"), int) else 0)  # the report's
    if not out.records and not out.runs:
        raise RecordingError(f"{path}: no drd run in it (a drd recording has JSON messages on {RECORDS}: "
                             "`missionctl dry-run --record` or `run --record` writes one)")
    if out.damage is None and not out.runs:
        out.damage = "it ends before the run's summary (cut short)"
    if not out.runs:  # cut before the end: each mission's summary from its records
        out.cut = True
        out.runs = [{"format": FORMAT, "mission": records[0].path.split("/", 1)[0], "id": key, "records": key,
                     "sim_time": max(r.at for r in records), "wall_time": 0.0} for key, records in out.records.items()]
    return out


def _decoded(topic: str, decode: Callable[[bytes], Any], data: bytes) -> Any:
    """A protobuf message of `topic` (`/drd/tf`, `/drd/world`), or BadMessage: its bytes are not one (records audit
    26, D3: protobuf's DecodeError, no ValueError, ended `replay` with exit 70)."""
    from google.protobuf.message import DecodeError  # type: ignore[import-untyped]

    try:
        return decode(data)
    except DecodeError as e:
        raise BadMessage(f"a message on {topic} is not what its schema says: {e}") from None


def _camera_fov(topic: str, data: bytes) -> tuple[str, float]:
    """A camera frame's or brightness message's robot and field of view, or BadMessage (records audit 26, D3)."""
    frame = _loaded(topic, data)
    fov = frame.get("fov") if isinstance(frame, dict) else None
    if not isinstance(frame, dict) or not (fov is None or _amount(fov)):
        raise BadMessage(f"a message on {topic} is not an object with a number fov: {str(frame)[:80]}")
    return str(frame.get("robot")), float(fov or 0.0)


def _damaged() -> tuple[type[BaseException], ...]:
    """What the MCAP reader raises on a cut or damaged file: its own errors, a short read, and the decompressors'
    (lz4 raises RuntimeError on a bad checksum or a broken frame, zstandard its ZstdError)."""
    from mcap.exceptions import McapError

    kinds: list[type[BaseException]] = [McapError, struct.error, EOFError, RuntimeError,
                                        UnicodeDecodeError]  # a record's name or type no longer UTF-8
    try:
        from zstandard import ZstdError
    except ImportError:  # mcap reads zstd chunks only when it is installed
        pass
    else:
        kinds.append(ZstdError)
    return tuple(kinds)



def _unreadable(path: Path, e: BaseException) -> str:
    """Why a file is no recording, in words: an empty or very short file's reader error says nothing a user
    follows (an empty message, or `struct`'s "unpack requires a buffer of 4 bytes")."""
    try:
        size = path.stat().st_size
    except OSError:
        return _reason(e)
    if size == 0:
        return "the file is empty"
    if isinstance(e, struct.error) or not str(e).strip():
        return f"it ends after {size:,} bytes, before its first complete MCAP record (cut short, or not MCAP)"
    return _reason(e)


def _reason(e: BaseException) -> str:
    """The reader's error in one line (an lz4 error's text is its code: `ERROR_contentChecksum_invalid`)."""
    return (str(e).splitlines() or [type(e).__name__])[0][:200]


def _take_poses(out: Recording, decoded: Any, log_time: int) -> None:
    for t in decoded.transforms:
        if t.parent_frame_id != "world":  # a Scout in its Ranger's magazine
            carried = out.carried.setdefault(t.child_frame_id, [])
            if not carried or carried[-1][1] != t.parent_frame_id or (
                    out.tracks.get(t.child_frame_id) and out.tracks[t.child_frame_id][-1][0] > carried[-1][0]):
                carried.append((log_time / 1e9, t.parent_frame_id))
            continue
        h = 2 * math.atan2(t.rotation.z, t.rotation.w)
        heading = math.atan2(math.sin(h), math.cos(h))  # in (-pi, pi]
        out.tracks.setdefault(t.child_frame_id, []).append(
            (log_time / 1e9, t.translation.x, t.translation.y, heading))


def _take_views(out: Recording, scene: Any, log_time: int = 0) -> None:
    """The cameras' fields of view a `/drd/world` update draws (`Recorder.view`: an entity `fov/<robot>` with
    its `fov` in radians), so a replay knows a camera that never saw anyone; and the bodies it deletes (a lost
    robot's: `Recorder.delete_robots`)."""
    for d in scene.deletions:
        if d.id.startswith("body/"):
            out.gone.setdefault(d.id.removeprefix("body/"), log_time / 1e9)
    for e in scene.entities:
        if e.id.startswith(FOV):
            fov = next((m.value for m in e.metadata if m.key == "fov"), None)
            try:
                if fov is not None:  # (a file written before the views said it: its camera frames say it)
                    out.fovs.setdefault(e.id.removeprefix(FOV), float(fov))
            except ValueError:
                continue


class BadMessage(RecordingError, ValueError):
    """A message of a drd channel that is not what the channel's schema says (not the file's damage: the reader
    read it whole); a ValueError too, which the reading turns into `cannot read it as a drd recording: ...`."""


def _loaded(topic: str, data: bytes) -> Any:
    """A JSON message of `topic`, or BadMessage: not JSON (NaN and the infinities are not JSON either)."""
    def constant(name: str) -> Any:
        raise BadMessage(f"a message on {topic} holds {name}, which is not JSON")

    try:
        return json.loads(data, parse_constant=constant)
    except BadMessage:
        raise
    except ValueError as e:  # a UnicodeDecodeError too, which the reader's damage must not be taken for
        raise BadMessage(f"a message on {topic} is not JSON ({type(e).__name__}: {e})") from None
    except RecursionError:  # a RuntimeError, which the reader's damage must not be taken for (records audit 26, D4)
        raise BadMessage(f"a message on {topic} is nested too deeply to be a drd message") from None


def _amount(value: Any) -> bool:
    """A finite number of 0 or more (not a bool): a time, a speed, a field of view."""
    return isinstance(value, int | float) and not isinstance(value, bool) and 0 <= value < math.inf


#: A run summary's fields (`drd.dryrun.summary`): (key, what it must be, in words, whether it may be left out).
_RUN_FIELDS: tuple[tuple[str, Callable[[Any], bool], str, bool], ...] = (
    ("mission", lambda v: isinstance(v, str), "a string", False),
    ("records", lambda v: isinstance(v, str), "a string", False),
    ("sim_time", _amount, "a number of 0 or more", False),
    ("wall_time", _amount, "a number of 0 or more", True),
    ("controller_away", _amount, "a number of 0 or more", True),
    ("order", lambda v: isinstance(v, int) and not isinstance(v, bool), "an integer", True),
    ("id", lambda v: isinstance(v, str), "a string", True),
    ("priority", lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1, "an integer of 1 or more", True),
    ("speed", lambda v: _amount(v) and v > 0, "a positive number", True),
    ("on_cluster", lambda v: isinstance(v, bool), "true or false", True),
    ("injections", lambda v: isinstance(v, list) and all(isinstance(i, dict) for i in v), "a list of objects", True),
    ("scouts", lambda v: isinstance(v, list) and all(isinstance(i, dict) for i in v), "a list of objects", True),
)


def _run_problem(run: dict[str, Any]) -> str | None:
    """What a run summary (`/drd/runs`) lacks of its schema (`JSON_SCHEMAS[RUNS]`), in words (None: it is one):
    every field `dryrun.rebuilt` reads is checked here, so a replay never fails on one (records audit 26, D2)."""
    for key, fits, said, optional in _RUN_FIELDS:
        value = run.get(key)
        if value is None and optional:
            continue
        if not fits(value):
            return f"has {key} {value!r}, not {said}"
    return None


def _take(out: Recording, topic: str, data: bytes) -> None:
    if topic == RECORDS:
        d = _loaded(topic, data)
        problem = record_problem(d)  # what `replay --trace` writes back out must be a trace `check-trace` takes
        if problem is not None:
            raise BadMessage(f"a message on {topic}: {problem}")
        r = rec.from_dict(d)
        if r is not None:
            key, seq = str(d.get("mission", "")), d.get("seq")
            out.records.setdefault(key, []).append(r)
            out.seqs.setdefault(key, []).append(seq if isinstance(seq, int) else None)
            out.order.append(key)
    elif topic == RUNS:
        run = _loaded(topic, data)
        if not isinstance(run, dict) or run.get("format") != FORMAT:
            raise BadMessage(f"a run summary of format {run.get('format') if isinstance(run, dict) else run!r},"
                             f" not {FORMAT}")
        problem = _run_problem(run)
        if problem is not None:
            raise BadMessage(f"a run summary (mission {run.get('mission')!r}) {problem}")
        out.runs.append(run)


def state_at(recording: Recording, at: float) -> dict[str, Any]:
    """The run at sim time `at`: each mission's active leaves (running, waiting or suspended), what each behavior
    holds and who waits behind whom, from its records up to then; and where each robot was."""
    from drd.explain import Explainer

    missions = []
    for run in recording.runs:
        upto = [r for r in recording.records.get(str(run.get("records")), []) if r.at <= at + 1e-9]
        ex = Explainer(upto)
        ended = next((r for r in reversed(upto) if isinstance(r, rec.Finished)), None)
        missions.append({"mission": run.get("mission"), "id": run.get("id") or run.get("records"),
                         "outcome": ended.outcome if ended else None, "active": ex.active_now(),
                         "holds": ex.holds_now(), "waiting": ex.waiting_now()})
    where = {rid: {"x": round(p[0], 3), "y": round(p[1], 3), "heading": round(p[2], 4)}
             for rid in recording.robots() if (p := recording.pose(rid, at)) is not None
             and recording.gone.get(rid, math.inf) > at + 1e-9}  # a lost robot is no longer in the world
    ends = max([r.at for rs in recording.records.values() for r in rs] +
               [track[-1][0] for track in recording.tracks.values() if track], default=0.0)
    return {"at": at, "ends": round(ends, 6), "cut": recording.cut, "missions": missions,
            "robots": {k: v for k, v in where.items() if not k.startswith(INTRUDER)},
            "intruders": {k.removeprefix(INTRUDER): {"x": v["x"], "y": v["y"]} for k, v in where.items()
                          if k.startswith(INTRUDER)}}


#: A ROS 2 bag of a recording (`to_ros2_bag`): the topic and ROS 2 type of each channel it keeps. The scenes
#: (`/drd/world`, `/drd/trails`, `/drd/seen`) have no ROS 2 standard type short of markers, and are left out.
ROS2_TOPICS = {TF: ("/tf", "tf2_msgs/msg/TFMessage"), LOG: ("/rosout", "rcl_interfaces/msg/Log")}
#: The laser's reach in a bag (`LaserScan.range_max`): a Foxglove scan does not carry it; a beam that hit nothing
#: is +inf either way (REP 117).
ROS2_RANGE_MAX = 100.0


def to_ros2_bag(path: Path, bag: Path) -> dict[str, int]:
    """Write the recording at `path` as a ROS 2 bag (a folder, MCAP storage, CDR messages) at `bag`: `/tf`
    (`tf2_msgs/TFMessage`), `/<robot>/scan` (`sensor_msgs/LaserScan`), `/rosout` (`rcl_interfaces/Log`) and each
    JSON channel as `std_msgs/String` on its own topic. Messages per topic written; RecordingError if `path` is not
    a recording or `bag` exists (nothing is left at `bag` then). A file cut short (a crash) gives what its complete
    chunks hold, as `read` does. (`rosbags-convert` cannot: it reads ROS bags only, and refuses an MCAP file whose
    profile is not `ros2`.)

    The bag's metadata is rosbag2's version 8, whose `offered_qos_profiles` is a YAML string: Humble's rosbag2
    reads that layout (and so does every later one), not version 9's list (the "Jazzy bags in Humble" problem)."""
    from mcap.reader import NonSeekingReader
    from mcap_protobuf.decoder import DecoderFactory
    from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
    from rosbags.typesys import Stores, get_typestore

    store, factory, counts = get_typestore(Stores.ROS2_HUMBLE), DecoderFactory(), dict[str, int]()
    connections: dict[str, Any] = {}
    try:
        with path.open("rb") as fh, Writer(bag, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
            try:
                for schema, channel, message in NonSeekingReader(fh).iter_messages(log_time_order=False):
                    decode = None if schema is None or channel.message_encoding == "json" else \
                        factory.decoder_for(channel.message_encoding, schema)
                    converted = _ros2(store, channel.topic, message.log_time,
                                      message.data if decode is None else _decoded(channel.topic, decode, message.data))
                    if converted is None:
                        continue
                    topic, kind, msg = converted
                    if topic not in connections:
                        connections[topic] = writer.add_connection(topic, kind, typestore=store)
                    writer.write(connections[topic], message.log_time, store.serialize_cdr(msg, kind))
                    counts[topic] = counts.get(topic, 0) + 1
            except _damaged():  # cut short: the complete chunks before are the bag
                if not counts:
                    raise
    except (OSError, WriterError) + _damaged() as e:
        if bag.is_dir():  # what the writer began is no bag: nothing half-written is left behind
            shutil.rmtree(bag, ignore_errors=True)
        raise RecordingError(f"{path}: cannot write it as a ROS 2 bag at {bag}: {_unreadable(path, e)}") from e
    return counts


def _ros2(store: Any, topic: str, ns: int, message: Any) -> tuple[str, str, Any] | None:
    """One message of a recording as (topic, ROS 2 type, message), or None for one a bag does not keep."""
    T = store.types
    stamp = T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def header(frame: str) -> Any:
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    if topic == TF:
        return "/tf", "tf2_msgs/msg/TFMessage", T["tf2_msgs/msg/TFMessage"](transforms=[
            T["geometry_msgs/msg/TransformStamped"](header=header(t.parent_frame_id), child_frame_id=t.child_frame_id,
                                                    transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=t.translation.x, y=t.translation.y, z=t.translation.z),
                rotation=T["geometry_msgs/msg/Quaternion"](x=t.rotation.x, y=t.rotation.y, z=t.rotation.z,
                                                           w=t.rotation.w))) for t in message.transforms])
    if topic.startswith(SCAN):
        import numpy as np

        n = len(message.ranges)
        return f"/{topic.removeprefix(SCAN)}/scan", "sensor_msgs/msg/LaserScan", T["sensor_msgs/msg/LaserScan"](
            header=header(message.frame_id), angle_min=message.start_angle, angle_max=message.end_angle,
            angle_increment=(message.end_angle - message.start_angle) / max(1, n - 1), time_increment=0.0,
            scan_time=SCAN_EVERY, range_min=0.0, range_max=ROS2_RANGE_MAX,
            ranges=np.asarray(message.ranges, dtype=np.float32), intensities=np.zeros(0, dtype=np.float32))
    if topic == LOG:
        return "/rosout", "rcl_interfaces/msg/Log", T["rcl_interfaces/msg/Log"](
            stamp=stamp, level=20, name=message.name, msg=message.message, file="", function="", line=0)
    if topic in JSON_SCHEMAS:
        return topic, "std_msgs/msg/String", T["std_msgs/msg/String"](data=bytes(message).decode("utf-8"))
    return None
