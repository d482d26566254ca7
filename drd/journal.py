"""The controller's journal: every running mission's request and latest state, kept so that a restarted controller,
or a standby that takes over, resumes them (issue #16).

`Journal` is the interface the controller uses; it has two backends. `SqliteJournal` (the default, for the one
controller of a cluster) is an SQLite database on the controller's disk; `EtcdJournal` keeps the same records in a
replicated etcd cluster, which several controller hosts share (`cluster.store` in hosts.yaml), and writes only
while its controller is the elected one (`drd.cluster.election`).

The SQLite backend: a database in WAL mode in the controller's run directory (`<run dir>/<cluster>/journal.sqlite`):
SQLite is in the standard library, a commit is atomic and survives a crash of the process (`synchronous=NORMAL` in WAL
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

Finished missions stay in the journal (up to `keep`, the ones that ended first go first), each with its status as
`missionctl status` showed it when it ended (`missions.ended`, `missions.status`), so a restarted controller lists
them again (`finished()`). A journal written before those two columns existed gains them when opened (its old
finished rows have no status: they are listed from their outcome and reason).

The etcd backend holds the same three tables as keys under `drd/<cluster>/journal/` (`version`, `mission/<id>`,
`request/<id>`, `state/<id>`, `world`), each value JSON; every write is one transaction that holds only if the
leader key is still the one its controller created (its term): a controller that lost the election writes nothing.
"""

from __future__ import annotations

import json
import logging
import sqlite3
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drd.errors import ConfigurationError

if TYPE_CHECKING:
    from drd.etcd import Etcd

log = logging.getLogger("drd.journal")

VERSION = 1

_SCHEMA = """
create table if not exists meta (key text primary key, value text not null);
create table if not exists missions (
    id text primary key, request text not null, priority integer not null, base real not null,
    until real not null, started real not null, outcome text, reason text not null default '',
    ended real, status text);
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
class Finished:
    """A mission the journal holds as ended: its status as it was listed then (`id`, `outcome`, `reason`, ...)."""

    id: str
    ended: float  # wall time (`time.time()`) it ended
    status: dict[str, Any]


def _status(mission: str, outcome: str, reason: str, status: str | dict[str, Any] | None) -> dict[str, Any]:
    """A finished mission's status as journaled; one journaled without any (an older drd): from its outcome."""
    found = json.loads(status) if isinstance(status, str) else status
    if isinstance(found, dict):
        return found
    return {"id": mission, "outcome": outcome, "reason": reason}


@dataclass(frozen=True)
class WorldState:
    """The world the missions ran in: its name, the Creators' generation, when it began on the executive's clock
    (`base`: `SimTimeClock.origin`) and the clock's time,
    the number of the last record sent, the Static Dependency Database's changes (resource -> key -> value: a
    launched Scout's `carrier`), and when it was saved."""

    name: str
    generation: int
    base: float
    now: float
    seq: int
    properties: dict[str, dict[str, Any]] = field(default_factory=dict)
    saved: float = 0.0  # wall time (`time.time()`) of the save


class Journal(ABC):
    """Where the controller keeps its missions (see the module); every backend is thread-safe: the mission loop
    saves while request handlers begin and finish missions."""

    keep: int = 100

    @abstractmethod
    def close(self) -> None:
        """Let go of the store (the records stay)."""

    @abstractmethod
    def begin(self, mission: str, request: dict[str, Any], priority: int, base: float, until: float) -> None:
        """A mission started (before its first control cycle)."""

    @abstractmethod
    def save(self, states: dict[str, tuple[float, dict[str, Any]]], world: WorldState) -> None:
        """The missions' states after a control cycle (mission -> (time, snapshot)) and the world's, at once."""

    @abstractmethod
    def finish(self, mission: str, outcome: str, reason: str, status: dict[str, Any] | None = None) -> None:
        """A mission ended: it is no longer resumed; `status`: what `missionctl status` lists of it (kept for a
        restarted controller); the first ended beyond `keep` are dropped."""

    @abstractmethod
    def running(self) -> list[Journaled]:
        """The missions that had not ended when the journal was last written, oldest first."""

    def finished(self) -> list[Finished]:
        """The missions that ended (at most `keep`), in the order they ended: a restarted controller's history
        (a backend that keeps none has none)."""
        return []

    @abstractmethod
    def world(self) -> WorldState | None:
        """The world the missions ran in, if one was saved."""

    def flush(self, timeout: float = 10.0) -> bool:
        """Wait for the writes queued so far (a backend that writes as it is called has none); whether they are
        written."""
        return True


