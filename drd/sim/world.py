"""`worlds/*.yaml`: the strict loader of the buildings the simulator runs (format in docs/worlds.md).

A world is read in one pass that collects every problem (`worlds/corridor.yaml: doors[2].width:
expected a number, got 'wide'`) and raises them together as a `WorldError`, so a broken file is
fixed in one go. Walls are merged and door gaps cut here, once (see `drd.sim.geometry`), so the
simulator never has to reason about overlapping walls. `parse_world` is pure; `load_world` reads
the file; `check_hosts` compares robot ids with a `hosts.yaml` cluster.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drd.config import ConfigReader, display_path, join_key, read_yaml
from drd.sim import geometry
from drd.sim.geometry import Point, Segment
from drd.sim.model import (
    INTRUDER_RADIUS,
    RANGER_RADIUS,
    SCOUT_RADIUS,
    Battery,
    Door,
    DoorState,
    Intruder,
    LightZone,
    Obstacle,
    RangerSpawn,
    Room,
    ScoutSpawn,
    Wall,
    Waypoint,
    World,
    WorldError,
    WorldProblem,
)
from dsl.errors import did_you_mean

if TYPE_CHECKING:
    from drd.hosts import Cluster

__all__ = [
    "Door", "DoorState", "Intruder", "LightZone", "Obstacle", "RangerSpawn", "Room", "ScoutSpawn", "Wall",
    "Waypoint", "World", "WorldError", "WorldProblem", "check_hosts", "load_world", "parse_world",
]

_ID = re.compile(r"[A-Za-z_][A-Za-z0-9_]*", re.ASCII)
_TOP = ("name", "description", "light", "walls", "rooms", "doors", "obstacles", "intruders", "rangers", "scouts",
        "battery")
_BATTERY = ("idle", "per_meter", "start")
_LIGHT = ("ambient", "dark")
_DARK = ("at", "radius", "level")
_WALL = ("from", "to")
_ROOM = ("id", "rect", "light", "walls")
_DOOR = ("id", "at", "width", "state")
_OBSTACLE = ("rect", "height")
_INTRUDER = ("id", "path", "loop", "radius")
_WAYPOINT = ("t", "at")
_RANGER = ("id", "at", "heading", "magazine")
_SCOUT = ("id", "at", "heading")
DEFAULT_AMBIENT = 0.8
DEFAULT_DARK_LEVEL = 0.05


def parse_world(data: object, source: str) -> World:
    """Check the YAML data of a world file and build the world.

    Raises:
        WorldError: with every problem found, once the whole file has been read.
    """
    reader = _Reader(source)
    world = reader.world(data)
    if reader.problems or world is None:
        raise WorldError(reader.problems)
    return world


def load_world(path: str | os.PathLike[str]) -> World:
    """Read and check a world file; problems name it as given (relative to the working directory when inside).

    Raises:
        WorldError: the file is missing or unreadable, is not valid YAML (with the line), or has problems.
    """
    path = Path(path)
    source = display_path(path)
    data = read_yaml(path, source, WorldError)
    return parse_world(data, source)


def hosts_charges(cluster: Cluster) -> dict[str, float]:
    """Each robot's `battery` property in hosts.yaml (a number, 0..1): what its charge is before anything drains."""
    return {r.id: float(v) for r in cluster.robots if isinstance(v := r.properties.get("battery"), (int, float))
            and not isinstance(v, bool)}


def charged(world: World, charges: Mapping[str, float]) -> World:
    """`world` with `charges` (`hosts_charges`) as the start charge of its robots that its own `battery.start` does
    not name: hosts.yaml's `battery: 0.5` is what a simulated robot starts with (semantics audit 7: every robot
    started full, so `where r.battery > 0.7` picked the one hosts.yaml said was half empty). The world's own
    figures win; a robot the world lacks is left out (`check_hosts` names it)."""
    robots = {r.id for r in world.rangers} | set(world.scout_ids)
    start = {rid: c for rid, c in charges.items() if rid in robots} | dict(world.battery.start)
    if start == dict(world.battery.start):
        return world
    return dataclasses.replace(world, battery=dataclasses.replace(world.battery, start=tuple(sorted(start.items()))))


