"""The geometry of what a robot senses, in its own frame: one module for every perception behavior.

A laser `Scan` (drd.hw): beam `i` points `angle(i)` radians off the heading (right to left, increasing) and reads
`ranges[i]` metres, exactly `max_range` where it hit nothing; its hit point is `(r cos, r sin)`, x ahead, y to
the left. `Scan.beams()` gives every beam's angle, cosine and sine once per laser, so nothing here calls a
trigonometric function per beam. Offered: which beams a sector holds (`between`, `ahead`, `Beams.span`), the hit
points in one (`points`), how open it is (`openness`), the nearest reading in the robot's path
(`nearest_in_path`), the free distance ahead (`clearance_ahead`), the front reading (`front_range`), the corridor
walls (`fit_wall`, `corridor`, `expected`) and whether a wall closes the way (`wall_across`); and the bearings the
camera behaviors share (`wrap`, `region_bearings`, `circular_mean`).

Every function is pure. The costly ones (a side's points, a wall fit, the clearance) take an optional `ScanMemo`
that the calling component owns, so what several of them derive from the one scan of a control cycle is computed
once for that component; nothing is kept in this module between calls.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, TypeVar

from drd.hw.interfaces import Beams, Scan

T = TypeVar("T")

# -- bearings ------------------------------------------------------------------------------------------------------


def wrap(angle: float) -> float:
    """The same angle in [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def region_bearings(fov: float, n: int) -> list[float]:
    """Bearing (rad, left positive) of the centre of each of `n` camera brightness regions, right to left."""
    if n == 1:
        return [0.0]
    return [-fov / 2 + fov / (2 * n) + i * fov / n for i in range(n)]


def circular_mean(angles: Sequence[float]) -> float:
    """The mean direction of `angles` (rad): the bearing of the sum of their unit vectors."""
    return math.atan2(sum(math.sin(a) for a in angles), sum(math.cos(a) for a in angles))


# -- sectors of a scan ---------------------------------------------------------------------------------------------


def between(beams: Beams, lo: float, hi: float) -> tuple[int, int]:
    """The beams `i0 <= i < i1` whose angle lies strictly between `lo` and `hi` (`Beams.span` is the closed
    interval)."""
    return bisect.bisect_right(beams.angles, lo), bisect.bisect_left(beams.angles, hi)


def ahead(beams: Beams) -> tuple[int, int]:
    """The beams in front of the robot: strictly within 90 degrees of the heading."""
    return between(beams, -math.pi / 2, math.pi / 2)


def points(scan: Scan, lo: float, hi: float) -> list[tuple[float, float, float]]:
    """(angle, x, y) in the robot frame of the beams with angle in [lo, hi] that hit something."""
    b, far = scan.beams(), scan.max_range
    i0, i1 = b.span(lo, hi)
    return [(a, r * c, r * s) for a, r, c, s in zip(b.angles[i0:i1], scan.ranges[i0:i1], b.cos[i0:i1], b.sin[i0:i1],
                                                    strict=True) if r < far]


def openness(scan: Scan, lo: float, hi: float) -> float:
    """How open a sector is: the sum of the ranges of the beams strictly between `lo` and `hi` (a miss adds
    `max_range`)."""
    i0, i1 = between(scan.beams(), lo, hi)
    return sum(scan.ranges[i0:i1])


def nearest_in_path(scan: Scan, half_width: float) -> float:
    """The forward distance (m) of the nearest reading in the robot's path: the least x > 0 over every beam whose
    reading lies less than `half_width` off the axis, a miss counting at its `max_range`; inf if there is none.
    (`clearance_ahead` is the free distance: hits only, the laser's range when there is none.)"""
    b = scan.beams()
    return min([x for r, c, s in zip(scan.ranges, b.cos, b.sin, strict=True)
                if (x := r * c) > 0 and -half_width < r * s < half_width], default=math.inf)


def front_range(scan: Scan, half_angle: float) -> float:
    """The shortest reading of the beams within `half_angle` (rad) of the heading, half a beam step of margin
    included; ValueError if the scan has no such beam."""
    b, within = scan.beams(), half_angle + scan.angle_step / 2
    return min(r for a, r in zip(b.angles, scan.ranges, strict=True) if abs(a) <= within)


# -- corridor walls ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Wall:
    """A corridor wall fitted in the robot frame: perpendicular distance and angle of the wall (rad, CCW)."""

    distance: float
    angle: float
    inliers: int


class ScanMemo:
    """What the helpers derive from the latest scan a component read (a side's points, wall fits, the clearance),
    keyed by what they computed, so that asking again about the same scan costs nothing.

    One per component instance, kept by the component (never in module state, so nothing is shared between
    instances or missions). It holds one scan: a new scan (another object) starts it afresh. A scan whose ranges
    are not a tuple could change, so nothing is kept for it. Results are the same with or without a memo."""

    __slots__ = ("_data", "_scan")

    def __init__(self) -> None:
        self._scan: Scan | None = None
        self._data: dict[Any, Any] = {}

    def of(self, scan: Scan) -> dict[Any, Any] | None:
        """The derived data of `scan` (empty at first), or None for a scan that is not kept."""
        if scan is self._scan:
            return self._data
        if not isinstance(scan.ranges, tuple):
            return None
        self._scan, self._data = scan, {}
        return self._data


def _scratch(scan: Scan, memo: ScanMemo | None) -> dict[Any, Any]:
    """Where to keep what is derived from `scan`: the memo's, or a dict for this call only."""
    data = memo.of(scan) if memo is not None else None
    return {} if data is None else data


def _kept(data: dict[Any, Any], key: object, compute: Callable[[], T]) -> T:
    """`data[key]`, computed the first time it is asked for."""
    if key not in data:
        data[key] = compute()
    value: T = data[key]
    return value


#: The beams a wall fit looks at, per side: 20 to 160 degrees off the heading, left (+1) or right (-1).
SECTORS: Mapping[int, tuple[float, float]] = MappingProxyType(
    {1: (math.radians(20), math.radians(160)), -1: (math.radians(-160), math.radians(-20))})
#: A starting distance needs SUPPORT abeam distances (itself included) at most SPREAD metres above it.
SUPPORT, SPREAD = 6, 0.08


def fit_wall(scan: Scan, side: int, expect: float | None = None, memo: ScanMemo | None = None) -> Wall | None:
    """Fit the wall on one side (+1 left, -1 right) by least squares on the beams near it, robust to door gaps
    and end walls: start from a lateral distance abeam that enough beams agree on (the nearest one, or the one
    nearest `expect`, the last known distance), keep the points close to it.

    A pure function of its arguments. With a `memo`, what it derives from the scan is kept there: the points of a
    side are computed once per scan, and a fit whose first inliers are those of an earlier fit is that fit.
    """
    data = _scratch(scan, memo)
    return _kept(data, ("fit", side, expect), lambda: _fit(scan, side, expect, data))


def _side(scan: Scan, side: int) -> tuple[list[float], list[float], list[float]]:
    """The hits on one side, as x and lateral distance (parallel lists), and the supported starting distances."""
    lo, hi = SECTORS[1 if side > 0 else -1]
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


def _fit(scan: Scan, side: int, expect: float | None, data: dict[Any, Any]) -> Wall | None:
    xs, ys, support = _kept(data, ("side", side), lambda: _side(scan, side))
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
    return _kept(data, ("refine", side, first), lambda: _refine(xs, ys, first, side))


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


def corridor(scan: Scan, expect: tuple[float | None, float | None] = (None, None), jump: float = 0.4,
             memo: ScanMemo | None = None) -> tuple[Wall | None, Wall | None]:
    """The left and right walls (either may be None where no wall is seen, or where the fit is more than `jump`
    metres from the expected distance: a room seen through a doorway, not the corridor wall)."""
    out = []
    for side, exp in ((1, expect[0]), (-1, expect[1])):
        w = fit_wall(scan, side, exp, memo)
        out.append(None if w is None or (exp is not None and abs(w.distance - exp) > jump) else w)
    return out[0], out[1]


def expected(walls: tuple[Wall | None, Wall | None],
             expect: tuple[float | None, float | None]) -> tuple[float | None, float | None]:
    """The wall distances to expect in the next scan: those of the walls just fitted, else the last known."""
    left, right = walls
    return (left.distance if left else expect[0], right.distance if right else expect[1])


# -- the way ahead -------------------------------------------------------------------------------------------------

#: Free space ahead (m) below which the corridor has ended: a wall across the way.
END = 0.9
#: Half the width of the swath that must be free ahead (m): the Ranger's radius and a margin.
BODY = 0.35
#: A wall across the way spans more than WIDER metres of the lane within ACROSS metres either side of the axis.
ACROSS, WIDER = 0.9, 1.0


def clearance_ahead(scan: Scan, half_width: float = BODY, memo: ScanMemo | None = None) -> float:
    """Free distance straight ahead (m) in a swath `2 * half_width` wide: the nearest hit in front of the robot
    within that lateral distance of its axis, or the laser's range when nothing is there."""
    far = scan.max_range
    return _kept(_scratch(scan, memo), ("clearance", half_width), lambda: min(
        [r * c for r, c, s in _ahead(scan) if r < far and -half_width < r * s < half_width], default=far))


def _ahead(scan: Scan) -> zip[tuple[float, float, float]]:
    """(range, cos, sin) of the beams in front of the robot (`ahead`)."""
    b = scan.beams()
    i0, i1 = ahead(b)
    return zip(scan.ranges[i0:i1], b.cos[i0:i1], b.sin[i0:i1], strict=True)


def wall_across(scan: Scan, within: float = END, memo: ScanMemo | None = None) -> bool:
    """The corridor ends here: the way ahead is blocked within `within` metres, and by something wider than a
    person (hits ahead spanning over `WIDER` metres across, looking within `ACROSS` of the axis: inside the
    corridor's side walls), so an intruder walking by is not taken for the end."""
    if clearance_ahead(scan, memo=memo) >= within:
        return False
    far, depth = scan.max_range, within + 0.25
    across = [y for r, c, s in _ahead(scan) if r < far and 0 < r * c < depth and -ACROSS < (y := r * s) < ACROSS]
    return bool(across) and max(across) - min(across) >= WIDER
