"""The ownership invariant, checked from a trace alone (the records of `docs/trace.md`, as dicts).

What a run promises, whatever happened in it: a device obeys only the behavior subtree holding its current
grant, at that grant's epoch; an exclusive unit has one holder at a time; every hold ends by the end of a
finished mission. `check` reads `granted` (units and epochs), `revoked`/`released`/`exited` (ends of holds) and
`command` records, in order, per mission (`mission` field, when a trace holds several), and lists every breach.
`read_trace` turns a trace file's lines into records, each checked against docs/trace.md's tables first: a
record `check` would misread (a time that is not a number, a command without its device) is the file's error, at
its line, not a pass or a crash. Pure: the caller opens the file (`missionctl check-trace` does).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from drd.errors import DrdError


class TraceError(DrdError):
    """A trace file that is not a trace: `where` is `FILE:LINE` of the first bad record."""

    kind = "trace"


#: A field's test and what it should be, as an error says it.
FieldType = tuple[Callable[[Any], bool], str]


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _integer(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


STRING: FieldType = (lambda v: isinstance(v, str), "a string")
NUMBER: FieldType = (_number, "a number")
INTEGER: FieldType = (_integer, "an integer")
BOOLEAN: FieldType = (lambda v: isinstance(v, bool), "true or false")
EPOCH: FieldType = (lambda v: v is None or _integer(v), "an integer or null")
STRINGS: FieldType = (lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v), "a list of strings")
OBJECT: FieldType = (lambda v: isinstance(v, dict), "an object")
NAMES: FieldType = (lambda v: isinstance(v, dict) and all(isinstance(x, str) for x in v.values()),
                    "an object of strings")
EPOCHS: FieldType = (lambda v: isinstance(v, dict) and all(_integer(x) for x in v.values()),
                     "an object of integers")
HOLDS: FieldType = (lambda v: isinstance(v, dict) and all(NAMES[0](x) for x in v.values()),
                    "an object of objects of strings")

#: The fields every record has (docs/trace.md, "Every record"), and those some traces have.
COMMON: dict[str, FieldType] = {"kind": STRING, "at": NUMBER, "path": STRING}
COMMON_OPTIONAL: dict[str, FieldType] = {"mission": STRING, "seq": INTEGER}
#: Each kind's fields (docs/trace.md, "Kinds"): drd writes all of them in every record of the kind.
KINDS: dict[str, dict[str, FieldType]] = {
    "entered": {"state": STRING},
    "exited": {"state": STRING, "status": STRING},
    "taken": {"target": STRING, "trigger": STRING, "label": STRING},
    "waiting": {"needs": STRINGS, "blocked_by": STRINGS},
    "reserved": {"by": STRING, "needs": STRINGS},
    "granted": {"resources": NAMES, "epochs": EPOCHS},
    "revoked": {"resources": STRINGS, "reason": STRING},
    "released": {"resources": STRINGS, "reason": STRING},
    "suspended": {},
    "resumed": {},
    "command": {"device": STRING, "method": STRING, "epoch": EPOCH, "accepted": BOOLEAN, "reason": STRING},
    "halted": {"device": STRING, "method": STRING, "reason": STRING, "error": STRING},
    "restored": {"since": NUMBER, "paused": NUMBER},
    "event": {"name": STRING, "fields": OBJECT},
    "log": {"text": STRING},
    "finished": {"outcome": STRING, "reason": STRING},
}
#: Fields added to a kind later (a field is only ever added): checked when there, not required of older traces.
KINDS_OPTIONAL: dict[str, dict[str, FieldType]] = {"exited": {"reason": STRING}, "granted": {"shares": NAMES},
                                                   "waiting": {"holds": HOLDS}}


def record_problem(record: Any) -> str | None:
    """What is wrong with one parsed trace line, or None. A kind this version does not know is checked for the
    common fields only: readers ignore what they do not know (docs/trace.md, "Stability")."""
    if not isinstance(record, dict):
        return f"a record is a JSON object, not {_json_kind(record)}"
    kind = record.get("kind")
    own = KINDS.get(kind, {}) if isinstance(kind, str) else {}
    what = f"`{kind}` record" if isinstance(kind, str) and kind in KINDS else "record"
    for required, fields in ((True, COMMON), (True, own), (False, COMMON_OPTIONAL),
                             (False, KINDS_OPTIONAL.get(kind, {}) if isinstance(kind, str) else {})):
        for name, (test, expected) in fields.items():
            if name not in record:
                if required:
                    listed = ", ".join(f"`{f}`" for f in (*COMMON, *own))
                    return f"{what} without `{name}` (its fields: {listed}; docs/trace.md)"
                continue
            if not test(record[name]):
                return f"{what}: `{name}` is {_shown(record[name])}, not {expected}"
    return None


def read_trace(lines: Iterable[bytes], name: str) -> list[dict[str, Any]]:
    """The records of a trace's lines (JSON objects, blank lines skipped), each checked by `record_problem`;
    `TraceError` at `name:LINE` for the first line that is not a record."""
    records: list[dict[str, Any]] = []
    for number, raw in enumerate(lines, 1):
        where = f"{name}:{number}"
        try:
            text = raw.decode("utf-8").rstrip()  # the line's end: a column of an error is on this line
        except UnicodeDecodeError as e:
            raise TraceError(f"not UTF-8 text (byte {e.start + 1} of the line)", where=where) from None
        if not text.strip():
            continue
        try:
            record = json.loads(text)
        except json.JSONDecodeError as e:
            raise TraceError(f"not a JSON record: {e.msg} (column {e.colno})", where=where) from None
        except (ValueError, RecursionError) as e:  # a number of 4,300 digits or more, nesting too deep for Python:
            raise TraceError(f"not a JSON record drd reads: {_why(e)}", where=where) from None  # records audit 26, D4
        problem = record_problem(record)
        if problem is not None:
            raise TraceError(problem, where=where)
        records.append(record)
    return records


def _json_kind(value: Any) -> str:
    return {list: "a list", str: "a string", bool: "a boolean", type(None): "null"}.get(type(value), "a number")


def _shown(value: Any) -> str:
    text = json.dumps(value, ensure_ascii=False)
    return text if len(text) <= 40 else text[:37] + "..."


@dataclass(frozen=True, slots=True)
class Breach:
    """One violation of the invariant, at a record of the trace."""

    at: float
    kind: str  # "non-holder command", "double hold", "held at the end", "after finished", "time backwards"
    detail: str


@dataclass
class OwnershipReport:
    records: int = 0
    commands: int = 0
    accepted: int = 0
    refused: int = 0
    grants: int = 0
    breaches: list[Breach] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.breaches

    def summary(self) -> str:
        return (f"ownership: {self.accepted} accepted commands of {self.commands} ({self.refused} refused),"
                f" {self.grants} grants; {len(self.breaches)} breaches")


def _why(e: BaseException) -> str:
    return "nested too deeply" if isinstance(e, RecursionError) else str(e)


def under(path: str, holder: str) -> bool:
    """Whether `path` is `holder` or lies in its subtree."""
    return path == holder or path.startswith(holder + "/")


def check(records: Iterable[Mapping[str, Any]], sharable: Collection[str] = ()) -> OwnershipReport:
    """Check a trace's records in order; `sharable`: unit ids that several holders may hold at once."""
    report = OwnershipReport()
    holders: dict[tuple[str, str], dict[str, int]] = {}  # (mission, unit) -> {holder path: epoch}
    epochs: dict[str, int] = {}  # exclusive unit -> the epoch of its last grant
    finished: set[str] = set()
    seen: list[Mapping[str, Any]] = []
    for r in records:
        seen.append(r)
        report.records += 1
        kind, mission, path = r.get("kind"), str(r.get("mission", "")), str(r.get("path", ""))
        at = float(r.get("at", 0.0) or 0.0)
        if kind == "granted":
            report.grants += 1
            report.breaches += _grant_breaches(r, holders, epochs, sharable)
        elif kind in ("revoked", "released"):
            for unit in r.get("resources") or ():
                holders.get((mission, str(unit)), {}).pop(path, None)
        elif kind == "exited":
            for (m, _), held in holders.items():
                if m == mission:
                    held.pop(path, None)
        elif kind == "finished":
            finished.add(mission)
            left = [(u, h) for (m, u), held in holders.items() if m == mission for h in held]
            for unit, holder in left:
                report.breaches.append(Breach(at, "held at the end", f"{holder} still holds {unit}"))
        elif kind == "command":
            report.commands += 1
            if not r.get("accepted"):
                report.refused += 1
                continue
            report.accepted += 1
            unit, epoch = str(r.get("device")), r.get("epoch")
            held = holders.get((mission, unit), {})
            if not any(under(path, h) and e == epoch for h, e in held.items()):
                have = ", ".join(f"{h} at epoch {e}" for h, e in held.items()) or "nobody"
                report.breaches.append(Breach(at, "non-holder command", f"{path} commanded {unit}."
                                              f"{r.get('method')} at epoch {epoch}; holders: {have}"))
    report.breaches += order_breaches(seen)
    return report


