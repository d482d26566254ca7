"""What `missionctl status` and `missionctl run` show with several missions (multi-mission audit D2, D4, D7):
why a mission waits (its need with its `where`, its rank, who blocks it), holders of two same-name missions told
apart, a cluster run's report named by its id, and a progress line that says suspended or waiting. Pure."""

from __future__ import annotations

import io
import json
from typing import Any

from rich.console import Console  # noqa: TID251 - rendering the status and the report at a chosen width

from drd.cli.cluster import holder_label, progress_line, status_json, status_view, track_phase
from drd.cli.common import wrap_cut
from drd.cli.report import print_report
from drd.dryrun import DryRun
from drd.runtime import records as rec


def text(renderable: Any, width: int = 120) -> str:
    buf = io.StringIO()
    Console(file=buf, width=width, color_system=None).print(renderable)
    return buf.getvalue()


def status() -> dict[str, Any]:
    """Starved (p3, ranger2 only) waits behind CamHog, which holds ranger2; ranger1 is free."""
    tree = {"path": "Starved", "kind": "compound", "phase": "active", "resources": {},
            "children": [{"path": "Starved/WantEast", "kind": "compound", "phase": "waiting", "resources": {},
                          "children": []}]}
    waiter = {"holder": "Starved-92/Starved/WantEast", "priority": 1, "mission": "Starved-92",
              "needs": {"ranger": "Ranger"}, "mission_priority": 3, "where": {"ranger": 'ranger.id == "ranger2"'},
              "blocked_by": [{"holder": "CamHog-91/CamHog/HoldEast", "holds": {"ranger": "ranger2"},
                              "waiting": False}]}
    units = [{"id": f"{r}.drive", "type": "Drive", "host": r, "sharable": False, "capacity": 1.0, "load": load,
              "epoch": 1, "holders": holders, "queue": queue, "properties": {}}
             for r, load, holders, queue in (("ranger1", 0.0, [], []),
                                             ("ranger2", 1.0, ["CamHog-91/CamHog/HoldEast"], [waiter["holder"]]))]
    robots = [{"id": r, "type": "Ranger", "host": r, "parts": {"drive": f"{r}.drive"}, "holders": h}
              for r, h in (("ranger1", []), ("ranger2", ["CamHog-91/CamHog/HoldEast"]))]
    return {"cluster": "c", "answered_by": "hq", "at": 0.0, "hosts": [], "instances": [], "services": [],
            "resources": {"units": units, "robots": robots, "queue": [waiter], "removing": {}, "hosts": {}},
            "missions": [{"id": "CamHog-91", "outcome": None, "reason": "", "time": 9.0, "started": 0.0},
                         {"id": "Starved-92", "outcome": None, "reason": "", "time": 9.0, "started": 1.0,
                          "tree": tree}],
            "daemon": None, "errors": {}, "events": []}


def test_a_waiting_missions_tree_says_what_it_waits_for_its_rank_and_who_blocks_it() -> None:
    data = status_json(status())
    json.dumps(data, allow_nan=False)  # still strict JSON
    [node] = data["missions"][1]["tree"]["children"]
    assert node["phase"] == "waiting", "the old fields stay"
    assert node["waiting_for"] == {"needs": {"ranger": "Ranger"}, "where": {"ranger": 'ranger.id == "ranger2"'},
                                   "mission_priority": 3, "priority": 1,
                                   "blocked_by": [{"holder": "CamHog-91/CamHog/HoldEast",
                                                   "holds": {"ranger": "ranger2"}, "waiting": False}],
                                   "offline": []}
    shown = " ".join(text(status_view(status())).split())
    assert 'WantEast waiting for ranger: Ranger where ranger.id == "ranger2" (mission priority 3, priority 1) ' \
           "blocked by CamHog-91/HoldEast (ranger: ranger2)" in shown
    assert "Starved-92/WantEast (mission priority 3, priority 1)" in shown
    ranger1 = next(line for line in text(status_view(status())).splitlines() if "ranger1 Ranger" in line)
    assert "Starved" not in ranger1, "it can never take ranger1"


