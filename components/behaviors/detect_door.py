"""DetectDoor: find an open door as a gap in a corridor wall in the range scans.

A door is a run of beams on one side that reach well past the fitted corridor wall (into a room), with
wall hits on both sides of the run; its width is measured along the wall line. A closed door is a wall
segment to the laser, so it never shows up as a gap. The door's centre is given in odometry coordinates.
Doors already in the shared DoorLog (`visited`: a dict keyed by (rounded x, rounded y, side)) are skipped. At the end of
the corridor (a wall across the way, as FollowCorridor sees it) it fails: there is no new door left ahead, so
`FindNewDoor -> fail on error` ends that RoomSurveillance instance and the mission degrades gracefully. A wall it
was left facing when it started is not the end: FollowCorridor turns around, and the sweep back finds a door
missed on the way out; the end is the next wall across the way once the Ranger has moved.
"""

from __future__ import annotations

import math
import re
from typing import Any

from components.behaviors.scan import (
    SAME_LINE,
    Openings,
    ScanMemo,
    Wall,
    along,
    corridor,
    expected,
    wall_across,
    wrap,
)
from drd.hw.interfaces import Scan
from drd.runtime.component import Component, Status

#: How far past the wall line (m) a beam must reach to count as looking through a gap.
BEYOND = 0.5
#: Only doors whose centre is within this angle of abeam are reported (the geometry is best there).
ABEAM = math.radians(45)
_FAR = math.pi - 0.15  # beams closer than 0.15 rad to the wall's direction cross it too far away to tell
#: How far (m) the Ranger must have moved since the start before a wall across the way is the corridor's end: as
#: FollowCorridor, which turns around when it starts facing one.
LEAVE = 0.5
#: How long (s) a wall across may stand before a Ranger that has not left it yet ends the search all the same: turning
#: away takes FollowCorridor a few seconds; one that stands there did not (it ended, and the search stood for ever).
SETTLE = 20.0
#: How much (m) the corridor's width (left + right wall) may change from scan to scan while the Ranger keeps to its
#: line, and for how many scans in a row a changed width is taken for something beside the Ranger.
WIDTH_SLACK, SETTLE_SCANS = 0.25, 20
#: A maximal run of beams through the wall with a beam at the wall on both sides.
_GAP = re.compile(r"(?<=w)s{0,8}b+s{0,8}(?=w)")


def door_key(x: float, y: float, side: str) -> tuple[float, float, str]:
    """The DoorLog key of a door: its x and y rounded to the metre, and its side. Not x alone: in a building of
    parallel corridors two doors share an x, and one Ranger would skip the other's door as known."""
    return (float(round(x)), float(round(y)), side)


def known(log: Any, x: float, y: float, side: str, width: float) -> bool:
    """Whether the DoorLog already has this door: its centre within a door width of a logged one.

    Positions are in odometry coordinates, so the side (relative to the robot) does not matter: a
    Ranger that turned around sees the same door on its other side.
    """
    if not isinstance(log, dict):
        return False
    if door_key(x, y, side) in log:
        return True
    for rec in log.values():
        if isinstance(rec, dict) and math.hypot(rec["x"] - x, rec["y"] - y) < width:
            return True
    return False


