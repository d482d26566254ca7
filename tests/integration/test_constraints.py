"""Constraints on held resources (issue #11, the paper's goals d-e): monitored every cycle, enforced at the gate.

Dry-runs of the corridor world: the Ranger starts at (1, 0) facing east down the corridor, and FollowCorridor
drives it east. Positions are checked on the simulated robot itself (ground truth), the refusals in the trace.
"""

from __future__ import annotations

import io
import json
import math
import re
from typing import Any

import pytest

from drd.dryrun import DryRun, Mission, run_many
from drd.hosts import load_hosts
from drd.sim.world import load_world
from drd.tracecheck import check
from dsl import compile_text
from dsl.catalog import Catalog
from tests.conftest import ROOT


def dry(catalog: Catalog, text: str, until: float = 60.0) -> tuple[DryRun, list[dict[str, Any]]]:
    r = compile_text(text, catalog, "c.mission")
    assert r.ok and r.statechart is not None, [d.message for d in r.diagnostics]
    trace = io.StringIO()
    (report,) = run_many([Mission(r.statechart)], load_hosts(ROOT / "hosts.yaml", catalog),
                         load_world(ROOT / "worlds" / "corridor.yaml"), catalog, until=until, trace=trace)
    records = [json.loads(line, parse_constant=_no_constant) for line in trace.getvalue().splitlines()]
    assert check(records, {"ranger1.radio"}).ok
    return report, records


def _no_constant(name: str) -> Any:
    raise AssertionError(f"{name} in a trace line: not JSON")


def final_x(report: DryRun, robot: str = "ranger1") -> float:
    return report.tracks[robot][-1][1]


FENCED = """
mission Fenced {
    needs ranger: Ranger
    constraint fence: distance(ranger, point(1, 0)) <= 6
    FollowCorridor(speed: 0.5)
}
"""


def test_a_robot_driving_out_of_its_geofence_is_stopped_at_the_boundary_and_the_holder_fails(
        catalog: Catalog) -> None:
    report, records = dry(catalog, FENCED, until=40.0)
    assert report.outcome == "failure"
    assert "constraint fence violated" in report.reason and "distance(ranger, point(1, 0)) <= 6" in report.reason
    x = final_x(report)
    assert 6.4 < x <= 7.0 + 0.05, x  # stopped at the fence (7 m), not before it and not past it
    violation = [r for r in records if r["kind"] == "event" and r["name"] == "violation"]
    assert violation and violation[0]["fields"]["name"] == "fence" and violation[0]["path"] == "Fenced"
    refused = [r for r in records if r["kind"] == "command" and not r["accepted"]]
    assert refused and "constraint fence" in refused[0]["reason"]


def test_the_halt_a_refusal_causes_comes_after_the_refused_command(catalog: Catalog) -> None:
    """Records audit 18, #4: docs/trace.md's causal order. The `halted` a constraint's refusal causes (same reason)
    was written before the refused `command`."""
    _report, records = dry(catalog, FENCED, until=40.0)
    lines = [(i, r) for i, r in enumerate(records) if r["kind"] in ("command", "halted") and "constraint fence" in
             r.get("reason", "")]
    halts = [(i, r) for i, r in lines if r["kind"] == "halted"]
    assert halts
    for i, halt in halts:
        cause = [j for j, r in lines if r["kind"] == "command" and r["reason"] == halt["reason"]
                 and r["at"] == halt["at"] and r["device"] == halt["device"]]
        assert cause and cause[0] < i, (i, halt, cause)


HANDLED = """
mission Patrol {
    needs ranger: Ranger
    constraint fence: distance(ranger, point(1, 0)) <= 6
    start -> Out
    FollowCorridor(speed: 0.5) as Out
    Out -> Home on violation [event.name == "fence"]
    ReturnToStart(speed: 0.4) as Home
}
"""


def test_a_violation_handler_takes_over_and_drives_back_inside(catalog: Catalog) -> None:
    report, records = dry(catalog, HANDLED, until=120.0)
    assert report.outcome == "success", report.reason
    taken = [r for r in records if r["kind"] == "taken" and r["trigger"] == "event"]
    assert [(r["path"], r["target"]) for r in taken] == [("Patrol/Out", "Patrol/Home")]
    xs = [x for _t, x, _y in report.tracks["ranger1"]]
    assert max(xs) <= 7.05 and math.hypot(final_x(report) - 1.0, report.tracks["ranger1"][-1][2]) < 1.0
    home = [r for r in records if r["kind"] == "command" and r["path"] == "Patrol/Home"]
    assert home and all(r["accepted"] for r in home)  # driving back in breaks nothing


ROOMS = """
mission Indoors {
    needs ranger: Ranger
    constraint stay: inside(ranger, "n1", "s1") or ranger.x < 4
    FollowCorridor(speed: 0.5)
}
"""


def test_a_region_constraint_stops_the_robot_where_it_would_leave(catalog: Catalog) -> None:
    report, _ = dry(catalog, ROOMS, until=40.0)
    assert report.outcome == "failure" and "constraint stay violated" in report.reason
    assert 3.4 < final_x(report) <= 4.05


