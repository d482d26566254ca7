"""A wall across the way with a door in it ends the corridor (worlds audit 17, D4), from synthetic scans: the door's
way is free, so the one-surface rule does not see the end; two people abreast are not a wall (pure)."""

from __future__ import annotations

import math

from components.behaviors.scan import door_across, surface_across, wall_across
from drd.hw.interfaces import Scan

N, FAR = 181, 8.0


def cast(hit: object) -> Scan:
    """A 180-degree scan of 181 beams; `hit(angle)` is the range of each beam (FAR for none)."""
    angles = [-math.pi / 2 + i * math.pi / (N - 1) for i in range(N)]
    return Scan(tuple(min(FAR, hit(a)) for a in angles), -math.pi / 2, math.pi / (N - 1), FAR)  # type: ignore[operator]


def corridor_end(ahead: float, door: float | None, tilt: float = 0.0) -> Scan:
    """A corridor 2.5 m wide whose end wall is `ahead` m away (turned `tilt` rad), a door `door` m wide in it,
    centred, opening on a room 4 m deep."""
    def hit(a: float) -> float:
        c, s = math.cos(a - tilt), math.sin(a)
        side = 1.25 / abs(s) if s else math.inf
        if c <= 0:
            return side
        to_end = ahead / c
        y = to_end * math.sin(a - tilt)
        if door is not None and abs(y) < door / 2:
            return min(side, (ahead + 4.0) / c)  # through the door, to the room's back wall
        return min(side, to_end)
    return cast(hit)


def test_an_end_wall_with_a_door_in_it_is_the_end() -> None:
    scan = corridor_end(0.85, 1.0)
    assert not surface_across(scan) and door_across(scan) and wall_across(scan)
    assert door_across(corridor_end(0.85, 1.2, tilt=0.3))  # at an angle, a wider door
    assert wall_across(corridor_end(0.85, None)) and not door_across(corridor_end(0.85, None))  # solid: one surface
    assert not wall_across(corridor_end(2.0, 1.0))  # still 2 m away


def test_two_people_abreast_are_not_a_wall() -> None:
    people = [(0.8, -0.45), (0.8, 0.45)]

    def hit(a: float) -> float:
        best = math.inf
        for px, py in people:  # a ray against a circle of radius 0.25
            b = px * math.cos(a) + py * math.sin(a)
            d = b * b - (px * px + py * py - 0.25 ** 2)
            if d >= 0 and b - math.sqrt(d) > 0:
                best = min(best, b - math.sqrt(d))
        s = math.sin(a)
        return min(best, 1.25 / abs(s) if s else math.inf)

    scan = cast(hit)
    assert not door_across(scan) and not wall_across(scan)


def test_a_side_open_abeam_for_a_corridors_width_is_where_it_turns_a_door_is_not() -> None:
    """Worlds audit 17, D5: at an L's corner the side wall has been missing abeam since the other leg began; beside a
    door, for the door's width only (even a door next to the end wall)."""
    from components.behaviors.scan import TURN, Openings

    def side(left: float, right: float) -> Scan:
        return cast(lambda a: left if a > 1.5 else right if a < -1.5 else 3.0)

    openings = Openings()
    for x in (10.0, 10.5, 11.0, 11.5):  # a door 1 m wide on the left, then the wall again
        openings.update(side(4.0 if 10.4 < x < 11.4 else 1.25, 1.25), x, 0.0)
    assert openings.turn(11.5, 0.0) is None
    for x in (12.0, 12.5, 13.0, 13.0 + TURN):  # the left wall ends at 12: the other leg, beyond the laser's range
        openings.update(side(FAR, 1.25), x, 0.0)
    assert openings.turn(13.0 + TURN, 0.0) == 1
    openings.reset()
    assert openings.turn(13.0 + TURN, 0.0) is None