class SqliteJournal(Journal):
    """The default backend: an SQLite database in WAL mode on the controller's disk (see the module)."""

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
            columns = {row[1] for row in self._db.execute("pragma table_info(missions)")}
            for column in ("ended real", "status text"):  # a journal of an older drd: the history's columns
                if column.split()[0] not in columns:
                    self._db.execute(f"alter table missions add column {column}")
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
            self._db.execute("insert or replace into missions values (?, ?, ?, ?, ?, ?, null, '', null, null)",
                             (mission, json.dumps(request), priority, base, until, time.time()))

    def save(self, states: dict[str, tuple[float, dict[str, Any]]], world: WorldState) -> None:
        """The missions' states after a control cycle (mission -> (time, snapshot)) and the world's, at once."""
        with self._lock, self._db:
            self._db.executemany("insert or replace into states values (?, ?, ?)",
                                 [(m, at, json.dumps(snap, separators=(",", ":"))) for m, (at, snap) in states.items()])
            self._db.execute("insert or replace into world values (1, ?, ?, ?, ?, ?, ?, ?)",
                             (world.name, world.generation, world.base, world.now, world.seq,
                              json.dumps(world.properties, default=str), time.time()))

    def finish(self, mission: str, outcome: str, reason: str, status: dict[str, Any] | None = None) -> None:
        """A mission ended: it is no longer resumed; the first ended beyond `keep` are dropped."""
        kept = json.dumps(status, default=str) if status is not None else None
        with self._lock, self._db:
            self._db.execute("update missions set outcome = ?, reason = ?, ended = ?, status = ? where id = ?",
                             (outcome, reason, time.time(), kept, mission))
            self._db.execute("delete from states where mission = ?", (mission,))
            self._db.execute("delete from missions where outcome is not null and id not in (select id from missions"
                             " where outcome is not null order by coalesce(ended, started) desc limit ?)",
                             (self.keep,))

    def finished(self) -> list[Finished]:
        with self._lock:
            rows = self._db.execute(
                "select id, outcome, reason, coalesce(ended, started), status from missions where outcome is not null"
                " order by coalesce(ended, started) desc limit ?", (self.keep,)).fetchall()
        try:
            return [Finished(r[0], float(r[3]), _status(r[0], r[1], r[2], r[4])) for r in reversed(rows)]
        except (ValueError, TypeError) as e:
            raise JournalError(f"{self.path}: a damaged entry: {e}") from None

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


