"""FollowCorridor with something in the way (worlds audit 13, D3-D5), from the outside: the real executive, drivers and
simulator (`drd.dryrun.run_many`) on worlds written here, the ground-truth track and the report checked.

A person crossing the corridor was taken for its end (with the side wall beyond it, its hits spanned a wall's
width), and the door past it was never found; a box it cannot get past held the mission until the time limit."""

from __future__ import annotations

from typing import Any

import yaml

from drd.dryrun import DryRun, Mission, run_many
from drd.hosts import load_hosts
from drd.sim.world import parse_world
from dsl import compile_text
from dsl.catalog import Catalog
from tests.conftest import ROOT

CORRIDOR = """
name: {name}
light: {{ambient: 0.9}}
walls:
  - {{from: [0, 1.25], to: [20, 1.25]}}
  - {{from: [0, -1.25], to: [20, -1.25]}}
  - {{from: [0, -1.25], to: [0, 1.25]}}
  - {{from: [20, -1.25], to: [20, 1.25]}}
rooms:
  - {{id: r0, rect: [3, 1.25, 7, 5.25], light: 0.6}}
  - {{id: r1, rect: [12, -5.25, 16, -1.25], light: 0.6}}
doors:
  - {{id: d0, at: [5, 1.25], width: 1.0}}
  - {{id: d1, at: [14, -1.25], width: 1.0}}
rangers:
  - {{id: ranger1, at: [1, 0], heading: 0, magazine: [scout1, scout2, scout3, scout4, scout5, scout6]}}
"""
HUNT = """
mission Hunt {
    needs ranger: Ranger
    shared found: DoorLog
    start -> Seek
    Seek -> Seek
    Seek -> done on error
}
behavior Seek {
    parallel until DetectDoor {
        FollowCorridor(speed: 0.5)
        AvoidObstacles(margin: 0.3)
        DetectDoor(min_width: 0.7)
    }
}
"""


SWEEP = """
mission Sweep {
    needs ranger: Ranger
    parallel until FollowCorridor {
        FollowCorridor(speed: 0.5)
        AvoidObstacles(margin: 0.3)
    }
}
"""


def dry(catalog: Catalog, name: str, extra: dict[str, Any], until: float = 300.0, mission: str = HUNT) -> DryRun:
    data = yaml.safe_load(CORRIDOR.format(name=name))
    data.update(extra)
    r = compile_text(mission, catalog, "m.mission")
    assert r.ok and r.statechart is not None, [d.message for d in r.diagnostics]
    (report,) = run_many([Mission(r.statechart)], load_hosts(ROOT / "hosts.yaml", catalog),
                         parse_world(data, f"{name}.yaml"), catalog, until=until)
    return report


def test_a_person_crossing_is_waited_for_not_taken_for_the_end(catalog: Catalog) -> None:
    crossing = {"intruders": [{"id": "passerby", "loop": True, "path": [
        {"t": 0, "at": [9, -1.0]}, {"t": 4, "at": [9, 1.0]}, {"t": 8, "at": [9, -1.0]}]}]}
    report = dry(catalog, "crossing", crossing)
    assert report.outcome == "success", report.reason
    assert sorted(round(d["x"]) for d in report.doors) == [5, 14]  # the door past the person too
    assert max(x for _t, x, _y in report.tracks["ranger1"]) > 18.5  # to the real end (x = 20)


def test_a_box_it_cannot_get_past_fails_the_search_with_a_reason_not_the_time_limit(catalog: Catalog) -> None:
    report = dry(catalog, "box", {"obstacles": [{"rect": [8, -0.3, 8.6, 0.3], "height": 0.3}]}, until=600.0,
                 mission=SWEEP)
    # the previous code: stopped at the time limit, shuttling before the box
    assert report.outcome == "failure" and report.sim_time < 120, report.reason
    said = [line["text"] for line in report.logs()]
    assert any("no progress: got no more than 0.5 m farther in 30 s" in t for t in said), said
    assert max(x for _t, x, _y in report.tracks["ranger1"]) < 8.0 - 0.3  # it never went through the box