def test_a_waiter_for_the_robots_of_a_host_offline_is_told_it_waits_for_that_host() -> None:
    """No holder is in its way: the robot it may take is on a host seen down, or that did not answer a call (its
    resources are granted to no one new meanwhile); `status` said it waited, blocked by no one."""
    data = status()
    resources = data["resources"]
    waiter = resources["queue"][0]
    waiter["blocked_by"], waiter["offline"] = [], ["ranger2"]
    ranger2 = resources["units"][1]
    ranger2.update(holders=[], load=0.0, offline=True)
    resources["robots"][1]["holders"] = []
    [node] = status_json(data)["missions"][1]["tree"]["children"]
    assert node["waiting_for"]["offline"] == ["ranger2"]
    shown = " ".join(text(status_view(data)).split())
    assert "(mission priority 3, priority 1) blocked by host ranger2 (offline: down, or it did not answer)" in shown
    assert "ranger2 did not answer a call: its resources are granted to no one new until it reports again" in shown


def cli_text(renderable: Any, width: int) -> str:
    """As the CLI's console draws it: soft_wrap (no wrapping by rich), so a line too long is cropped by the tree."""
    buf = io.StringIO()
    Console(file=buf, width=width, color_system=None, soft_wrap=True).print(renderable)
    return buf.getvalue()


def test_why_a_node_waits_goes_below_it_and_the_blocker_shows_at_80_columns() -> None:
    lines = cli_text(status_view(status(), 80), 80).splitlines()
    assert max(len(line) for line in lines) <= 80, "\n".join(lines)
    node = next(i for i, line in enumerate(lines) if "WantEast  waiting" in line)
    below = lines[node + 1:node + 4]
    assert any(line.strip() == "blocked by CamHog-91/HoldEast (ranger: ranger2)" for line in below), lines
    assert any('where ranger.id == "ranger2"' in line for line in below), lines


def test_a_long_reason_is_cut_with_an_ellipsis_and_several_blockers_are_counted_first() -> None:
    data = status()
    where = " or ".join(f'ranger.id == "ranger{i}"' for i in range(2, 30))
    [waiter] = data["resources"]["queue"]
    waiter["where"] = {"ranger": where}
    waiter["blocked_by"] = [{"holder": f"NightGuard-95150{i}/NightGuard/GuardPost", "holds": {"ranger": f"ranger{i}"},
                             "waiting": False} for i in range(10, 20)]
    lines = cli_text(status_view(data, 80), 80).splitlines()
    assert max(len(line) for line in lines) <= 80, "\n".join(lines)
    node = next(i for i, line in enumerate(lines) if "WantEast  waiting" in line)
    below = [line.strip() for line in lines[node + 1:node + 5]]
    assert below[0].startswith("for ranger: Ranger where") and below[1].endswith("…"), below
    assert below[2].startswith("blocked by 10: NightGuard-9515010/GuardPost (ranger: ranger10)"), below
    assert below[3].endswith("…") and "hosts" in lines[node + 5], lines


def test_wrap_cut_wraps_at_spaces_and_marks_a_cut() -> None:
    assert wrap_cut("a bb ccc", 4, 3) == ["a bb", "ccc"]
    assert wrap_cut("a bb ccc dddd", 4, 2) == ["a bb", "ccc…"]
    assert all(len(line) <= 10 for line in wrap_cut("x" * 50, 10, 2))


def test_two_holders_of_same_name_missions_stay_apart_when_cut() -> None:
    a, b = "NightGuard-9515067/NightGuard/GuardPost", "NightGuard-9515087/NightGuard/GuardPost"
    for room in (16, 20, 24, 28):
        cut = holder_label(a, room), holder_label(b, room)
        assert cut[0] != cut[1], (room, cut)
        assert all(c.endswith("/GuardPost") and len(c) <= max(room, 19) for c in cut), cut
    assert holder_label(a) == "NightGuard-9515067/GuardPost"
    assert holder_label(a, several=False) == "GuardPost"


def test_a_cluster_runs_report_opens_with_its_mission_id() -> None:
    run = DryRun("NightGuard", "stopped", "stopped by operator", 12.0, 3.0, mission_id="NightGuard-9515087",
                 on_cluster=True)
    buf = io.StringIO()
    print_report(run, console=Console(file=buf, width=100, color_system=None))
    assert buf.getvalue().startswith("mission NightGuard-9515087  stopped")
    run.on_cluster = False  # a dry-run of one mission keeps its name
    buf = io.StringIO()
    print_report(run, console=Console(file=buf, width=100, color_system=None))
    assert buf.getvalue().startswith("mission NightGuard  stopped")


