"""What the system knows about components, as pure data: the checker's view of the manifests.

Elementary behaviors, resource controllers (RC), aggregates (ARC) and data types are not
declared in missions; they come from `components/<Name>/manifest.yaml`, loaded by
`drd.manifests`. The language only needs this typed summary of them, so `dsl/` stays free
of I/O and a test can build a catalog by hand.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from enum import StrEnum
from types import MappingProxyType

#: The value types of the language. Resource and data types are component names.
SCALAR_TYPES = ("int", "float", "bool", "str", "duration")


class Kind(StrEnum):
    BEHAVIOR = "behavior"
    """An elementary behavior: a leaf state, run as a component instance."""
    RC = "rc"
    """A resource controller: one device behind an interface (a drive, a camera)."""
    ARC = "arc"
    """An aggregate resource controller: a typed group of RCs (a Ranger)."""
    DATA = "data"
    """A shared data type (`shared map: OccupancyMap`)."""


class Process(StrEnum):
    CONTAINER = "container"
    """Runs in one of the Creator's pre-started worker processes (fast to place)."""
    DEDICATED = "dedicated"
    """Gets a process of its own."""


@dataclass(frozen=True, slots=True)
class Limit:
    """The range a numeric value may take where it is written, and its unit, for the message that refuses a value
    outside it: a device option or robot property in hosts.yaml (`beams: {min: 1, max: 4096}`), a behavior's
    parameter in a mission (`speed: {type: float, min: 0, max: 2, unit: m/s}`). `duration`: the bounds are seconds,
    shown as durations (`0s..24h`)."""

    min: float | None = None
    max: float | None = None
    unit: str = ""
    duration: bool = False

    def refuses(self, value: float) -> str:
        """Why `value` is outside the range ('' when it is inside); NaN and infinities are always outside. An int is
        compared as it is (a YAML integer of 400 digits has no float)."""
        if isinstance(value, float) and not math.isfinite(value):
            expected = f" (expected {self.text})" if self.min is not None or self.max is not None else ""
            return f"{value} is not a finite number{expected}"
        if (self.min is not None and value < self.min) or (self.max is not None and value > self.max):
            return f"{self.show(value)} is out of range: {self.text}"
        return ""

    @property
    def text(self) -> str:
        """`0..2 m/s`, `3..4096`, `0s..24h`, `0..` (no maximum)."""
        low = "" if self.min is None else self.show(self.min)
        high = "" if self.max is None else self.show(self.max)
        return f"{low}..{high}{' ' + self.unit if self.unit and not self.duration else ''}"

    def show(self, value: float) -> str:
        """A value as the range is written: an integer without `.0`, a duration with its unit."""
        if isinstance(value, int) and abs(value) >= 10**15:
            return f"an integer of {len(str(value)) if value.bit_length() < 10_000 else 'thousands of'} digits"
        value = float(value)
        if self.duration:
            return duration_text(value)
        return f"{int(value)}" if value.is_integer() and abs(value) < 1e15 else f"{value:g}"

    @property
    def bounded(self) -> bool:
        """Both ends declared: what every standard numeric parameter and property has."""
        return self.min is not None and self.max is not None


def possessive(name: str) -> str:
    """`FollowCorridor's`, `AvoidObstacles'`: how a message names what a component's manifest says."""
    return f"{name}'" if name.endswith("s") else f"{name}'s"


def duration_text(seconds: float) -> str:
    """Seconds as a duration literal of the language (`86400` -> `24h`, `0.25` -> `250ms`): the largest unit that
    writes it exactly, else seconds."""
    for unit, size in (("h", 3600.0), ("min", 60.0), ("s", 1.0), ("ms", 0.001)):
        count = seconds / size
        if seconds and abs(count) >= 1 and abs(count - round(count)) < 1e-9:
            return f"{round(count)}{unit}"
    return "0s" if seconds == 0 else f"{seconds:g}s"


@dataclass(frozen=True, slots=True)
class ParamSpec:
    """A typed parameter. `default` is a Python value (durations in seconds)."""

    name: str
    type: str
    default: object = None
    required: bool = False
    description: str = ""
    #: The range of a numeric parameter (its manifest's `min`, `max`, `unit`): a constant argument outside it is a
    #: located compile error, an evaluated one fails the state as it is entered.
    limit: Limit | None = None
    #: A `str` parameter that names a property of the robot one of the behavior's needs is bound to (LaunchScout's
    #: `carrier_property` of its `scout`): the compiler checks the robot's type has it, where the type is known.
    property_of: str | None = None


