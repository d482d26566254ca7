"""The scan geometry the perception behaviors share (`components.behaviors.scan`), on synthetic scans whose
answers are known: a laser ray-cast against a few line segments in the robot frame (x ahead, y to the left)."""

from __future__ import annotations

import math

import pytest

from components.behaviors.scan import (
    ScanMemo,
    ahead,
    between,
    circular_mean,
    clearance_ahead,
    corridor,
    expected,
    fit_wall,
    front_range,
    nearest_in_path,
    openness,
    points,
    region_bearings,
    wall_across,
    wrap,
)
from drd.hw.interfaces import Scan

Segment = tuple[tuple[float, float], tuple[float, float]]
FAR = 8.0


def cast(segments: list[Segment], beams: int = 181, fov: float = math.pi, far: float = FAR) -> Scan:
    """The scan a laser at the origin, facing +x, takes of `segments`: each beam reads its nearest crossing."""
    step = fov / (beams - 1)
    ranges = []
    for i in range(beams):
        a = -fov / 2 + i * step
        dx, dy = math.cos(a), math.sin(a)
        best = far
        for (x1, y1), (x2, y2) in segments:
            ex, ey = x2 - x1, y2 - y1
            den = dx * ey - dy * ex
            if abs(den) < 1e-12:
                continue
            t = (x1 * ey - y1 * ex) / den  # along the beam
            u = (x1 * dy - y1 * dx) / den  # along the segment
            if 0 < t < best and 0 <= u <= 1:
                best = t
        ranges.append(best)
    return Scan(tuple(ranges), -fov / 2, step, far)


def corridor_scan(left: float = 1.0, right: float = 1.5, tilt: float = 0.0) -> Scan:
    """Walls at `left` metres to the left and `right` to the right, both turned by `tilt` (rad, CCW)."""
    c, s = math.cos(tilt), math.sin(tilt)

    def wall(y: float) -> Segment:
        return ((-20 * c - y * s, -20 * s + y * c), (20 * c - y * s, 20 * s + y * c))

    return cast([wall(left), wall(-right)])


# -- bearings ------------------------------------------------------------------------------------------------------


def test_wrap_keeps_an_angle_in_minus_pi_to_pi() -> None:
    assert wrap(0.3) == pytest.approx(0.3)
    assert wrap(math.pi) == pytest.approx(-math.pi)
    assert wrap(1.5 * math.pi) == pytest.approx(-0.5 * math.pi)
    assert wrap(-2.5 * math.pi) == pytest.approx(-0.5 * math.pi)


def test_region_bearings_are_the_centres_of_equal_strips_right_to_left() -> None:
    assert region_bearings(math.pi, 1) == [0.0]
    assert region_bearings(math.pi, 4) == pytest.approx([-3 * math.pi / 8, -math.pi / 8, math.pi / 8, 3 * math.pi / 8])


def test_the_circular_mean_of_bearings_on_either_side_of_the_back_is_the_back() -> None:
    assert abs(wrap(circular_mean([math.pi - 0.1, -math.pi + 0.1]) - math.pi)) < 1e-9  # the plain mean says 0
    assert circular_mean([0.1, 0.3]) == pytest.approx(0.2)


# -- beams and sectors ---------------------------------------------------------------------------------------------


def test_beam_angles_run_right_to_left_first_middle_last() -> None:
    b = cast([]).beams()
    assert len(b.angles) == 181
    assert b.angles[0] == pytest.approx(-math.pi / 2)
    assert b.angles[90] == pytest.approx(0.0, abs=1e-12)
    assert b.angles[-1] == pytest.approx(math.pi / 2)
    assert (b.cos[90], b.sin[90]) == pytest.approx((1.0, 0.0))
    assert b.sin[0] == pytest.approx(-1.0) and b.sin[-1] == pytest.approx(1.0)


def test_between_leaves_out_the_ends_that_span_keeps() -> None:
    b = Scan((1.0,) * 5, -1.0, 0.5, FAR).beams()  # angles -1, -0.5, 0, 0.5, 1
    assert between(b, -0.5, 0.5) == (2, 3)
    assert b.span(-0.5, 0.5) == (1, 4)
    assert between(b, -0.6, 0.6) == (1, 4)
    assert between(b, 2.0, 3.0) == (5, 5)  # no beam there: an empty range


