"""A generated building of N wings, as world data and matching hosts data (pure: no I/O).

Each wing is a closed corridor along x, like `worlds/corridor.yaml`, with rooms on both sides, one dark corner at
the back of each room, one intruder walking between two rooms, and one Ranger at its west end carrying the wing's
Scouts. Wings are stacked north to south with a 1 m solid gap between them (no shared wall, so one wing's dark
corners do not darken its neighbour's rooms). Every wing has exactly as many open doors as its Ranger has Scouts,
so the corridor mission (`RoomSurveillance[1..count(Scout)]`, a Scout whose carrier is the Ranger) runs unchanged
on it, one RoomSurveillance per Scout and the wings in parallel. `missionctl world generate` writes the two
mappings as files (`drd.cli.world`); `parse_world` and `drd.hosts.parse_hosts` read them like any other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from drd.errors import ConfigurationError

#: Geometry of one wing (metres): corridor width, room depth and width, the corridor's ends past the rooms.
CORRIDOR, DEPTH, ROOM, END = 2.5, 5.0, 6.0, 2.0
#: Solid space between two wings: no light, wall or radio crosses it.
GAP = 1.0
#: Limits of the generator: a hosts file gives each host its own loopback port (7447 up), and a wing's Scouts
#: share its one radio channel.
MAX_WINGS, MAX_SCOUTS = 500, 99
FIRST_PORT = 7447


class BuildingError(ConfigurationError, ValueError):
    """A building that cannot be generated (a count out of range), said as a user reads it."""


@dataclass(frozen=True)
class Building:
    """What to generate: `wings` wings of `scouts` Scouts each (one Ranger per wing)."""

    wings: int
    scouts: int

    def __post_init__(self) -> None:
        problems = [f"--{what} {n}: expected 1 to {top}" for what, n, top in
                    (("wings", self.wings, MAX_WINGS), ("scouts", self.scouts, MAX_SCOUTS))
                    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= top]
        if problems:
            raise BuildingError("; ".join(problems))

    @property
    def name(self) -> str:
        """The world's (and the cluster's) name: `building_50x19`."""
        return f"building_{self.wings}x{self.scouts}"

    @property
    def robots(self) -> int:
        return self.wings * (1 + self.scouts)

    @property
    def rooms_per_side(self) -> int:
        return max(1, math.ceil(self.scouts / 2))

    @property
    def length(self) -> float:
        """The corridor's length (every wing's)."""
        return END + ROOM * self.rooms_per_side + END

    @property
    def pitch(self) -> float:
        """The distance between two wings' corridor centre lines."""
        return CORRIDOR + 2 * DEPTH + GAP

    def centre(self, wing: int) -> float:
        """The y of wing `wing`'s (0-based) corridor centre line; the first wing is at y = 0, the others south."""
        return -wing * self.pitch

    def ranger(self, wing: int) -> str:
        return f"ranger{wing + 1}"

    def scout_ids(self, wing: int) -> list[str]:
        """The wing's Scouts, numbered across the building (`scout1`..`scout950`), in launch order."""
        first = wing * self.scouts + 1
        return [f"scout{n}" for n in range(first, first + self.scouts)]


def counted(n: int, noun: str) -> str:
    """`1 wing`, `3 wings`: the count and its noun, singular or plural."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def world(b: Building) -> dict[str, Any]:
    """The world file's data (docs/worlds.md)."""
    data: dict[str, Any] = {
        "name": b.name,
        "description": f"A generated building: {counted(b.wings, 'wing')}, each a {b.length:g} m corridor with "
                       f"{2 * b.rooms_per_side} rooms ({counted(b.scouts, 'door')} open), one Ranger with "
                       f"{counted(b.scouts, 'Scout')} and one intruder per wing.",
        "light": {"ambient": 0.9, "dark": []},
        "walls": [], "rooms": [], "doors": [], "intruders": [], "rangers": [],
    }
    for wing in range(b.wings):
        _wing(b, wing, data)
    return data