@dataclass(frozen=True, slots=True)
class NeedSpec:
    """A resource an elementary behavior uses.

    `of` lists ARC types, in order of preference, whose part may serve the need when an
    ancestor holds such an aggregate (`camera: Camera of [Scout, Ranger]`).
    """

    name: str
    type: str
    of: tuple[str, ...] = ()
    quantity: float | None = None
    description: str = ""


@dataclass(frozen=True, slots=True)
class RecordSpec:
    """A named record with typed fields: a component output or an event. An output's `type` is the data type it
    produces (`Door`), which inputs of that type bind to; "record" when it declares fields only."""

    name: str
    fields: Mapping[str, str] = field(default_factory=dict)
    type: str = "record"
    description: str = ""


@dataclass(frozen=True, slots=True)
class InputSpec:
    """A datum an elementary behavior reads, of a data type (`door: Door`, `visited: DoorLog`).

    The mission binds it to what is in scope where the behavior is used: a sibling's output or an ancestor's
    `shared` datum, by name, else by type, else explicitly (`AlignRanger(door: finder.door)`); `optional` inputs
    may stay unbound (the component then reads None). See `dsl.dataflow`."""

    name: str
    type: str
    optional: bool = False
    description: str = ""


@dataclass(frozen=True, slots=True)
class Scheduling:
    """Core and priority assignment (ESAIR): CPU affinity and nice level."""

    cores: tuple[int, ...] | None = None
    nice: int = 0


@dataclass(frozen=True, slots=True)
class ComponentType:
    """One manifest, typed. Fields that do not apply to a kind stay empty."""

    name: str
    kind: Kind
    description: str = ""
    params: tuple[ParamSpec, ...] = ()
    needs: tuple[NeedSpec, ...] = ()
    inputs: tuple[InputSpec, ...] = ()
    outputs: tuple[RecordSpec, ...] = ()
    events: tuple[RecordSpec, ...] = ()
    interfaces: tuple[str, ...] = ()
    parts: Mapping[str, str] = field(default_factory=dict)
    properties: Mapping[str, str] = field(default_factory=dict)
    limits: Mapping[str, Limit] = field(default_factory=dict)  # a numeric property's range in hosts.yaml
    fields: Mapping[str, str] = field(default_factory=dict)  # a data type's (a Door's width, x, y, side)
    sharable: bool = False
    capacity: float | None = None
    multiplicity: int | None = None
    entry_point: str | None = None
    process: Process = Process.CONTAINER
    scheduling: Scheduling = Scheduling()
    #: a behavior whose state can be snapshotted and restored elsewhere (`missionctl migrate`); no device needs
    movable: bool = False
    source: str = "<builtin>"
    #: The abstract types this one is a kind of (`extends: [Robot]`): a trader query for one matches this one.
    extends: tuple[str, ...] = ()
    #: Declares properties only (`Robot`, `Sensor`): never a device or robot itself, nor a mission's need.
    abstract: bool = False

    def param(self, name: str) -> ParamSpec | None:
        return next((p for p in self.params if p.name == name), None)

    def output(self, name: str) -> RecordSpec | None:
        return next((o for o in self.outputs if o.name == name), None)

    def input(self, name: str) -> InputSpec | None:
        return next((i for i in self.inputs if i.name == name), None)

    @property
    def is_resource(self) -> bool:
        """A type a mission may need and hosts.yaml may name: an rc or arc, not an abstract one."""
        return self.kind in (Kind.RC, Kind.ARC) and not self.abstract


#: Properties every resource has, whatever its manifest says.
BUILTIN_PROPERTIES: Mapping[str, str] = MappingProxyType({"id": "str", "host": "str"})
#: What every robot (an aggregate) tells of itself at run time: where it is (metres, radians, in the world's frame,
#: as its odometry has it) and the charge left (0 to 1). Constraints and guards read them (`ranger.x`).
ROBOT_PROPERTIES: Mapping[str, str] = MappingProxyType({"x": "float", "y": "float", "heading": "float",
                                                          "battery": "float"})