def test_ahead_is_strictly_within_ninety_degrees() -> None:
    b = cast([]).beams()
    assert ahead(b) == (1, 180)  # the beams at exactly -90 and +90 degrees are abeam, not ahead
    wide = cast([], beams=361, fov=2 * math.pi).beams()
    i0, i1 = ahead(wide)
    assert all(abs(a) < math.pi / 2 for a in wide.angles[i0:i1])
    assert abs(wide.angles[i0 - 1]) >= math.pi / 2 - 1e-9 and abs(wide.angles[i1]) >= math.pi / 2 - 1e-9


def test_points_are_the_hits_of_a_closed_sector_in_the_robot_frame() -> None:
    scan = cast([((2.0, -5.0), (2.0, 5.0))])  # a wall across, 2 m ahead
    pts = points(scan, -0.1, 0.1)
    assert pts and all(x == pytest.approx(2.0) for _, x, _ in pts)
    middle = [p for p in pts if abs(p[0]) < 1e-9]
    assert middle == [pytest.approx((0.0, 2.0, 0.0))]
    assert points(scan, math.radians(80), math.radians(90)) == []  # those beams miss the wall: no hit, no point


def test_openness_sums_the_ranges_of_a_sector_misses_at_max_range() -> None:
    scan = Scan((1.0, 2.0, 3.0, 4.0, 5.0), -1.0, 0.5, 5.0)
    assert openness(scan, -0.6, 0.6) == pytest.approx(2.0 + 3.0 + 4.0)
    assert openness(scan, 0.0, 1.0) == pytest.approx(4.0)  # open: the beams at 0 and 1 are out
    assert openness(scan, 2.0, 3.0) == 0.0


# -- the way ahead -------------------------------------------------------------------------------------------------


def test_nearest_in_path_takes_the_nearest_reading_inside_the_swath() -> None:
    post = [((1.5, -0.1), (1.5, 0.1))]  # 1.5 m ahead, 0.2 m wide
    assert nearest_in_path(cast(post), 0.3) == pytest.approx(1.5)
    beside = [((1.0, 0.5), (1.0, 0.7))]  # nearer, but 0.5 m off the axis
    assert nearest_in_path(cast(post + beside), 0.3) == pytest.approx(1.5)
    assert nearest_in_path(cast(post + beside), 0.8) == pytest.approx(1.0)


def test_nearest_in_path_counts_a_miss_at_max_range_and_is_inf_with_no_reading_ahead() -> None:
    # every beam misses: the ones within 0.3 m of the axis at 8 m are those within 2 degrees, the nearest x is theirs
    assert nearest_in_path(cast([]), 0.3) == pytest.approx(FAR * math.cos(math.radians(2)))
    all_round = cast([((-1.0, -0.1), (-1.0, 0.1))], beams=361, fov=2 * math.pi)  # a post 1 m behind the robot
    assert nearest_in_path(all_round, 0.3) == pytest.approx(FAR * math.cos(math.radians(2)))  # not in its path
    behind = Scan((1.0, 1.0), math.pi - 0.1, 0.2, FAR)  # only beams pointing backwards
    assert nearest_in_path(behind, 0.3) == math.inf


def test_clearance_ahead_is_the_nearest_hit_in_the_swath_or_the_laser_range() -> None:
    assert clearance_ahead(cast([])) == FAR
    assert clearance_ahead(cast([((3.0, -0.2), (3.0, 0.2))])) == pytest.approx(3.0)
    assert clearance_ahead(cast([((1.0, 0.5), (1.0, 0.7))])) == FAR  # off the default 0.35 m half-width
    assert clearance_ahead(cast([((1.0, 0.5), (1.0, 0.7))]), half_width=0.6) == pytest.approx(1.0)


