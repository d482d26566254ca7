"""What the Resource Controller Manager talks about: resources, requests and its decisions.

Everything here is a frozen dataclass so that a decision can be compared in a test, written to a
trace and sent over the bus as is: the manager hands records out and never mutates them. Mappings
are copied on construction (plain dicts, so records stay picklable); treat them as read-only.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Literal, TypeAlias


@dataclass(frozen=True, slots=True)
class Unit:
    """A Resource Controller (RC): one drive, camera, launcher or radio channel.

    An exclusive unit (the default) has one holder at a time, for at least its `slice` (else the
    manager's default) once others wait. A sharable one is split by quantity:
    the quantities granted on it never add up to more than `capacity`. `properties` carry the
    static dependencies (`mounted_on`, `carrier`) that `where` constraints look at.
    """

    id: str
    type: str
    sharable: bool = False
    capacity: float = 1.0
    properties: Mapping[str, object] = field(default_factory=dict, hash=False)
    host: str = ""
    #: Minimum time slice on this exclusive unit when a need sets none (a Ranger's drive: travel takes time).
    slice: float | None = None

    def __post_init__(self) -> None:
        if not self.id or not self.type:
            raise ValueError(f"a unit needs an id and a type, got id={self.id!r} type={self.type!r}")
        if not self.capacity > 0:
            raise ValueError(f"unit {self.id}: capacity must be > 0, got {self.capacity}")
        if self.slice is not None and not self.slice > 0:
            raise ValueError(f"unit {self.id}: slice must be > 0, got {self.slice}")
        object.__setattr__(self, "properties", dict(self.properties))


@dataclass(frozen=True, slots=True)
class Aggregate:
    """An Aggregate Resource Controller (ARC) instance, e.g. one Ranger.

    Holding an aggregate means holding every part at once, so `parts` (part name -> unit id) must
    name known units. Several aggregates may share a sharable part (a common radio channel).
    """

    id: str
    type: str
    parts: Mapping[str, str] = field(default_factory=dict, hash=False)
    properties: Mapping[str, object] = field(default_factory=dict, hash=False)
    host: str = ""

    def __post_init__(self) -> None:
        if not self.id or not self.type:
            raise ValueError(f"an aggregate needs an id and a type, got id={self.id!r} type={self.type!r}")
        object.__setattr__(self, "parts", dict(self.parts))
        object.__setattr__(self, "properties", dict(self.properties))

    @property
    def units(self) -> tuple[str, ...]:
        """The part units, once each, in part order."""
        return tuple(dict.fromkeys(self.parts.values()))


#: What a need is matched against: a single unit or a whole aggregate.
Candidate: TypeAlias = Unit | Aggregate
#: `where(candidate, chosen)`: `chosen` maps the earlier needs of the same request to their candidates.
Where: TypeAlias = Callable[[Candidate, Mapping[str, Candidate]], bool]


def units_of(candidate: Candidate) -> tuple[str, ...]:
    """The unit ids a candidate occupies."""
    return candidate.units if isinstance(candidate, Aggregate) else (candidate.id,)


@dataclass(frozen=True, slots=True)
class NeedRequest:
    """One `needs name: Type [where ...] [quantity q] [for D]` of a behavior.

    `type` names a unit type or an aggregate type. `quantity` matters only for sharable units (an
    exclusive unit is always taken whole). `slice` is the minimum time slice in seconds on exclusive
    units (None: the manager's default). `where` is evaluated by the solver, never stored elsewhere.
    """

    name: str
    type: str
    quantity: float = 1.0
    slice: float | None = None
    where: Where | None = None

    def __post_init__(self) -> None:
        if not self.name or not self.type:
            raise ValueError(f"a need needs a name and a type, got name={self.name!r} type={self.type!r}")
        if not self.quantity > 0:
            raise ValueError(f"need {self.name}: quantity must be > 0, got {self.quantity}")
        if self.slice is not None and not self.slice > 0:
            raise ValueError(f"need {self.name}: slice must be > 0, got {self.slice}")


@dataclass(frozen=True, slots=True)
class Request:
    """All the needs of one behavior instance, granted together or not at all.

    `holder` is the behavior instance path ("CorridorSurveillance/RoomSurveillance[2]"); a path is
    owned by each of its prefixes, which is how nested requests enter the wait-for graph.
    `priority` 1 is the highest. Requests of several missions sharing the manager are ranked by their
    missions' priorities first (`mission_priority`, 1 the highest), then by their own: `rank`. `mission` only
    names the mission in snapshots.
    """

    holder: str
    priority: int
    needs: tuple[NeedRequest, ...] = ()
    mission: str = ""
    mission_priority: int = 1

    @property
    def rank(self) -> tuple[int, int]:
        """(mission priority, priority): the smaller is served first."""
        return self.mission_priority, self.priority

    def __post_init__(self) -> None:
        if not self.holder:
            raise ValueError("a request needs a holder path")
        object.__setattr__(self, "needs", tuple(self.needs))
        names = [need.name for need in self.needs]
        if len(set(names)) != len(names):
            duplicates = sorted({name for name in names if names.count(name) > 1})
            raise ValueError(f"request of {self.holder}: duplicate need names {', '.join(duplicates)}")


ReleaseReason: TypeAlias = Literal["release", "expired", "host lost", "resource lost", "cancelled"]


@dataclass(frozen=True, slots=True)
class Granted:
    """All needs of `holder` are granted: start (or, with `resumed`, resume) the behavior.

    `epochs` are fencing tokens: a unit's epoch strictly increases with each grant of it, so a
    driver can refuse commands carrying an older epoch. The lease runs until `lease_until` unless
    renewed; exclusive units are kept at least until `slice_until`. A resumed grant may name other
    units than the grant that was revoked (another camera of the same type).
    """

    holder: str
    assignment: Mapping[str, str] = field(hash=False)
    units: tuple[str, ...]
    epochs: Mapping[str, int] = field(hash=False)
    lease_until: float
    slice_until: float
    resumed: bool = False


@dataclass(frozen=True, slots=True)
class Revoked:
    """`holder` lost all its units at a slice boundary to `by` and is suspended.

    Its request is queued again at the back of its priority; a later `Granted(resumed=True)`
    resumes it.
    """

    holder: str
    units: tuple[str, ...]
    reason: Literal["preempted"]
    by: str


@dataclass(frozen=True, slots=True)
class Released:
    """Units left `holder` for good: released, lease expired, host or resource lost, or cancelled.

    `units` is empty when a request that was still waiting is withdrawn. `needs` names the needs given back
    whole (all of them unless a release named some).
    """

    holder: str
    units: tuple[str, ...]
    reason: ReleaseReason
    needs: tuple[str, ...] = ()
    #: The resources whose loss ended it (a host or a resource lost), of those it held: the rest went with them.
    lost: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Waiting:
    """The request is queued; `blocked_by` names the holders and better-placed waiters in its way."""

    holder: str
    blocked_by: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Reserved:
    """A preallocation is registered; it joins the queue, ahead of its equals, at `at`."""

    holder: str
    at: float


@dataclass(frozen=True, slots=True)
class Renewed:
    """The lease of `holder` now runs until `lease_until`."""

    holder: str
    lease_until: float


@dataclass(frozen=True, slots=True)
class Deadlock:
    """A wait-for cycle was found; the waiting request of `victim` is cancelled to break it."""

    cycle: tuple[str, ...]
    victim: str


@dataclass(frozen=True, slots=True)
class Unsatisfiable:
    """No known unit can ever satisfy `need` (type unknown, constraint or capacity): not queued."""

    holder: str
    need: str
    reason: str


Decision: TypeAlias = Granted | Revoked | Released | Waiting | Reserved | Renewed | Deadlock | Unsatisfiable