def test_a_broken_inside_says_how_far_outside_not_a_signed_number(catalog: Catalog) -> None:
    """Users audit 12, D7: `inside(...)` broke "(-3.64 against 0)", a number for a yes/no condition."""
    report, _ = dry(catalog, "mission Room {\n    needs ranger: Ranger\n    constraint stay: inside(ranger, \"n1\")\n"
                             "    FollowCorridor(speed: 0.5)\n}\n", until=10.0)
    assert report.outcome == "failure", report.reason
    assert re.fullmatch(r'constraint stay violated: inside\(ranger, "n1"\) \(\d+\.\d\d m outside\)', report.reason)
    # joined with `and`, the part that decided says it (reverify audit 14, D4: "(-1.6 against 0)")
    report, _ = dry(catalog, "mission Room {\n    needs ranger: Ranger\n    constraint stay: inside(ranger, \"n1\") and"
                             " ranger.x < 30\n    FollowCorridor(speed: 0.5)\n}\n", until=10.0)
    assert report.reason.endswith(" m outside)") and "against" not in report.reason, report.reason


def test_a_battery_floor_can_be_read_and_checked(catalog: Catalog) -> None:
    text = FENCED.replace("distance(ranger, point(1, 0)) <= 6", "ranger.battery >= 2")
    report, records = dry(catalog, text, until=10.0)
    assert report.outcome == "failure" and "constraint fence violated: ranger.battery >= 2" in report.reason
    assert final_x(report) < 1.2  # it never drove: the floor was broken from the start
    # not even one step's worth: broken at entry, the behavior is violated before its first step (ROS 2 audit 22,
    # #2: the robot got one driving Twist, then the stop); its only command is the stop of its terminate
    assert [(r["method"], r["accepted"]) for r in records if r["kind"] == "command"] == [("stop", True)], records
    assert [r["at"] for r in records if r["kind"] == "exited"] == [0.0, 0.0]


def test_a_constraint_that_cannot_be_measured_for_two_seconds_counts_as_broken(catalog: Catalog) -> None:
    """ROS 2 audit 17, D1: a stale or NaN battery made `ranger.battery >= 0.5` impossible to measure; it was logged
    once and guarded nothing, and the robot drove on. Not measurable for `UNMEASURED` seconds, a constraint breaks:
    the robot stops and the behavior gets `violation` (here it fails, naming why)."""
    from drd.runtime.constraints import UNMEASURED

    text = FENCED.replace("    constraint fence: distance(ranger, point(1, 0)) <= 6",
                          '    var room: str = "nowhere"\n    constraint fence: inside(ranger, room)')
    report, records = dry(catalog, text, until=20.0)
    assert report.outcome == "failure", report.reason
    assert report.reason == ('constraint fence violated: inside(ranger, room) (not measured: no room named nowhere'
                             f' in this world, for {UNMEASURED:g} s)'), report.reason
    logged = [r for r in records if r["kind"] == "log" and "cannot be measured" in r["text"]]
    violation = [r for r in records if r["kind"] == "event" and r["name"] == "violation"]
    assert len(logged) == 1 and violation
    assert violation[0]["fields"]["value"] is None  # not known: null in the trace, which stays strict JSON (review)
    assert violation[0]["at"] - logged[0]["at"] == pytest.approx(UNMEASURED, abs=0.11)
    assert final_x(report) < 1.0 + 0.5 * (UNMEASURED + 0.5)  # stopped once broken, not at the corridor's end
    # a condition that holds by a side it can measure is not broken by the other (review of the change)
    holding = FENCED.replace("    constraint fence: distance(ranger, point(1, 0)) <= 6",
                             '    var room: str = "nowhere"\n'
                             "    constraint fence: distance(ranger, point(1, 0)) <= 100 or inside(ranger, room)")
    report, records = dry(catalog, holding, until=20.0)
    assert report.outcome != "failure" and not [r for r in records if r.get("name") == "violation"], report.reason


def test_constraints_are_checked_at_compile_time(catalog: Catalog) -> None:
    def messages(text: str) -> list[str]:
        return [d.message for d in compile_text(text, catalog, "c.mission").diagnostics]

    assert messages(FENCED.replace("<= 6", "")) == ["constraint fence expects bool, got float"]
    assert "distance expects a robot or a point, got int" in messages(FENCED.replace("point(1, 0)", "3"))
    assert any("declared twice" in m for m in messages(FENCED.replace(
        "    FollowCorridor", "    constraint fence: ranger.battery > 0.1\n    FollowCorridor")))
    assert messages(HANDLED.replace('event.name == "fence"', "event.nope")) == [
        "violation has no field nope"]


THROWN = """
mission Thrown {
    needs ranger: Ranger
    needs pup: Scout where pup.id == "scout1"
    constraint tether: distance(pup, ranger) <= 1
    LaunchScout(max_range: 5)
}
"""


def test_a_launch_that_would_throw_a_constrained_scout_past_its_fence_is_refused(catalog: Catalog) -> None:
    """Safety audit 8, D3: the guard predicted only the launcher's robot, so LaunchScout threw a Scout 5 m against a
    1 m tether and the violation came after the landing. A launch is predicted where the Scout lands."""
    report, records = dry(catalog, THROWN, until=10.0)
    launches = [r for r in records if r["kind"] == "command" and r["method"] == "launch"]
    assert launches and not any(r["accepted"] for r in launches), launches
    assert "constraint tether" in launches[0]["reason"], launches[0]
    assert report.outcome == "failure" and "scout1" not in {s.get("scout") for s in report.scouts}
    x, y = report.tracks["scout1"][-1][1:3] if report.tracks.get("scout1") else (1.0, 0.0)
    assert math.hypot(x - 1.0, y) < 1.0, (x, y)  # it never left the Ranger's magazine