#: What every device (an RC) tells of itself besides its manifest's properties: which driver runs it (`sim`,
#: `ros2`, a driver of the user's), so a need can ask for a real camera (`where cam.driver != "sim"`).
DEVICE_PROPERTIES: Mapping[str, str] = MappingProxyType({"driver": "str"})
#: The event a behavior gets when one of its constraints is violated (`A -> B on violation`).
VIOLATION = RecordSpec("violation", MappingProxyType({"name": "str", "resource": "str", "value": "float",
                                                      "limit": "float"}), "event",
                       "A constraint of the behavior does not hold: its name, the robot, the measured value and the"
                       " limit.")


@dataclass(frozen=True)
class Catalog:
    """Every known component type by name, and every event any of them emits."""

    components: Mapping[str, ComponentType]

    @classmethod
    def of(cls, types: Iterable[ComponentType]) -> Catalog:
        return cls({t.name: t for t in types})

    def get(self, name: str) -> ComponentType | None:
        return self.components.get(name)

    def names(self, *kinds: Kind) -> list[str]:
        """Every name, or those of `kinds` less the abstract types (what a mission or hosts.yaml may name)."""
        return [n for n, t in self.components.items() if not kinds or (t.kind in kinds and not t.abstract)]

    def supertypes(self, name: str) -> list[str]:
        """Every type `name` extends, directly or not, nearest first (a cycle, refused at load, ends the walk)."""
        out: list[str] = []
        todo = list(getattr(self.components.get(name), "extends", ()))
        while todo:
            sup = todo.pop(0)
            if sup not in out and sup != name:
                out.append(sup)
                todo += getattr(self.components.get(sup), "extends", ())
        return out

    def subtypes(self, name: str) -> list[str]:
        """`name` and every type that extends it, directly or not: what a trader query for `name` matches."""
        return [name] + [n for n in self.components if n != name and name in self.supertypes(n)]

    @property
    def events(self) -> dict[str, RecordSpec]:
        out: dict[str, RecordSpec] = {VIOLATION.name: VIOLATION}
        for t in self.components.values():
            for e in t.events:
                out.setdefault(e.name, e)
        return out

    def properties(self, type_name: str) -> dict[str, str]:
        """The queryable properties of a resource type (`scout.carrier`, `cam.id`)."""
        t = self.components.get(type_name)
        props = dict(BUILTIN_PROPERTIES)
        if t is not None:
            if t.kind is Kind.ARC:
                props.update(ROBOT_PROPERTIES)
            elif t.kind is Kind.RC:
                props.update(DEVICE_PROPERTIES)
            props.update(t.properties)
            props.update(t.parts)  # `ranger.camera` names the part
        return props

    def references(self) -> dict[str, frozenset[str]]:
        """Per robot type, its properties typed with a robot type (`carrier: Ranger`): their value names another
        robot, which an expression reads as that robot (`scout.carrier.id`, `scout.carrier.battery`)."""
        robots = {n for n, t in self.components.items() if t.kind is Kind.ARC}
        return {n: frozenset(p for p, ty in self.properties(n).items() if ty in robots) for n in robots}

    def part_of(self, arc: str, rc_type: str) -> str | None:
        """The name of the single part of `arc` with type `rc_type`, if exactly one."""
        t = self.components.get(arc)
        if t is None or t.kind is not Kind.ARC:
            return None
        hits = [n for n, ty in t.parts.items() if ty == rc_type]
        return hits[0] if len(hits) == 1 else None


def inherit(types: Iterable[ComponentType]) -> list[ComponentType]:
    """The types with their supertypes' properties and limits added (nearest first; their own win), so every reader
    of `properties` sees a Ranger's `battery` declared once, in `Robot`. Unknown supertypes and cycles are skipped
    here: `drd.manifests.check_references` refuses them first."""
    by_name = {t.name: t for t in types}
    catalog = Catalog(by_name)
    out = []
    for t in by_name.values():
        props: dict[str, str] = {}
        limits: dict[str, Limit] = {}
        for sup in reversed(catalog.supertypes(t.name)):  # the farthest first: nearer ones override
            s = by_name.get(sup)
            if s is not None:
                props.update(s.properties)
                limits.update(s.limits)
        if props or limits:
            t = replace(t, properties={**props, **t.properties}, limits={**limits, **t.limits})
        out.append(t)
    return out
