"""The journal's asynchronous writes (issue #16): one save in flight, the ones queued behind it merged into the
newest, `begin`/`finish` in order, reads and a clean stop after everything queued; the inner journal's guard holds."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

from drd.journal import DeferredJournal, Journal, Journaled, SqliteJournal, WorldState


def world(now: float) -> WorldState:
    return WorldState("corridor", 1, 0.0, now, int(now * 10))


class Slow(Journal):
    """A journal whose saves wait for `gate` (a store that is slow to commit), noting every write it gets."""

    def __init__(self) -> None:
        self.gate = threading.Event()
        self.entered = threading.Event()
        self.writes: list[tuple[str, Any]] = []
        self.refuse = False  # a guard like the etcd backend's election: writes nothing once set

    def close(self) -> None:
        self.writes.append(("close", None))

    def begin(self, mission: str, request: dict[str, Any], priority: int, base: float, until: float) -> None:
        if not self.refuse:
            self.writes.append(("begin", mission))

    def save(self, states: dict[str, tuple[float, dict[str, Any]]], world: WorldState) -> None:
        self.entered.set()
        self.gate.wait(10)
        if not self.refuse:
            self.writes.append(("save", (sorted((m, at) for m, (at, _s) in states.items()), world.now)))

    def finish(self, mission: str, outcome: str, reason: str, status: dict[str, Any] | None = None) -> None:
        if not self.refuse:
            self.writes.append(("finish", mission))

    def running(self) -> list[Journaled]:
        return []

    def world(self) -> WorldState | None:
        return None


def test_saves_queued_behind_a_slow_write_merge_into_the_newest() -> None:
    inner = Slow()
    journal = DeferredJournal(inner)
    journal.save({"A": (1.0, {})}, world(1.0))  # in flight: waits for the gate
    assert inner.entered.wait(5)
    journal.save({"A": (2.0, {}), "B": (2.0, {})}, world(2.0))  # queued
    journal.save({"A": (3.0, {})}, world(3.0))  # merged into the queued one: A's newest, B's only, the newest world
    journal.save({"C": (4.0, {})}, world(4.0))
    assert journal.merged == 2
    inner.gate.set()
    assert journal.flush(5)
    assert inner.writes == [("save", ([("A", 1.0)], 1.0)),
                            ("save", ([("A", 3.0), ("B", 2.0), ("C", 4.0)], 4.0))]
    assert journal.written == 2
    journal.close()
    assert inner.writes[-1] == ("close", None)


def test_begin_and_finish_wait_their_turn_behind_the_saves_queued_before_them() -> None:
    inner = Slow()
    journal = DeferredJournal(inner)
    journal.save({"A": (1.0, {})}, world(1.0))
    assert inner.entered.wait(5)
    journal.save({"A": (2.0, {})}, world(2.0))
    finished = threading.Thread(target=journal.finish, args=("A", "success", ""))
    finished.start()
    finished.join(0.2)
    assert finished.is_alive()  # it waits for the saves queued before it: A's state is deleted after its last save
    journal.save({"B": (3.0, {})}, world(3.0))  # after the finish: not merged into the save before it
    inner.gate.set()
    finished.join(5)
    assert journal.flush(5)
    assert [kind for kind, _ in inner.writes] == ["save", "save", "finish", "save"]
    assert inner.writes[2] == ("finish", "A")
    journal.close()


def test_the_inner_guard_decides_at_the_moment_of_each_write() -> None:
    """A controller fenced while a save waited writes nothing (the etcd backend asks its election at each write)."""
    inner = Slow()
    journal = DeferredJournal(inner)
    journal.save({"A": (1.0, {})}, world(1.0))
    assert inner.entered.wait(5)
    inner.refuse = True  # fenced meanwhile
    journal.save({"A": (2.0, {})}, world(2.0))
    inner.gate.set()
    journal.close()
    assert inner.writes == [("close", None)]


def test_a_clean_stop_writes_the_last_state_and_a_resume_reads_it(tmp_path: Path) -> None:
    journal = DeferredJournal(SqliteJournal(tmp_path / "journal.sqlite"))
    journal.begin("M-1", {"source": "mission M {}"}, 1, 0.0, 600.0)
    for step in range(1, 201):
        journal.save({"M-1": (step * 0.1, {"step": step})}, world(step * 0.1))
    journal.close()
    again = SqliteJournal(tmp_path / "journal.sqlite")
    [job] = again.running()
    assert job.snapshot == {"step": 200} and abs(job.at - 20.0) < 1e-9
    saved = again.world()
    assert saved is not None and abs(saved.now - 20.0) < 1e-9
    again.close()
