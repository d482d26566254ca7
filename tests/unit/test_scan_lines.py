"""The straight walls of a scan (`scan.segments`, `scan.dominant_direction`) and the wall fit that starts from the
longest wall (`scan.strongest_wall`), on synthetic scans cast against known segments (`test_scan_geometry.cast`).
FollowCorridor turns to the corridor's line with them when started at a steep angle (a Ranger aimed at a door)."""

from __future__ import annotations

import math

import pytest

from components.behaviors.scan import Segment, dominant_direction, fit_wall, line_gap, segments, strongest_wall
from tests.unit.test_scan_geometry import cast


def turned(walls: list[tuple[tuple[float, float], tuple[float, float]]], angle: float) -> list[
        tuple[tuple[float, float], tuple[float, float]]]:
    """`walls` as a robot turned `angle` (rad, CCW) sees them: rotated by -angle."""
    c, s = math.cos(-angle), math.sin(-angle)
    return [((c * ax - s * ay, s * ax + c * ay), (c * bx - s * by, s * bx + c * by)) for (ax, ay), (bx, by) in walls]


# a corridor 2.5 m wide along x, a door 1 m wide in its left wall at x = 0.7..1.7, a room behind it
CORRIDOR = [((-10.0, 1.25), (0.7, 1.25)), ((1.7, 1.25), (10.0, 1.25)), ((-10.0, -1.25), (10.0, -1.25)),
            ((0.7, 1.25), (0.7, 6.0)), ((1.7, 1.25), (1.7, 6.0)), ((-3.0, 6.0), (5.0, 6.0))]


def test_a_corridor_seen_straight_is_along_the_heading() -> None:
    found = segments(cast(CORRIDOR))
    assert found and all(s.length > 0 for s in found)
    assert dominant_direction(found, 0.35) == pytest.approx(0.0, abs=0.02)


@pytest.mark.parametrize("angle", [1.0, -1.0, 0.6, -1.3])
def test_aimed_at_the_door_the_corridor_is_off_by_the_turn(angle: float) -> None:
    """From the corridor's middle, aimed `angle` off it: the walls' line is `-angle` in the robot frame."""
    line = dominant_direction(segments(cast(turned(CORRIDOR, angle))), 0.35)
    assert line is not None and line_gap(line, -angle) < 0.03


def test_a_wall_faced_at_a_steep_angle_is_one_segment_not_a_fit() -> None:
    wall = [((-6.0, 1.0), (6.0, 1.0))]
    seen = cast(turned(wall, 1.1))
    found = segments(seen)
    assert len(found) == 1 and line_gap(found[0].direction, -1.1) < 0.01
    assert found[0].length > 2.5


def test_the_side_walls_outweigh_an_end_wall() -> None:
    """2 m from a corridor's end wall, facing it: the side walls, parallel, carry more length than the end."""
    end = [((-10.0, 1.25), (2.0, 1.25)), ((-10.0, -1.25), (2.0, -1.25)), ((2.0, -1.25), (2.0, 1.25))]
    assert dominant_direction(segments(cast(end)), 0.35) == pytest.approx(0.0, abs=0.02)


def test_no_hits_no_direction() -> None:
    assert segments(cast([])) == []
    assert dominant_direction([], 0.35) is None
    # the longest single segment loses to two shorter ones on one line
    assert dominant_direction([Segment(1.0, 3.0), Segment(0.1, 2.0), Segment(0.15, 1.5)], 0.35) == 0.1


def test_a_small_thing_near_by_does_not_hide_the_long_wall() -> None:
    """The nearest lateral distance is a post 0.6 m to the left; the wall behind it at 1.25 m is the long one."""
    scene = [((-10.0, 1.25), (10.0, 1.25)), ((0.3, 0.6), (0.9, 0.62))]
    nearest = fit_wall(cast(scene), 1)
    assert nearest is not None and nearest.distance == pytest.approx(0.6, abs=0.03)  # the post
    wall = strongest_wall(cast(scene), 1)
    assert wall is not None and wall.distance == pytest.approx(1.25, abs=0.03) and abs(wall.angle) < 0.02


def test_a_wall_across_is_one_surface_not_a_person_beside_a_wall() -> None:
    """Worlds audit 13, D3: a person ahead and a side wall beyond spanned WIDER together: "end of the corridor"."""
    from components.behaviors.scan import wall_across

    person_and_wall = [((0.8, -0.3), (0.8, 0.1)), ((1.0, 0.5), (1.1, 0.88))]
    assert not wall_across(cast(person_and_wall))
    assert wall_across(cast([((0.8, -1.25), (0.8, 1.25))]))  # the end: one surface across the way
    assert not wall_across(cast([((0.8, -0.25), (0.8, 0.25))]))  # a person alone