class EtcdJournal(Journal):
    """The replicated backend: the journal's records as keys of an etcd cluster (see the module), written only while
    the leader key `leader` is the one created at revision `term` (this controller's election). A write refused for
    that reason means another controller acts: nothing more is written, and `on_fenced(reason)` is told once."""

    def __init__(self, etcd: Etcd, cluster: str, term: int, *, leader: str, keep: int = 100,
                 on_fenced: Callable[[str], None] | None = None, acting: Callable[[], bool] | None = None) -> None:
        """`acting()`: whether its controller still acts by its own reckoning (`drd.cluster.election`); asked before
        each write too, so a controller that resigned or whose lease ran out writes nothing while its key lingers."""
        from drd.etcd import EtcdError, created_at, put

        self.etcd = etcd
        self.prefix = f"drd/{cluster}/journal/"
        self.term = term
        self.leader = leader
        self.keep = keep
        self.on_fenced = on_fenced
        self.acting = acting
        self.fenced = ""  # why it writes no more ("" while it does)
        self.where = f"etcd ({', '.join(etcd.endpoints)}) {self.prefix}"
        self._lock = threading.Lock()
        try:
            found = etcd.get(self.prefix + "version")
            if found is None:
                etcd.txn([created_at(self.prefix + "version", 0)], [put(self.prefix + "version", str(VERSION))])
            elif found.value.decode() != str(VERSION):
                raise JournalError(f"{self.where}: journal version {found.value.decode()}, this drd reads version"
                                   f" {VERSION}: delete the keys under {self.prefix} to start without resuming")
        except EtcdError as e:
            raise JournalError(f"{self.where}: cannot use the journal: {e}") from None

    def close(self) -> None:
        """Nothing to let go: each write is a request of its own."""

    def _write(self, ops: list[dict[str, Any]]) -> bool:
        """One transaction of `ops`, if this controller still holds the election; whether it was written."""
        from drd.etcd import EtcdError, created_at

        with self._lock:
            if self.fenced or (self.acting is not None and not self.acting()):
                return False
            try:
                ok, _rev, _ = self.etcd.txn([created_at(self.leader, self.term)], ops)
            except EtcdError as e:  # etcd unreachable: this controller's lease runs out too, and it is fenced
                log.warning("journal not written (%s): %s", self.where, e)
                return False
            if ok:
                return True
            self.fenced = f"the leader key is no longer this controller's (term {self.term}): another one acts"
        log.warning("journal: %s; it writes nothing more", self.fenced)
        if self.on_fenced is not None:
            self.on_fenced(self.fenced)
        return False

    def begin(self, mission: str, request: dict[str, Any], priority: int, base: float, until: float) -> None:
        from drd.etcd import put

        meta = {"priority": priority, "base": base, "until": until, "started": time.time(), "outcome": None,
                "reason": ""}
        self._write([put(self.prefix + f"request/{mission}", json.dumps(request)),
                     put(self.prefix + f"mission/{mission}", json.dumps(meta))])

    def save(self, states: dict[str, tuple[float, dict[str, Any]]], world: WorldState) -> None:
        from drd.etcd import put

        ops = [put(self.prefix + f"state/{m}", json.dumps({"at": at, "snapshot": snap}, separators=(",", ":")))
               for m, (at, snap) in states.items()]
        data = {"name": world.name, "generation": world.generation, "base": world.base, "now": world.now,
                "seq": world.seq, "properties": world.properties, "saved": time.time()}
        self._write([*ops, put(self.prefix + "world", json.dumps(data, default=str))])

    def finish(self, mission: str, outcome: str, reason: str, status: dict[str, Any] | None = None) -> None:
        from drd.etcd import EtcdError, delete, put

        try:
            found = self.etcd.get(self.prefix + f"mission/{mission}")
            meta = json.loads(found.value) if found is not None else {"priority": 1, "base": 0.0, "until": 0.0,
                                                                      "started": time.time()}
            finished = sorted(((_ended(m), kv.key) for kv, m in self._metas() if m.get("outcome") is not None
                               and kv.key != self.prefix + f"mission/{mission}"), reverse=True)
        except (EtcdError, ValueError) as e:
            log.warning("journal: mission %s not marked finished (%s): %s", mission, self.where, e)
            return
        meta |= {"outcome": outcome, "reason": reason, "ended": time.time(),
                 "status": json.loads(json.dumps(status, default=str)) if status is not None else None}
        dropped = [key.rsplit("/", 1)[1] for _started, key in finished[max(0, self.keep - 1):]]
        self._write([put(self.prefix + f"mission/{mission}", json.dumps(meta)),
                     delete(self.prefix + f"state/{mission}"),
                     *[delete(self.prefix + f"{kind}/{m}") for m in dropped for kind in ("mission", "request")]])

    def _metas(self) -> list[tuple[Any, dict[str, Any]]]:
        return [(kv, json.loads(kv.value)) for kv in self.etcd.prefix(self.prefix + "mission/")]

    def running(self) -> list[Journaled]:
        from drd.etcd import EtcdError

        try:
            jobs = sorted((m["started"], kv.key.rsplit("/", 1)[1], m) for kv, m in self._metas()
                          if m.get("outcome") is None)
            out = []
            for _started, mid, m in jobs:
                request = self.etcd.get(self.prefix + f"request/{mid}")
                state = self.etcd.get(self.prefix + f"state/{mid}")
                saved = json.loads(state.value) if state is not None else None
                out.append(Journaled(mid, json.loads(request.value) if request is not None else {},
                                     int(m["priority"]), float(m["base"]), float(m["until"]),
                                     float(saved["at"]) if saved is not None else float(m["base"]),
                                     saved["snapshot"] if saved is not None else None))
            return out
        except EtcdError as e:
            raise JournalError(f"{self.where}: cannot read the journal: {e}") from None
        except (ValueError, TypeError, KeyError) as e:
            raise JournalError(f"{self.where}: a damaged entry: {e}") from None

    def finished(self) -> list[Finished]:
        from drd.etcd import EtcdError

        try:
            ended = sorted((_ended(m), kv.key.rsplit("/", 1)[1], m) for kv, m in self._metas()
                           if m.get("outcome") is not None)
            return [Finished(mid, float(at), _status(mid, str(m["outcome"]), str(m.get("reason", "")),
                                                     m.get("status")))
                    for at, mid, m in ended[-self.keep:] if self.keep > 0]
        except EtcdError as e:
            raise JournalError(f"{self.where}: cannot read the journal: {e}") from None
        except (ValueError, TypeError, KeyError) as e:
            raise JournalError(f"{self.where}: a damaged entry: {e}") from None

    def world(self) -> WorldState | None:
        from drd.etcd import EtcdError

        try:
            found = self.etcd.get(self.prefix + "world")
            if found is None:
                return None
            w = json.loads(found.value)
            return WorldState(str(w["name"]), int(w["generation"]), float(w["base"]), float(w["now"]), int(w["seq"]),
                              dict(w.get("properties") or {}), float(w.get("saved") or 0.0))
        except EtcdError as e:
            raise JournalError(f"{self.where}: cannot read the journal: {e}") from None
        except (ValueError, TypeError, KeyError) as e:
            raise JournalError(f"{self.where}: a damaged entry: {e}") from None


