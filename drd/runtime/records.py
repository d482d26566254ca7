"""What listeners receive: one frozen record per entry, exit, transition, grant, event...

Every record names the behavior instance by its path (aliases and instance indices
included, e.g. `SharedCamera/first/Observe` or `CorridorSurveillance/RoomSurveillance[2]`)
and the sim or wall time it happened at. `to_dict` gives the JSON-lines trace form.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

_FIELDS: dict[type, tuple[str, ...]] = {}


def _fields(cls: type) -> tuple[str, ...]:
    found = _FIELDS.get(cls)
    if found is None:
        found = _FIELDS[cls] = tuple(f.name for f in fields(cls))
    return found


@dataclass(frozen=True, slots=True)
class Record:
    at: float
    path: str

    @property
    def kind(self) -> str:
        return type(self).__name__.lower()

    def to_dict(self) -> dict[str, Any]:
        """The record as the trace has it: `kind`, then its fields (shallow: records are frozen, and what they
        hold is plain data already; `dataclasses.asdict` deep-copied every field of every record)."""
        out: dict[str, Any] = {"kind": self.kind}
        for name in _fields(type(self)):
            out[name] = getattr(self, name)
        return out


@dataclass(frozen=True, slots=True)
class Entered(Record):
    state: str


@dataclass(frozen=True, slots=True)
class Exited(Record):
    state: str
    status: str  # success, failure, stopped
    reason: str = ""  # why it failed, when it failed on its own (a timeout, a lost resource, an entry that failed)


@dataclass(frozen=True, slots=True)
class Taken(Record):
    """A transition: `path` is the source instance, `target` the target's path."""

    target: str
    trigger: str
    label: str = ""


@dataclass(frozen=True, slots=True)
class Waiting(Record):
    """`blocked_by`: this mission's blockers by path, another mission's as `<mission id>/<path>`; `holds`: what
    each of those other missions' blockers held then (need -> resource id; {} for a waiter). The trace has
    `holds` only when another mission blocks: what a reader cannot find in this mission's own records."""

    needs: tuple[str, ...]
    blocked_by: tuple[str, ...] = ()
    holds: dict[str, dict[str, str]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": "waiting", "at": self.at, "path": self.path, "needs": self.needs,
                               "blocked_by": self.blocked_by}
        if self.holds:  # a field added later: absent when it says nothing (one mission's traces are unchanged)
            out["holds"] = self.holds
        return out


@dataclass(frozen=True, slots=True)
class Reserved(Record):
    """`path`'s needs are preallocated now, while `by` (the state before it) runs: it will start without waiting."""

    by: str
    needs: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Granted(Record):
    """`path` holds these resources from now on: need -> resource id, and for an aggregate each of its parts
    (`ranger.drive` -> `ranger1.drive`); `epochs`: unit id -> the fencing epoch of this grant.

    A sharable unit (a radio channel) is not held but shared: it is in `shares` (need -> unit id), never in
    `resources`, so the trace says from its records alone which grants may overlap (several holders at once, up to
    the unit's capacity) and which may not (`drd.tracecheck`, ../shared/tools/check_ownership.py)."""

    resources: dict[str, str] = field(default_factory=dict)
    epochs: dict[str, int] = field(default_factory=dict)
    shares: dict[str, str] = field(default_factory=dict)

    @property
    def named(self) -> dict[str, str]:
        """Everything the grant names, held or shared: what a report lists as the behavior's resources."""
        return {**self.resources, **self.shares} if self.shares else dict(self.resources)


@dataclass(frozen=True, slots=True)
class Revoked(Record):
    """The manager preempted `path` at a slice boundary (a `released` with reason `revoked` follows)."""

    resources: tuple[str, ...] = ()
    reason: str = ""


#: Why a hold ended (`Released.reason`).
END_REASONS = ("exit", "release", "revoked", "host lost", "resource lost", "expired", "cancelled",
               "controller lost")


