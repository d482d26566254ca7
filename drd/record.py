"""A run as an MCAP file (issue #13, first part): what the mission did, where the robots were, and its ending.

Written with the Foxglove SDK (its MCAP writer and standard schemas), read back with `mcap`, so any MCAP tool
(Foxglove, `ros2 bag`, PlotJuggler, the `mcap` CLI) opens it. Message log times are sim time. Channels:

- `/drd/records`: every trace record, JSON (`docs/trace.md`: `kind`, `at`, `path`, its fields, `mission`);
- `/drd/world`: `foxglove.SceneUpdate`, once at the start: the walls, each door (its colour its state) and each
  room's name, in the `world` frame;
- `/drd/tf`: `foxglove.FrameTransforms`, each robot's pose in the `world` frame every control cycle, and each
  intruder's (frame `intruder/<id>`);
- `/drd/runs`: one JSON message per mission when the run ends: what the records cannot say (its id, priority,
  speed, wall time, the injections, where each placed Scout ended), so `replay` rebuilds the same report.

The MCAP writer indexes the file as it goes (chunks), so a file cut short by a crash is still readable up to its
last chunk.
"""

from __future__ import annotations

import bisect
import json
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drd.errors import ConfigurationError
from drd.runtime import records as rec
from drd.runtime.trace import trace_line
from drd.sim.model import World

RECORDS, TF, RUNS, WORLD = "/drd/records", "/drd/tf", "/drd/runs", "/drd/world"
WORLD_ATTACHMENT = "world.yaml"
#: Chunks of this size (uncompressed), and a flush every this many seconds of sim time.
CHUNK_BYTES, FLUSH_EVERY = 64 * 1024, 1.0
#: The frame of an intruder (a person walking through the world, not a robot): `intruder/<id>`.
INTRUDER = "intruder/"
#: The version of this layout, in the file's metadata (`drd` record `format`).
FORMAT = "drd-run-1"


class RecordingError(ConfigurationError):
    """A recording cannot be written or read (the message names the file)."""


def _ns(seconds: float) -> int:
    return max(0, int(round(seconds * 1e9)))


