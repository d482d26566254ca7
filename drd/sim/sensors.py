"""What the simulated sensors measure, from geometry alone: ray casts in the pymunk space, plus seeded noise.

Kept apart from the physics so the rule "a sensor reports only what it could see" lives in one
short file: every reading here is a ray cast from the robot (range, line of sight, the surface a
camera region looks at) or a distance, never a lookup of where things really are beyond that.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import pymunk

from drd.sim.geometry import Point
from drd.sim.model import World

# Collision categories: which shapes a query or a contact considers.
WALL, DOOR, OBSTACLE, RANGER, SCOUT, INTRUDER = 1, 2, 4, 8, 16, 32
#: What blocks sight, radio and flight: walls and closed doors (obstacles are low, people are not opaque walls).
TALL = WALL | DOOR
EVERYTHING = 0xFFFFFFFF
#: What line of sight and radio look for: walls and closed doors.
SIGHT = pymunk.ShapeFilter(mask=TALL)
#: What a camera's image shows: walls, closed doors and obstacles.
_SEEN = pymunk.ShapeFilter(mask=TALL | OBSTACLE)
_TAU = 2 * math.pi
#: `RayCaster.crossings`: how far past a hit (m) the next query starts, and how many hits it walks at most.
_PAST, _MAX_CROSSINGS = 1e-6, 64


@dataclass(frozen=True, slots=True)
class Noise:
    """Standard deviations of the Gaussian noise added to readings and actions (all seeded).

    The defaults are those of a cheap lidar, camera and wheel encoders; `NOISELESS` is for
    looking at geometry alone.
    """

    range: float = 0.01
    """Range beams, metres."""
    bearing: float = 0.005
    """Camera detections' bearing, radians."""
    distance: float = 0.03
    """Camera detections' distance, as a fraction of the distance."""
    light: float = 0.02
    """Measured light level (0..1)."""
    odometry: float = 0.01
    """Wheel odometry, as a fraction of the distance travelled (and of the angle turned)."""
    launch_heading: float = 0.01
    """Launch direction, radians."""
    launch_distance: float = 0.02
    """Launch distance, as a fraction of the distance."""