@dataclass(frozen=True, slots=True)
class Released(Record):
    """A hold of `path` ended, for these resource ids (aggregates and their units); `reason` is one of
    `END_REASONS`. Every end of a hold has one, before any grant of the units it freed."""

    resources: tuple[str, ...] = ()
    reason: str = ""


@dataclass(frozen=True, slots=True)
class Command(Record):
    """An actuator command reached the gate of `device`: from the component at `path`, at the `epoch` it was
    bound with (None: unbound); `accepted` says whether the driver got it, `reason` why not."""

    device: str = ""
    method: str = ""
    epoch: int | None = None
    accepted: bool = False
    reason: str = ""


@dataclass(frozen=True, slots=True)
class Halted(Record):
    """The system brought `device` to its safe stop (`method`) because the authority of `path` over it ended
    (`reason`); `error` if the device could not be reached."""

    device: str = ""
    method: str = ""
    reason: str = ""
    error: str = ""


@dataclass(frozen=True, slots=True)
class Suspended(Record):
    pass


@dataclass(frozen=True, slots=True)
class Resumed(Record):
    pass


@dataclass(frozen=True, slots=True)
class Restored(Record):
    """The mission was entered again from its journal after its controller was lost: its state as saved at
    `since` (sim time), after `paused` seconds without a controller (the holds of the lost controller ended,
    `released` with reason `controller lost`, just before). On a cluster `paused` is wall time: the world waits for
    its controller, so sim time stands still meanwhile. A dry-run's world goes on without one (the robots stand
    still): its `paused` is sim time, the outage it predicts (records audit 18, #5)."""

    since: float = 0.0
    paused: float = 0.0


@dataclass(frozen=True, slots=True)
class Event(Record):
    """An event emitted by a component or an action; `path` is who emitted it."""

    name: str
    fields: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Log(Record):
    text: str


@dataclass(frozen=True, slots=True)
class Finished(Record):
    """The mission ended: `outcome` is success, failure or stopped."""

    outcome: str
    reason: str = ""


def plain(value: Any) -> Any:
    """A value as JSON can carry it: mappings with string keys, lists for tuples and sets, resources by their
    id, anything else by its string. Exact types are tried first: what is sent is mostly plain already."""
    t = type(value)
    if t is str or t is float or t is int or t is bool or value is None:
        return value
    if t is dict:
        return {k if type(k) is str else str(k): plain(v) for k, v in value.items()}
    if t is list or t is tuple:
        return [plain(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set):
        return [plain(v) for v in value]
    if isinstance(value, bool | int | float | str):
        return value
    native = python_scalar(value)
    if native is not value:
        return native
    return getattr(value, "id", None) or str(value)


def python_scalar(value: Any) -> Any:
    """A numpy scalar (`np.float32(2.5)`, `np.int64`, `np.bool_`: what computing on a sensor's arrays gives) as the
    Python value it holds; anything else as it is. numpy itself is not imported: only its values are recognized."""
    item = getattr(value, "item", None)
    if item is not None and type(value).__module__ == "numpy" and getattr(value, "ndim", None) == 0:
        native = item()
        if isinstance(native, bool | int | float | str):
            return native
    return value


def from_dict(data: Mapping[str, Any]) -> Record | None:
    """The record a trace line (or a recording's message) describes, `to_dict`'s inverse; None for a kind this
    version does not know (a newer writer's). Lists become tuples, as the records hold them; extra keys (the
    `mission` of a trace line) are ignored."""
    cls = _KINDS.get(str(data.get("kind", "")))
    if cls is None:
        return None
    values: dict[str, Any] = {name: tuple(v) if isinstance(v := data.get(name), list) else v
                              for name in _fields(cls) if name in data}
    try:
        return cls(**values)
    except TypeError:  # a field missing: not a record of this version
        return None


#: Record classes by kind, from this module's names: `dataclass(slots=True)` makes a new class, so the
#: subclasses Python remembers of `Record` include the replaced originals.
_KINDS: dict[str, type[Record]] = {cls.__name__.lower(): cls for cls in list(globals().values())
                                   if isinstance(cls, type) and issubclass(cls, Record) and cls is not Record}
