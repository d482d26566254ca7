"""The report built from records (a dry-run's and a cluster run's alike), where a black-box audit found it wrong:
holds split by `release(x)` named the whole grant in each row; a state entered again lost its earlier run from
the timeline; a cluster run's `mission` was its id and its paths kept the mission's name; times were not
rounded as `missionctl run` rounds them; a team that lost its instances said `last failure: failed`."""

from __future__ import annotations

import io

from rich.console import Console  # noqa: TID251 - rendering the text report at a chosen width

from drd.cli.cluster import mission_name
from drd.cli.report import print_report
from drd.dryrun import DryRun, report_time
from drd.runtime import records as rec
from drd.runtime.component import Component, Status
from dsl import compile_text
from dsl.catalog import Catalog
from tests.runtime_support import Harness, ranger_world

#: `Outpost` holds a Ranger (`carrier`) and a Scout (`mite`), then `release(carrier)` (the audit's m2_posts).
CARRIER = {"carrier": "rover_a", "mite": "mite1", "carrier.drive": "alpha.a_drive", "carrier.cam": "alpha.a_cam",
           "mite.wheels": "alpha.mite1.w", "mite.radio": "alpha.a_radio"}
UNITS = ("alpha.a_drive", "alpha.a_cam", "alpha.mite1.w", "alpha.a_radio")


def report(records: list[rec.Record], mission: str = "PostMites", mission_id: str = "PostMites-1",
           sim_time: float = 75.5) -> DryRun:
    return DryRun(mission, "success", "", sim_time, 0.0, records=records, mission_id=mission_id)


def text_of(r: DryRun, width: int = 100) -> list[str]:
    buf = io.StringIO()
    print_report(r, console=Console(file=buf, width=width, force_terminal=True, color_system=None))
    return buf.getvalue().splitlines()


def cells(lines: list[str], count: int) -> list[list[str]]:
    """The rows of the text report's tables of `count` columns, cell by cell."""
    return [[c.strip() for c in line.split("│")[1:-1]] for line in lines if line.count("│") == count + 1]


def released_carrier() -> DryRun:
    path = "PostMites/Outpost[0]"
    return report([rec.Entered(0.0, "PostMites", "PostMites"), rec.Entered(0.0, path, "PostMites/Outpost[*]"),
                   rec.Granted(0.0, path, dict(CARRIER), dict.fromkeys(UNITS, 1)),
                   rec.Released(8.899999999999984, path, ("rover_a", "alpha.a_drive", "alpha.a_cam"), "release"),
                   rec.Released(67.50000000000044, path, ("mite1", "alpha.mite1.w", "alpha.a_radio"), "exit"),
                   rec.Exited(67.50000000000044, path, "PostMites/Outpost[*]", "success")])


def test_a_hold_split_by_a_release_names_in_each_row_only_what_it_held() -> None:
    holds = released_carrier().holds()
    assert [(h["resources"], h["units"], h["from"], h["to"], h["ended"]) for h in holds] == [
        ({"carrier": "rover_a"}, ["alpha.a_cam", "alpha.a_drive"], 0.0, 8.9, "released"),
        ({"mite": "mite1"}, ["alpha.a_radio", "alpha.mite1.w"], 8.9, 67.5, "exited")]
    rows = cells(text_of(released_carrier()), 5)
    assert rows == [["Outpost[0]", "carrier=rover_a", "0.0", "8.9", "released"],
                        ["Outpost[0]", "mite=mite1", "8.9", "67.5", "exited"]]


def test_a_hold_that_ends_whole_keeps_every_need_in_its_row() -> None:
    path = "M/Look"
    r = report([rec.Granted(0.0, path, {"eye": "cam1", "link": "radio1"}, {"cam1": 1, "radio1": 1}),
                rec.Revoked(4.0, path, ("cam1", "radio1"), "preempted by M/Other"),
                rec.Released(4.0, path, ("cam1", "radio1"), "revoked")], "M", "M-1", 10.0)
    assert [(h["resources"], h["ended"]) for h in r.holds()] == [({"eye": "cam1", "link": "radio1"}, "revoked")]


