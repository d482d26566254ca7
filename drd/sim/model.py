"""The world the simulator runs: frozen records built once from a `worlds/*.yaml` file.

Pure data plus the two functions of time and place the file defines (where an intruder is at
time t, how much light there is at a point), so the renderer, the simulator and the tests all
agree on them. Angles are radians here; world files write headings in degrees for people.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from enum import StrEnum

from drd.config import ConfigError, ConfigProblem
from drd.sim.geometry import Point

#: Body sizes, shared by the loader (a robot may not start inside a wall) and the simulator.
RANGER_RADIUS = 0.3
SCOUT_RADIUS = 0.08
INTRUDER_RADIUS = 0.25


class DoorState(StrEnum):
    OPEN = "open"
    """A gap in its wall: rays, robots and launched Scouts pass."""
    CLOSED = "closed"
    """A solid segment across the gap; it can be opened at run time."""
    BLOCKED = "blocked"
    """Open but obstructed (furniture, a jammed leaf): as solid as closed, and not openable."""


@dataclass(frozen=True, slots=True)
class Wall:
    """A solid wall segment. Walls of a loaded world are merged and already have their door gaps cut."""

    a: Point
    b: Point


@dataclass(frozen=True, slots=True)
class Door:
    """A doorway in a wall, from `a` to `b` along the wall. `room` is the room it opens into, if any."""

    id: str
    a: Point
    b: Point
    width: float
    state: DoorState
    room: str | None = None

    @property
    def center(self) -> Point:
        return ((self.a[0] + self.b[0]) / 2, (self.a[1] + self.b[1]) / 2)


@dataclass(frozen=True, slots=True)
class Room:
    """An axis-aligned room: its area sets the ambient light; its walls were generated unless `walls: false`."""

    id: str
    x0: float
    y0: float
    x1: float
    y1: float
    light: float

    def contains(self, x: float, y: float) -> bool:
        return self.x0 <= x <= self.x1 and self.y0 <= y <= self.y1

    @property
    def center(self) -> Point:
        return ((self.x0 + self.x1) / 2, (self.y0 + self.y1) / 2)


@dataclass(frozen=True, slots=True)
class LightZone:
    """A dark corner: `level` at its centre, rising smoothly (quadratically) to the ambient light at `radius`."""

    x: float
    y: float
    radius: float
    level: float


@dataclass(frozen=True, slots=True)
class Obstacle:
    """A low box on the floor: it blocks rolling; a Scout jumps over it if it is no higher than its foot reaches."""

    x0: float
    y0: float
    x1: float
    y1: float
    height: float


@dataclass(frozen=True, slots=True)
class Waypoint:
    t: float
    x: float
    y: float


@dataclass(frozen=True, slots=True)
class Intruder:
    """A person walking a timed path, straight between waypoints; a looping path ends where it starts."""

    id: str
    path: tuple[Waypoint, ...]
    loop: bool = False
    radius: float = INTRUDER_RADIUS
    _times: tuple[float, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_times", tuple(w.t for w in self.path))  # for bisect, once

    def position(self, t: float) -> Point:
        """Where the intruder is at sim time `t`: at its first waypoint before it, its last after (unless looping)."""
        first, last = self.path[0], self.path[-1]
        if t <= first.t or len(self.path) == 1:
            return (first.x, first.y)
        if t >= last.t:
            if not self.loop:
                return (last.x, last.y)
            t = first.t + math.fmod(t - first.t, last.t - first.t)
        i = bisect.bisect_right(self._times, t)
        w0, w1 = self.path[i - 1], self.path[min(i, len(self.path) - 1)]
        f = 0.0 if w1.t == w0.t else (t - w0.t) / (w1.t - w0.t)
        return (w0.x + (w1.x - w0.x) * f, w0.y + (w1.y - w0.y) * f)


@dataclass(frozen=True, slots=True)
class RangerSpawn:
    """A Ranger's start pose (heading in radians) and the Scouts in its magazine, first launched first."""

    id: str
    x: float
    y: float
    heading: float
    magazine: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class ScoutSpawn:
    """A Scout that starts on the floor rather than in a magazine."""

    id: str
    x: float
    y: float
    heading: float


