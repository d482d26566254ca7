"""Why a mission ended, read from its records alone: the failure chain down to each failed leaf, the leaves still
active when it was stopped, and who each waiting behavior waited for.

Records only, never the interpreter's state, so a dry-run, a cluster's `missionctl run` (which sees only records)
and a preview at start explain the same way. Pure: no I/O.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Collection, Iterator, Sequence
from typing import Any

from drd.runtime import records as rec

#: Ends of a hold that take a behavior's resources away (it then fails for that reason, not its own).
_LOST = ("host lost", "resource lost", "expired")
#: Records the stop of a mission writes as it shuts everything down (`Interpreter.stop`), all at its last instant.
_SHUTDOWN = (rec.Released, rec.Halted, rec.Command, rec.Revoked, rec.Log)


class Explainer:
    """Reads a mission's records to say why it ended: the failure chain, or what was still active and waiting
    (`waiting` also serves a preview: who would wait at start, and behind whom)."""

    def __init__(self, records: Sequence[rec.Record]):
        self.records = records
        self.parent: dict[str, str] = {}
        self.children: dict[str, list[str]] = {}
        self.instances: set[str] = set()  # paths of a multiplicity's instances (`lookouts[0]`)
        for r in records:
            if isinstance(r, rec.Entered) and r.path not in self.parent:
                if r.state.endswith("[*]"):
                    parent = r.path[:r.path.rfind("[")]
                    self.instances.add(r.path)
                else:
                    parent = r.path.rpartition("/")[0]
                self.parent[r.path] = parent
                self.children.setdefault(parent, []).append(r.path)

    # --- a success that lost something ------------------------------------------------------------------
    def degraded(self) -> list[dict[str, Any]]:
        """The instances of a multiplicity that failed although their mission did not (graceful degradation: a
        lost Scout fails its RoomSurveillance, the others go on): `[{path, at, reason}]`, each with the reason of
        its own failure chain, so a success never hides what it lost."""
        out = []
        for r in self.records:
            if isinstance(r, rec.Exited) and r.status == "failure" and r.path in self.instances:
                end = self.records.index(r)
                rows = self._explain(r.path, end, r.reason)
                leaves = [row["reason"] for row in rows[1:] if row.get("reason")] or [r.reason or "failed"]
                out.append({"path": r.path, "at": round(r.at, 6), "reason": leaves[-1]})
        return out

    # --- the failure chain -------------------------------------------------------------------------------
    def chain(self, reason: str) -> list[dict[str, Any]]:
        finished = next((r for r in reversed(self.records) if isinstance(r, rec.Finished)), None)
        root = finished.path if finished is not None else next(
            (r.path for r in self.records if isinstance(r, rec.Entered)), "")
        end = self._last(rec.Exited, root, len(self.records), status="failure")
        rows = self._explain(root, len(self.records) if end is None else end, reason)
        for row in rows:
            path = row["path"]
            row["leaf"] = not any(o["path"].startswith((path + "/", path + "[")) for o in rows)
        return rows

    def _explain(self, node: str, end: int, reason: str = "") -> list[dict[str, Any]]:
        """`node` failed at record `end` (its `exited`): its row, then the rows of what made it fail."""
        start = self._last(rec.Entered, node, end) or 0
        records = self.records
        for i in range(end - 1, start, -1):
            r = records[i]
            if isinstance(r, rec.Taken) and r.target == f"{node}/fail" and self.parent.get(r.path) == node:
                child, label = r.path, r.label.split(" / ")[0].strip()
                name = _name(child)
                if r.trigger == "error":
                    j = self._last(rec.Exited, child, i, status="failure", after=start)
                    if j is not None:
                        return [self._row(node, reason or f"{name} failed"), *self._explain(child, j)]
                    return [self._row(node, reason or f"{name} failed"), self._row(child, self._own(child, start, i))]
                if r.trigger == "timeout":
                    ran = self._active_below(child, i)
                    why = f"timed out {label}" + (f" (while {', '.join(_name(p) for p in ran)} ran)" if ran else "")
                    return [self._row(node, reason or f"{name} timed out"), self._row(child, why)]
                why = f"{label} -> fail" if label else "completed, then -> fail"
                return [self._row(node, reason or f"{name}: {why}"), self._row(child, why)]
        failed = [(c, j) for c in self.children.get(node, ())
                  if (j := self._last(rec.Exited, c, end, status="failure", after=start)) is not None]
        if failed and any(c in self.instances for c, _ in failed):
            instances = [c for c in self.children.get(node, ()) if c in self.instances]
            name = _name(node)
            found = re.search(rf"only \d+ of at least \d+ instances of {re.escape(name)} can succeed", self.reason_text)
            why = (found.group(0) + f" ({len(failed)} failed)") if found else (
                f"{len(failed)} of {len(instances)} instances failed")
            rows = [self._row(node, reason or why)]
            for c, j in failed:
                rows += self._explain(c, j)
            return rows
        if failed:
            c, j = max(failed, key=lambda f: f[1])
            return [self._row(node, reason or f"{_name(c)} failed"), *self._explain(c, j)]
        return [self._row(node, reason or self._own(node, start, end))]

    @functools.cached_property
    def reason_text(self) -> str:
        finished = next((r for r in reversed(self.records) if isinstance(r, rec.Finished)), None)
        return finished.reason if finished is not None else ""

    def _own(self, node: str, start: int, end: int) -> str:
        """A behavior's own reason for failing: the resources it lost, else the reason its exit gives, else its last
        log line, else what its multiplicity logged about it."""
        window = self.records[start:end + 1]
        lost = next((r for r in window if isinstance(r, rec.Released) and r.path == node and r.reason in _LOST), None)
        if lost is not None:
            return f"lost {lost.resources[0] if lost.resources else 'its resources'} ({lost.reason})"
        exited = self.records[end] if end < len(self.records) else None
        if isinstance(exited, rec.Exited) and exited.path == node and exited.reason not in ("", "failed"):
            return exited.reason  # the interpreter's own words (a component's plain failure says only "failed")
        said = next((r.text for r in reversed(window) if isinstance(r, rec.Log) and r.path == node), None)
        if said is not None:
            return said
        parent = self.parent.get(node, "")
        for r in self.records[end + 1:end + 4]:
            if isinstance(r, rec.Log) and r.path == parent and r.text.startswith("an instance failed: "):
                return r.text.removeprefix("an instance failed: ")
        return "failed"

    def _active_below(self, node: str, at: int) -> list[str]:
        """The leaves under `node` active at record `at`."""
        active: dict[str, None] = {}
        for r in self.records[:at]:
            if r.path.startswith((node + "/", node + "[")):
                if isinstance(r, rec.Entered):
                    active[r.path] = None
                elif isinstance(r, rec.Exited):
                    active.pop(r.path, None)
        return _leaves(active)

    def _last(self, kind: type[rec.Record], path: str, before: int, status: str | None = None,
              after: int = -1) -> int | None:
        """The index of the last record of `kind` about `path` before index `before` (and after `after`)."""
        for i in range(min(before, len(self.records)) - 1, after, -1):
            r = self.records[i]
            if isinstance(r, kind) and r.path == path and (status is None or getattr(r, "status", None) == status):
                return i
        return None

    @staticmethod
    def _row(path: str, reason: str) -> dict[str, Any]:
        return {"path": path, "reason": reason}

    # --- what a stopped run left behind ------------------------------------------------------------------
    def _cut(self) -> int:
        """Where the stop's shutdown begins: the records before it are the run as it was when stopped."""
        records = self.records
        end = next((i for i in range(len(records) - 1, -1, -1) if isinstance(records[i], rec.Finished)),
                   len(records))
        at = records[end].at if end < len(records) else (records[-1].at if records else 0.0)
        i = end
        while i > 0:
            r = records[i - 1]
            if abs(r.at - at) > 1e-9 or not (isinstance(r, _SHUTDOWN) or (isinstance(r, rec.Exited)
                                                                          and r.status == "stopped")):
                break
            i -= 1
        return i

    def _replay(self) -> Iterator[rec.Record]:
        return iter(self.records[:self._cut()])

    def still_active(self) -> list[dict[str, Any]]:
        """The leaves active when the run was stopped (before the stop's own shutdown), each with its state."""
        return _active(self._replay(), {w["path"] for w in self.waiting()})

    def active_now(self) -> list[dict[str, Any]]:
        """The leaves active after the last record (a replay `--at` gives the records up to that time)."""
        return _active(iter(self.records), {w["path"] for w in self.waiting_now()})

    def holds_now(self) -> dict[str, dict[str, str]]:
        """What each behavior holds after the last record (need -> unit, robots and devices alike)."""
        holds: dict[str, dict[str, str]] = {}
        for r in self.records:
            if isinstance(r, rec.Granted):
                holds[r.path] = r.named
            elif isinstance(r, rec.Released):
                gone = set(r.resources)
                holds[r.path] = {k: v for k, v in holds.get(r.path, {}).items() if v not in gone}
            elif isinstance(r, rec.Exited):
                holds.pop(r.path, None)
        return {path: held for path, held in holds.items() if held}

    def waiting(self) -> list[dict[str, Any]]:
        """Who waited when the run was stopped (before the stop's own shutdown), and behind whom."""
        return _waiting(self._replay())

    def waiting_now(self) -> list[dict[str, Any]]:
        """Who waits after the last record, and behind whom (a preview's records end at start)."""
        return _waiting(iter(self.records))