def test_front_range_reads_the_beams_about_the_heading() -> None:
    scan = Scan((9.0, 4.0, 5.0, 3.0, 9.0), -0.2, 0.1, 10.0)  # angles -0.2 .. 0.2
    assert front_range(scan, 0.0) == 5.0  # the centre beam alone (half a step of margin: 0.05)
    assert front_range(scan, 0.06) == 3.0  # and its neighbours
    with pytest.raises(ValueError):
        front_range(Scan((1.0, 1.0), 1.0, 0.1, 10.0), 0.03)  # no beam near the heading


def test_wall_across_tells_an_end_wall_from_a_person() -> None:
    assert wall_across(cast([((0.6, -1.0), (0.6, 1.0))]))  # a wall across, 0.6 m ahead
    assert not wall_across(cast([((0.6, -0.2), (0.6, 0.2))]))  # something narrow: a person
    assert not wall_across(cast([((2.0, -1.0), (2.0, 1.0))]))  # a wall, but farther than END
    assert not wall_across(cast([]))


# -- corridor walls ------------------------------------------------------------------------------------------------


def test_fit_wall_finds_each_side_distance_and_angle() -> None:
    scan = corridor_scan(1.0, 1.5)
    left, right = fit_wall(scan, 1), fit_wall(scan, -1)
    assert left is not None and right is not None
    assert (left.distance, left.angle) == pytest.approx((1.0, 0.0), abs=1e-6)
    assert (right.distance, right.angle) == pytest.approx((1.5, 0.0), abs=1e-6)
    assert left.inliers > 20


def test_fit_wall_measures_a_turned_corridor() -> None:
    left, right = corridor(corridor_scan(1.0, 1.2, tilt=0.1))
    assert left is not None and right is not None
    assert left.angle == pytest.approx(0.1, abs=1e-6) and right.angle == pytest.approx(0.1, abs=1e-6)
    assert left.distance == pytest.approx(1.0, abs=1e-6) and right.distance == pytest.approx(1.2, abs=1e-6)


def test_no_wall_without_enough_hits() -> None:
    assert fit_wall(cast([]), 1) is None
    assert corridor(cast([])) == (None, None)


def test_corridor_drops_a_wall_far_from_the_expected_distance_and_expected_keeps_the_last() -> None:
    scan = corridor_scan(1.0, 1.5)
    left, right = walls = corridor(scan, (2.0, 1.45))
    assert left is None, "1.0 m is more than the jump from 2.0 m: a room seen through a door, not the wall"
    assert right is not None and right.distance == pytest.approx(1.5, abs=1e-6)
    assert expected(walls, (2.0, 1.45)) == pytest.approx((2.0, 1.5))
    assert expected((None, None), (None, 0.8)) == (None, 0.8)


# -- the memo a component keeps ------------------------------------------------------------------------------------


def test_a_memo_changes_no_result() -> None:
    scan, memo = corridor_scan(1.0, 1.5, tilt=0.05), ScanMemo()
    for _ in range(2):  # the second time from the memo
        assert fit_wall(scan, 1, 0.9, memo) == fit_wall(scan, 1, 0.9)
        assert corridor(scan, (1.0, None), memo=memo) == corridor(scan, (1.0, None))
        assert clearance_ahead(scan, 0.5, memo) == clearance_ahead(scan, 0.5)
        assert wall_across(scan, memo=memo) == wall_across(scan)
    data = memo.of(scan)
    assert data and ("fit", 1, 0.9) in data and ("clearance", 0.5) in data, "the memo is filled and read"


def test_a_memo_holds_the_latest_scan_only_and_belongs_to_one_owner() -> None:
    first, second, memo = corridor_scan(), corridor_scan(), ScanMemo()
    fit_wall(first, 1, memo=memo)
    kept = memo.of(first)
    assert kept and memo.of(first) is kept
    assert memo.of(second) == {}, "an equal but other scan starts afresh"
    assert memo.of(first) == {}, "the first scan's data went with it"
    assert ScanMemo().of(first) == {}, "another component's memo shares nothing"
    changing = Scan([1.0, 2.0], 0.0, 0.1, FAR)  # type: ignore[arg-type]  # ranges that could change
    assert memo.of(changing) is None
    assert clearance_ahead(changing, memo=memo) == 1.0 and memo.of(changing) is None  # computed, not kept