def check_hosts(world: World, cluster: Cluster) -> list[WorldProblem]:
    """Robot ids the world and a hosts.yaml cluster disagree on: every robot must be in both, Scouts with one carrier.

    Empty when a dry-run can map each configured robot onto a simulated body.
    """
    problems: list[WorldProblem] = []
    rangers = {r.id for r in world.rangers}
    scouts = set(world.scout_ids)

    def fail(key: str, message: str) -> None:
        problems.append(WorldProblem(world.source, key, message))

    types = {r.id: r.type for r in cluster.robots}
    for robot in cluster.robots:
        if robot.type == "Ranger" and robot.id not in rangers:
            fail("rangers", f"no Ranger {robot.id!r}, which {cluster.source} configures")
        elif robot.type == "Scout" and robot.id not in scouts:
            fail("scouts", f"no Scout {robot.id!r} in a magazine or in scouts, which {cluster.source} configures")
        elif robot.id not in rangers | scouts:  # a kind of the team's own
            fail("scouts" if robot.carrier else "rangers or scouts",  # a carried one's is a Scout's body
                 f"no robot {robot.id!r} (a {robot.type}), which {cluster.source} configures: a robot of any type"
                 " takes a body here, a Ranger's under rangers (0.3 m, with a magazine for the robots it carries)"
                 " or a Scout's under scouts or in a magazine (0.08 m)")
        elif (robot.type == "Scout" or robot.carrier) and world.carrier(robot.id) != robot.carrier:
            # a Scout, or a robot of any type the hosts file has carried (users audit 17, D2: a team's Beacon on the
            # floor ran); a team's robot in a magazine without `carrier` may name its carrier otherwise (`mothership`)
            fail(_spawn_key(world, robot.id), _carrier_mismatch(world, cluster, robot.id, robot.type,
                                                                robot.carrier, types))
    configured = {r.id for r in cluster.robots}
    for rid in [*sorted(rangers), *world.scout_ids]:
        if rid not in configured:
            fail(_spawn_key(world, rid), f"robot {rid!r} is not configured in {cluster.source}")
    return problems


def _carrier_mismatch(world: World, cluster: Cluster, rid: str, kind: str, configured: str | None,
                      types: Mapping[str, str]) -> str:
    """Why the world and hosts.yaml disagree on what carries robot `rid` (a `kind`), and how to make them agree."""
    carrier = world.carrier(rid)
    where = f"in the magazine of {carrier}" if carrier else "on the floor" if rid in world.scout_ids else (
        "under rangers (a body no magazine holds)")
    carried = f"carried by {configured}" if configured else "not carried"
    if configured:
        fix = f"put it in {configured}'s magazine here, or remove its carrier there"
    elif kind == "Scout" and types.get(carrier or "", "Ranger") != "Ranger":  # `Scout` declares `carrier: Ranger`
        fix = (f"move it from {carrier}'s magazine to scouts here: {carrier} is a {types[carrier or '']}, and"
               " only a Ranger carries Scouts (a Scout's carrier is a Ranger)")
    else:
        fix = f"move it from {carrier}'s magazine to scouts here, or give it carrier: {carrier} there"
    return f"{kind} {rid!r} starts {where}, but {cluster.source} has it {carried}: {fix}"


def _spawn_key(world: World, rid: str) -> str:
    """Where a robot starts in the world file: `rangers[i]`, `rangers[i].magazine` or `scouts[i]`."""
    for i, ranger in enumerate(world.rangers):
        if ranger.id == rid:
            return f"rangers[{i}]"
        if rid in ranger.magazine:
            return f"rangers[{i}].magazine"
    return next((f"scouts[{i}]" for i, s in enumerate(world.scouts) if s.id == rid), "scouts")