NOISELESS = Noise(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class Detection:
    """An intruder in a camera's view: where it appears relative to the camera, and how bright it is there.

    `label` is the track label a person detector would give (the intruder's id); `bearing` is in
    radians relative to the camera's heading, positive to the left (counter-clockwise).
    """

    label: str
    bearing: float
    distance: float
    light: float


def beam_angles(heading: float, n: int, fov: float) -> list[float]:
    """`n` beams spread evenly over `fov`, from right (heading - fov/2) to left, as a laser scan is ordered."""
    if n == 1:
        return [heading]
    step = fov / (n - 1)
    return [heading - fov / 2 + i * step for i in range(n)]


class RayCaster:
    """The fraction along a segment at which it first hits a shape: pymunk's `segment_query_first`, lean.

    A scan is ~181 casts, ten times a second, per Ranger, and pymunk's wrapper (a SegmentQueryInfo
    and two Vec2d per cast) costs three times the query itself. So when pymunk's cffi layer is
    there, chipmunk's own function is called directly with one reused result buffer: the same
    query, the same numbers (tests/unit/test_sim_physics.py checks both paths agree); else the public API.
    `fan` casts a whole scan in one loop (the filter converted to C once), and `crossings` counts the
    walls on a line by walking its first hits instead of building pymunk's list of every hit.
    """

    def __init__(self, space: pymunk.Space, fast: bool = True) -> None:
        self.space = space
        self._query: Any = None
        self._filters: dict[pymunk.ShapeFilter, tuple[Any, Any]] = {}
        if fast:
            try:
                from pymunk._chipmunk_cffi import ffi, lib

                self._query, self._handle = lib.cpSpaceSegmentQueryFirst, space._space
                self._info, self._null, self._ffi = ffi.new("cpSegmentQueryInfo *"), ffi.NULL, ffi
                self._ends = ffi.new("cpVect[2]")  # `fan`'s ray, reused (the array owns the memory of both views)
                self._start, self._end = self._ends[0], self._ends[1]
            except (ImportError, AttributeError):  # another pymunk layout: the public API gives the same answers
                self._query = None

    def first(self, a: Point, b: Point, radius: float, flt: pymunk.ShapeFilter) -> float | None:
        """The fraction (0..1) of `ab` at which the first matching shape is hit, or None."""
        if self._query is None:
            info = self.space.segment_query_first(a, b, radius, flt)
            return None if info is None else info.alpha
        if self._query(self._handle, a, b, radius, flt, self._info) == self._null:
            return None
        alpha: float = self._info.alpha
        return alpha

    def fan(self, origin: Point, angles: list[float], length: float, flt: pymunk.ShapeFilter) -> list[float | None]:
        """`first` along rays of `length` from `origin` at each of `angles` (absolute, radians): one call per
        scan, so the per-ray work is a tight loop (the filter is converted to C once, not per ray)."""
        ox, oy = origin
        cos, sin = math.cos, math.sin
        if self._query is None:
            first = self.first
            return [first(origin, (ox + length * cos(a), oy + length * sin(a)), 0.0, flt) for a in angles]
        query, handle, info = self._query, self._handle, self._info
        cflt = self._filter(flt)
        start, end = self._start, self._end  # C structs filled in place: cheaper than a tuple converted per call
        start.x, start.y = ox, oy
        out: list[float | None] = []
        append = out.append
        for a in angles:
            end.x = ox + length * cos(a)
            end.y = oy + length * sin(a)
            if query(handle, start, end, 0.0, cflt, info):
                append(info.alpha)
            else:  # a NULL shape pointer is false: nothing hit
                append(None)
        return out

    def crossings(self, a: Point, b: Point, flt: pymunk.ShapeFilter) -> int:
        """`walls_between` for any filter: how many distinct points (to the centimetre) of `ab` lie on a matching
        shape. Walked as first hits, each a lean query, rather than pymunk's list of every hit (Python objects
        and a callback per hit): past each hit by a micrometre, until nothing is hit."""
        (ax, ay), (bx, by) = a, b
        length = math.hypot(bx - ax, by - ay)
        if self._query is None or length == 0:
            return _distinct_hits(self.space, a, b, flt)
        ux, uy = (bx - ax) / length, (by - ay) / length
        query, handle, info, cflt = self._query, self._handle, self._info, self._filter(flt)
        seen: set[tuple[float, float]] = set()
        start, t = a, 0.0
        for _ in range(_MAX_CROSSINGS):
            if not query(handle, start, b, 0.0, cflt, info):
                return len(seen)
            t += info.alpha * (length - t)
            seen.add((round(ax + t * ux, 2), round(ay + t * uy, 2)))
            t += _PAST
            if t >= length:
                return len(seen)
            start = (ax + t * ux, ay + t * uy)
        return _distinct_hits(self.space, a, b, flt)  # a wall along `ab` itself: let pymunk list the hits

    def _filter(self, flt: pymunk.ShapeFilter) -> Any:
        """`flt` as a C struct, made once per distinct filter (cffi would convert the tuple on every call)."""
        c = self._filters.get(flt)
        if c is None:
            owner = self._ffi.new("cpShapeFilter *", tuple(flt))
            c = self._filters[flt] = (owner, owner[0])  # the struct view does not keep its memory alive
        return c[1]


def scan(rays: RayCaster, origin: Point, heading: float, n: int, max_range: float, fov: float,
         group: int, rng: random.Random, sigma: float, still: RayCaster | None = None,
         near: Sequence[tuple[float, float, float, float]] = ()) -> list[float]:
    """Distances along `n` beams to the first shape of any kind; `max_range` exactly when nothing is hit.

    With `still` (the same static shapes, alone) and `near` (the bounding boxes of every other shape a beam
    could meet), a beam that passes no box is cast in `still`: the same walls give the same distance."""
    angles = beam_angles(heading, n, fov)
    flt = pymunk.ShapeFilter(group=group)
    shadows = _shadows(origin, near) if still is not None else None
    if still is None or shadows is None:
        alphas = rays.fan(origin, angles, max_range, flt)
    else:
        alphas = still.fan(origin, angles, max_range, flt)
        # A beam is cast again, among the moving shapes too, only if it points at one's box and meets no wall
        # before reaching it: a box farther than the wall cannot change the first hit.
        shaded = [i for i, near_by in _shaded(angles, shadows)
                  if (alpha := alphas[i]) is None or alpha * max_range >= near_by - 1e-6]
        if shaded:
            for i, alpha in zip(shaded, rays.fan(origin, [angles[i] for i in shaded], max_range, flt), strict=True):
                alphas[i] = alpha
    if not sigma:
        return [max_range if a is None else min(a * max_range, max_range) for a in alphas]
    noise = iter(gaussians(rng, len(alphas) - alphas.count(None), sigma)).__next__  # one sample per hit, in order
    return [max_range if a is None else 0.0 if (d := a * max_range + noise()) < 0.0 else max_range if d > max_range
            else d for a in alphas]


def _shadows(origin: Point, boxes: Sequence[tuple[float, float, float, float]],
             pad: float = 1e-4) -> list[tuple[float, float, float]] | None:
    """The directions (centre, half width, radians) in which a ray from `origin` may pass through one of the
    boxes (left, bottom, right, top), widened by `pad`, with the box's distance from `origin`; None when
    `origin` is in (or next to) one of them."""
    ox, oy = origin
    out = []
    for left, bottom, right, top in boxes:
        left, bottom, right, top = left - 1e-6, bottom - 1e-6, right + 1e-6, top + 1e-6
        if left <= ox <= right and bottom <= oy <= top:
            return None
        centre = math.atan2((bottom + top) / 2 - oy, (left + right) / 2 - ox)
        spread = [wrap(math.atan2(y - oy, x - ox) - centre) for x in (left, right) for y in (bottom, top)]
        low, high = min(spread), max(spread)
        distance = math.hypot(max(left - ox, 0.0, ox - right), max(bottom - oy, 0.0, oy - top))
        out.append((centre + (low + high) / 2, (high - low) / 2 + pad, distance))
    return out


def _shaded(angles: list[float], shadows: list[tuple[float, float, float]]) -> list[tuple[int, float]]:
    """The indexes of the evenly spaced `angles` within a shadow (centre, half width, distance), in order, and
    a beam either side of each (a superset, computed per shadow rather than per beam and shadow), each with the
    distance of the nearest shadow it is in."""
    n = len(angles)
    if not shadows or n == 0:
        return []
    if n == 1:
        near = [d for mid, half, d in shadows if abs(wrap(angles[0] - mid)) <= half]
        return [(0, min(near))] if near else []
    start, step = angles[0], (angles[-1] - angles[0]) / (n - 1)
    if step <= 0:
        return [(i, min(d for _, _, d in shadows)) for i in range(n)]
    picked: dict[int, float] = {}
    for mid, half, distance in shadows:
        offset = (mid - start) % _TAU
        for centre in (offset - _TAU, offset, offset + _TAU):
            low, high = math.floor((centre - half) / step) - 1, math.ceil((centre + half) / step) + 1
            for i in range(max(low, 0), min(high, n - 1) + 1):
                if distance < picked.get(i, math.inf):
                    picked[i] = distance
    return sorted(picked.items())


def gaussians(rng: random.Random, n: int, sigma: float) -> list[float]:
    """`n` independent samples of N(0, sigma^2) from `rng`: Box-Muller on pairs of uniforms, two samples per
    pair, so one scan's noise costs a loop of `rng.random()` instead of a `rng.gauss()` call per beam."""
    out: list[float] = []
    uniform, log, sqrt, cos, sin = rng.random, math.log, math.sqrt, math.cos, math.sin
    for _ in range((n + 1) // 2):
        r = sigma * sqrt(-2.0 * log(1.0 - uniform()))  # 1 - u is in (0, 1]: log never sees 0
        t = _TAU * uniform()
        out.append(r * cos(t))
        out.append(r * sin(t))
    if len(out) > n:
        out.pop()
    return out


def clear(rays: RayCaster, a: Point, b: Point) -> bool:
    """True when no wall or closed door lies between `a` and `b` (line of sight)."""
    return rays.first(a, b, 0.0, SIGHT) is None


def detect(rays: RayCaster, world: World, origin: Point, heading: float, fov: float, max_range: float,
           min_light: float, targets: dict[str, Point], rng: random.Random | Callable[[], random.Random],
           noise: Noise) -> list[Detection]:
    """The targets in the field of view, in range, in line of sight and lit at least `min_light`, in label order.

    `rng` may be given as a function that returns the reading's generator: it is then asked for only when a
    target is seen (seeding one costs more than the rest of a reading that sees nobody), and draws the same."""
    out = []
    for label, (x, y) in targets.items():
        dx, dy = x - origin[0], y - origin[1]
        if dx > max_range or -dx > max_range or dy > max_range or -dy > max_range:
            continue  # farther than max_range on one axis alone, so d > max_range below: the same answer, cheaper
        d = math.hypot(dx, dy)
        bearing = wrap(math.atan2(dy, dx) - heading)
        if d > max_range or abs(bearing) > fov / 2:
            continue
        lit = world.light(x, y)
        if lit < min_light or not clear(rays, origin, (x, y)):
            continue
        if not isinstance(rng, random.Random):
            rng = rng()
        out.append(Detection(label, bearing + rng.gauss(0.0, noise.bearing),
                             max(0.0, d * (1 + rng.gauss(0.0, noise.distance))),
                             _unit(lit + rng.gauss(0.0, noise.light))))
    return out


def brightness(rays: RayCaster, world: World, origin: Point, heading: float, fov: float, n: int,
               max_range: float, rng: random.Random, sigma: float) -> list[float]:
    """Mean light of `n` image regions, right to left: the light on the surface each region's centre looks at.

    A camera sees lit surfaces, so this samples the light map where the central ray of each region
    meets a wall, door or obstacle (or at `max_range`), which is how a dark corner shows up in an image.
    """
    angles = beam_angles(heading, n, fov - fov / n if n > 1 else 0.0)
    alphas = rays.fan(origin, angles, max_range, _SEEN)
    out = []
    for a, alpha in zip(angles, alphas, strict=True):
        dx, dy = max_range * math.cos(a), max_range * math.sin(a)
        k = 1.0 if alpha is None else alpha
        lit = world.light(origin[0] + k * dx, origin[1] + k * dy)
        out.append(_unit(lit + (rng.gauss(0.0, sigma) if sigma else 0.0)))
    return out


def walls_between(space: pymunk.Space, a: Point, b: Point) -> int:
    """How many walls or closed doors the straight line from `a` to `b` crosses (a corner counts once).

    `RayCaster.crossings(a, b, TALL filter)` gives the same count faster (the simulator's radio uses it)."""
    return _distinct_hits(space, a, b, SIGHT)


def _distinct_hits(space: pymunk.Space, a: Point, b: Point, flt: pymunk.ShapeFilter) -> int:
    hits = space.segment_query(a, b, 0.0, flt)
    return len({(round(h.point.x, 2), round(h.point.y, 2)) for h in hits})


def wrap(angle: float) -> float:
    """The same angle in [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _unit(value: float) -> float:
    return min(max(value, 0.0), 1.0)
