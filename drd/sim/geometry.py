"""Plane geometry for building worlds: merging wall segments and cutting door gaps in them.

World files may describe the same wall twice (a room's side and the corridor's side are one
wall), and authors should not have to split a long corridor wall by hand around every door.
So walls are merged into maximal segments and doors cut gaps in them here, once, when a world
is loaded: the simulator and the renderer then see each wall exactly once, which also keeps the
radio model's wall count honest.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

Point = tuple[float, float]
Segment = tuple[Point, Point]

#: Distance under which two points count as equal: well below any sensor noise, well above float error.
EPS = 1e-6


def length(a: Point, b: Point) -> float:
    return math.hypot(b[0] - a[0], b[1] - a[1])


def point_segment_distance(p: Point, a: Point, b: Point) -> float:
    """Distance from `p` to the closest point of the segment `ab`."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    den = dx * dx + dy * dy
    t = 0.0 if den == 0 else max(0.0, min(1.0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / den))
    return math.hypot(p[0] - a[0] - t * dx, p[1] - a[1] - t * dy)


def rect_sides(x0: float, y0: float, x1: float, y1: float) -> list[Segment]:
    """The four sides of an axis-aligned rectangle, counter-clockwise from the bottom."""
    return [((x0, y0), (x1, y0)), ((x1, y0), (x1, y1)), ((x1, y1), (x0, y1)), ((x0, y1), (x0, y0))]


def merge(segments: Iterable[Segment]) -> list[Segment]:
    """Maximal segments covering the same points: axis-aligned ones are merged when they overlap or touch.

    Oblique segments are only de-duplicated. The result is sorted (horizontal by y then x, then vertical
    by x then y, then oblique in first-seen order), so a world always builds the same space.
    """
    lines: dict[tuple[str, float], list[tuple[float, float]]] = {}
    oblique: dict[Segment, None] = {}
    for a, b in segments:
        if length(a, b) <= EPS:
            continue
        if abs(a[1] - b[1]) <= EPS:
            lines.setdefault(("h", a[1]), []).append((min(a[0], b[0]), max(a[0], b[0])))
        elif abs(a[0] - b[0]) <= EPS:
            lines.setdefault(("v", a[0]), []).append((min(a[1], b[1]), max(a[1], b[1])))
        else:
            oblique.setdefault(min((a, b), (b, a)))
    out: list[Segment] = []
    for (axis, at), spans in sorted(lines.items()):
        for lo, hi in _union(spans):
            out.append(((lo, at), (hi, at)) if axis == "h" else ((at, lo), (at, hi)))
    return out + list(oblique)


def _union(spans: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    merged: list[tuple[float, float]] = []
    for lo, hi in sorted(spans):
        if merged and lo <= merged[-1][1] + EPS:
            merged[-1] = (merged[-1][0], max(merged[-1][1], hi))
        else:
            merged.append((lo, hi))
    return merged


def locate(p: Point, segments: Sequence[Segment]) -> tuple[int, float] | None:
    """The index of the segment `p` lies on and `p`'s distance from its first end, or None."""
    for i, (a, b) in enumerate(segments):
        if point_segment_distance(p, a, b) <= EPS:
            return i, length(a, p)
    return None


def along(a: Point, b: Point, s: float) -> Point:
    """The point at distance `s` from `a` towards `b`."""
    d = length(a, b)
    return (a[0] + (b[0] - a[0]) * s / d, a[1] + (b[1] - a[1]) * s / d)


def cut(segment: Segment, gaps: Iterable[tuple[float, float]]) -> list[Segment]:
    """What is left of `segment` once the gaps (distances from its first end) are taken out."""
    a, b = segment
    pieces: list[Segment] = []
    start = 0.0
    for lo, hi in sorted(gaps):
        if lo - start > EPS:
            pieces.append((along(a, b, start), along(a, b, lo)))
        start = max(start, hi)
    end = length(a, b)
    if end - start > EPS:
        pieces.append((along(a, b, start), b) if start > 0 else (a, b))
    return pieces
