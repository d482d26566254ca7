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
        return json.dumps(_finite(data), default=_default, separators=(",", ":"), allow_nan=False)


def _finite(value: Any) -> Any:
    """`value` with every non-finite float (at any depth) as None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


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