def _active(records: Iterator[rec.Record], waiting: set[str]) -> list[dict[str, Any]]:
    """The leaves active after `records`, each `running`, `waiting` (for resources) or `suspended` (preempted)."""
    active: dict[str, float] = {}
    suspended: set[str] = set()
    for r in records:
        if isinstance(r, rec.Entered):
            active[r.path] = r.at
        elif isinstance(r, rec.Exited):
            active.pop(r.path, None)
            suspended.discard(r.path)
        elif isinstance(r, rec.Suspended):
            suspended.add(r.path)
        elif isinstance(r, rec.Resumed):
            suspended.discard(r.path)
        elif isinstance(r, rec.Restored):  # its states are entered again, those still in force as saved
            for path in [p for p in active if within(p, r.path)]:
                del active[path]
            suspended = {p for p in suspended if not within(p, r.path)}

    def state(path: str) -> str:
        if path in waiting:
            return "waiting"
        frozen = bool(suspended) and (path in suspended or not suspended.isdisjoint(_owners(path)))
        return "suspended" if frozen else "running"

    # earliest first, then by path: the order of the entries of one instant depends on when grants came back
    return sorted(({"path": p, "since": round(active[p], 6), "state": state(p)} for p in _leaves(active)),
                  key=lambda row: (row["since"], row["path"]))