def reentered() -> DryRun:
    """`ears -> ears on FenceHit`: entered at 0.0, exited (stopped) and entered again at 11.6, done at 41.6."""
    ears, wait = "FencedTrip/ears", "FencedTrip/ears/Wait"
    return report([rec.Entered(0.0, "FencedTrip", "FencedTrip"), rec.Entered(0.0, ears, ears),
                   rec.Entered(0.0, wait, wait), rec.Exited(11.6, wait, wait, "stopped"),
                   rec.Exited(11.6, ears, ears, "stopped"), rec.Entered(11.6, ears, ears),
                   rec.Entered(11.6, wait, wait), rec.Exited(41.6, wait, wait, "success"),
                   rec.Exited(41.6, ears, ears, "success"), rec.Exited(41.6, "FencedTrip", "FencedTrip", "success")],
                  "FencedTrip", "FencedTrip-1", 41.6)


def test_a_state_entered_again_has_a_timeline_row_per_entry() -> None:
    rows = [(t["path"].removeprefix("FencedTrip/"), t["entered"], t["exited"], t["status"])
            for t in reentered().timeline()]
    assert rows == [("FencedTrip", 0.0, 41.6, "success"), ("ears", 0.0, 11.6, "stopped"),
                    ("ears/Wait", 0.0, 11.6, "stopped"), ("ears", 11.6, 41.6, "success"),
                    ("ears/Wait", 11.6, 41.6, "success")]
    assert cells(text_of(reentered()), 4) == [
        ["FencedTrip", "0.0", "41.6", "success"], ["ears", "0.0", "11.6", "stopped"],
        ["ears/Wait", "0.0", "11.6", "stopped"], ["ears", "11.6", "41.6", "success"],
        ["ears/Wait", "11.6", "41.6", "success"]]


def test_alike_instances_still_fold_into_one_row_and_a_reentry_stays_apart() -> None:
    records: list[rec.Record] = [rec.Entered(0.0, "T", "T")]
    records += [rec.Entered(0.0, f"T/W[{i}]", "T/W[*]") for i in range(5)]
    records += [rec.Exited(1.0, f"T/W[{i}]", "T/W[*]", "success") for i in range(5)]
    records += [rec.Entered(1.0, "T/W[0]", "T/W[*]"), rec.Exited(2.0, "T/W[0]", "T/W[*]", "success"),
                rec.Exited(2.0, "T", "T", "success")]
    rows = cells(text_of(report(records, "T", "T-1", 2.0)), 4)
    assert rows == [["T", "0.0", "2.0", "success"], ["W[0..4] (5)", "0.0", "1.0", "success"],
                        ["W[0]", "1.0", "2.0", "success"]]


def test_a_cluster_runs_report_means_by_mission_and_id_what_a_dry_runs_does() -> None:
    assert mission_name("HallSentry-9539828") == "HallSentry"
    assert mission_name("Odd") == "Odd" and mission_name("A-b") == "A-b"  # no number: not an id of ours
    records: list[rec.Record] = [rec.Entered(0.0, "HallSentry", "HallSentry"),
                                 rec.Entered(0.0, "HallSentry/Warmup", "HallSentry/Warmup"),
                                 rec.Exited(2.0, "HallSentry/Warmup", "HallSentry/Warmup", "success")]
    cluster = report(records, mission_name("HallSentry-9539828"), "HallSentry-9539828", 2.0)
    data = cluster.to_dict()
    assert (data["mission"], data["id"]) == ("HallSentry", "HallSentry-9539828")
    assert [row[0] for row in cells(text_of(cluster), 4)] == ["HallSentry", "Warmup"]
    assert text_of(cluster)[0].startswith("mission HallSentry  success")


def test_report_times_are_rounded_as_a_cluster_run_rounds_them() -> None:
    data = report(released_carrier().records, sim_time=21.400000000000034).to_dict()
    assert data["sim_time"] == 21.4 == report_time(21.400000000000034)
    assert [(h["from"], h["to"]) for h in data["holds"]] == [(0.0, 8.9), (8.9, 67.5)]
    assert [t["exited"] for t in data["timeline"]] == [None, 67.5]
    assert report_time(report_time(8.899999999999984)) == report_time(8.899999999999984) == 8.9  # idempotent