@dataclass(frozen=True, slots=True)
class Battery:
    """How robots' charge (0 empty .. 1 full) runs down: `idle` per second while on the floor (computer, sensors),
    `per_meter` per metre driven (the wheels); `start` the charge of named robots at the start (others start at
    hosts.yaml's `battery`, `drd.sim.world.charged`, else full).

    A fraction, not a percent, because it is what a mission compares: hosts.yaml's static `battery: 1.0` and the
    manifests' "charge left (0 to 1)" use that scale, so `ranger.battery >= 0.2` means the same read from the
    simulator or from hosts.yaml. The default drains nothing: the shipped worlds and missions were written against
    a battery that never changes, and any other default would be an invented figure that moves every dry-run's
    outcome (a 30-minute mission keeps its full charge). A world that wants a floor to bite sets a rate."""

    idle: float = 0.0
    per_meter: float = 0.0
    start: tuple[tuple[str, float], ...] = ()


@dataclass(frozen=True, slots=True)
class World:
    """A loaded world. `source` names the file, so later problems (hosts matching) can point at it."""

    name: str
    walls: tuple[Wall, ...]
    doors: tuple[Door, ...] = ()
    rooms: tuple[Room, ...] = ()
    ambient: float = 1.0
    dark: tuple[LightZone, ...] = ()
    obstacles: tuple[Obstacle, ...] = ()
    intruders: tuple[Intruder, ...] = ()
    rangers: tuple[RangerSpawn, ...] = ()
    scouts: tuple[ScoutSpawn, ...] = ()
    description: str = ""
    source: str = "<world>"
    battery: Battery = Battery()
    _light_cells: dict[tuple[int, int], tuple[tuple[Room, ...], tuple[LightZone, ...]]] | None = field(
        default=None, init=False, repr=False, compare=False)
    _carriers: dict[str, str] | None = field(default=None, init=False, repr=False, compare=False)

    def light(self, x: float, y: float) -> float:
        """The light level (0 dark .. 1 bright) at a point: the room's ambient light, dimmed by dark corners."""
        cells = self._light_cells
        if cells is None:
            cells = self._index_light()
        try:
            rooms, dark = cells.get((math.floor(x), math.floor(y)), (self.rooms, self.dark))
        except (ValueError, OverflowError):  # not a finite point: look at everything, as for one outside
            rooms, dark = self.rooms, self.dark
        base = self.ambient
        for r in rooms:
            if r.x0 <= x <= r.x1 and r.y0 <= y <= r.y1:
                base = r.light
                break
        level = base
        for z in dark:
            d = math.hypot(x - z.x, y - z.y)
            if d < z.radius and z.level < base:
                level = min(level, z.level + (base - z.level) * (d / z.radius) ** 2)
        return level

    def _index_light(self) -> dict[tuple[int, int], tuple[tuple[Room, ...], tuple[LightZone, ...]]]:
        """For each 1 m cell of the world, the rooms and dark corners that may cover a point of it (in file order,
        so the first room containing a point is still the one that sets its light): `light` looks at those only.
        Points outside every cell look at everything."""
        x0, y0, x1, y1 = self.bounds
        for z in self.dark:
            x0, y0, x1, y1 = min(x0, z.x - z.radius), min(y0, z.y - z.radius), max(x1, z.x + z.radius), \
                max(y1, z.y + z.radius)
        # each room and dark corner visits the cells its box touches, in file order: linear in the building, where
        # every cell testing every room was quadratic (12 s for a 50-wing building). Cell i (the points i <= x <=
        # i + 1) touches [bx0, bx1] when bx0 <= i + 1 and i <= bx1, that is ceil(bx0) - 1 <= i <= floor(bx1) for
        # an integer i: the ranges below are exactly those cells, with no test per cell
        # A cell's items are kept as a bit set (an int: bit n for boxes[n]), and each distinct set becomes its
        # tuples once, shared by every cell with that set: a few thousand objects where lists per cell were
        # 110,000, which cost more in the collector's passes (0.4 s in a 1,000-robot run) than the loop itself.
        i0, i1, j0, j1 = math.floor(x0), math.floor(x1), math.floor(y0), math.floor(y1)
        boxes: list[tuple[float, float, float, float]] = [
            *((r.x0, r.y0, r.x1, r.y1) for r in self.rooms),
            *((z.x - z.radius, z.y - z.radius, z.x + z.radius, z.y + z.radius) for z in self.dark)]
        found: dict[tuple[int, int], int] = {}
        for n, (bx0, by0, bx1, by1) in enumerate(boxes):
            bit = 1 << n
            rows = range(max(j0, math.ceil(by0) - 1), min(j1, math.floor(by1)) + 1)
            for i in range(max(i0, math.ceil(bx0) - 1), min(i1, math.floor(bx1)) + 1):
                for j in rows:
                    found[i, j] = found.get((i, j), 0) | bit
        n_rooms = len(self.rooms)
        empty: tuple[tuple[Room, ...], tuple[LightZone, ...]] = ((), ())
        shared: dict[int, tuple[tuple[Room, ...], tuple[LightZone, ...]]] = {0: empty}
        cells: dict[tuple[int, int], tuple[tuple[Room, ...], tuple[LightZone, ...]]] = {}
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                bits = found.get((i, j), 0)
                value = shared.get(bits)
                if value is None:
                    items, rest = [], bits
                    while rest:  # lowest bit first: file order
                        low = rest & -rest
                        items.append(low.bit_length() - 1)
                        rest ^= low
                    value = shared[bits] = (
                        tuple(self.rooms[n] for n in items if n < n_rooms),
                        tuple(self.dark[n - n_rooms] for n in items if n >= n_rooms))
                cells[i, j] = value
        object.__setattr__(self, "_light_cells", cells)  # a cache: frozen for everything else
        return cells

    def room_at(self, x: float, y: float) -> Room | None:
        return next((r for r in self.rooms if r.contains(x, y)), None)

    def door(self, door_id: str) -> Door:
        for d in self.doors:
            if d.id == door_id:
                return d
        raise KeyError(f"no door {door_id!r} in {self.source}")

    @property
    def scout_ids(self) -> tuple[str, ...]:
        """Every Scout: those in magazines (in order), then those on the floor."""
        return tuple(s for r in self.rangers for s in r.magazine) + tuple(s.id for s in self.scouts)

    def carrier(self, scout_id: str) -> str | None:
        """The Ranger whose magazine holds the Scout at the start, or None.

        Looked up in a dict built on first use (`check_hosts` asks once per robot: scanning every magazine was
        quadratic at fleet size). The index cannot go stale: a World is frozen and a launch empties the simulator's
        copy of the magazine (`drd.sim.robots`), never this record, which says where each Scout starts."""
        index = self._carriers
        if index is None:
            index = {}
            for r in self.rangers:
                for sid in r.magazine:
                    index.setdefault(sid, r.id)  # the first Ranger listing it, as the scan found it
            object.__setattr__(self, "_carriers", index)  # a cache: frozen for everything else
        return index.get(scout_id)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) around every wall, room and spawn: what a picture of the world must show."""
        xs = [p[0] for w in self.walls for p in (w.a, w.b)] + [v for r in self.rooms for v in (r.x0, r.x1)]
        ys = [p[1] for w in self.walls for p in (w.a, w.b)] + [v for r in self.rooms for v in (r.y0, r.y1)]
        xs += [r.x for r in self.rangers] + [s.x for s in self.scouts]
        ys += [r.y for r in self.rangers] + [s.y for s in self.scouts]
        return (min(xs, default=0.0), min(ys, default=0.0), max(xs, default=0.0), max(ys, default=0.0))


WorldProblem = ConfigProblem


class WorldError(ConfigError):
    """A world file has problems; carries all of them, so a broken file is fixed in one pass."""