def find_gaps(scan: Any, min_width: float, expect: tuple[float | None, float | None] = (None, None),
              memo: ScanMemo | None = None) -> list[dict[str, float | str]]:
    """Door gaps in one scan, in the robot frame: {width, x, y, side, bearing}. Of two fitted walls not on one line
    only the one with more inliers is a corridor wall (`along`): turning back to the corridor's line after a launch,
    the fit on the other side followed an obstacle's face, and a door was reported in mid-corridor (worlds audit 17,
    D1: a Scout was thrown into the corridor)."""
    walls = along(corridor(scan, expect, memo=memo), 0.0, None)
    b = scan.beams()
    out: list[dict[str, float | str]] = []
    for wall, sgn, side in ((walls[0], 1, "left"), (walls[1], -1, "right")):
        if wall is None:
            continue
        d, tilt = wall.distance, wall.angle * sgn  # the wall line in the side's frame: y' = d / cos + x' tan
        ct, st = math.cos(tilt), math.sin(tilt)
        # A beam's angle from the wall direction, on this side, is a = sgn * angle - tilt; only beams with
        # 0.15 < a < pi - 0.15 can be told apart (the others count as short). `b.span` finds them, with a margin
        # for rounding: the test on `a` itself below decides.
        lo, hi = (0.15 + tilt - 1e-9, _FAR + tilt + 1e-9) if sgn > 0 else (-_FAR - tilt - 1e-9, -0.15 - tilt + 1e-9)
        i0, i1 = b.span(lo, hi)
        # per beam of the span: the range at which it crosses the wall line (None where it runs too close to the
        # wall's direction to tell), with the sine of a from the beam tables; then whether it reaches well beyond
        # the wall ("b"), stops at the wall ("w") or short of it / nothing ("s")
        ranges, angles, cos, sin = scan.ranges[i0:i1], b.angles[i0:i1], b.cos[i0:i1], b.sin[i0:i1]
        crossing = [d / (sgn * s * ct - c * st) if 0.15 < t * sgn - tilt < _FAR else None
                    for t, c, s in zip(angles, cos, sin, strict=True)]
        kinds = "".join(["s" if x is None else "b" if r >= x + BEYOND else "w" if -0.15 < r - x < 0.15 else "s"
                         for r, x in zip(ranges, crossing, strict=True)])

        # a door: a run of beams through the wall between two beams at it (beams out of the span are short)
        for run in _GAP.finditer(kinds):
            i, j = run.start(), run.end() - 1
            # where the beams on either side of each jamb cross the wall line, along the wall
            w0, b0, b1, w1 = [x * (cos[k] * ct + sgn * sin[k] * st) for k in (i - 1, i, j, j + 1)
                              if (x := crossing[k]) is not None]
            # the jambs lie between the last wall hit and the first beam through, on either side
            e1, e2 = (w0 + b0) / 2, (b1 + w1) / 2
            width = abs(e1 - e2)
            xc = (e1 + e2) / 2
            bearing = math.atan2(d, xc)
            if width >= min_width and abs(bearing - math.pi / 2) <= ABEAM:
                # back to the robot frame: rotate the wall frame by tilt, mirror for the right side
                rx, ry = xc * ct - d * st, sgn * (xc * st + d * ct)
                out.append({"width": width, "x": rx, "y": ry, "side": side})
    return out


def same_width(walls: tuple[Wall | None, Wall | None], expect: tuple[float | None, float | None],
               width: float | None, odd: int) -> tuple[tuple[Wall | None, Wall | None], float | None, int]:
    """The two fits, less one that changes the corridor's width (left + right): something beside the Ranger, not its
    wall; with the width and the count of such scans in a row after this one. An object coming close on one side
    dragged that side's expected distance along, each fit within `jump` of the last, until the real wall was
    rejected for good and no door on that side was seen (the ROS 2 cluster run missed the door at x = 23). A width
    that stays changed for `SETTLE_SCANS` scans is the corridor's. Pure."""
    left, right = walls
    if left is None or right is None:
        return walls, width, odd
    now = left.distance + right.distance
    if width is None or odd >= SETTLE_SCANS:  # kept, not followed: a slow drag would move it too
        return walls, now, 0
    if abs(now - width) <= WIDTH_SLACK:
        return walls, width, 0
    moved = [abs(w.distance - e) if e is not None else 0.0 for w, e in ((left, expect[0]), (right, expect[1]))]
    return ((left, None) if moved[0] <= moved[1] else (None, right)), width, odd + 1  # the one that moved less


def across(walls: tuple[Wall | None, Wall | None], expect: tuple[float | None, float | None],
           width: float | None) -> tuple[float | None, float | None]:
    """The last known distances, but a side whose wall was not seen is expected across the corridor from the other
    one when the width is known: an expectation gone astray comes back. Pure."""
    left, right = walls
    if width is None or (left is None) == (right is None):
        return expect
    if left is None and right is not None:
        return width - right.distance, expect[1]
    return expect[0], width - left.distance if left is not None else expect[1]