#: The largest box a world's walls, rooms and robots may span (square metres): its light map keeps a cell per square
#: metre (2 km x 2 km took 1.1 GB at the first light reading; 4 km ran out of memory: worlds audit 17, D6).
MAX_AREA = 1_000_000


class _Reader(ConfigReader):
    """Collects problems; each reader reports what is wrong and returns None (or a safe value) to go on with."""

    def __init__(self, source: str) -> None:
        super().__init__(source)
        self.ids: dict[str, str] = {}  # id -> key path of the entry that took it
        self.obstacles: list[Obstacle] = []
        self.enclosure: tuple[float, float, float, float] | None = None  # the walls' box, when there are walls

    # -- the sections

    def world(self, data: object) -> World | None:
        if not isinstance(data, dict):
            self.fail("", f"expected a mapping with keys {', '.join(_TOP)}, got {_got(data)}")
            return None
        self.keys(data, "", _TOP, required=("name",))
        name = self.ident(data["name"], "name") if "name" in data else None
        description = self.text(data["description"], "description") if "description" in data else ""
        ambient, dark = self.light(data.get("light", {}), "light")
        raw: list[Segment] = [seg for _, v, k in self.entries(data, "walls") if (seg := self.wall(v, k))]
        rooms = [room for _, v, k in self.entries(data, "rooms") if (room := self.room(v, k, ambient, raw))]
        near_rooms = _Rooms(rooms)
        self.overlaps(near_rooms)
        walls = geometry.SegmentIndex(geometry.merge(raw))
        if raw and not any(p.key.startswith("walls") for p in self.problems):  # a robot may not start outside
            xs, ys = [x for a, b in raw for x in (a[0], b[0])], [y for a, b in raw for y in (a[1], b[1])]
            self.enclosure = (min(xs), min(ys), max(xs), max(ys))  # the building (`pose`), once the walls are sound
        doors = [door for _, v, k in self.entries(data, "doors") if (door := self.door(v, k, walls, near_rooms))]
        gaps = self.gaps(doors, walls)
        solid = [Wall(*p) for i, w in enumerate(walls.segments) for p in geometry.cut(w, gaps.get(i, ()))]
        obstacles = [o for _, v, k in self.entries(data, "obstacles") if (o := self.obstacle(v, k))]
        self.obstacles = obstacles  # a robot may not start in one (`pose`)
        intruders = [n for _, v, k in self.entries(data, "intruders") if (n := self.intruder(v, k))]
        blocking = geometry.SegmentIndex([(w.a, w.b) for w in solid]
                                         + [(d.a, d.b) for d in doors if d.state is not DoorState.OPEN])
        rangers = [ranger for _, v, k in self.entries(data, "rangers") if (ranger := self.ranger(v, k, blocking))]
        scouts = [scout for _, v, k in self.entries(data, "scouts") if (scout := self.scout(v, k, blocking))]
        battery = self.battery(data["battery"], "battery") if "battery" in data else Battery()
        robots = {r.id for r in rangers} | {s.id for s in scouts} | {sid for r in rangers for sid in r.magazine}
        for rid, _ in battery.start:
            if rid not in robots:
                self.fail(f"battery.start.{rid}", f"no robot {rid!r} in this world")
        built = World(name or "", tuple(solid), tuple(doors), tuple(rooms), ambient, tuple(dark), tuple(obstacles),
                      tuple(intruders), tuple(rangers), tuple(scouts), description, self.source, battery)
        x0, y0, x1, y1 = built.bounds
        if (x1 - x0) * (y1 - y0) > MAX_AREA:  # the light map keeps a cell per square metre of it (worlds audit 17)
            self.fail("", f"the world spans {_num(round(x1 - x0, 1))} x {_num(round(y1 - y0, 1))} m, more than "
                          f"{MAX_AREA:,} square metres: its walls, rooms and robots must fit in a smaller box (a "
                          "long corridor is fine: a 500-wing building is 64 x 6,749 m)")
        return built

    def battery(self, value: object, key: str) -> Battery:
        data = self.mapping(value, key)
        self.keys(data, key, _BATTERY)
        idle = self.number(data["idle"], f"{key}.idle", zero=True) if "idle" in data else 0.0
        per_meter = self.number(data["per_meter"], f"{key}.per_meter", zero=True) if "per_meter" in data else 0.0
        start = []
        for robot, charge in self.mapping(data.get("start", {}), f"{key}.start").items():
            level = self.number(charge, f"{key}.start.{robot}", zero=True)
            if level is not None and level > 1:
                self.fail(f"{key}.start.{robot}", f"expected a charge from 0 (empty) to 1 (full), got {_num(level)}")
            elif level is not None:
                start.append((str(robot), level))
        return Battery(idle or 0.0, per_meter or 0.0, tuple(start))

    def light(self, value: object, key: str) -> tuple[float, list[LightZone]]:
        data = self.mapping(value, key)
        self.keys(data, key, _LIGHT)
        ambient = self.level(data["ambient"], f"{key}.ambient") if "ambient" in data else None
        zones = []
        for _, z, k in self.entries(data, "dark", key):
            self.keys(z, k, _DARK, required=("at", "radius"))
            at = self.point(z["at"], f"{k}.at") if "at" in z else None
            radius = self.number(z["radius"], f"{k}.radius", positive=True) if "radius" in z else None
            level = self.level(z["level"], f"{k}.level") if "level" in z else DEFAULT_DARK_LEVEL
            if at and radius and level is not None:
                zones.append(LightZone(at[0], at[1], radius, level))
        return (DEFAULT_AMBIENT if ambient is None else ambient), zones

    def wall(self, data: dict[Any, Any], key: str) -> Segment | None:
        self.keys(data, key, _WALL, required=_WALL)
        a = self.point(data["from"], f"{key}.from") if "from" in data else None
        b = self.point(data["to"], f"{key}.to") if "to" in data else None
        if a and b and geometry.length(a, b) <= geometry.EPS:
            self.fail(key, "from and to are the same point")
            return None
        return (a, b) if a and b else None

    def room(self, data: dict[Any, Any], key: str, ambient: float, walls: list[Segment]) -> Room | None:
        self.keys(data, key, _ROOM, required=("id", "rect"))
        rid = self.new_id(data["id"], f"{key}.id") if "id" in data else None
        rect = self.rect(data["rect"], f"{key}.rect") if "rect" in data else None
        light = self.level(data["light"], f"{key}.light") if "light" in data else ambient
        if self.flag(data.get("walls", True), f"{key}.walls") and rect:
            walls.extend(geometry.rect_sides(*rect))
        return Room(rid, *rect, light if light is not None else ambient) if rid and rect else None

    def overlaps(self, near: _Rooms) -> None:
        """Each room against the earlier rooms near it, in file order (the order of a scan of every pair)."""
        rooms = near.rooms
        for i, r in enumerate(rooms):
            for j in near.grid.near((r.x0, r.y0, r.x1, r.y1)):
                if j >= i:
                    break
                other = rooms[j]
                if r.x0 < other.x1 and other.x0 < r.x1 and r.y0 < other.y1 and other.y0 < r.y1:
                    self.fail(f"{self.ids[r.id]}.rect", f"overlaps room {other.id}")

    def door(self, data: dict[Any, Any], key: str, walls: geometry.SegmentIndex, rooms: _Rooms) -> Door | None:
        self.keys(data, key, _DOOR, required=("id", "at", "width"))
        did = self.new_id(data["id"], f"{key}.id") if "id" in data else None
        at = self.point(data["at"], f"{key}.at") if "at" in data else None
        width = self.number(data["width"], f"{key}.width", positive=True) if "width" in data else None
        state = self.state(data.get("state", "open"), f"{key}.state")
        located = walls.locate(at) if at else None
        if at and located is None:
            self.fail(f"{key}.at", f"[{_num(at[0])}, {_num(at[1])}] is not on a wall")
        if not (did and at and width and state and located):
            return None
        (a, b), s = walls.segments[located[0]], located[1]
        if s - width / 2 < -geometry.EPS or s + width / 2 > geometry.length(a, b) + geometry.EPS:
            self.fail(f"{key}.width", f"{_num(width)} m does not fit in its wall, which ends"
                      f" {_num(round(min(s, geometry.length(a, b) - s), 3))} m from the door's centre")
            return None
        room = rooms.first_around(at)
        return Door(did, geometry.along(a, b, s - width / 2), geometry.along(a, b, s + width / 2), width, state, room)

    def gaps(self, doors: Sequence[Door], walls: geometry.SegmentIndex) -> dict[int, list[tuple[float, float]]]:
        """Wall index -> the spans its doors take out of it (distances from its first end); overlaps are problems."""
        spans: dict[int, list[tuple[float, float, Door]]] = {}
        for door in doors:
            located = walls.locate(door.center)
            if located:
                s, half = located[1], door.width / 2
                spans.setdefault(located[0], []).append((s - half, s + half, door))
        for found in spans.values():
            found.sort(key=lambda span: span[:2])
            for (_, hi, first), (lo, _, second) in zip(found, found[1:], strict=False):
                if lo < hi - geometry.EPS:
                    self.fail(f"{self.ids[second.id]}.at", f"overlaps door {first.id}")
        return {i: [(lo, hi) for lo, hi, _ in found] for i, found in spans.items()}

    def obstacle(self, data: dict[Any, Any], key: str) -> Obstacle | None:
        self.keys(data, key, _OBSTACLE, required=_OBSTACLE)
        rect = self.rect(data["rect"], f"{key}.rect") if "rect" in data else None
        height = self.number(data["height"], f"{key}.height", positive=True) if "height" in data else None
        return Obstacle(*rect, height) if rect and height else None

    def intruder(self, data: dict[Any, Any], key: str) -> Intruder | None:
        self.keys(data, key, _INTRUDER, required=("id", "path"))
        iid = self.new_id(data["id"], f"{key}.id") if "id" in data else None
        loop = self.flag(data.get("loop", False), f"{key}.loop")
        radius = self.number(data["radius"], f"{key}.radius", positive=True) if "radius" in data else INTRUDER_RADIUS
        path: list[Waypoint] = []
        if "path" in data and isinstance(data["path"], list) and not data["path"]:
            self.fail(f"{key}.path", "expected at least one waypoint")
        for _, w, k in self.entries(data, "path", key):
            self.keys(w, k, _WAYPOINT, required=_WAYPOINT)
            t = self.number(w["t"], f"{k}.t", zero=True) if "t" in w else None
            at = self.point(w["at"], f"{k}.at") if "at" in w else None
            if t is not None and path and t <= path[-1].t:
                self.fail(f"{k}.t", f"expected a time after the previous waypoint's ({_num(path[-1].t)}),"
                          f" got {_num(t)}")
            elif t is not None and at:
                path.append(Waypoint(t, *at))
        if loop and len(path) >= 2 and (path[0].x, path[0].y) != (path[-1].x, path[-1].y):
            self.fail(f"{key}.path", "a looping path must end where it starts"
                      f" ([{_num(path[0].x)}, {_num(path[0].y)}]), so the intruder never jumps")
        elif loop and len(path) < 2 and path:
            self.fail(f"{key}.loop", "a looping path needs at least two waypoints")
        return Intruder(iid, tuple(path), bool(loop), radius) if iid and path and radius else None

    def ranger(self, data: dict[Any, Any], key: str, blocking: geometry.SegmentIndex) -> RangerSpawn | None:
        self.keys(data, key, _RANGER, required=("id", "at"))
        pose = self.pose(data, key, blocking, RANGER_RADIUS, "a body under rangers")
        magazine: list[str] = []
        value = data.get("magazine", [])
        if not isinstance(value, list):
            self.fail(f"{key}.magazine", f"expected a list of Scout ids, got {_got(value)}")
            value = []
        for i, sid in enumerate(value):
            scout = self.new_id(sid, f"{key}.magazine[{i}]")
            if scout:
                magazine.append(scout)
        return RangerSpawn(*pose, tuple(magazine)) if pose else None

    def scout(self, data: dict[Any, Any], key: str, blocking: geometry.SegmentIndex) -> ScoutSpawn | None:
        self.keys(data, key, _SCOUT, required=("id", "at"))
        pose = self.pose(data, key, blocking, SCOUT_RADIUS, "a body under scouts")
        return ScoutSpawn(*pose) if pose else None

    def pose(self, data: dict[Any, Any], key: str, blocking: geometry.SegmentIndex, radius: float,
             what: str) -> tuple[str, float, float, float] | None:
        rid = self.new_id(data["id"], f"{key}.id") if "id" in data else None
        at = self.point(data["at"], f"{key}.at") if "at" in data else None
        heading = self.number(data["heading"], f"{key}.heading") if "heading" in data else 0.0
        if at:
            clearance = blocking.clearance(at, radius)
            if clearance < radius:
                self.fail(f"{key}.at", f"{_num(round(clearance, 3))} m from a wall or closed door;"
                          f" {what} needs {_num(radius)} m")
            box = self.enclosure  # worlds audit 17, D7: a Ranger 18 m outside the building ran until --until
            if box and not (box[0] < at[0] < box[2] and box[1] < at[1] < box[3]):
                self.fail(f"{key}.at", f"outside the building: its walls span x {_num(box[0])}..{_num(box[2])}, "
                          f"y {_num(box[1])}..{_num(box[3])}")
            for i, o in enumerate(self.obstacles):  # worlds audit 17, D7: a Ranger inside one ran, stuck, 30 s
                gap = math.hypot(max(o.x0 - at[0], 0.0, at[0] - o.x1), max(o.y0 - at[1], 0.0, at[1] - o.y1))
                if gap < radius:
                    self.fail(f"{key}.at", f"{_num(round(gap, 3))} m from obstacles[{i}]" + (
                        " (inside it)" if gap == 0 else "") + f"; {what} needs {_num(radius)} m")
        if rid is None or at is None or heading is None:
            return None
        return rid, at[0], at[1], math.radians(heading)

    # -- typed readers

    def describe(self, value: object) -> str:
        return _got(value)

    def entries(self, data: Mapping[Any, Any], name: str, prefix: str = "",
                ) -> Iterator[tuple[int, dict[Any, Any], str]]:
        """The (index, mapping, key path) of each well-formed item of the list `data[name]`, if present."""
        key = join_key(prefix, name)
        value = data.get(name, [])
        if not isinstance(value, list):
            self.fail(key, f"expected a list, got {_got(value)}")
            return
        for i, item in enumerate(value):
            if isinstance(item, dict):
                yield i, item, f"{key}[{i}]"
            else:
                self.fail(f"{key}[{i}]", f"expected a mapping, got {_got(item)}")

    def ident(self, value: object, key: str) -> str | None:
        text = self.text(value, key)
        if text and not _ID.fullmatch(text):
            self.fail(key, f"{text!r} is not a name (letters, digits and _, not starting with a digit)")
        return text if _ID.fullmatch(text) else None

    def new_id(self, value: object, key: str) -> str | None:
        """An id not used before anywhere in the file: rooms, doors, intruders and robots share one namespace."""
        name = self.ident(value, key)
        if name and name in self.ids:
            self.fail(key, f"{name!r} is already the id of {self.ids[name]}")
            return None
        if name:
            self.ids[name] = key.rsplit(".", 1)[0] if key.endswith(".id") else key
        return name

    def number(self, value: object, key: str, positive: bool = False, zero: bool = False) -> float | None:
        if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
            self.fail(key, f"expected a number, got {_got(value)}")
            return None
        if positive and value <= 0 or zero and value < 0:
            self.fail(key, f"expected a {'positive' if positive else 'non-negative'} number, got {_num(value)}")
            return None
        return float(value)

    def level(self, value: object, key: str) -> float | None:
        number = self.number(value, key)
        if number is not None and not 0 <= number <= 1:
            self.fail(key, f"expected a light level from 0 (dark) to 1 (bright), got {_num(number)}")
            return None
        return number

    def point(self, value: object, key: str) -> Point | None:
        if not isinstance(value, list) or len(value) != 2:
            self.fail(key, f"expected a point [x, y], got {_got(value)}")
            return None
        x, y = (self.number(v, f"{key}[{i}]") for i, v in enumerate(value))
        return (x, y) if x is not None and y is not None else None

    def rect(self, value: object, key: str) -> tuple[float, float, float, float] | None:
        if not isinstance(value, list) or len(value) != 4:
            self.fail(key, f"expected a rectangle [x0, y0, x1, y1], got {_got(value)}")
            return None
        x0, y0, x1, y1 = (self.number(v, f"{key}[{i}]") for i, v in enumerate(value))
        if x0 is None or y0 is None or x1 is None or y1 is None:
            return None
        if x0 >= x1 or y0 >= y1:
            self.fail(key, f"expected x0 < x1 and y0 < y1, got [{', '.join(_num(v) for v in (x0, y0, x1, y1))}]")
            return None
        return x0, y0, x1, y1

    def flag(self, value: object, key: str) -> bool | None:
        if isinstance(value, bool):
            return value
        self.fail(key, f"expected true or false, got {_got(value)}")
        return None

    def state(self, value: object, key: str) -> DoorState | None:
        options = [s.value for s in DoorState]
        if isinstance(value, str) and value in options:
            return DoorState(value)
        hint = did_you_mean(str(value), options) or f"expected one of {', '.join(options)}"
        self.fail(key, f"unknown door state {_got(value)} ({hint})")
        return None