class Recorder:
    """Writes one run into `path`: `record` for each trace record, `poses` each control cycle, `end` once."""

    def __init__(self, path: Path) -> None:
        import foxglove
        from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel

        self.path = path
        self.context = foxglove.Context()  # this run's own: nothing global, several recorders may coexist
        from foxglove.mcap import MCAPWriteOptions

        try:  # small chunks, flushed each second of sim time: a run cut short keeps all but its last second
            self.writer = foxglove.open_mcap(str(path), allow_overwrite=True, context=self.context,
                                             writer_options=MCAPWriteOptions(chunk_size=CHUNK_BYTES))
        except Exception as e:  # the SDK's own errors: a folder that does not exist, no permission
            raise RecordingError(f"{path}: cannot write the recording: {e}") from e
        self.records = foxglove.Channel(RECORDS, message_encoding="json", context=self.context,
                                        schema=_json_schema(foxglove, "drd.Record", RECORD_SCHEMA))
        self.runs = foxglove.Channel(RUNS, message_encoding="json", context=self.context,
                                     schema=_json_schema(foxglove, "drd.Run", RUN_SCHEMA))
        self.tf = FrameTransformsChannel(TF, context=self.context)
        self.world = SceneUpdateChannel(WORLD, context=self.context)
        self.closed = False
        self.flushed = 0.0  # the sim time of the last flush

    def scene(self, world: World) -> None:
        """The world as a scene at time 0: walls, doors (green open, orange closed, red blocked), room names; and
        its file as the attachment `world.yaml`, so a replay can draw the run without it."""
        source = Path(world.source)
        if source.is_file():
            self.writer.attach(log_time=0, create_time=0, name=WORLD_ATTACHMENT, media_type="application/yaml",
                               data=source.read_bytes())
        from foxglove.messages import (
            Color,
            LinePrimitive,
            LinePrimitiveLineType,
            Point3,
            Pose,
            Quaternion,
            SceneEntity,
            SceneUpdate,
            TextPrimitive,
            Vector3,
        )

        def line(points: list[tuple[float, float]], color: Color, width: float) -> LinePrimitive:
            return LinePrimitive(type=LinePrimitiveLineType.LineList, thickness=width, scale_invariant=False,
                                 points=[Point3(x=x, y=y, z=0.0) for x, y in points], color=color)

        flat = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
        doors = {"open": Color(r=0.2, g=0.7, b=0.3, a=1.0), "closed": Color(r=0.95, g=0.6, b=0.1, a=1.0),
                 "blocked": Color(r=0.85, g=0.15, b=0.15, a=1.0)}
        walls = [p for w in world.walls for p in ((w.a[0], w.a[1]), (w.b[0], w.b[1]))]
        entities = [SceneEntity(frame_id="world", id="walls", lines=[line(walls, Color(r=0.3, g=0.3, b=0.35, a=1.0),
                                                                           0.08)])]
        entities += [SceneEntity(frame_id="world", id=f"door/{d.id}",
                                 lines=[line([(d.a[0], d.a[1]), (d.b[0], d.b[1])], doors[d.state.value], 0.12)])
                     for d in world.doors]
        entities += [SceneEntity(frame_id="world", id=f"room/{r.id}", texts=[TextPrimitive(
            pose=Pose(position=Vector3(x=(r.x0 + r.x1) / 2, y=(r.y0 + r.y1) / 2, z=0.0), orientation=flat),
            billboard=True, font_size=0.4, scale_invariant=False, color=Color(r=0.1, g=0.1, b=0.1, a=1.0),
            text=r.id)]) for r in world.rooms]
        self.world.log(SceneUpdate(entities=entities), log_time=0)

    def record(self, mission: str, r: rec.Record) -> None:
        self.records.log(trace_line(r, mission, exact=True), log_time=_ns(r.at))

    def poses(self, at: float, poses: dict[str, tuple[float, float, float]]) -> None:
        """Each robot's (x, y, heading) at sim time `at`, as frame transforms from `world`."""
        from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Timestamp, Vector3

        stamp = Timestamp(sec=int(at), nsec=int(round((at - int(at)) * 1e9)) % 1_000_000_000)
        self.tf.log(FrameTransforms(transforms=[
            FrameTransform(timestamp=stamp, parent_frame_id="world", child_frame_id=rid,
                           translation=Vector3(x=x, y=y, z=0.0),
                           rotation=Quaternion(x=0.0, y=0.0, z=math.sin(h / 2), w=math.cos(h / 2)))
            for rid, (x, y, h) in sorted(poses.items())]), log_time=_ns(at))
        if at - self.flushed >= FLUSH_EVERY:
            self.flushed = at
            self.writer.flush()

    def end(self, runs: Sequence[dict[str, Any]], at: float) -> None:
        """Each mission's run summary (`summary`), then close the file."""
        for run in runs:
            self.runs.log(json.dumps({"format": FORMAT, **run}, default=_default), log_time=_ns(at))
        self.close()

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.writer.close()


def _default(value: Any) -> Any:
    return getattr(value, "id", None) or str(value)


#: The JSON schemas of the two JSON channels (named, so a viewer lists `drd.Record`, not an anonymous schema).
RECORD_SCHEMA = {"type": "object", "required": ["kind", "at", "path", "mission"], "properties": {
    "kind": {"type": "string"}, "at": {"type": "number"}, "path": {"type": "string"}, "mission": {"type": "string"}}}
RUN_SCHEMA = {"type": "object", "required": ["format", "mission", "records", "sim_time"], "properties": {
    "format": {"type": "string"}, "mission": {"type": "string"}, "records": {"type": "string"},
    "sim_time": {"type": "number"}, "wall_time": {"type": "number"}}}


def _json_schema(foxglove: Any, name: str, schema: dict[str, Any]) -> Any:
    return foxglove.Schema(name=name, encoding="jsonschema", data=json.dumps(schema).encode())