def _grant_breaches(r: Mapping[str, Any], holders: dict[tuple[str, str], dict[str, int]], epochs: dict[str, int],
                    sharable: Collection[str]) -> list[Breach]:
    """A `granted` record's units taken into `holders` (and an exclusive one's epoch into `epochs`): a double hold,
    and an exclusive unit granted at an epoch not above its previous grant's (epochs strictly increase per unit,
    across a controller's restart too: a reused one would let a stale command pass a gate)."""
    out = []
    at, mission, path = float(r.get("at", 0.0) or 0.0), str(r.get("mission", "")), str(r.get("path", ""))
    shares = set(dict(r.get("shares") or {}).values())  # a share of a sharable unit, not a hold
    for unit, epoch in dict(r.get("epochs") or {}).items():
        held = holders.setdefault((mission, unit), {})
        exclusive = unit not in sharable and unit not in shares
        others = [h for h in held if h != path]
        shared_by_missions = [(m, u) for (m, u), hs in holders.items() if u == unit and m != mission and hs]
        if exclusive and (others or shared_by_missions):
            who = others or [f"{m}: {', '.join(holders[(m, u)])}" for m, u in shared_by_missions]
            out.append(Breach(at, "double hold", f"{unit} granted to {path} while held by {', '.join(who)}"))
        if exclusive and unit in epochs and int(epoch) <= epochs[unit]:
            out.append(Breach(at, "epoch reused", f"{unit} granted to {path} at epoch {epoch}, not above the epoch "
                                                  f"of its grant before ({epochs[unit]})"))
        if exclusive:
            epochs[unit] = max(epochs.get(unit, 0), int(epoch))
        held[path] = int(epoch)
    return out