def _wing(b: Building, wing: int, data: dict[str, Any]) -> None:
    """One wing's walls, rooms, doors, dark corners, intruder and Ranger, added to `data`."""
    yc, half, x1 = b.centre(wing), CORRIDOR / 2, b.length
    w = wing + 1
    data["walls"] += [{"from": [0, yc + half], "to": [x1, yc + half]}, {"from": [0, yc - half], "to": [x1, yc - half]},
                      {"from": [0, yc - half], "to": [0, yc + half]}, {"from": [x1, yc - half], "to": [x1, yc + half]}]
    # the doors in the order the Ranger passes them, west to east, alternating sides 2 m apart; the first
    # `scouts` are open, the rest (one at most) closed
    order: list[tuple[int, str]] = [(i, side) for i in range(b.rooms_per_side) for side in ("n", "s")]
    for k, (i, side) in enumerate(order):
        rx0 = END + ROOM * i
        sign = 1 if side == "n" else -1
        near, far = yc + sign * half, yc + sign * (half + DEPTH)
        rid = f"w{w}_{side}{i + 1}"
        data["rooms"].append({"id": rid, "rect": [rx0, min(near, far), rx0 + ROOM, max(near, far)],
                              "light": 0.6 if (i + (side == "s")) % 2 == 0 else 0.7})
        data["doors"].append({"id": f"door_{rid}", "at": [rx0 + (2.0 if side == "n" else 4.0), near],
                              "width": 1.0, "state": "open" if k < b.scouts else "closed"})
        # the dark corner at the back of the room, away from its door
        corner_x = rx0 + ROOM - 0.6 if side == "n" else rx0 + 0.6
        data["light"]["dark"].append({"at": [round(corner_x, 3), round(far - sign * 0.6, 3)], "radius": 1.5})
    # an intruder paces the second north room (the first with one room a side), never the corridor: a person in
    # the corridor stops the Ranger or spoils a launch, which is the corridor world's test, not this one's
    rx0 = END + ROOM * min(1, b.rooms_per_side - 1)
    a, c = [rx0 + 1.5, yc + half + 1.5], [rx0 + 4.5, yc + half + 3.5]
    data["intruders"].append({"id": f"intruder{w}", "loop": True,
                              "path": [{"t": 0, "at": _pt(a)}, {"t": 10, "at": _pt(c)}, {"t": 20, "at": _pt(a)}]})
    data["rangers"].append({"id": b.ranger(wing), "at": [1, yc], "heading": 0, "magazine": b.scout_ids(wing)})


def _pt(p: list[float]) -> list[float]:
    return [round(p[0], 3), round(p[1], 3)]


def hosts(b: Building, world_name: str | None = None) -> dict[str, Any]:
    """The hosts file's data (docs/hosts.md): a controller, then one host per wing with its Ranger, its Scouts
    (carrier: that Ranger) and their devices, all `sim` drivers on loopback; the first wing's host also runs the
    simulator. `world_name`: `cluster.world` (default: the building's name)."""
    out: dict[str, Any] = {
        "cluster": {"name": b.name, "security": {"mode": "none"}, "lease": "3s",
                    "placement": {"cpu": 1.0, "memory": 0.5, "instances": 0.2}, "world": world_name or b.name},
        "hosts": {"controller": {"endpoint": f"tcp/127.0.0.1:{FIRST_PORT}", "roles": ["controller"], "cores": 2}},
    }
    for wing in range(b.wings):
        ranger = b.ranger(wing)
        devices: dict[str, Any] = {
            "drive": {"type": "Drive", "driver": "sim", "slice": "60s", "options": {"max_speed": 0.8}},
            "ranges": {"type": "RangeSensor", "driver": "sim", "options": {"beams": 181, "max_range": 8.0}},
            "camera": {"type": "Camera", "driver": "sim", "options": {"resolution": 640, "fov": 60.0}},
            "launcher": {"type": "Launcher", "driver": "sim", "options": {"max_range": 6.0}},
            # one channel for the wing, wide enough for all its Scouts at once
            "radio": {"type": "RadioChannel", "driver": "sim", "capacity": max(10, b.scouts),
                      "options": {"range": 30.0}},
        }
        robots: dict[str, Any] = {ranger: {"type": "Ranger", "parts": {"drive": "drive", "ranges": "ranges",
                                                                          "camera": "camera", "launcher": "launcher"},
                                           "properties": {"battery": 1.0, "magazine": b.scouts}}}
        for scout in b.scout_ids(wing):
            devices[f"{scout}.wheels"] = {"type": "Drive", "driver": "sim", "options": {"max_speed": 0.3}}
            devices[f"{scout}.foot"] = {"type": "Jump", "driver": "sim", "options": {"max_height": 0.3}}
            devices[f"{scout}.camera"] = {"type": "Camera", "driver": "sim", "options": {"resolution": 320,
                                                                                        "fov": 90.0}}
            robots[scout] = {"type": "Scout", "carrier": ranger,
                             "parts": {"wheels": f"{scout}.wheels", "foot": f"{scout}.foot",
                                       "camera": f"{scout}.camera", "radio": "radio"},
                             "properties": {"battery": 1.0}}
        out["hosts"][ranger] = {"endpoint": f"tcp/127.0.0.1:{FIRST_PORT + 1 + wing}",
                                "roles": ["worker", "simulator"] if wing == 0 else ["worker"],
                                "devices": devices, "robots": robots}
    return out
