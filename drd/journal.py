"""The controller's journal: every running mission's request and latest state, on disk, so a restarted controller
resumes them (issue #16).

An SQLite database in WAL mode in the controller's run directory (`<run dir>/<cluster>/journal.sqlite`): SQLite
is in the standard library, a commit is atomic and survives a crash of the process (`synchronous=NORMAL` in WAL
mode loses at most the last commits on a power cut, never the file), and one file is easy to inspect
(`sqlite3 journal.sqlite 'select id, outcome from missions'`). The format is versioned (`meta.version`): a
journal of another version is refused with a clear error, never misread.

- `missions`: one row per mission: its run request (the mission's source and options, as `RunMission` carried
  them), its priority, the executive's time when it started (`base`) and its time limit, and once it ended its
  outcome and reason.
- `states`: per running mission, its state after the last control cycle that changed it (`drd.runtime.snapshot`)
  and the executive's time then.
- `world`: the world the missions run in (name, the Creators' generation, the executive clock's base and time)
  and the number of the last record sent (a resumed executive numbers on from it).

Finished missions stay in the journal (up to `keep`, the oldest go first) for `missionctl status` after a restart.
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drd.errors import ConfigurationError

VERSION = 1

_SCHEMA = """
create table if not exists meta (key text primary key, value text not null);
create table if not exists missions (
    id text primary key, request text not null, priority integer not null, base real not null,
    until real not null, started real not null, outcome text, reason text not null default '');
create table if not exists states (mission text primary key, at real not null, snapshot text not null);
create table if not exists world (
    id integer primary key check (id = 1), name text not null, generation integer not null,
    base real not null, now real not null, seq integer not null, properties text not null, saved real not null);
"""


class JournalError(ConfigurationError):
    """The journal cannot be used (another version, a damaged file); the message names the file."""


@dataclass(frozen=True)
class Journaled:
    """A mission the journal holds as running: what resuming it needs."""

    id: str
    request: dict[str, Any]
    priority: int
    base: float
    until: float
    at: float  # the executive's time of its last saved state
    snapshot: dict[str, Any] | None  # None: it started, and no state was saved before the loss


@dataclass(frozen=True)
class WorldState:
    """The world the missions ran in: its name, the Creators' generation, the executive clock's base and time,
    the number of the last record sent, the Static Dependency Database's changes (resource -> key -> value: a
    launched Scout's `carrier`), and when it was saved."""

    name: str
    generation: int
    base: float
    now: float
    seq: int
    properties: dict[str, dict[str, Any]] = field(default_factory=dict)
    saved: float = 0.0  # wall time (`time.time()`) of the save


class Journal:
    """See the module. Thread-safe: the mission loop saves while request handlers begin and finish missions."""

    def __init__(self, path: Path, keep: int = 100) -> None:
        self.path = path
        self.keep = keep
        self._lock = threading.Lock()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None)
            self._db.execute("pragma journal_mode=wal")
            self._db.execute("pragma synchronous=normal")
            self._db.executescript(_SCHEMA)
            found = self._db.execute("select value from meta where key = 'version'").fetchone()
            if found is None:
                self._db.execute("insert into meta values ('version', ?)", (str(VERSION),))
            elif found[0] != str(VERSION):
                raise JournalError(f"{path}: journal version {found[0]}, this drd reads version {VERSION}: move the"
                                   " file away to start without resuming its missions")
        except sqlite3.Error as e:
            raise JournalError(f"{path}: cannot use the journal: {e}") from None

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def begin(self, mission: str, request: dict[str, Any], priority: int, base: float, until: float) -> None:
        """A mission started (before its first control cycle)."""
        with self._lock, self._db:
            self._db.execute("insert or replace into missions values (?, ?, ?, ?, ?, ?, null, '')",
                             (mission, json.dumps(request), priority, base, until, time.time()))

    def save(self, states: dict[str, tuple[float, dict[str, Any]]], world: WorldState) -> None:
        """The missions' states after a control cycle (mission -> (time, snapshot)) and the world's, at once."""
        with self._lock, self._db:
            self._db.executemany("insert or replace into states values (?, ?, ?)",
                                 [(m, at, json.dumps(snap, separators=(",", ":"))) for m, (at, snap) in states.items()])
            self._db.execute("insert or replace into world values (1, ?, ?, ?, ?, ?, ?, ?)",
                             (world.name, world.generation, world.base, world.now, world.seq,
                              json.dumps(world.properties, default=str), time.time()))

    def finish(self, mission: str, outcome: str, reason: str) -> None:
        """A mission ended: it is no longer resumed; the oldest finished beyond `keep` are dropped."""
        with self._lock, self._db:
            self._db.execute("update missions set outcome = ?, reason = ? where id = ?", (outcome, reason, mission))
            self._db.execute("delete from states where mission = ?", (mission,))
            self._db.execute("delete from missions where outcome is not null and id not in (select id from missions"
                             " where outcome is not null order by started desc limit ?)", (self.keep,))

    def running(self) -> list[Journaled]:
        """The missions that had not ended when the journal was last written, oldest first."""
        with self._lock:
            rows = self._db.execute(
                "select m.id, m.request, m.priority, m.base, m.until, s.at, s.snapshot from missions m left join"
                " states s on s.mission = m.id where m.outcome is null order by m.started").fetchall()
        try:
            return [Journaled(r[0], json.loads(r[1]), int(r[2]), float(r[3]), float(r[4]),
                              float(r[5]) if r[5] is not None else float(r[3]),
                              json.loads(r[6]) if r[6] is not None else None) for r in rows]
        except (ValueError, TypeError) as e:
            raise JournalError(f"{self.path}: a damaged entry: {e}") from None

    def world(self) -> WorldState | None:
        with self._lock:
            row = self._db.execute("select name, generation, base, now, seq, properties, saved from world where"
                                   " id = 1").fetchone()
        if row is None:
            return None
        try:
            return WorldState(str(row[0]), int(row[1]), float(row[2]), float(row[3]), int(row[4]), json.loads(row[5]),
                              float(row[6]))
        except (ValueError, TypeError) as e:
            raise JournalError(f"{self.path}: a damaged entry: {e}") from None