def test_return_to_start_behind_something_it_cannot_get_round_fails_with_a_reason(catalog: Catalog) -> None:
    """Worlds audit 13, D1: behind a box against a wall, ReturnToStart stood still to the time limit, saying nothing.
    Here a person walks out of room r0 into the middle of the corridor behind the robot, and stays there."""
    out_and_back = """
mission OutAndBack {
    needs ranger: Ranger
    start -> FollowCorridor
    FollowCorridor(speed: 0.5)
    FollowCorridor -> ReturnToStart after 12s
}
"""
    person = {"intruders": [{"id": "visitor", "path": [{"t": 0, "at": [4.0, 4.0]}, {"t": 10, "at": [4.0, 4.0]},
                                                        {"t": 14, "at": [3.0, 0.0]}]}]}
    report = dry(catalog, "visited", person, until=600.0, mission=out_and_back)
    assert report.outcome == "failure" and report.sim_time < 120, (report.outcome, report.sim_time, report.reason)
    assert "ReturnToStart: no progress: got no more than 0.5 m nearer home in 30 s" in report.reason, report.reason


def test_a_door_in_the_end_wall_is_the_corridors_end_not_a_way_on(catalog: Catalog) -> None:
    """Worlds audit 17, D4: with a door in the end wall the way ahead was free, the Ranger drove through it into the
    room, and DetectDoor said "the corridor ends here" from inside the room. The wall across with a door in it is
    the end: the Ranger stops in the corridor."""
    end_door = {"rooms": [{"id": "r0", "rect": [3, 1.25, 7, 5.25], "light": 0.6},
                          {"id": "r_end", "rect": [20, -2.5, 24, 2.5], "light": 0.6}],
                "doors": [{"id": "d0", "at": [5, 1.25], "width": 1.0}, {"id": "d_end", "at": [20, 0], "width": 1.0}]}
    report = dry(catalog, "end_door", end_door, until=120.0, mission=SWEEP)
    assert report.outcome == "success", report.reason
    assert "end of the corridor" in [line["text"] for line in report.logs()]
    assert 18.5 < max(x for _t, x, _y in report.tracks["ranger1"]) < 20 - 0.3  # to the end, never through its door


def test_an_l_shaped_corridors_corner_is_turned_and_its_second_leg_searched(catalog: Catalog) -> None:
    """Worlds audit 17, D5: the corner of an L has a wall across the way, and was taken for the corridor's end: the
    second leg (two doors) was never searched. At a wall across, a side whose wall has been missing abeam for a
    corridor's width is where the corridor goes on: FollowCorridor turns there and DetectDoor does not end."""
    ell = {"walls": [{"from": [0, -1.25], "to": [15, -1.25]}, {"from": [15, -1.25], "to": [15, 15]},
                     {"from": [0, 1.25], "to": [12.5, 1.25]}, {"from": [12.5, 1.25], "to": [12.5, 15]},
                     {"from": [0, -1.25], "to": [0, 1.25]}, {"from": [12.5, 15], "to": [15, 15]}],
           "rooms": [{"id": "south", "rect": [4, -5, 10, -1.25], "light": 0.6},
                     {"id": "west", "rect": [8, 3, 12.5, 8], "light": 0.6},
                     {"id": "east", "rect": [15, 5, 20, 10], "light": 0.6}],
           "doors": [{"id": "d_south", "at": [7, -1.25], "width": 1.0}, {"id": "d_west", "at": [12.5, 5.5], "width": 1},
                     {"id": "d_east", "at": [15, 7.5], "width": 1.0}]}
    report = dry(catalog, "ell", ell, until=400.0)
    assert report.outcome == "success", report.reason
    found = sorted((round(d["x"] * 2) / 2, round(d["y"] * 2) / 2) for d in report.doors)
    assert found == [(7.0, -1.5), (12.5, 5.5), (15.0, 7.5)], report.doors  # each door once, the second leg's too
    said = [line["text"] for line in report.logs()]
    assert "FollowCorridor: the corridor turns left here" in said, said
    assert max(y for _t, _x, y in report.tracks["ranger1"]) > 13.5  # to the second leg's end (y = 15)


