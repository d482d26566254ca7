"""A listener that writes every record as one JSON line: the `--trace` file."""

from __future__ import annotations

import json
import math
from typing import IO, Any

from drd.runtime.records import Record


def _default(value: Any) -> Any:
    """Resources and other objects appear by their id or text."""
    return getattr(value, "id", None) or str(value)


def trace_line(record: Record, mission: str = "", exact: bool = False) -> str:
    """One record as a trace line (`docs/trace.md`), also a recording's message (`drd.record`, `exact`: its time
    unrounded, so that a replay computes the very durations the run did)."""
    data = record.to_dict()
    if not exact:
        data["at"] = round(data["at"], 6)  # float steps (0.1 s ten times) would read 0.9999999999999999
    if mission:
        data["mission"] = mission
    try:
        return json.dumps(data, default=_default, separators=(",", ":"), allow_nan=False)
    except ValueError:  # a NaN or an infinity (a component's event field): JSON has none, so null, as orjson writes
        return json.dumps(finite(data), default=_default, separators=(",", ":"), allow_nan=False)


def finite(data: Any) -> Any:
    """`data` with every float that is not finite (inf, NaN), at any depth, as None: what strict JSON may hold (a
    trace line, a `--json` output)."""
    if isinstance(data, float):
        return data if math.isfinite(data) else None
    if isinstance(data, dict):
        return {k: finite(v) for k, v in data.items()}
    if isinstance(data, list | tuple):
        return [finite(v) for v in data]
    return data


class TraceWriter:
    """Attach with `interpreter.attach(TraceWriter(fh, mission))`; each record becomes one line, with the mission
    it belongs to (several missions may write one file). The format is `docs/trace.md`."""

    def __init__(self, out: IO[str], mission: str = "", flush_every: int = 64):
        self.out = out
        self.mission = mission
        self.flush_every = flush_every
        self.count = 0

    def __call__(self, record: Record) -> None:
        self.out.write(trace_line(record, self.mission) + "\n")
        self.count += 1
        if self.count % self.flush_every == 0:
            self.out.flush()
