"""The manager's bookkeeping: the resource registry with its usage, and the indexed wait queue.

Kept apart from the policy in `manager` so that each index has one owner that keeps it
consistent: usage sums per unit, per-unit heaps of claiming waiters, waiters per need type, and
waiters per ancestor path (for the wait-for graph).
"""

from __future__ import annotations

from bisect import insort
from collections.abc import Container, Iterable, Mapping
from dataclasses import dataclass, field
from heapq import heappop, heappush
from typing import Any

from drd.rcm.deadlock import ancestors
from drd.rcm.model import Aggregate, Candidate, NeedRequest, Request, Unit, units_of
from drd.rcm.solver import EPS, Solution, alternatives, demand_of

#: Queue order: (mission priority, priority, 0 for a due reservation else 1, reservation time, request order).
Key = tuple[int, int, int, float, int]


@dataclass(slots=True, eq=False)
class Wait:
    """A queued request. `claims` are the units of all its possible assignments."""

    request: Request
    key: Key
    since: int  # order of the first request, kept across revocations
    resumed: bool
    given: dict[str, Candidate]
    claims: frozenset[str] = frozenset()

    @property
    def holder(self) -> str:
        return self.request.holder

    def describe(self) -> dict[str, Any]:
        return {
            "holder": self.holder,
            "priority": self.request.priority,
            "mission": self.request.mission,
            "mission_priority": self.request.mission_priority,
            "needs": {n.name: n.type for n in self.request.needs},
            "resumed": self.resumed,
        }


@dataclass(slots=True, eq=False)
class Hold:
    """A grant in force. `alloc` covers intact needs; `loose` what is left of needs partly released."""

    request: Request
    gid: int
    since: int
    chosen: dict[str, Candidate]
    alloc: dict[str, dict[str, float]]
    given: dict[str, Candidate]
    lease_until: float
    slice_until: float
    granted_at: float
    loose: dict[str, float] = field(default_factory=dict)
    overtime: bool = False

    def names(self) -> tuple[str, ...]:
        """The needs still held whole."""
        return tuple(self.alloc)

    def quantities(self) -> dict[str, float]:
        """What the holder takes of each unit, in grant order."""
        total: dict[str, float] = {}
        for demand in (*self.alloc.values(), self.loose):
            for unit, quantity in demand.items():
                total[unit] = total.get(unit, 0.0) + quantity
        return total

    def give_back(self, names: set[str]) -> None:
        """Drop needs named by need name or candidate id, and units named by id.

        A need losing only some of its units is no longer intact: what remains of it is `loose`.
        """
        held = self.quantities().keys()
        for name, candidate in self.chosen.items():
            if name in self.alloc and (name in names or candidate.id in names):
                del self.alloc[name]
        unit_ids = names & held
        for name in [n for n, demand in self.alloc.items() if not unit_ids.isdisjoint(demand)]:
            for unit, quantity in self.alloc.pop(name).items():
                self.loose[unit] = self.loose.get(unit, 0.0) + quantity
        for unit in unit_ids:
            self.loose.pop(unit, None)

    def describe(self) -> dict[str, Any]:
        return {
            "priority": self.request.priority,
            "mission": self.request.mission,
            "mission_priority": self.request.mission_priority,
            "assignment": {n: c.id for n, c in self.chosen.items() if n in self.alloc},
            "units": list(self.quantities()),
            "granted_at": self.granted_at,
            "lease_until": self.lease_until,
            "slice_until": self.slice_until,
        }


@dataclass(slots=True, eq=False)
class Pending:
    """A reservation not yet due."""

    request: Request
    at: float
    order: int