def _waiting(records: Iterator[rec.Record]) -> list[dict[str, Any]]:
    """`[{path, since, needs, blocked_by: [{path, holds}], blockers}]`: each waiter with who is in its way after
    `records` (`current_blockers`), `holds` what that holder holds then (need -> unit)."""
    waiters = Waiters()
    for r in records:
        waiters.take(r)
    return waiters.waiting()


class LastRequest:
    """Each behavior's last request for resources: what it waits for, as a wait after a preemption names none
    (docs/trace.md; the dry-run's report, `explain` and a recording's `/drd/active` all read it so)."""

    def __init__(self) -> None:
        self._needs: dict[str, list[str]] = {}

    def take(self, r: rec.Waiting) -> list[str]:
        """The needs `r` waits for: its own, else the last ones its behavior asked."""
        if r.needs:
            self._needs[r.path] = list(r.needs)
        return self.of(r.path)

    def of(self, path: str) -> list[str]:
        return list(self._needs.get(path, ()))


class Waiters:
    """Who waits for resources, and behind whom, kept from a mission's records as they come (`take`): what
    `explain` says after the last record and a recording's `/drd/active` at each change."""

    def __init__(self) -> None:
        self.waits: dict[str, dict[str, Any]] = {}  # path -> the wait, in the order they began
        self.holds: dict[str, dict[str, str]] = {}  # path -> need -> unit, without aggregates' parts
        self.asked = LastRequest()
        self.units = UnitTypes()

    def take(self, r: rec.Record) -> None:
        self.units.take(r)
        if isinstance(r, rec.Waiting):
            needs = self.asked.take(r)
            w = self.waits.setdefault(r.path, {"path": r.path, "since": round(r.at, 6), "needs": needs,
                                               "blocked_by": []})
            if r.blocked_by:
                w["blocked_by"], w["held"] = list(r.blocked_by), r.holds
        elif isinstance(r, rec.Granted):
            self.waits.pop(r.path, None)
            self.holds[r.path] = {k: v for k, v in r.named.items() if "." not in k}
        elif isinstance(r, rec.Released):
            gone = set(r.resources)
            self.holds[r.path] = {k: v for k, v in self.holds.get(r.path, {}).items() if v not in gone}
        elif isinstance(r, rec.Exited):
            self.waits.pop(r.path, None)
            self.holds.pop(r.path, None)
        elif isinstance(r, rec.Restored):  # its holds ended (`released`), its waiters ask again
            for path in [p for p in self.waits if within(p, r.path)]:
                del self.waits[path]

    def waiting(self) -> list[dict[str, Any]]:
        """Each waiter now, with who is in its way (`current_blockers`) and what each of them holds."""
        by_type = self.units.holders_by_type(self.holds)
        return [blocked(w, self.holds, current_blockers(w, by_type, self.waits)) for w in self.waits.values()]


#: How many blockers a waiting behavior names with what each holds (`blocked_by`); `blockers` counts them all, so
#: a thousand waiters behind fifty holders stay linear in size (report, `--json`, `/drd/active`).
BLOCKERS_SHOWN = 3