def _ended(meta: dict[str, Any]) -> float:
    """When a mission of the etcd journal ended (one an older drd journaled: when it started)."""
    return float(meta.get("ended") or meta.get("started") or 0.0)


class DeferredJournal(Journal):
    """Another journal's writes on a thread of their own (issue #16: a replicated write is a raft commit on a quorum's
    disks, a quarter of the executive's time per step when the loop waited for it).

    One write is in flight at a time. A save made while another waits to go is merged into it (each mission's newest
    state, the newest world), so the loop never queues behind the store and a resume takes the last state written.
    `begin` and `finish` go in order behind the saves queued before them and are waited for (a mission is durable
    before its first record; a finished one's state is deleted after its last save, never resurrected by it).
    Reads wait for the writes queued before them. `flush` waits for everything queued; `close` flushes first. The
    inner journal's guards hold as they are, at the moment of each write (the etcd backend's election: a write only
    while the leader key is this controller's)."""

    def __init__(self, inner: Journal) -> None:
        self.inner = inner
        self.keep = inner.keep
        self.written = 0  # saves written
        self.merged = 0  # saves merged into one still waiting (never written by themselves)
        self._cond = threading.Condition()
        self._queue: list[tuple[Any, ...]] = []  # ("save", (states, world)) or ("call", done event, function)
        self._busy = False
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="drd-journal", daemon=True)
        self._thread.start()

    def save(self, states: dict[str, tuple[float, dict[str, Any]]], world: WorldState) -> None:
        """Queue the save (merged into the one waiting, if any); returns at once."""
        with self._cond:
            if self._closed:
                return
            if self._queue and self._queue[-1][0] == "save":
                waiting, _older = self._queue[-1][1]
                self._queue[-1] = ("save", ({**waiting, **states}, world))
                self.merged += 1
            else:
                self._queue.append(("save", (dict(states), world)))
            self._cond.notify_all()

    def begin(self, mission: str, request: dict[str, Any], priority: int, base: float, until: float) -> None:
        self._through(lambda: self.inner.begin(mission, request, priority, base, until))

    def finish(self, mission: str, outcome: str, reason: str, status: dict[str, Any] | None = None) -> None:
        self._through(lambda: self.inner.finish(mission, outcome, reason, status))

    def running(self) -> list[Journaled]:
        self.flush()
        return self.inner.running()

    def finished(self) -> list[Finished]:
        self.flush()
        return self.inner.finished()

    def world(self) -> WorldState | None:
        self.flush()
        return self.inner.world()

    def flush(self, timeout: float = 10.0) -> bool:
        """Wait until every write queued so far is done (at most `timeout` s); whether they are."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._queue or self._busy:
                left = deadline - time.monotonic()
                if left <= 0 or not self._thread.is_alive():
                    return False
                self._cond.wait(left)
        return True

    def close(self) -> None:
        """Write what is queued, stop the writer, let go of the store."""
        if not self.flush():
            log.warning("journal: closed with writes still queued (the store did not answer)")
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(timeout=5)
        self.inner.close()

    def _through(self, call: Callable[[], None]) -> None:
        """Queue `call` behind the saves queued before it and wait for it (bounded: a store that does not answer
        fences its controller anyway)."""
        done = threading.Event()
        with self._cond:
            if self._closed:
                return
            self._queue.append(("call", done, call))
            self._cond.notify_all()
        if not done.wait(30.0):
            log.warning("journal: a write waited 30 s for the store; going on")

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._closed:
                    self._cond.wait()
                if not self._queue:
                    return
                item = self._queue.pop(0)
                self._busy = True
            try:
                if item[0] == "save":
                    self.inner.save(*item[1])
                    self.written += 1
                else:
                    item[2]()
            except Exception:  # a write that fails must not stop the ones after it
                log.exception("journal: a write failed")
            finally:
                if item[0] == "call":
                    item[1].set()
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()