class Registry:
    """Known units and aggregates (by type, in id order) and how much of each unit is in use.

    Implements the solver's `Catalog`. Epochs survive a unit's removal so that fencing tokens keep
    increasing when a host comes back.
    """

    def __init__(self) -> None:
        self.units: dict[str, Unit] = {}
        self.aggregates: dict[str, Aggregate] = {}
        self.epochs: dict[str, int] = {}
        self.epoch_floor = 0  # every unit's epochs are above it, those of units added later too (`raise_epochs`)
        self.used: dict[str, dict[str, float]] = {}  # unit -> holder -> quantity
        self.load: dict[str, float] = {}
        self.full: set[str] = set()  # units with no room left (capacity - load <= EPS), or offline
        #: units of a host seen down and not yet removed: kept (their grants survive a short freeze) but with no room
        #: for anyone new, so a waiter is not granted a robot whose host cannot run its components
        self.offline: set[str] = set()
        self.version = 0  # bumped on any change of resources or usage (what a cached answer depends on)
        self._by_type: dict[str, list[str]] = {}
        self._demands: dict[tuple[str, float], dict[str, float]] = {}
        self._typed: dict[str, tuple[Candidate, ...]] = {}
        self._typed_units: dict[str, tuple[str, ...]] = {}
        self._alternatives: dict[tuple[NeedRequest, ...], tuple[list[Solution], bool]] = {}

    def candidates(self, type: str) -> tuple[Candidate, ...]:
        """Units and aggregates of a type, by id (cached until a resource of that type changes)."""
        found = self._typed.get(type)
        if found is None:
            found = self._typed[type] = tuple(self.candidate(cid) for cid in self._by_type.get(type, ()))
        return found

    def units_of_type(self, type: str) -> tuple[str, ...]:
        """The units of the candidates of a type, once each, in candidate order (cached like `candidates`)."""
        found = self._typed_units.get(type)
        if found is None:
            units = dict.fromkeys(u for c in self.candidates(type) for u in units_of(c))
            found = self._typed_units[type] = tuple(units)
        return found

    def unit(self, unit_id: str) -> Unit:
        """A registered unit."""
        return self.units[unit_id]

    def demand(self, candidate: Candidate, need: NeedRequest) -> Mapping[str, float]:
        """What a candidate takes of its units for a need (cached: parts never change)."""
        key = (candidate.id, need.quantity)
        demand = self._demands.get(key)
        if demand is None:
            demand = self._demands[key] = demand_of(self, candidate, need)
        return demand

    def alternatives(
        self, needs: tuple[NeedRequest, ...], given: Mapping[str, Candidate], limit: int
    ) -> tuple[list[Solution], bool]:
        """`solver.alternatives`, cached per needs until any resource changes.

        The instances of one behavior share their needs, so a queue of a thousand RoomSurveillance
        instances enumerates their assignments once. `where` must depend only on its arguments.
        """
        if given:
            return alternatives(needs, self, given, limit)
        found = self._alternatives.get(needs)
        if found is None:
            found = self._alternatives[needs] = alternatives(needs, self, None, limit)
        return found

    def candidate(self, cid: str) -> Candidate:
        """A registered unit or aggregate."""
        found = self.units.get(cid) or self.aggregates.get(cid)
        if found is None:
            raise KeyError(f"unknown resource {cid!r}")
        return found

    def add(self, candidate: Candidate) -> None:
        if candidate.id in self.units or candidate.id in self.aggregates:
            raise ValueError(f"resource {candidate.id!r} is already registered")
        if isinstance(candidate, Aggregate):
            missing = [u for u in candidate.units if u not in self.units]
            if missing:
                raise ValueError(f"aggregate {candidate.id}: unknown part units {', '.join(missing)}")
            self.aggregates[candidate.id] = candidate
        else:
            self.units[candidate.id] = candidate
            self.epochs.setdefault(candidate.id, self.epoch_floor)
        self.version += 1
        insort(self._by_type.setdefault(candidate.type, []), candidate.id)
        self._typed.pop(candidate.type, None)
        self._typed_units.pop(candidate.type, None)
        self._alternatives.clear()

    def including(self, extra: Iterable[Candidate]) -> Registry:
        """A new registry of these resources and `extra` (those of a known id left out), unused: what could be."""
        found = Registry()
        known: dict[str, Candidate] = {**self.units, **self.aggregates}
        every = [*known.values(), *(c for c in extra if c.id not in known)]
        for candidate in sorted(every, key=lambda c: isinstance(c, Aggregate)):
            found.add(candidate)
        return found

    def replace(self, candidate: Candidate) -> None:
        """Swap in a new version of a registered resource (same id and type)."""
        self.version += 1
        if isinstance(candidate, Aggregate):
            self.aggregates[candidate.id] = candidate
        else:
            self.units[candidate.id] = candidate
            self._refill(candidate.id)  # a new capacity may change room
        self._typed.pop(candidate.type, None)
        self._alternatives.clear()

    def remove(self, cid: str) -> None:
        """Forget a resource; its usage must already be given back."""
        candidate = self.candidate(cid)
        self.version += 1
        ids = self._by_type[candidate.type]
        ids.remove(cid)
        if not ids:
            del self._by_type[candidate.type]
        self.aggregates.pop(cid, None)
        self.units.pop(cid, None)
        self.load.pop(cid, None)
        self.full.discard(cid)
        self.offline.discard(cid)
        self._demands.clear()
        self._typed.pop(candidate.type, None)
        self._typed_units.pop(candidate.type, None)
        self._alternatives.clear()

    def describe(self) -> dict[str, Any]:
        """Units (with usage and epochs) and aggregates as plain dicts."""
        units = {
            u: {
                "type": unit.type,
                "host": unit.host,
                "sharable": unit.sharable,
                "capacity": unit.capacity,
                "load": self.load.get(u, 0.0),
                "epoch": self.epochs[u],
                "holders": dict(sorted(self.used.get(u, {}).items())),
                "properties": dict(unit.properties),
                "offline": u in self.offline,
            }
            for u, unit in sorted(self.units.items())
        }
        aggregates = {
            a: {
                "type": agg.type,
                "host": agg.host,
                "parts": dict(agg.parts),
                "properties": dict(agg.properties),
            }
            for a, agg in sorted(self.aggregates.items())
        }
        return {"units": units, "aggregates": aggregates}

    def free(self, unit_id: str) -> float:
        """Room left on a unit: none while it is offline."""
        return 0.0 if unit_id in self.offline else self.units[unit_id].capacity - self.load.get(unit_id, 0.0)

    def set_offline(self, unit_ids: Iterable[str], offline: bool) -> None:
        """Take registered units offline (no room for anyone new; their holders keep them) or back online."""
        for unit_id in unit_ids:
            if offline:
                self.offline.add(unit_id)
            else:
                self.offline.discard(unit_id)
            self._refill(unit_id)
        self.version += 1

    def _refill(self, unit_id: str) -> None:
        """Keep `full` true to a unit's room."""
        if self.free(unit_id) <= EPS:
            self.full.add(unit_id)
        else:
            self.full.discard(unit_id)

    def set_use(self, unit_id: str, holder: str, quantity: float) -> None:
        """Record what `holder` takes of a unit (0 removes it), keeping the load sum exact."""
        self.version += 1
        used = self.used.setdefault(unit_id, {})
        if quantity > 0:
            used[holder] = quantity
        else:
            used.pop(holder, None)
        if used:
            self.load[unit_id] = sum(used.values())
        else:
            del self.used[unit_id]
            self.load[unit_id] = 0.0
        self._refill(unit_id)

    def next_epoch(self, unit_id: str) -> int:
        self.epochs[unit_id] += 1
        return self.epochs[unit_id]

    def raise_epochs(self, floor: int) -> None:
        """Every unit's next epochs above `floor`, the units known now and those added later."""
        self.epoch_floor = max(self.epoch_floor, floor)
        for unit_id, epoch in self.epochs.items():
            self.epochs[unit_id] = max(epoch, floor)