class UnitTypes:
    """Which type each unit is, from this mission's records alone: a `waiting` or `reserved` record says the type
    of each need (`ranger: Ranger`), and a grant the unit each need got. Who is in a waiter's way now is read from
    it (`current_blockers`): the records say who blocked when a wait began, never again."""

    def __init__(self) -> None:
        self.needs: dict[str, dict[str, str]] = {}  # path -> need -> type
        self.types: dict[str, str] = {}  # unit -> type

    def take(self, r: rec.Record) -> None:
        if isinstance(r, rec.Waiting | rec.Reserved) and r.needs:
            self.needs[r.path] = dict(need_type(n) for n in r.needs)
        elif isinstance(r, rec.Granted):
            declared = self.needs.get(r.path, {})
            for need, unit in r.named.items():
                if need in declared:
                    self.types[unit] = declared[need]

    def holders_by_type(self, holds: dict[str, dict[str, str]]) -> dict[str, list[str]]:
        """Type -> the behaviors holding a unit of it now, for the types none of whose known units is free (a type
        with a free unit is not what a waiter waits for). `holds`: path -> need -> unit."""
        held: dict[str, set[str]] = {}
        for path, named in holds.items():
            for unit in named.values():
                kind = self.types.get(unit)
                if kind is not None:
                    held.setdefault(kind, set()).add(path)
        busy = {unit for named in holds.values() for unit in named.values()}
        free = {kind for unit, kind in self.types.items() if unit not in busy}
        return {kind: sorted(paths, key=natural) for kind, paths in held.items() if kind not in free}


def need_type(need: str) -> tuple[str, str]:
    """`ranger: Ranger` -> (`ranger`, `Ranger`)."""
    name, _, kind = need.partition(":")
    return name.strip(), kind.strip().split(" ", 1)[0]


def current_blockers(wait: dict[str, Any], by_type: dict[str, list[str]], waits: Collection[str]) -> list[str]:
    """Who is in `wait`'s way now, holders first (what a reader asks first: who has it): this mission's holders now
    of a unit of a type it needs (`UnitTypes.holders_by_type`), the waiters its `waiting` record named that still
    wait (ahead of it in the queue), and the other missions' blockers its record named (their holds are not in
    these records). A waiter whose record named nobody (nothing grants it) stays so."""
    recorded: list[str] = wait["blocked_by"]
    if not recorded:
        return []
    foreign = wait.get("held") or {}
    found: dict[str, None] = {}
    for need in wait["needs"]:
        found.update(dict.fromkeys(p for p in by_type.get(need_type(need)[1], ()) if p != wait["path"]))
    found.update(dict.fromkeys(b for b in recorded if b in waits and b != wait["path"]))
    found.update(dict.fromkeys(b for b in recorded if b in foreign))
    return list(found)


def blocked(wait: dict[str, Any], holds: dict[str, dict[str, str]], current: list[str] | None = None) -> dict[str, Any]:
    """A report's waiting behavior: `{path, since, needs, blocked_by: [{path, holds}], blockers}`, its first
    `BLOCKERS_SHOWN` blockers (`current`, else its record's) each with what it holds (need -> resource id), and how
    many there are. This mission's blockers' holds are from its records (`holds`, by path); another mission's
    blocker (`<mission id>/<path>`) has its `mission` too, and its holds are the `waiting` record's."""
    held: dict[str, dict[str, str]] = wait.get("held") or {}
    every = wait["blocked_by"] if current is None else current
    return {**{k: v for k, v in wait.items() if k not in ("held", "blocked_by")},
            "blocked_by": [{"path": b, "mission": b.partition("/")[0], "holds": held[b]} if b in held
                           else {"path": b, "holds": holds.get(b, {})} for b in every[:BLOCKERS_SHOWN]],
            "blockers": len(every)}


def natural(path: str) -> tuple[Any, ...]:
    """A sort key that orders `X[2]` before `X[10]`."""
    return tuple(int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path))


def _name(path: str) -> str:
    """The last step of a path: `Pair/lookouts[0]/Go` -> `Go`."""
    return path.rsplit("/", 1)[-1]


def _leaves(paths: Iterator[str] | dict[str, Any]) -> list[str]:
    """The paths with no other path below them, in their order: those that are no other's `_owners` (one pass
    over each path's characters rather than every pair: a 1,000-robot run has 2,000 active paths)."""
    every = list(paths)
    owners = {owner for q in every for owner in _owners(q)}
    return [p for p in every if p not in owners]


def within(path: str, root: str) -> bool:
    """Whether `path` is `root` or below it (`root/...`, `root[i]...`)."""
    return path == root or path.startswith((root + "/", root + "["))


def _owners(path: str) -> list[str]:
    """The prefixes of `path` that end just before a `/` or a `[`: the paths it is below."""
    return [path[:i] for i, c in enumerate(path) if c in "/["]
