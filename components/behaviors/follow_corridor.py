"""FollowCorridor: keep to the middle of the corridor from the side ranges, driving forward.

Also home of the small scan helpers the other Ranger behaviors share (wall fit, clearance),
all computed in the robot frame from a `Scan` and from odometry, never from ground truth.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Any

from drd.hw.interfaces import Scan
from drd.runtime.component import Component, Status

#: Gains of the P controller: rad/s per metre off the centre line, and per radian of heading error.
K_LATERAL = 1.2
K_HEADING = 2.0
MAX_OMEGA = 1.0


def points(scan: Scan, lo: float, hi: float) -> list[tuple[float, float, float]]:
    """(angle, x, y) in the robot frame of the beams with angle in [lo, hi] that hit something."""
    b, far = scan.beams(), scan.max_range
    i0, i1 = b.span(lo, hi)
    return [(a, r * c, r * s) for a, r, c, s in zip(b.angles[i0:i1], scan.ranges[i0:i1], b.cos[i0:i1], b.sin[i0:i1],
                                                    strict=True) if r < far]


@dataclass(frozen=True)
class Wall:
    """A corridor wall fitted in the robot frame: perpendicular distance and angle of the wall (rad, CCW)."""

    distance: float
    angle: float
    inliers: int


#: The beams a wall fit looks at, per side: 20 to 160 degrees off the heading, left (+1) or right (-1).
_SECTOR = {1: (math.radians(20), math.radians(160)), -1: (math.radians(-160), math.radians(-20))}
#: A starting distance needs SUPPORT abeam distances (itself included) at most SPREAD metres above it.
SUPPORT, SPREAD = 6, 0.08


def fit_wall(scan: Scan, side: int, expect: float | None = None) -> Wall | None:
    """Fit the wall on one side (+1 left, -1 right) by least squares on the beams near it, robust to door gaps
    and end walls: start from a lateral distance abeam that enough beams agree on (the nearest one, or the one
    nearest `expect`, the last known distance), keep the points close to it.

    A pure function of its arguments. What it derives from a scan is kept with the scan (`derived`), so the
    behaviors that read the same scan in one control cycle (the laser's driver hands them one `Scan`) share it:
    the points of a side are computed once, and a fit whose first inliers are those of an earlier fit is that fit.
    """
    memo = derived(scan)
    if memo is None:
        return _fit(scan, side, expect, {})
    key = ("fit", side, expect)
    if key not in memo:
        memo[key] = _fit(scan, side, expect, memo)
    wall: Wall | None = memo[key]
    return wall


def _side(scan: Scan, side: int) -> tuple[list[float], list[float], list[float]]:
    """The hits on one side, as x and lateral distance (parallel lists), and the supported starting distances."""
    lo, hi = _SECTOR[1 if side > 0 else -1]
    b, far = scan.beams(), scan.max_range
    i0, i1 = b.span(lo, hi)
    beams = zip(scan.ranges[i0:i1], b.cos[i0:i1], b.sin[i0:i1], strict=True)
    if side > 0:
        pts = [(r * c, y) for r, c, s in beams if r < far and (y := r * s) > 0.05]
    else:
        pts = [(r * c, y) for r, c, s in beams if r < far and (y := -(r * s)) > 0.05]
    abeam = sorted([y for x, y in pts if abs(x) <= 2 * y])  # within about 60 degrees of the perpendicular
    # abeam is sorted: abeam[i] has SUPPORT values within SPREAD above it exactly when abeam[i + SUPPORT - 1] does
    support = [y for y, z in zip(abeam, abeam[SUPPORT - 1:], strict=False) if z - y < SPREAD]
    return [x for x, _ in pts], [y for _, y in pts], support


def _fit(scan: Scan, side: int, expect: float | None, memo: dict[Any, Any]) -> Wall | None:
    key = ("side", side)
    if key not in memo:
        memo[key] = _side(scan, side)
    xs, ys, support = memo[key]
    if not support:
        return None
    if expect is None:
        d0 = support[0]
    else:  # the supported distance nearest the expected one (support is sorted)
        j = bisect.bisect_left(support, expect)
        d0 = support[j - 1] if j == len(support) or (j > 0 and expect - support[j - 1] <= support[j] - expect) \
            else support[j]
    # first pass: the points within 0.25 m of the line y = d0; the rest depends on d0 only through them
    first = tuple([i for i, y in enumerate(ys) if -0.25 < y - d0 < 0.25])
    refined = ("refine", side, first)
    if refined not in memo:
        memo[refined] = _refine(xs, ys, first, side)
    wall: Wall | None = memo[refined]
    return wall


def _refine(xs: list[float], ys: list[float], first: tuple[int, ...], side: int) -> Wall | None:
    """Least squares on the `first` inliers, then again on the points within 0.1 m of that line."""
    inl = first
    m = c = 0.0
    for gate in (None, 0.1):
        if gate is not None:
            inl = tuple([i for i, (x, y) in enumerate(zip(xs, ys, strict=True)) if -gate < y - (m * x + c) < gate])
        n = len(inl)
        if n < 5:
            return None
        ix, iy = [xs[i] for i in inl], [ys[i] for i in inl]
        mx, my = sum(ix) / n, sum(iy) / n
        dxs = [x - mx for x in ix]
        sxx = sum([dx * dx for dx in dxs])
        if sxx < 1e-6:
            return None
        m = sum([dx * (y - my) for dx, y in zip(dxs, iy, strict=True)]) / sxx
        c = my - m * mx
    a = math.atan(m)
    return Wall(c * math.cos(a), side * a, n)


#: Data derived from the latest few scans (wall fits, their points), by scan identity: see `derived`.
_DERIVED: dict[int, tuple[Scan, dict[Any, Any]]] = {}
_DERIVED_SCANS = 8


def derived(scan: Scan) -> dict[Any, Any] | None:
    """A dict for what helpers derive from `scan` (keyed by what they computed), kept while `scan` is one of the
    few latest seen; None for a scan whose ranges are not a tuple (it could change, so nothing is kept).

    Keyed by identity: the entry holds the scan itself, so its id cannot be reused while the entry exists, and a
    `Scan` with a tuple of ranges never changes."""
    entry = _DERIVED.get(id(scan))
    if entry is not None and entry[0] is scan:
        return entry[1]
    if not isinstance(scan.ranges, tuple):
        return None
    if len(_DERIVED) >= _DERIVED_SCANS:
        for old in list(_DERIVED)[:len(_DERIVED) + 1 - _DERIVED_SCANS]:  # the oldest (dicts keep insertion order)
            _DERIVED.pop(old, None)
    memo: dict[Any, Any] = {}
    _DERIVED[id(scan)] = (scan, memo)
    return memo


def corridor(scan: Scan, expect: tuple[float | None, float | None] = (None, None),
             jump: float = 0.4) -> tuple[Wall | None, Wall | None]:
    """The left and right walls (either may be None where no wall is seen, or where the fit is more than `jump`
    metres from the expected distance: a room seen through a doorway, not the corridor wall)."""
    out = []
    for side, exp in ((1, expect[0]), (-1, expect[1])):
        w = fit_wall(scan, side, exp)
        out.append(None if w is None or (exp is not None and abs(w.distance - exp) > jump) else w)
    return out[0], out[1]


#: Free space ahead (m) below which the corridor has ended: a wall across the way.
END = 0.9
#: Half the width of the swath that must be free ahead (m): the Ranger's radius and a margin.
BODY = 0.35
#: A wall across the way spans more than WIDER metres of the lane within ACROSS metres either side of the axis.
ACROSS, WIDER = 0.9, 1.0
#: Turning around: rate (rad/s), and how close to the reverse heading (rad) counts as turned.
TURN_RATE, TURNED = 0.8, 0.15


def clearance_ahead(scan: Scan, half_width: float = BODY) -> float:
    """Free distance straight ahead (m) in a swath `2 * half_width` wide: the nearest hit in front of the robot
    within that lateral distance of its axis, or the laser's range when nothing is there."""
    memo = derived(scan)
    key = ("clearance", half_width)
    if memo is not None and key in memo:
        free: float = memo[key]
        return free
    far = scan.max_range
    free = min([r * c for r, c, s in _ahead(scan) if r < far and -half_width < r * s < half_width], default=far)
    if memo is not None:
        memo[key] = free
    return free


def _ahead(scan: Scan) -> zip[tuple[float, float, float]]:
    """(range, cos, sin) of the beams in front of the robot (bearing strictly within 90 degrees of the heading)."""
    b = scan.beams()
    i0, i1 = bisect.bisect_right(b.angles, -math.pi / 2), bisect.bisect_left(b.angles, math.pi / 2)
    return zip(scan.ranges[i0:i1], b.cos[i0:i1], b.sin[i0:i1], strict=True)


def wall_across(scan: Scan, within: float = END) -> bool:
    """The corridor ends here: the way ahead is blocked within `within` metres, and by something wider than a
    person (hits ahead spanning over `WIDER` metres across, looking within `ACROSS` of the axis: inside the
    corridor's side walls), so an intruder walking by is not taken for the end."""
    if clearance_ahead(scan) >= within:
        return False
    far, depth = scan.max_range, within + 0.25
    across = [y for r, c, s in _ahead(scan) if r < far and 0 < r * c < depth and -ACROSS < (y := r * s) < ACROSS]
    return bool(across) and max(across) - min(across) >= WIDER


def wrap(a: float) -> float:
    """An angle in [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


class FollowCorridor(Component):
    """Drive forward at `speed`, steering to the centre line and along the walls, to the end of the corridor.

    The end is a wall across the way less than `END` metres ahead: then it stops and succeeds. Something
    narrower in the way (a person) only stops it until it has passed.
    Started facing an end (a Ranger left there by the previous sweep), it first turns around on the spot.
    """

    def start(self) -> None:
        self.width: float | None = None
        self.expect: tuple[float | None, float | None] = (None, None)
        self.origin: tuple[float, float] | None = None
        self.turn_to: float | None = None  # heading to turn to, when turning around

    def step(self, now: float) -> Status:
        speed = float(self.ctx.params["speed"])
        drive = self.device("drive")
        scan = self.device("ranges").scan()
        x, y, a = drive.odometry()
        if self.turn_to is not None:
            if abs(wrap(self.turn_to - a)) > TURNED:
                drive.set_velocity(0.0, TURN_RATE)
                return Status.RUNNING
            self.turn_to, self.origin = None, (x, y)
        if self.origin is None:
            self.origin = (x, y)
        blocked = clearance_ahead(scan) < END
        if blocked and wall_across(scan):
            if math.hypot(x - self.origin[0], y - self.origin[1]) < 0.5:  # started facing the end
                self.turn_to = wrap(a + math.pi)
                drive.set_velocity(0.0, TURN_RATE)
                return Status.RUNNING
            drive.stop()
            self.ctx.log("end of the corridor")
            return Status.SUCCESS
        left, right = corridor(scan, self.expect)
        self.expect = (left.distance if left else self.expect[0], right.distance if right else self.expect[1])
        walls = [w for w in (left, right) if w is not None]
        heading = sum(w.angle for w in walls) / len(walls) if walls else 0.0  # the corridor's direction
        offset = 0.0  # how far left of the centre line the robot is
        if left and right:
            self.width = left.distance + right.distance
            offset = (right.distance - left.distance) / 2
        elif self.width and left:
            offset = self.width / 2 - left.distance
        elif self.width and right:
            offset = right.distance - self.width / 2
        omega = K_HEADING * heading - K_LATERAL * offset
        omega = max(-MAX_OMEGA, min(MAX_OMEGA, omega))
        # something narrower than the corridor in the way (a person, or a wall we are angled into): turn on the
        # spot as the walls say and wait for the way to clear
        drive.set_velocity(0.0 if blocked else speed, omega)
        return Status.RUNNING

    def suspend(self) -> None:
        self.device("drive").stop()

    def terminate(self, status: Status) -> None:
        self.device("drive").stop()
