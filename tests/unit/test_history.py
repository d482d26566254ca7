"""Finished missions across a controller restart (soak audit defects 2 and 3): the journal gives them back in the
order they ended, with their status as listed, bounded by `keep`; the executive lists them again, before its own,
and never keeps more than `history` finished missions, even when the last one ended between two steps."""

from __future__ import annotations

from pathlib import Path

from drd.bus import LocalNetwork
from drd.executive import EntryPoints, Executive, MissionCommand, MissionStatus
from drd.journal import SqliteJournal
from drd.manifests import load_catalog
from drd.runtime.clock import SimClock
from dsl import compile_text


def test_the_journal_gives_back_finished_missions_in_the_order_they_ended_bounded_by_keep(tmp_path: Path) -> None:
    path = tmp_path / "journal.sqlite"
    journal = SqliteJournal(path, keep=2)
    for mid in ("A-1", "B-2", "C-3", "D-4"):
        journal.begin(mid, {"source": mid}, 1, 0.0, 60.0)
    for mid in ("C-3", "A-1", "D-4"):  # not the order they started
        journal.finish(mid, "success", "", {"id": mid, "outcome": "success", "reason": "", "time": 4.5,
                                            "placements": [{"path": "p", "host": "ranger1"}]})
    journal.close()
    again = SqliteJournal(path, keep=2)
    ended = again.finished()
    assert [f.id for f in ended] == ["A-1", "D-4"], "the last two that ended, first ended first"
    assert ended[1].status == {"id": "D-4", "outcome": "success", "reason": "", "time": 4.5,
                               "placements": [{"path": "p", "host": "ranger1"}]}
    assert [j.id for j in again.running()] == ["B-2"]
    again.close()


def test_a_journal_without_the_status_column_is_read_with_its_outcome(tmp_path: Path) -> None:
    import sqlite3

    path = tmp_path / "journal.sqlite"
    db = sqlite3.connect(path)  # the tables an older drd made: no `ended`, no `status`
    db.executescript("create table meta (key text primary key, value text not null); insert into meta values"
                     " ('version', '1'); create table missions (id text primary key, request text not null, priority"
                     " integer not null, base real not null, until real not null, started real not null, outcome"
                     " text, reason text not null default ''); insert into missions values ('Old-1', '{}', 1, 0, 9,"
                     " 5.0, 'failure', 'host r2 is down');")
    db.commit()
    db.close()
    journal = SqliteJournal(path, keep=10)
    assert [(f.id, f.status) for f in journal.finished()] == [
        ("Old-1", {"id": "Old-1", "outcome": "failure", "reason": "host r2 is down"})]
    journal.begin("New-2", {}, 1, 0.0, 9.0)  # and it still takes new missions
    journal.finish("New-2", "success", "", {"id": "New-2", "outcome": "success"})
    assert [f.id for f in journal.finished()] == ["Old-1", "New-2"]
    journal.close()


def _executive(history: int) -> tuple[Executive, SimClock, LocalNetwork]:
    clock = SimClock()
    net = LocalNetwork()
    return Executive(net.session("c"), clock, EntryPoints(load_catalog()), history=history), clock, net


def _finished(ex: Executive) -> list[str]:
    return [m["id"] for m in ex.status().missions if m.get("outcome") is not None]


def test_status_keeps_history_finished_missions_when_the_last_one_is_stopped_between_steps() -> None:
    ex, clock, net = _executive(history=2)
    cat = load_catalog()
    quick = compile_text("mission Quick {\n    Wait(duration: 1s)\n}\n", cat, "q.mission").statechart
    slow = compile_text("mission Slow {\n    Wait(duration: 1h)\n}\n", cat, "s.mission").statechart
    assert quick is not None and slow is not None
    ex.submit(quick, "Quick-1")
    ex.submit(quick, "Quick-2")
    ex.submit(slow, "Slow-3")
    for _ in range(20):
        clock.advance(0.1)
        ex.step()
    assert _finished(ex) == ["Quick-1", "Quick-2"]
    reply = net.session("operator").call("drd/local/executive", MissionCommand("stop", "Slow-3"))
    assert isinstance(reply, MissionStatus) and reply.missions[0]["outcome"] == "stopped"
    assert _finished(ex) == ["Quick-2", "Slow-3"], "history 2: the first ended goes when the last ends"


def test_a_restarted_executive_lists_the_missions_that_ended_before_first_bounded_by_history() -> None:
    ex, clock, net = _executive(history=3)
    before = [(f"Old-{n}", {"id": f"Old-{n}", "mission": "Old", "outcome": "success", "reason": "", "time": n})
              for n in range(1, 5)]
    ex.restore_history(before)
    assert [m["id"] for m in ex.status().missions] == ["Old-2", "Old-3", "Old-4"]
    assert ex.status().missions[0] == {"id": "Old-2", "mission": "Old", "outcome": "success", "reason": "", "time": 2}
    cat = load_catalog()
    quick = compile_text("mission Quick {\n    Wait(duration: 1s)\n}\n", cat, "q.mission").statechart
    assert quick is not None
    ex.submit(quick, "Quick-5")
    for _ in range(20):
        clock.advance(0.1)
        ex.step()
    assert [m["id"] for m in ex.status().missions] == ["Old-3", "Old-4", "Quick-5"]
    reply = net.session("operator").call("drd/local/executive", MissionCommand("stop", "Old-4"))
    assert isinstance(reply, MissionStatus) and reply.missions[0]["already_ended"] is True
