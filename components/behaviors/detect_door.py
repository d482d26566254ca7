"""DetectDoor: find an open door as a gap in a corridor wall in the range scans.

A door is a run of beams on one side that reach well past the fitted corridor wall (into a room), with
wall hits on both sides of the run; its width is measured along the wall line. A closed door is a wall
segment to the laser, so it never shows up as a gap. The door's centre is given in odometry coordinates.
Doors already in the shared DoorLog (`visited`: a dict keyed by (rounded x, side)) are skipped.
"""

from __future__ import annotations

import math
from typing import Any

from components.behaviors.follow_corridor import corridor
from drd.runtime.component import Component, Status

#: How far past the wall line (m) a beam must reach to count as looking through a gap.
BEYOND = 0.5
#: Only doors whose centre is within this angle of abeam are reported (the geometry is best there).
ABEAM = math.radians(30)


def door_key(x: float, side: str) -> tuple[float, str]:
    """The DoorLog key of a door: its x rounded to the metre, and its side."""
    return (float(round(x)), side)


def known(log: Any, x: float, y: float, side: str, width: float) -> bool:
    """Whether the DoorLog already has this door: its centre within a door width of a logged one.

    Positions are in odometry coordinates, so the side (relative to the robot) does not matter: a
    Ranger that turned around sees the same door on its other side.
    """
    if not isinstance(log, dict):
        return False
    if door_key(x, side) in log:
        return True
    for rec in log.values():
        if isinstance(rec, dict) and math.hypot(rec["x"] - x, rec["y"] - y) < width:
            return True
    return False


def find_gaps(scan: Any, min_width: float, expect=(None, None)) -> list[dict[str, float | str]]:
    """Door gaps in one scan, in the robot frame: {width, x, y, side, bearing}."""
    walls = corridor(scan, expect)
    out: list[dict[str, float | str]] = []
    for wall, sgn, side in ((walls[0], 1, "left"), (walls[1], -1, "right")):
        if wall is None:
            continue
        d, tilt = wall.distance, wall.angle * sgn  # the wall line in the side's frame: y' = d / cos + x' tan
        rel = []  # per beam: (+1 beyond the wall, 0 at the wall, -1 short of it / nothing) and the wall crossing x
        for i, r in enumerate(scan.ranges):
            a = scan.angle(i) * sgn - tilt  # beam angle measured from the wall direction, on this side
            if not 0.15 < a < math.pi - 0.15:
                rel.append((-1, 0.0))
                continue
            cross = d / math.sin(a)  # range at which the beam crosses the wall line
            xw = cross * math.cos(a)  # along the wall
            if r >= cross + BEYOND:
                rel.append((1, xw))
            elif abs(r - cross) < 0.15:
                rel.append((0, xw))
            else:
                rel.append((-1, xw))
        i = 0
        while i < len(rel):
            if rel[i][0] != 1:
                i += 1
                continue
            j = i
            while j + 1 < len(rel) and rel[j + 1][0] == 1:
                j += 1
            if i > 0 and j + 1 < len(rel) and rel[i - 1][0] == 0 and rel[j + 1][0] == 0:
                # the jambs lie between the last wall hit and the first beam through, on either side
                e1 = (rel[i - 1][1] + rel[i][1]) / 2
                e2 = (rel[j][1] + rel[j + 1][1]) / 2
                width = abs(e1 - e2)
                xc = (e1 + e2) / 2
                bearing = math.atan2(d, xc)
                if width >= min_width and abs(bearing - math.pi / 2) <= ABEAM:
                    # back to the robot frame: rotate the wall frame by tilt, mirror for the right side
                    c, s = math.cos(tilt), math.sin(tilt)
                    rx, ry = xc * c - d * s, sgn * (xc * s + d * c)
                    out.append({"width": width, "x": rx, "y": ry, "side": side})
            i = j + 1
    return out


class DetectDoor(Component):
    """Succeeds with output `door` (odometry coordinates) and event DoorDetected on a new open door."""

    def start(self) -> None:
        self.expect: tuple[float | None, float | None] = (None, None)

    def _pose(self) -> tuple[float, float, float] | None:
        """Odometry, from the robot's Drive if this component was given one (the runtime may add it), else from
        a `pose` service; without either the door is reported in the robot frame."""
        if "drive" in self.ctx.devices:
            return self.device("drive").odometry()
        odo = self.ctx.services.get("odometry")
        return odo() if callable(odo) else None

    def step(self, now: float) -> Status:
        min_width = float(self.ctx.params.get("min_width", 0.7))
        scan = self.device("ranges").scan()
        left, right = corridor(scan, self.expect)
        self.expect = (left.distance if left else self.expect[0], right.distance if right else self.expect[1])
        pose = self._pose() or (0.0, 0.0, 0.0)
        log = self.shared("visited")
        for gap in find_gaps(scan, min_width, self.expect):
            px, py, pa = pose
            x = px + gap["x"] * math.cos(pa) - gap["y"] * math.sin(pa)
            y = py + gap["x"] * math.sin(pa) + gap["y"] * math.cos(pa)
            width, side = float(gap["width"]), str(gap["side"])
            if known(log, x, y, side, max(width, 1.0)):
                continue
            door = {"width": round(width, 3), "x": round(x, 3), "y": round(y, 3), "side": side}
            if isinstance(log, dict):
                log[door_key(x, side)] = dict(door)
            self.ctx.outputs["door"] = door
            self.ctx.emit("DoorDetected", width=door["width"], x=door["x"], y=door["y"])
            return Status.SUCCESS
        return Status.RUNNING