class DetectDoor(Component):
    """Succeeds with output `door` (odometry coordinates) and event DoorDetected on a new open door."""

    def start(self) -> None:
        self.expect: tuple[float | None, float | None] = (None, None)
        self.width: float | None = None  # the corridor's width (left + right), while on its line
        self.odd = 0  # scans in a row whose two walls gave another width
        self.memo = ScanMemo()  # what the scan helpers derive from this cycle's scan
        self.openings = Openings()  # an L's or a T's corner is no end: FollowCorridor turns there
        self.origin: tuple[float, float] | None = None  # where it started (odometry), once known
        self.began: float | None = None  # when it was first stepped
        self.heading: float | None = None  # the odometry's heading when the expected distances were (re)started

    def resume(self) -> None:
        """Given the Ranger back: `SETTLE` counts afresh (FollowCorridor, resumed too, turns away first)."""
        self.began = None

    def _just_started(self, pose: tuple[float, float, float] | None, now: float) -> bool:
        """Still within `LEAVE` of where it started: a wall ahead then is one it was left facing (the previous
        instance launched its Scout from there, or the sweep ended there), which FollowCorridor turns away from,
        sweeping back; it is the corridor's end once the Ranger has moved (a sweep back finds the doors missed on the
        way out). Without odometry, any wall across the way is the end."""
        return pose is not None and self.origin is not None and math.hypot(
            pose[0] - self.origin[0], pose[1] - self.origin[1]) < LEAVE and now - (self.began or now) < SETTLE

    def _pose(self) -> tuple[float, float, float] | None:
        """Odometry, from the robot's Drive if this component was given one (the runtime may add it), else from
        a `pose` service; without either the door is reported in the robot frame."""
        if "drive" in self.ctx.devices:
            x, y, heading = self.device("drive").odometry()
            return float(x), float(y), float(heading)
        odo = self.ctx.services.odometry
        return odo() if odo is not None else None

    def _expected(self, scan: Scan, pose: tuple[float, float, float] | None) -> tuple[float | None, float | None]:
        """The wall distances to expect next, started afresh whenever the robot has turned SAME_LINE from the heading
        they were started at (FollowCorridor turning to the corridor's line, or around): fits taken from across the
        corridor are of other things (a room's wall through a door locked the expectation at 1.68 m for a wall at
        1.25 m, and the next door went unseen), and after a turn around left and right have swapped. By heading,
        not by turn rate: a rate per step depends on how often it is stepped (on a cluster a door was missed)."""
        heading = pose[2] if pose is not None else None
        if heading is not None and (self.heading is None or abs(wrap(heading - self.heading)) > SAME_LINE):
            self.heading, self.expect, self.width, self.odd = heading, (None, None), None, 0
        walls, self.width, self.odd = same_width(corridor(scan, self.expect, memo=self.memo), self.expect,
                                                 self.width, self.odd)
        return expected(walls, across(walls, self.expect, self.width))

    def step(self, now: float) -> Status:
        min_width = float(self.ctx.params["min_width"])
        scan = self.device("ranges").scan()
        found = self._pose()
        if self.began is None:
            self.began = now
        if self.origin is None and found is not None:
            self.origin = found[:2]
        if found is not None:
            self.openings.update(scan, found[0], found[1])
        if wall_across(scan, memo=self.memo) and not self._just_started(found, now) and (
                found is None or self.openings.turn(found[0], found[1]) is None):
            self.ctx.log("the corridor ends here, with no new door")  # no new door between here and the end
            return Status.FAILURE
        self.expect = self._expected(scan, found)
        pose = found or (0.0, 0.0, 0.0)
        log = self.input("visited")
        for gap in find_gaps(scan, min_width, self.expect, self.memo):
            px, py, pa = pose
            gx, gy = float(gap["x"]), float(gap["y"])
            x = px + gx * math.cos(pa) - gy * math.sin(pa)
            y = py + gx * math.sin(pa) + gy * math.cos(pa)
            width, side = float(gap["width"]), str(gap["side"])
            if known(log, x, y, side, max(width, 1.0)):
                continue
            door = {"width": round(width, 3), "x": round(x, 3), "y": round(y, 3), "side": side,
                    "from": {"x": round(px, 3), "y": round(py, 3)}}  # where the Ranger stood: AlignRanger returns
            if isinstance(log, dict):
                log[door_key(x, y, side)] = dict(door)
            self.ctx.outputs["door"] = door
            self.ctx.emit("DoorDetected", width=door["width"], x=door["x"], y=door["y"])
            return Status.SUCCESS
        return Status.RUNNING