# ---------------------------------------------------------------- small helpers


def _got(value: object) -> str:
    """How a wrong value is shown: as written in YAML (`'wide'`, `null`, `true`), or `a list` / `a mapping`."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict | list):
        return "a mapping" if isinstance(value, dict) else "a list"
    return repr(value) if isinstance(value, str) else _num(value) if isinstance(value, int | float) else str(value)


def _num(value: float) -> str:
    """`2` rather than `2.0`: numbers in messages look like the file's."""
    return str(int(value)) if isinstance(value, float) and value.is_integer() else str(value)


class _Rooms:
    """Rooms with a grid of their boxes, so a door finds its room among its neighbours, not among all rooms."""

    def __init__(self, rooms: Sequence[Room]) -> None:
        self.rooms = rooms
        self.grid = geometry.GridIndex([(r.x0, r.y0, r.x1, r.y1) for r in rooms])

    def first_around(self, p: Point) -> str | None:
        """The id of the first room (in file order) with `p` on a side, as a scan of every room finds it: a room
        `_on_boundary` accepts has its box within 2 EPS of `p`."""
        margin = 2 * geometry.EPS
        for i in self.grid.near((p[0] - margin, p[1] - margin, p[0] + margin, p[1] + margin)):
            if _on_boundary(p, self.rooms[i]):
                return self.rooms[i].id
        return None


def _on_boundary(p: Point, room: Room) -> bool:
    """Whether `p` lies on a side of `room` (within `geometry.EPS`). A point outside the room's box widened by
    twice that is farther from every side, so it is turned away before the four distances (a door looks at
    every room: 1,000 doors x 1,000 rooms in a generated building)."""
    x, y = p
    margin = 2 * geometry.EPS
    if not (room.x0 - margin <= x <= room.x1 + margin and room.y0 - margin <= y <= room.y1 + margin):
        return False
    return any(geometry.point_segment_distance(p, a, b) <= geometry.EPS
               for a, b in geometry.rect_sides(room.x0, room.y0, room.x1, room.y1))