def test_a_t_junctions_bar_is_searched_both_ways_and_the_search_ends(catalog: Catalog) -> None:
    """Worlds audit 19, D1: after turning into a T's bar, the Ranger left at the bar's end read the end wall 0.905 m
    away (the laser's noise), turned 88 degrees to that wall's line and took the side wall for the end; DetectDoor,
    not moved since, never ended the search, which stood until the time limit. Both arms of the bar are searched."""
    dark = [{"at": at, "radius": 1.5} for at in ([4.6, 1.85], [13.1, 6.6], [20.6, 6.6], [13.1, -10.4], [20.6, -10.4])]
    tee = {"light": {"ambient": 0.9, "dark": dark},
           "walls": [{"from": [0, -1.25], "to": [0, 1.25]}, {"from": [0, 1.25], "to": [17.5, 1.25]},
                     {"from": [0, -1.25], "to": [17.5, -1.25]}, {"from": [17.5, 1.25], "to": [17.5, 15]},
                     {"from": [17.5, -15], "to": [17.5, -1.25]}, {"from": [20, -15], "to": [20, 15]},
                     {"from": [17.5, 15], "to": [20, 15]}, {"from": [17.5, -15], "to": [20, -15]}],
           "rooms": [{"id": "a1", "rect": [4, 1.25, 9, 6.25]}, {"id": "nw", "rect": [12.5, 6, 17.5, 11]},
                     {"id": "ne", "rect": [20, 6, 25, 11]}, {"id": "sw", "rect": [12.5, -11, 17.5, -6]},
                     {"id": "se", "rect": [20, -11, 25, -6]}],
           "doors": [{"id": "d_a1", "at": [6.5, 1.25], "width": 1.0}, {"id": "d_nw", "at": [17.5, 8.5], "width": 1},
                     {"id": "d_ne", "at": [20, 9], "width": 1.0}, {"id": "d_sw", "at": [17.5, -8.5], "width": 1},
                     {"id": "d_se", "at": [20, -9], "width": 1.0}]}
    surveillance = (ROOT / "missions" / "corridor_surveillance.mission").read_text(encoding="utf-8")
    report = dry(catalog, "tee", tee, until=900.0, mission=surveillance)
    assert report.outcome == "success" and report.sim_time < 600, (report.outcome, report.sim_time, report.reason)
    found = sorted((round(d["x"]), round(d["y"])) for d in report.doors)
    assert found == [(6, 1), (17, -9), (17, 8), (20, -9), (20, 9)], report.doors


def test_a_u_corridor_is_swept_to_its_far_end_though_that_end_is_nearer_the_start(catalog: Catalog) -> None:
    """Worlds audit 19, D7: progress was the distance from where FollowCorridor started, which a U's last leg brings
    back down (from 20 m to 7.5 m here): driving freely along it, the sweep failed "no progress ... no way past what
    blocks the corridor". Progress counts from the last corner turned at."""
    walls = [((0, -1.25), (0, 1.25)), ((0, -1.25), (20, -1.25)), ((20, -1.25), (20, 8.75)), ((0, 8.75), (20, 8.75)),
             ((0, 6.25), (0, 8.75)), ((0, 1.25), (17.5, 1.25)), ((17.5, 1.25), (17.5, 6.25)), ((0, 6.25), (17.5, 6.25))]
    u = {"walls": [{"from": list(a), "to": list(b)} for a, b in walls], "rooms": [], "doors": []}
    report = dry(catalog, "ushape", u, until=200.0, mission=SWEEP)
    assert report.outcome == "success", report.reason
    said = [line["text"] for line in report.logs()]
    assert said.count("FollowCorridor: the corridor turns left here") == 2, said
    end = report.tracks["ranger1"][-1]
    assert end[1] < 2.5 and end[2] > 6.5, end  # at the far end of the last leg