class Speaks(Component):
    """Fails in its own words, as DetectDoor does at the end of the corridor, with a plain `Status.FAILURE`."""

    def step(self, now: float) -> Status:
        assert self.ctx is not None
        self.ctx.log("no door in sight")
        return Status.FAILURE


def test_a_team_that_lost_its_instances_gives_the_leafs_words(catalog: Catalog) -> None:
    text = "mission Team { Post[2] }\nbehavior Post { needs s: Scout\n    start -> Leg\n    Leg -> fail on error }\n" \
           "behavior Leg { Wait(duration: 5s) }\n"
    compiled = compile_text(text, catalog, "t.mission")
    assert compiled.ok and compiled.statechart is not None
    h = Harness(compiled.statechart, {"Wait": Speaks}, ranger_world(1, 2))
    assert h.run() == "failure"
    [finished] = h.of(rec.Finished)
    assert finished.reason.endswith("last failure: no door in sight)"), finished.reason
    assert [r.text for r in h.of(rec.Log) if r.path == "Team/Post"] == ["an instance failed: no door in sight"] * 2
    r = DryRun("Team", finished.outcome, finished.reason, finished.at, 0.0, records=h.records)
    assert "failed; last failure: no door in sight)" in text_of(r, 200)[0]


def test_a_restore_ends_what_ran_before_it_in_the_timeline_explain_and_the_live_view() -> None:
    """Users audit 17, D3: after a controller was lost and the mission restored from its journal, the entries from
    before stayed `active` (no exit) in the report of a mission that succeeded; a state entered after the journal's
    save and not entered again stayed active in `explain` and a recording's `/drd/active`."""
    from drd.explain import Explainer
    from drd.record import ActiveView

    records: list[rec.Record] = [
        rec.Entered(0.0, "M", "M"), rec.Entered(0.0, "M/A", "M/A"), rec.Entered(0.0, "M/B[0]", "M/B[*]"),
        rec.Waiting(1.0, "M/B[0]", ("s: Scout",)),
        rec.Entered(5.5, "M/A/C", "M/A/C"),  # after the journal's save at 5.0: undone by the restore
        rec.Restored(8.0, "M", since=5.0, paused=3.0),
        rec.Entered(8.0, "M", "M"), rec.Entered(8.0, "M/A", "M/A"), rec.Entered(8.0, "M/B[0]", "M/B[*]"),
        rec.Granted(8.0, "M/B[0]", {"s": "scout1"}, {"scout1": 1}),
        rec.Exited(9.0, "M/B[0]", "M/B[*]", "success"), rec.Exited(9.0, "M/A", "M/A", "success"),
        rec.Exited(9.0, "M", "M", "success"),
    ]
    rows = report(records[:-3]).timeline()
    assert [(r["path"], r["entered"], r["exited"], r["status"]) for r in rows[:4]] == [
        ("M", 0.0, 5.0, "controller lost"), ("M/A", 0.0, 5.0, "controller lost"),
        ("M/B[0]", 0.0, 5.0, "controller lost"), ("M/A/C", 5.5, 5.5, "controller lost")]
    assert [(r["path"], r["exited"]) for r in report(records).timeline()[4:]] == [("M", 9.0), ("M/A", 9.0),
                                                                                 ("M/B[0]", 9.0)]
    assert [(w["path"], w["from"], w["to"], w["ended"]) for w in report(records).waits()] == [
        ("M/B[0]", 1.0, 5.0, "controller lost")]  # the wait the restore ended; asked again and granted at once
    now = Explainer(records[:-3]).active_now()
    assert [(a["path"], a["since"], a["state"]) for a in now] == [("M/A", 8.0, "running"), ("M/B[0]", 8.0, "running")]
    view = ActiveView("M-1")
    for r in records[:-3]:
        view.take(r)
    state = view.state(8.0)
    assert [(a["path"], a["since"]) for a in state["active"]] == [("M/A", 8.0), ("M/B[0]", 8.0)]
    assert state["waiting"] == [] and state["holds"] == {"M/B[0]": {"s": "scout1"}}