def test_the_progress_line_says_suspended_and_waiting_from_the_records() -> None:
    phases: dict[str, str] = {}
    active = ["NightGuard", "NightGuard/GuardPost", "NightGuard/GuardPost/Roam"]
    for r in (rec.Waiting(0.0, "NightGuard/GuardPost", ("ranger: Ranger",)), rec.Granted(0.0, "NightGuard/GuardPost")):
        track_phase(phases, r)
    assert str(progress_line(1.0, active, 80, phases)).endswith("active Roam")
    track_phase(phases, rec.Suspended(13.7, "NightGuard/GuardPost"))
    line = str(progress_line(14.0, active, 80, phases))
    assert line.endswith("suspended Roam") and "active" not in line, line
    track_phase(phases, rec.Resumed(38.3, "NightGuard/GuardPost"))
    assert str(progress_line(39.0, active, 80, phases)).endswith("active Roam")
    track_phase(phases, rec.Waiting(2.0, "Starved/WantEast", ("ranger: Ranger",)))
    assert str(progress_line(3.0, ["Starved", "Starved/WantEast"], 80, phases)).endswith("waiting WantEast")
    track_phase(phases, rec.Exited(4.0, "Starved/WantEast", "Starved/WantEast", "stopped"))
    assert "Starved/WantEast" not in phases


def test_a_restore_clears_what_was_suspended_before_the_controller_was_lost() -> None:
    """Safety audit 7 (seen on its cluster): a node suspended before a controller loss, entered again by the restore
    and granted, was still shown `suspended` (no `resumed` follows a restore)."""
    phases: dict[str, str] = {}
    active = ["HogN", "HogN/Rogue"]
    track_phase(phases, rec.Suspended(7.1, "HogN"))
    for r in (rec.Restored(9.3, "HogN", 7.0, 2.0), rec.Waiting(9.3, "HogN", ("r: Ranger",)), rec.Granted(17.3, "HogN")):
        track_phase(phases, r)
    assert str(progress_line(18.0, active, 80, phases)).endswith("active Rogue"), phases


def test_a_mission_that_holds_or_waits_at_its_top_says_so_on_its_line() -> None:
    """Cluster audit 17, D1: `mission HighHold { needs ranger: Ranger where ... }` waiting showed `running` and
    nothing under it (only the root's children were drawn); its holder's root-level grant was not shown either."""
    data = status()
    waiter = data["resources"]["queue"][0]
    waiter["holder"] = "Starved-92/Starved"
    data["resources"]["units"][1]["queue"] = [waiter["holder"]]
    data["missions"][1]["tree"] = {"path": "Starved", "kind": "compound", "phase": "waiting", "resources": {},
                                   "children": []}
    data["missions"][0]["tree"] = {"path": "CamHog", "kind": "leaf", "phase": "active",
                                   "resources": {"ranger": "ranger2", "ranger.drive": "ranger2.drive"},
                                   "children": []}
    shown = " ".join(text(status_view(data)).split())
    assert "CamHog-91 running 9s ranger2" in shown
    assert 'Starved-92 running 8s waiting for ranger: Ranger where ranger.id == "ranger2" (mission priority 3, ' \
           "priority 1) blocked by CamHog-91/HoldEast (ranger: ranger2)" in shown, shown


def test_a_failed_missions_long_reason_wraps_below_it_at_80_columns() -> None:
    """Placement audit 24, #9: the reason was cropped at the width with no mark, and read as the whole reason."""
    reason = ("no host can run Solo: controller: no worker role; pc1: multiplicity 1 reached; ranger1: multiplicity 1"
              " reached; ranger2: down")
    data = {**status(), "missions": [{"id": "TwoSolos-93", "outcome": "failure", "reason": reason, "time": 2.0}]}
    lines = cli_text(status_view(data, 80), 80).splitlines()
    assert max(len(line) for line in lines) <= 80, "\n".join(lines)
    head = next(i for i, line in enumerate(lines) if "TwoSolos-93  failure" in line)
    assert " ".join(line.strip() for line in lines[head + 1:head + 3]) == reason, lines
    short = {**status(), "missions": [{"id": "Bad-94", "outcome": "failure", "reason": "stopped", "time": 2.0}]}
    assert "Bad-94  failure  stopped" in cli_text(status_view(short, 80), 80)
