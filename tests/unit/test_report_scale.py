"""Reports at fleet size (scale audit D3, D4, D6): blockers are the current ones, their number is bounded per
waiter, still-active rows fold, lines fit the width, and the live line counts repeated leaves."""

from __future__ import annotations

import io

from rich.console import Console  # noqa: TID251 - rendering the report at a chosen width

from drd.cli.report import live_line, print_report, still_active_lines
from drd.dryrun import DryRun
from drd.explain import BLOCKERS_SHOWN, Explainer
from drd.record import ActiveView
from drd.runtime import records as rec

M = "M"
NEEDS = ("ranger: Ranger", "scout: Scout")


def _fleet() -> list[rec.Record]:
    """Two Rangers, first held by M/R[0] and M/R[1], then (at 5 s) passed to M/R[2] and M/R[3]; R[4..9] wait from
    0 s, their records naming the first holders; R[0] and R[1] keep their Scouts."""
    out: list[rec.Record] = []
    for i in range(10):
        out.append(rec.Entered(0.0, f"{M}/R[{i}]", "R[*]"))
        out.append(rec.Waiting(0.0, f"{M}/R[{i}]", NEEDS))
    for i in range(2):
        out.append(rec.Granted(0.0, f"{M}/R[{i}]", {"ranger": f"ranger{i}", "scout": f"scout{i}"}))
    for i in range(2, 10):
        out.append(rec.Waiting(0.0, f"{M}/R[{i}]", (), (f"{M}/R[0]", f"{M}/R[1]")))
    for i in range(2):
        out.append(rec.Released(5.0, f"{M}/R[{i}]", (f"ranger{i}",), "release"))
        out.append(rec.Granted(5.0, f"{M}/R[{i + 2}]", {"ranger": f"ranger{i}", "scout": f"scout{i + 2}"}))
    return out


def test_blockers_are_the_holders_now_not_those_when_the_wait_began() -> None:
    waiting = Explainer(_fleet()).waiting_now()
    assert [w["path"] for w in waiting] == [f"{M}/R[{i}]" for i in range(4, 10)]
    first = waiting[0]["blocked_by"]
    # the Rangers' holders now come first, with what they hold now
    assert [b["path"] for b in first[:2]] == [f"{M}/R[2]", f"{M}/R[3]"]
    assert first[0]["holds"] == {"ranger": "ranger0", "scout": "scout2"}


def test_active_view_agrees_with_the_report() -> None:
    view = ActiveView("M-1")
    for r in _fleet():
        view.take(r)
    assert view.state(5.0)["waiting"] == Explainer(_fleet()).waiting_now()


def test_blockers_are_capped_and_counted() -> None:
    records = _fleet()
    records += [rec.Granted(6.0, f"{M}/S[{i}]", {"scout": f"scout{10 + i}"}) for i in range(20)]
    records[:0] = [rec.Waiting(0.0, f"{M}/S[{i}]", ("scout: Scout",)) for i in range(20)]
    w = Explainer(records).waiting_now()[0]
    assert len(w["blocked_by"]) == BLOCKERS_SHOWN
    assert w["blockers"] == 4 + 20  # R[0..3] hold a Scout each, S[0..19] one more: no Scout known free


def test_a_type_with_a_free_unit_blocks_nobody() -> None:
    records = [*_fleet(), rec.Exited(6.0, f"{M}/R[0]", "R[*]", "success")]  # scout0 is free again
    w = Explainer(records).waiting_now()[0]
    assert [b["path"] for b in w["blocked_by"]] == [f"{M}/R[2]", f"{M}/R[3]"] and w["blockers"] == 2


def test_still_active_rows_fold_and_fit_the_width() -> None:
    active = [{"path": f"{M}/R[{i}]", "since": 0.0, "state": "waiting"} for i in range(4, 1000)]
    blockers = [{"path": f"{M}/R[{i}]", "holds": {"ranger": f"ranger{i}", "scout": f"scout{i}"}} for i in range(3)]
    waiting = {row["path"]: {"path": row["path"], "since": 0.0, "needs": list(NEEDS), "blocked_by": blockers,
                             "blockers": 51} for row in active}
    lines = still_active_lines(active, waiting, M, 80)
    assert len(lines) == 4
    assert lines[0].plain.startswith("  R[4..999] (996)")
    assert lines[1].plain == "    for ranger: Ranger, scout: Scout"
    assert lines[2].plain.startswith("    51 in its way, held by R[0] (ranger0, scout0); ")
    assert all(len(line.plain) <= 80 for line in lines)