@dataclass
class Recording:
    """What a recording holds, read back: each mission's records, its run summary, and each robot's track
    (sim time, x, y, heading), decoded from the Foxglove transforms with `mcap_protobuf`."""

    records: dict[str, list[rec.Record]] = field(default_factory=dict)
    runs: list[dict[str, Any]] = field(default_factory=list)
    tracks: dict[str, list[tuple[float, float, float, float]]] = field(default_factory=dict)
    world: bytes | None = None  # the world file the run used (`world.yaml` attachment), if it was a file
    cut: bool = False  # the file ends before the run did (a crash): what its complete chunks held

    def load_world(self, name: str) -> World | None:
        """The recorded world (its problems name `name`), or None when the recording has none."""
        from drd.config import load_yaml
        from drd.sim.world import parse_world

        return None if self.world is None else parse_world(load_yaml(self.world.decode("utf-8")), name)

    def pose(self, robot: str, at: float) -> tuple[float, float, float] | None:
        """Where `robot` was at sim time `at` (its last recorded pose then), or None before its first."""
        track = self.tracks.get(robot, [])
        i = bisect.bisect_right([t for t, *_ in track], at + 1e-9)
        return None if i == 0 else track[i - 1][1:]


def read(path: Path) -> Recording:
    """Read a recording written by `Recorder`, in one streaming pass: a file cut short (a crash) gives what its
    complete chunks hold, with `cut` set and a summary made up from the records (RecordingError naming the file
    when it holds no drd run at all)."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader
    from mcap_protobuf.decoder import DecoderFactory

    out = Recording()
    factory = DecoderFactory()
    decoders: dict[int, Any] = {}  # a decoder per schema (by id), made from the schema in the file
    try:
        with path.open("rb") as fh:
            try:
                for schema, channel, message in NonSeekingReader(fh).iter_messages(log_time_order=False):
                    if channel.topic == TF and schema is not None:
                        decoder = decoders.get(schema.id) or decoders.setdefault(
                            schema.id, factory.decoder_for(channel.message_encoding, schema))
                        if decoder is not None:
                            _take_poses(out, decoder(message.data), message.log_time)
                    elif channel.topic in (RECORDS, RUNS):
                        _take(out, channel.topic, message.data)
            except (McapError, struct.error, EOFError):  # a file cut short: keep what its complete chunks held
                if not out.records:
                    raise
                out.cut = True
            fh.seek(0)
            try:
                out.world = next((a.data for a in NonSeekingReader(fh).iter_attachments()
                                  if a.name == WORLD_ATTACHMENT), None)
            except (McapError, struct.error, EOFError):
                pass
    except (OSError, McapError, ValueError, struct.error, EOFError) as e:
        raise RecordingError(f"{path}: cannot read it as a drd recording: {e}") from e
    if not out.records and not out.runs:
        raise RecordingError(f"{path}: no drd run in it")
    if not out.runs:  # cut before the end: each mission's summary from its records
        out.cut = True
        out.runs = [{"format": FORMAT, "mission": records[0].path.split("/", 1)[0], "id": key, "records": key,
                     "sim_time": max(r.at for r in records), "wall_time": 0.0} for key, records in out.records.items()]
    return out


def _take_poses(out: Recording, decoded: Any, log_time: int) -> None:
    for t in decoded.transforms:
        h = 2 * math.atan2(t.rotation.z, t.rotation.w)
        heading = math.atan2(math.sin(h), math.cos(h))  # in (-pi, pi]
        out.tracks.setdefault(t.child_frame_id, []).append(
            (log_time / 1e9, t.translation.x, t.translation.y, heading))


def _take(out: Recording, topic: str, data: bytes) -> None:
    if topic == RECORDS:
        d = json.loads(data)
        r = rec.from_dict(d)
        if r is not None:
            out.records.setdefault(str(d.get("mission", "")), []).append(r)
    elif topic == RUNS:
        run = json.loads(data)
        if run.get("format") != FORMAT:
            raise ValueError(f"a run summary of format {run.get('format')!r}, not {FORMAT}")
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
             for rid in sorted(recording.tracks) if (p := recording.pose(rid, at)) is not None}
    return {"at": at, "missions": missions, "robots": {k: v for k, v in where.items() if not k.startswith(INTRUDER)},
            "intruders": {k.removeprefix(INTRUDER): {"x": v["x"], "y": v["y"]} for k, v in where.items()
                          if k.startswith(INTRUDER)}}
