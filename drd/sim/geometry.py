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


Box = tuple[float, float, float, float]


class GridIndex:
    """Items (by their index) filed under the grid cells their bounding boxes cover, so a question about one
    place looks at the few items near it rather than all of them: a generated building of 500 wings has 50,000
    rooms, doors and walls, and a scan of all of them per door made loading quadratic (docs/design.md).

    `near` gives every item whose box meets the query box (boxes are closed, so touching counts), and maybe a
    few more, always in index order: a caller that keeps the first match of a linear scan keeps the same one.
    An item covering more than `MAX_CELLS` cells (a wall across the whole building) is kept in a short list
    that every query returns, rather than filed under thousands of cells.
    """

    MAX_CELLS = 256

    def __init__(self, boxes: Sequence[Box], cell: float | None = None) -> None:
        self.cell = cell if cell is not None else _cell_size(boxes)
        self.count = len(boxes)
        self.cells: dict[tuple[int, int], list[int]] = {}
        self.big: list[int] = []
        for i, box in enumerate(boxes):
            cx0, cy0, cx1, cy1 = self._span(box)
            if (cx1 - cx0 + 1) * (cy1 - cy0 + 1) > self.MAX_CELLS:
                self.big.append(i)
                continue
            for cx in range(cx0, cx1 + 1):
                for cy in range(cy0, cy1 + 1):
                    self.cells.setdefault((cx, cy), []).append(i)

    def _span(self, box: Box) -> tuple[int, int, int, int]:
        c = self.cell
        return (math.floor(box[0] / c), math.floor(box[1] / c), math.floor(box[2] / c), math.floor(box[3] / c))

    def near(self, box: Box) -> list[int]:
        """The indices (ascending, no repeats) of items whose boxes may meet `box`; all of those that do."""
        try:
            cx0, cy0, cx1, cy1 = self._span(box)
        except (ValueError, OverflowError):  # not a finite box: everything is a candidate
            return sorted({i for found in self.cells.values() for i in found} | set(self.big))
        if (cx1 - cx0 + 1) * (cy1 - cy0 + 1) > len(self.cells):
            found = {i for key, items in self.cells.items() if cx0 <= key[0] <= cx1 and cy0 <= key[1] <= cy1
                     for i in items}
        else:
            found = {i for cx in range(cx0, cx1 + 1) for cy in range(cy0, cy1 + 1)
                     for i in self.cells.get((cx, cy), ())}
        found.update(self.big)
        return sorted(found)


def _cell_size(boxes: Sequence[Box]) -> float:
    """A cell about as large as a typical item (the median of the boxes' larger sides), at least 1 m: most items
    then cover a few cells and most cells hold a few items."""
    sides = sorted(max(b[2] - b[0], b[3] - b[1]) for b in boxes)
    return max(1.0, sides[len(sides) // 2]) if sides else 1.0


def segment_box(a: Point, b: Point, margin: float = 0.0) -> Box:
    """The bounding box of the segment `ab`, widened by `margin` on every side."""
    return (min(a[0], b[0]) - margin, min(a[1], b[1]) - margin, max(a[0], b[0]) + margin, max(a[1], b[1]) + margin)


class SegmentIndex:
    """Segments with a `GridIndex` of their boxes: `locate` and `clearance` give exactly what a scan of every
    segment in order gives, looking only at those near the point."""

    def __init__(self, segments: Sequence[Segment]) -> None:
        self.segments = segments
        self.grid = GridIndex([segment_box(a, b) for a, b in segments])

    def locate(self, p: Point) -> tuple[int, float] | None:
        """As `locate(p, segments)`: a segment within EPS of `p` has its box within EPS of `p`."""
        for i in self.grid.near((p[0] - EPS, p[1] - EPS, p[0] + EPS, p[1] + EPS)):
            a, b = self.segments[i]
            if point_segment_distance(p, a, b) <= EPS:
                return i, length(a, p)
        return None

    def clearance(self, p: Point, radius: float) -> float:
        """The distance from `p` to the closest segment when that is under `radius` (then exactly the scan's
        minimum: every segment closer than `radius` is near `p`), else a distance of at least `radius` (or inf)."""
        near = self.grid.near((p[0] - radius, p[1] - radius, p[0] + radius, p[1] + radius))
        return min((point_segment_distance(p, *self.segments[i]) for i in near), default=math.inf)