def test_a_folded_row_is_cut_outside_its_range_and_a_blocker_shows_whole() -> None:
    """At fleet size (re-verification R3): `RoomSurveillance[16..18…/ServoToGoal (3)` lost which instances it
    was, and the blocker line was cut inside the first blocker's name."""
    root = "CorridorSurveillance"
    rs = f"{root}/RoomSurveillance"
    active = [{"path": f"{rs}[{i}]/HideInCorner/ServoToGoal", "since": 24.8, "state": "running"} for i in (16, 17, 18)]
    active += [{"path": f"{rs}[{i}]", "since": 0.0, "state": "waiting"} for i in range(40, 190)]
    blockers = [{"path": f"{rs}[{i}]", "holds": {"ranger": f"ranger{i}", "scout": f"scout{i}"}} for i in (30, 31)]
    waiting = {row["path"]: {"path": row["path"], "since": 0.0, "needs": list(NEEDS), "blocked_by": blockers,
                             "blockers": 40} for row in active if row["state"] == "waiting"}
    lines = [line.plain for line in still_active_lines(active, waiting, root, 80)]
    assert all(len(line) <= 80 for line in lines), lines
    folded = next(line for line in lines if "ServoToGoal" in line)
    assert "[16..18]/" in folded and folded.split()[0].endswith("/ServoToGoal"), folded
    assert "(3)" in folded
    assert any(line.startswith("    40 in its way, held by RoomSurveillance[30] (ranger30, scout30)") for line in lines)


def test_a_small_waiter_keeps_its_one_line() -> None:
    active = [{"path": f"{M}/A", "since": 1.0, "state": "waiting"}]
    waiting = {f"{M}/A": {"path": f"{M}/A", "since": 1.0, "needs": ["r: Ranger"],
                          "blocked_by": [{"path": f"{M}/B", "holds": {"r": "ranger1"}}], "blockers": 1}}
    [line] = still_active_lines(active, waiting, M, 100)
    assert line.plain == "  A  waiting since 1.0 s for r: Ranger, held by B (ranger1)"


def test_live_line_counts_leaves_and_keeps_the_counts() -> None:
    line = live_line(7.5, ["LocateDarkCorner"] * 40 + ["Watch"] * 3 + ["Go"], [f"h{i}" for i in range(50)],
                     [f"w{i}" for i in range(900)], width=100).plain
    assert "holds 50" in line and "waiting 900" in line
    assert "LocateDarkCorner x40, Watch x3, Go" in line
    assert len(line) <= 100
    small = live_line(1.0, ["Go"], ["A→ranger1"], ["B"]).plain
    assert "holds 1 (A→ranger1)" in small and "waiting 1 (B)" in small


def test_every_line_of_the_text_report_fits_the_width_log_lines_wrapped_whole() -> None:
    """The corridor report's `log:` lines and found doors reached 91 columns at 80 (re-verification R4.6)."""
    root = "CorridorSurveillance"
    path = f"{root}/RoomSurveillance[3]/HideInCorner/ServoToGoal"
    said = "blocked 1.2 m short of the goal: as close as it gets"
    run = DryRun(root, "success", "", 180.8, 9.0, records=[rec.Log(26.6, path, said)],
                 doors=[{"at": 4.7, "by": f"{root}/RoomSurveillance[10]/FindNewDoor/DetectDoor", "width": 0.98,
                         "x": 4.0, "y": -120.25}])
    buf = io.StringIO()
    print_report(run, console=Console(file=buf, width=80, color_system=None, soft_wrap=True))
    lines = buf.getvalue().splitlines()
    assert all(len(line) <= 80 for line in lines), [line for line in lines if len(line) > 80]
    at = next(i for i, line in enumerate(lines) if line.startswith("   26.6 s  "))
    assert " ".join(" ".join(lines[at:at + 2]).split()).endswith(f"ServoToGoal: {said}"), lines[at:at + 2]
    assert lines[at + 1].startswith(" " * 11), "the rest of the line is indented under the path"
    door = next(i for i, line in enumerate(lines) if "DetectDoor" in line)
    assert lines[door + 1].strip() == "y=-120.25"


def test_a_wait_after_a_preemption_says_what_it_waits_for() -> None:
    """Users audit 15 (a note): a holder preempted at a slice boundary is queued again with a `waiting` record of no
    needs (docs/trace.md); its row in the waits table had empty needs."""
    report = DryRun("M", "success", "", 20.0, 1.0)
    report.records += [rec.Entered(0.0, f"{M}/A", "A"), rec.Waiting(0.0, f"{M}/A", NEEDS),
                       rec.Granted(0.0, f"{M}/A", {"ranger": "ranger1", "scout": "scout1"}),
                       rec.Revoked(5.0, f"{M}/A", ("ranger1",), "preempted by M/B"),
                       rec.Released(5.0, f"{M}/A", ("ranger1",), "revoked"),
                       rec.Waiting(5.0, f"{M}/A", (), (f"{M}/B",)),
                       rec.Granted(10.0, f"{M}/A", {"ranger": "ranger1", "scout": "scout1"})]
    assert [(w["from"], w["to"], w["needs"]) for w in report.waits()] == [(0.0, 0.0, list(NEEDS)),
                                                                         (5.0, 10.0, list(NEEDS))]
    # and as `replay --at`, `explain` and `/drd/active` say it meanwhile (the review: only the table was fixed)
    meanwhile = report.records[:-1]
    assert [w["needs"] for w in Explainer(meanwhile).waiting_now()] == [list(NEEDS)]
    view = ActiveView("M-1")
    for r in meanwhile:
        view.take(r)
    assert [w["needs"] for w in view.state(7.0)["waiting"]] == [list(NEEDS)]
