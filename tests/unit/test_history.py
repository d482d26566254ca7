"""Finished missions across a controller restart (soak audit defect 2): the journal gives them back in the order
they ended, with their status as listed, bounded by `keep` (the executive's side: tests/integration/
test_executive_history.py)."""

from __future__ import annotations

from pathlib import Path

from drd.journal import SqliteJournal


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