@dataclass(slots=True, eq=False)
class ClaimGroup:
    """The waiters that claim one same set of units (the instances of one behavior, as a rule).

    One heap per claim set rather than one per unit: 950 waiters claiming 4,000 units are 950 entries, not
    3.8 million, and a unit's head is the best of the heads of the few groups claiming it. Stale entries
    (members gone, re-keyed or moved to another group) are dropped lazily by `WaitQueue.group_head`.
    """

    units: frozenset[str]
    heap: list[tuple[Key, str]] = field(default_factory=list)
    members: set[str] = field(default_factory=set)
    #: `WaitQueue.atoms` cache: (the queue's structure version it was computed at, the atoms)
    atoms: tuple[int, list[tuple[frozenset[str], tuple[ClaimGroup, ...]]]] = (-1, [])


class WaitQueue:
    """Waiting requests, indexed so that nothing scans the whole queue.

    - waiters are grouped by the set of units they claim (`ClaimGroup`: a heap of (key, holder) per set), and
      each unit knows the groups claiming it, so the best-placed claimant of a unit is the best of a few group
      heads; the units of a group split into atoms (units claimed by exactly the same groups, hence with the
      same head), so serving the claimants of a whole claim set looks at one head per atom, not per unit;
    - per need type, the waiters asking for it (to reconsider when such resources change);
    - per path, the waiting descendants, and `nested`: waiters with a holding ancestor.
    """

    def __init__(self) -> None:
        self.waits: dict[str, Wait] = {}
        self.nested: set[str] = set()
        self._group_of: dict[str, ClaimGroup] = {}
        self._groups: dict[frozenset[str], ClaimGroup] = {}  # live groups by claim set (content)
        self._unit_groups: dict[str, list[ClaimGroup]] = {}  # unit -> groups claiming it, in creation order
        self._version = 0  # bumped when a group appears or goes, or a unit is dropped: atoms are stale then
        self._typed: dict[str, set[str]] = {}
        self._desc: dict[str, set[str]] = {}

    def __contains__(self, holder: object) -> bool:
        return holder in self.waits

    def get(self, holder: str) -> Wait | None:
        return self.waits.get(holder)

    def add(self, wait: Wait, claims: frozenset[str], holding: Container[str]) -> None:
        holder = wait.holder
        self.waits[holder] = wait
        wait.claims = frozenset()
        self.reclaim(wait, claims)
        for need in wait.request.needs:
            self._typed.setdefault(need.type, set()).add(holder)
        for path in ancestors(holder):
            self._desc.setdefault(path, set()).add(holder)
            if path in holding:
                self.nested.add(holder)

    def remove(self, wait: Wait) -> None:
        holder = wait.holder
        del self.waits[holder]
        self._leave(holder)
        for type in {need.type for need in wait.request.needs}:
            typed = self._typed[type]
            typed.discard(holder)
            if not typed:
                del self._typed[type]
        for path in ancestors(holder):
            self._desc[path].discard(holder)
            if not self._desc[path]:
                del self._desc[path]
        self.nested.discard(holder)

    def reclaim(self, wait: Wait, claims: frozenset[str]) -> None:
        """Set the units a waiter claims: it moves to the group of that set; the same set again costs nothing."""
        if claims is wait.claims:
            return
        holder = wait.holder
        group = self._group_of.get(holder)
        wait.claims = claims
        if group is not None and group.units == claims and self._groups.get(claims) is group:
            return
        self._leave(holder)
        if claims:
            self._join(wait, claims)

    def _join(self, wait: Wait, claims: frozenset[str]) -> None:
        group = self._groups.get(claims)
        if group is None:
            group = self._groups[claims] = ClaimGroup(claims)
            for unit in claims:
                self._unit_groups.setdefault(unit, []).append(group)
            self._version += 1
        heappush(group.heap, (wait.key, wait.holder))
        group.members.add(wait.holder)
        self._group_of[wait.holder] = group

    def _leave(self, holder: str) -> None:
        group = self._group_of.pop(holder, None)
        if group is None:
            return
        group.members.discard(holder)
        if not group.members:
            self._drop_group(group)
        elif len(group.heap) > 2 * len(group.members) + 32:  # mostly stale: rebuild from the members
            group.heap = [(self.waits[h].key, h) for h in group.members]
            group.heap.sort()

    def _drop_group(self, group: ClaimGroup) -> None:
        if self._groups.get(group.units) is group:
            del self._groups[group.units]
        for unit in group.units:
            groups = self._unit_groups.get(unit)
            if groups is not None and group in groups:
                groups.remove(group)
                if not groups:
                    del self._unit_groups[unit]
        group.heap.clear()
        self._version += 1

    def group_head(self, group: ClaimGroup) -> tuple[Key, str] | None:
        """The best-placed member of a group."""
        heap = group.heap
        while heap:
            key, holder = heap[0]
            if self._group_of.get(holder) is group and self.waits[holder].key == key:
                return key, holder
            heappop(heap)
        return None

    def best(self, groups: Iterable[ClaimGroup]) -> tuple[Key, str] | None:
        """The best-placed member of any of the groups."""
        found: tuple[Key, str] | None = None
        for group in groups:
            head = self.group_head(group)
            if head is not None and (found is None or head < found):
                found = head
        return found

    def head(self, unit: str) -> tuple[Key, str] | None:
        """The best-placed waiter claiming a unit."""
        groups = self._unit_groups.get(unit)
        return self.best(groups) if groups else None

    def group(self, claims: frozenset[str]) -> ClaimGroup | None:
        """The live group of waiters claiming exactly these units, if any."""
        return self._groups.get(claims)

    def atoms(self, group: ClaimGroup) -> list[tuple[frozenset[str], tuple[ClaimGroup, ...]]]:
        """A group's units split by the groups that claim them (units with one head each), with those groups.

        Cached until a group appears or goes; computed from each unit's groups, so O(units of the group)."""
        version, atoms = group.atoms
        if version == self._version:
            return atoms
        split: dict[tuple[int, ...], tuple[list[str], list[ClaimGroup]]] = {}
        unit_groups = self._unit_groups
        for unit in group.units:
            groups = unit_groups.get(unit)
            if not groups:
                continue  # dropped: no longer a resource
            sig = tuple(map(id, groups))  # lists keep creation order, so one set of groups has one signature
            found = split.get(sig)
            if found is None:
                split[sig] = ([unit], groups)
            else:
                found[0].append(unit)
        atoms = [(frozenset(units), tuple(groups)) for units, groups in split.values()]
        group.atoms = (self._version, atoms)
        return atoms

    def claimants(self, unit: str) -> set[str]:
        """Every waiter claiming a unit."""
        return {h for group in self._unit_groups.get(unit, ()) for h in group.members}

    def drop_unit(self, unit: str) -> None:
        """A unit is gone: no one claims it any more (its claimants are reconsidered by the manager)."""
        for group in self._unit_groups.pop(unit, ()):
            if self._groups.get(group.units) is group:
                del self._groups[group.units]  # a claim set naming a removed unit: a new one is a new group
        self._version += 1

    def of_type(self, type: str) -> list[str]:
        """The waiters with a need of this type, best-placed first."""
        return sorted(self._typed.get(type, ()), key=lambda h: self.waits[h].key)

    def descendants(self, path: str) -> set[str]:
        return self._desc.get(path, set())

    def hold_added(self, holder: str) -> None:
        self.nested.update(self._desc.get(holder, ()))

    def hold_removed(self, holder: str, holding: Container[str]) -> None:
        for waiter in self._desc.get(holder, ()):
            if not any(path in holding for path in ancestors(waiter)):
                self.nested.discard(waiter)

    def order(self) -> list[str]:
        """Every waiter, best-placed first."""
        return [h for _, h in sorted((w.key, h) for h, w in self.waits.items())]
