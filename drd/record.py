"""A run as an MCAP file (issue #13, first part): what the mission did, where the robots were, and its ending.

Written with the Foxglove SDK (its MCAP writer and standard schemas), read back with `mcap`, so any MCAP tool
(Foxglove, `ros2 bag`, PlotJuggler, the `mcap` CLI) opens it. Message log times are sim time. Channels:

- `/drd/records`: every trace record, JSON (`docs/trace.md`: `kind`, `at`, `path`, its fields, `mission`);
- `/drd/tf`: `foxglove.FrameTransforms`, each robot's pose in the `world` frame, every control cycle;
- `/drd/runs`: one JSON message per mission when the run ends: what the records cannot say (its id, priority,
  speed, wall time, the injections, where each placed Scout ended), so `replay` rebuilds the same report.

The MCAP writer indexes the file as it goes (chunks), so a file cut short by a crash is still readable up to its
last chunk.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drd.errors import ConfigurationError
from drd.runtime import records as rec
from drd.runtime.trace import trace_line

RECORDS, TF, RUNS = "/drd/records", "/drd/tf", "/drd/runs"
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
        from foxglove.channels import FrameTransformsChannel

        self.path = path
        self.context = foxglove.Context()  # this run's own: nothing global, several recorders may coexist
        try:
            self.writer = foxglove.open_mcap(str(path), allow_overwrite=True, context=self.context)
        except Exception as e:  # the SDK's own errors: a folder that does not exist, no permission
            raise RecordingError(f"{path}: cannot write the recording: {e}") from e
        self.records = foxglove.Channel(RECORDS, message_encoding="json", context=self.context)
        self.runs = foxglove.Channel(RUNS, message_encoding="json", context=self.context)
        self.tf = FrameTransformsChannel(TF, context=self.context)
        self.closed = False

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


@dataclass
class Recording:
    """What a recording holds, read back: each mission's records and its run summary."""

    records: dict[str, list[rec.Record]] = field(default_factory=dict)
    runs: list[dict[str, Any]] = field(default_factory=list)


def read(path: Path) -> Recording:
    """Read a recording written by `Recorder` (RecordingError naming the file when it is not one)."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    out = Recording()
    try:
        with path.open("rb") as fh:
            for _schema, channel, message in make_reader(fh).iter_messages(topics=[RECORDS, RUNS]):
                _take(out, channel.topic, message.data)
    except (OSError, McapError, ValueError) as e:
        raise RecordingError(f"{path}: cannot read it as a drd recording: {e}") from e
    if not out.runs:
        raise RecordingError(f"{path}: no run summary in it (a recording cut short, or not drd's)")
    return out


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
    # /drd/tf is for viewers (protobuf, Foxglove's schema): a replay's report does not need the tracks