def unfinished(records: Iterable[Mapping[str, Any]]) -> list[Breach]:
    """A mission with records and no `finished`: the trace was cut short (a crash, a writer killed, a file cut at a
    line's end), or the mission still ran when it was read. Either way it is not a whole trace (docs/trace.md: a
    truncated trace is never a pass)."""
    last: dict[str, float] = {}
    ended: set[str] = set()
    for r in records:
        mission = str(r.get("mission", ""))
        last[mission] = float(r.get("at", 0.0) or 0.0)
        if r.get("kind") == "finished":
            ended.add(mission)
        elif opens_restore(r):
            ended.discard(mission)
    return [Breach(at, "unfinished", f"{mission or 'the mission'} has no `finished` record: the trace was cut short,"
                                     " or the mission still ran when it was written")
            for mission, at in last.items() if mission not in ended]


def opens_restore(r: Mapping[str, Any]) -> bool:
    """Whether `r` opens a restore (`released` with reason `controller lost`, or `restored`): the restored
    mission's clock goes on from its journal's last save, which may be before its last records."""
    return r.get("kind") == "restored" or r.get("kind") == "released" and r.get("reason") == "controller lost"


def order_breaches(records: Iterable[Mapping[str, Any]]) -> list[Breach]:
    """docs/trace.md's order, per mission: nothing of a mission after its `finished`, and its `at` never goes
    back, except where a restore opens (`opens_restore`)."""
    breaches: list[Breach] = []
    last: dict[str, tuple[float, str]] = {}  # mission -> (at, kind) of its latest record
    ended: set[str] = set()
    for r in records:
        mission, kind = str(r.get("mission", "")), str(r.get("kind"))
        at = float(r.get("at", 0.0) or 0.0)
        where = f"{kind} of {r.get('path', '')}" + (f" (seq {r['seq']})" if "seq" in r else "")
        if opens_restore(r):  # a restore enters the mission again (a dry-run's stopped executive ended it first)
            ended.discard(mission)
        if mission in ended:
            breaches.append(Breach(at, "after finished", f"{where} comes after {mission or 'the mission'} finished"))
        before = last.get(mission)
        if before is not None and at < before[0] and not opens_restore(r):
            breaches.append(Breach(at, "time backwards", f"{where} at {at:g} s comes after a {before[1]} at "
                                                         f"{before[0]:g} s"))
        last[mission] = (at, kind)
        if kind == "finished":
            ended.add(mission)
    return breaches
