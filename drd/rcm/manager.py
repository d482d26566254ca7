"""The Resource Pool: who gets which units, when, and who waits (pure, no I/O, no clock).

Every public call takes `now` (seconds) and returns a tuple of decision records; time only moves
through those arguments. Each call first applies what became due by `now` (expired leases, slice
boundaries, reservations coming due), so the outcome does not depend on how often `tick` is called.

Policy:

- All-or-nothing: a request is granted only when every need is met at once (`solver`).
- Priority 1 first. A waiting request *claims* every unit it might use (the units of all its
  possible assignments). A unit is usable by a request only if no better-placed waiter claims it,
  so a lower priority waits while a higher one waits for or holds any unit it needs, and equal
  priorities queue FIFO (by request order). Claims are indexed per unit in heaps, so a request or a
  freed unit only looks at the head waiter of the units involved: O(log n) in the queue length.
- Slices: a holder keeps its exclusive units for at least its slice (`NeedRequest.slice`, else the
  longest `Unit.slice` among the need's exclusive units, else `default_slice`; the longest of its
  exclusive needs). From that slice boundary on it is in
  overtime: an equal- or higher-priority waiter that can then be granted takes its units at once,
  and the holder is `Revoked` (suspended) and queued again at the back of its priority; it is
  resumed later by a `Granted(resumed=True)` (resuming is that flag, not a record of its own) on
  the very resources taken from it: its re-queued needs are `Pinned` to them. If one of them is
  removed meanwhile, it is `Unsatisfiable`, naming that resource. Equal priorities thus rotate round-robin and a
  higher priority displaces a lower one at the holder's slice boundary, never before. Sharable
  units are never preempted, and a holder is never preempted by its own descendant or ancestor.
- Sharable units: the quantities granted on a unit never exceed its capacity.
- Leases: a grant lasts `lease` seconds unless renewed; at `now >= lease_until` it is
  `Released("expired")`. Waiting requests have no lease.
- Fencing: a unit's epoch strictly increases with each grant of it (kept across hot-plug).
- Deadlocks: a holder path is owned by its prefixes, so "A" holding X while "A/child" waits is
  hold-and-wait. The wait-for graph (waiter -> holders and better claimants that alone stand in
  its way; holder -> its waiting descendants) is searched with networkx whenever some holder has
  a waiting descendant. Resolution: the victim is the waiting request on the cycle with the
  lowest priority (largest number), ties broken by the most recent first request; its request is
  cancelled and reported as `Deadlock(cycle, victim)`.
- Reservations (preallocation): a reserved request holds nothing before `at`; from `at` it queues
  ahead of every request of equal priority.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection, Iterable, Mapping
from heapq import heappop, heappush
from itertools import count, islice
from typing import Any

from drd.rcm.deadlock import choose_victim, find_cycle, same_owner
from drd.rcm.model import (
    Aggregate,
    Candidate,
    Deadlock,
    Decision,
    Granted,
    NeedRequest,
    Released,
    ReleaseReason,
    Renewed,
    Request,
    Reserved,
    Revoked,
    Unit,
    Unsatisfiable,
    Waiting,
    units_of,
)
from drd.rcm.solver import EPS, Solution, diagnose, first_solution, solutions
from drd.rcm.state import Hold, Key, Pending, Registry, Wait, WaitQueue

# Event kinds, in the order they are applied when due at the same instant.
_LEASE, _RESERVE, _SLICE = 0, 1, 2
#: An event due within this of `now` is due now: callers step time in floating-point increments (0.1 s ten times
#: is 0.9999999999999999 s), and a slice due at 5 s must end in the cycle at 5 s, not in the next one.
TIME_EPS = 1e-6


@dataclasses.dataclass(frozen=True, slots=True)
class Pinned:
    """The `where` of a suspended holder's re-queued need: only the resource it held (spec: "resumed when it gets
    it back"), whatever the need's own `where` says of it now. A `where` chooses what a holder gets; a holder keeps
    its grant when it no longer holds (a Scout its own LaunchScout threw is no longer carried), and so does one
    suspended meanwhile (safety audit 25, D2: such a holder could never resume, and failed its mission). Equal pins
    are equal, so the waiters' alternatives are cached as for any `where`."""

    id: str

    def __call__(self, candidate: Candidate, chosen: Mapping[str, Candidate]) -> bool:
        return candidate.id == self.id

    def narrow(self, candidates: Iterable[Candidate], chosen: Mapping[str, Candidate]) -> Iterable[Candidate]:
        """Only the pinned one: the solver need not look at the others."""
        return [c for c in candidates if c.id == self.id]


class _FreeFirst:
    """The registry as a preempting search reads it (`solver.Catalog`): each type's candidates grouped by kind (the
    robot type a unit is part of; an aggregate's own type), the kinds in the order they first come, and within a
    kind the free candidates before the held ones, each group in its own order. Made for one search."""

    def __init__(self, reg: Registry) -> None:
        self._reg = reg
        self._owners = {u: a.type for a in reg.aggregates.values() for u in a.units}
        self._typed: dict[str, tuple[Candidate, ...]] = {}

    def kind(self, candidate: Candidate) -> str:
        return candidate.type if isinstance(candidate, Aggregate) else self._owners.get(candidate.id, candidate.type)

    def kinds(self, solution: Solution) -> tuple[str, ...]:
        return tuple(self.kind(c) for c in solution.chosen.values())

    def candidates(self, type: str) -> tuple[Candidate, ...]:
        found = self._typed.get(type)
        if found is None:
            ordered = self._reg.candidates(type)
            rank: dict[str, int] = {}
            for c in ordered:
                rank.setdefault(self.kind(c), len(rank))
            used, units = self._reg.used, self._reg.units

            def held(c: Candidate) -> bool:
                return any(used.get(u) and not units[u].sharable for u in units_of(c))

            found = self._typed[type] = tuple(sorted(ordered, key=lambda c: (rank[self.kind(c)], held(c))))
        return found

    def unit(self, unit_id: str) -> Unit:
        return self._reg.unit(unit_id)

    def demand(self, candidate: Candidate, need: NeedRequest) -> Mapping[str, float]:
        return self._reg.demand(candidate, need)


class ResourceManager:
    """The Resource Controller Manager's decisions, as a pure state machine (see module docstring).

    :param lease: seconds a grant lasts without `renew`.
    :param default_slice: minimum holding time on exclusive units when a need sets none.
    :param max_alternatives: assignments enumerated per waiting request to compute its claims;
        beyond it a waiter claims every unit of its need types (safe, just less precise).
    """

    def __init__(self, *, lease: float = 3.0, default_slice: float = 5.0, max_alternatives: int = 256) -> None:
        if not (lease > 0 and default_slice > 0 and max_alternatives > 0):
            raise ValueError("lease, default_slice and max_alternatives must be > 0")
        self.lease = lease
        self.default_slice = default_slice
        self.max_alternatives = max_alternatives
        self._now = -math.inf
        self._order = count()
        self._reg = Registry()
        self._queue = WaitQueue()
        self._holds: dict[str, Hold] = {}
        self._pending: dict[str, Pending] = {}
        self._overtime: set[str] = set()
        #: exclusive units held by a holder in overtime: full, yet a waiter may get them (`_may_open`)
        self._ot_units: set[str] = set()
        self._events: list[tuple[float, int, int, str]] = []  # (time, kind, token, holder)
        self._frees = 0  # bumped whenever capacity is given back
        #: (id of a list of alternatives, capped, needs) -> (that list, its claims, their units): `_claims`' memo
        self._claims_memo: dict[tuple[int, bool, tuple[NeedRequest, ...]],
                                tuple[list[Solution], dict[str, float], frozenset[str]]] = {}
        self._interned: dict[frozenset[str], frozenset[str]] = {}  # `_claim_set`'s shared sets
        self._needs: dict[tuple[NeedRequest, ...], tuple[NeedRequest, ...]] = {}  # `_canonical`'s shared tuples
        #: `_blockers_of`' memo of the holders in the way of a claims' demand: (registry version, demand, them)
        self._held_memo: tuple[int, dict[str, float] | None, frozenset[str]] = (-1, None, frozenset())
        #: host -> the resources it had when `remove_host` dropped them, until it adds one again: a need that one of
        #: them would meet is told that its host is down, not that no robot satisfies it (cluster audit 19, #4)
        self._shelf: dict[str, list[Candidate]] = {}

    # -- hot-plug and the Static Dependency Database -------------------------------------------

    def add_unit(self, unit: Unit, now: float) -> tuple[Decision, ...]:
        """Register an RC; waiters of its type are reconsidered (it may be just what they need)."""
        out = self._begin(now)
        self._reg.add(unit)
        self._shelf.pop(unit.host, None)
        self._reconsider(self._queue.of_type(unit.type), now, out, {unit.id})
        return self._finish(now, out)

    def add_aggregate(self, aggregate: Aggregate, now: float) -> tuple[Decision, ...]:
        """Register an ARC instance; its parts must be registered units."""
        out = self._begin(now)
        self._reg.add(aggregate)
        self._shelf.pop(aggregate.host, None)
        self._reconsider(self._queue.of_type(aggregate.type), now, out, set(aggregate.units))
        return self._finish(now, out)

    def remove_host(self, host: str, now: float) -> tuple[Decision, ...]:
        """A host is gone: drop its units and aggregates (and aggregates using its units).

        Every holder of a lost unit or aggregate loses its whole grant (`Released("host lost")`),
        waiters that can no longer ever be met get `Unsatisfiable`, the rest keep waiting.
        """
        reg = self._reg
        ids = [u for u, unit in reg.units.items() if unit.host == host]
        ids += [a for a, agg in reg.aggregates.items() if agg.host == host]
        if ids:
            self._shelf[host] = [reg.candidate(cid) for cid in ids]
        return self.remove(ids, now, "host lost")

    def shelve(self, host: str, resources: Iterable[Candidate]) -> None:
        """Resources of `host` the manager does not have now (a configured host down, or not joined yet), kept aside
        until it adds one: a need only they would meet is told that the host is down (`_diagnose`), not that no
        robot satisfies it (cluster audit 20, #4: a controller restarted while ranger2 was down). No decision."""
        found = [c for c in resources if c.id not in self._reg.units and c.id not in self._reg.aggregates]
        if found:
            self._shelf[host] = found

    def shelf_waiters(self) -> dict[str, list[str]]:
        """Holder -> the hosts on the shelf (down, or not joined) whose resources could serve that waiter: it waits
        for them too, as for the holders in its way (faults audit 21, #2: `status` named only the holder of the
        other Ranger while the host down was what it waited for). Read-only, for `missionctl status`."""
        if not self._shelf or not self._queue.waits:
            return {}
        found: dict[str, list[str]] = {}
        for host, resources in sorted(self._shelf.items()):
            ids, reg = {c.id for c in resources}, self._reg.including(resources)
            for holder in self._queue.order():
                wait = self._queue.waits[holder]
                alts, _ = reg.alternatives(wait.request.needs, wait.given, self.max_alternatives)
                if any(c.id in ids for alt in alts for c in alt.chosen.values()):
                    found.setdefault(holder, []).append(host)
        return found

    def shelved(self, rid: str) -> Candidate | None:
        """A resource on the shelf by id (its host is down or not joined), or None: the `where` of a need only it
        would meet reads it (`scout.carrier.id == "ranger2"` while ranger2's host is down: cluster audit 20, #5)."""
        for found in self._shelf.values() if self._shelf else ():
            for c in found:
                if c.id == rid:
                    return c
        return None

    def set_host_offline(self, host: str, offline: bool, now: float) -> tuple[Decision, ...]:
        """A host seen down (`offline`) keeps its units until `remove_host`, grants and all (a short freeze costs
        nothing), but none of them is granted to anyone new: a waiter would get a robot whose components cannot run.
        Back online, the waiters they may serve are served."""
        out = self._begin(now)
        units = [u for u, unit in self._reg.units.items() if unit.host == host]
        self._reg.set_offline(units, offline)
        if not offline and units:
            self._frees += 1  # room given back: waiters that failed before are tried again
            self._dispatch(units, now, out)
        return self._finish(now, out)

    def remove(self, resource_ids: Iterable[str], now: float,
               reason: ReleaseReason = "resource lost") -> tuple[Decision, ...]:
        """Resources are gone (a robot lost, a host down): units and aggregates by id, plus every aggregate
        using a removed unit. Holders of any of them lose their whole grant (`Released(reason)`); waiters
        that can no longer be met get `Unsatisfiable`; unknown ids are ignored (it may be gone already)."""
        out = self._begin(now)
        reg = self._reg
        wanted = set(resource_ids)
        units = {u for u in reg.units if u in wanted}
        aggs = {a for a, agg in reg.aggregates.items() if a in wanted or not units.isdisjoint(agg.units)}
        touched = units.union(*(reg.aggregates[a].units for a in aggs))
        lost = {
            h
            for u in touched
            for h in reg.used.get(u, ())
            if not units.isdisjoint(self._holds[h].quantities())
            or any(c.id in aggs for c in self._holds[h].chosen.values())
        }
        affected = {h for u in touched for h in self._queue.claimants(u)}
        freed: set[str] = set()
        for holder in sorted(lost):
            hold = self._holds[holder]
            needs = hold.names()
            cause = sorted({u for u in hold.quantities() if u in units} | {c.id for c in hold.chosen.values()
                                                                           if c.id in aggs})
            released = self._end_hold(holder)
            out.append(Released(holder, released, reason, needs, tuple(cause)))
            freed.update(released)
        for cid in sorted(aggs | units):
            reg.remove(cid)
            self._queue.drop_unit(cid)
        self._reconsider(sorted(affected, key=lambda h: self._queue.waits[h].key), now, out, freed)
        return self._finish(now, out)

    def set_property(self, resource_id: str, key: str, value: object, now: float | None = None) -> tuple[Decision, ...]:
        """Change a static dependency (a launched Scout leaves its magazine).

        Waiters with a need of that type are reconsidered; holders keep what they were granted.
        Without `now`, the time of the previous call is used.
        """
        if now is None:
            now = self._now if self._now > -math.inf else 0.0
        out = self._begin(now)
        old = self._reg.candidate(resource_id)
        self._reg.replace(dataclasses.replace(old, properties={**old.properties, key: value}))
        self._reconsider(self._queue.of_type(old.type), now, out, set())
        return self._finish(now, out)

    # -- requests --------------------------------------------------------------------------------

    def request(self, request: Request, now: float) -> tuple[Decision, ...]:
        """Ask for all needs of a behavior: `Granted`, `Waiting` or `Unsatisfiable` (+ effects)."""
        out = self._begin(now)
        self._check_new_holder(request.holder)
        self._admit(self._canonical(request), now, out)
        return self._finish(now, out)

    def reserve(self, request: Request, now: float, at: float) -> tuple[Decision, ...]:
        """Preallocate: from `at` the request queues ahead of all requests of its priority.

        It holds and claims nothing before `at` (so it cannot create hold-and-wait):
        `Reserved` now, then `Granted` or `Waiting` once due.
        """
        out = self._begin(now)
        self._check_new_holder(request.holder)
        request = self._canonical(request)
        problem = self._diagnose(request.needs)
        if at <= now or problem is not None:
            self._admit(request, now, out, reserved_at=at)
        else:
            order = next(self._order)
            self._pending[request.holder] = Pending(request, at, order)
            heappush(self._events, (at, _RESERVE, order, request.holder))
            out.append(Reserved(request.holder, at))
        return self._finish(now, out)

    def release(self, holder: str, now: float, units: Collection[str] | None = None) -> tuple[Decision, ...]:
        """Give back everything, or only `units` (need names, candidate ids or unit ids).

        A need is released whole by its name or candidate id; releasing a single unit of a need
        keeps the need's other units held, but that need is no longer resumed after a revocation.
        Names not held are ignored (a release racing a revocation is harmless). Releasing
        everything while suspended withdraws the queued request.
        """
        out = self._begin(now)
        hold = self._holds.get(holder)
        wait = self._queue.get(holder)
        if hold is None:
            if wait is not None and units is None:
                self._withdraw(wait, "release", now, out)
            return self._finish(now, out)
        changed: tuple[str, ...] = ()
        before = hold.names()
        if units is None:
            freed = self._end_hold(holder)
        else:
            freed, changed = self._release_part(hold, set(units))
        if freed or changed:
            left = set(hold.alloc) if holder in self._holds else set()
            out.append(Released(holder, freed, "release", tuple(n for n in before if n not in left)))
            self._dispatch((*freed, *changed), now, out)
        return self._finish(now, out)

    def renew(self, holder: str, now: float) -> tuple[Decision, ...]:
        """Keep a grant alive for another `lease` seconds; nothing if it is not held (any more)."""
        out = self._begin(now)
        hold = self._holds.get(holder)
        if hold is not None:
            hold.lease_until = now + self.lease
            heappush(self._events, (hold.lease_until, _LEASE, hold.gid, holder))
            out.append(Renewed(holder, hold.lease_until))
        return self._finish(now, out)

    def cancel(self, holder: str, now: float) -> tuple[Decision, ...]:
        """Drop a holder's grant, queued request or reservation: `Released("cancelled")`."""
        out = self._begin(now)
        wait = self._queue.get(holder)
        if holder in self._holds:
            needs = self._holds[holder].names()
            units = self._end_hold(holder)
            out.append(Released(holder, units, "cancelled", needs))
            self._dispatch(units, now, out)
        elif wait is not None:
            self._withdraw(wait, "cancelled", now, out)
        elif self._pending.pop(holder, None) is not None:
            out.append(Released(holder, (), "cancelled"))
        return self._finish(now, out)

    def tick(self, now: float) -> tuple[Decision, ...]:
        """Apply what is due by `now`: lease expiry, slice boundaries, reservations."""
        return self._finish(now, self._begin(now))

    # -- queries -----------------------------------------------------------------------------

    def holders(self, unit_id: str) -> tuple[str, ...]:
        """Who holds a unit now."""
        return tuple(sorted(self._reg.used.get(unit_id, ())))

    def distinct(self, needs: tuple[NeedRequest, ...], limit: int = 10_000) -> int:
        """How many requests of these needs could hold distinct resources, as far as the known resources go: for
        the need with the most choices, the number of candidates (honoring `where`) that fill it in some complete
        assignment, capacity only (what is held now does not count). `limit` bounds the assignments looked at."""
        seen: dict[str, set[str]] = {n.name: set() for n in needs}
        units = self._reg.units
        for solution in islice(solutions(needs, self._reg, lambda u: units[u].capacity), limit):
            for name, candidate in solution.chosen.items():
                seen[name].add(candidate.id)
        return max((len(ids) for ids in seen.values()), default=0)

    def never(self, needs: tuple[NeedRequest, ...]) -> str | None:
        """Why these needs can never be met on the known resources (`need: reason`, as an `Unsatisfiable` says
        it), or None if they can."""
        found = self._diagnose(needs)
        return None if found is None else f"resource need {found[0]} can never be satisfied: {found[1]}"

    def epochs_above(self, floor: int) -> None:
        """Grant every unit from now on at epochs above `floor`: a controller that takes over the grants of another
        (restarted, elected) must never give an epoch the other gave, or a grant of its would look like one of the
        other's (safety audit 25, D1)."""
        self._reg.raise_epochs(floor)

    def highest_epoch(self) -> int:
        """The highest epoch given (or started above) so far, of any unit."""
        return max(self._reg.epochs.values(), default=self._reg.epoch_floor)

    def queue(self) -> tuple[str, ...]:
        """The waiting holders in the order they would be served (due reservations first)."""
        return tuple(self._queue.order())

    def snapshot(self) -> dict[str, Any]:
        """The whole state as plain dicts and lists, for `missionctl resources` and JSON traces."""
        return {
            "time": None if self._now == -math.inf else self._now,
            **self._reg.describe(),
            "holds": {h: hold.describe() for h, hold in sorted(self._holds.items())},
            "queue": [self._queue.waits[h].describe() for h in self._queue.order()],
            "reservations": {h: {"priority": p.request.priority, "mission_priority": p.request.mission_priority,
                                 "at": p.at} for h, p in sorted(self._pending.items())},
        }

    def waiters(self) -> list[tuple[Request, frozenset[str], tuple[str, ...]]]:
        """Each waiter in service order: its request, the units it claims (the queues it really stands in: a `where`
        narrows them) and who is in its way now (as its `Waiting` names them). Read-only, for `missionctl status`:
        a queue rebuilt from need types alone lists a waiter under robots it can never take."""
        found = []
        for holder in self._queue.order():
            wait = self._queue.waits[holder]
            alts, capped = self._reg.alternatives(wait.request.needs, wait.given, self.max_alternatives)
            blockers = self._blockers_of(wait, self._claims_of(wait, alts, capped)) if alts else set()
            found.append((wait.request, wait.claims, tuple(sorted(blockers))))
        return found

    # -- time ----------------------------------------------------------------------------------

    def _begin(self, now: float) -> list[Decision]:
        """Check the clock and apply every event due by `now`, in time order."""
        if now < self._now:
            raise ValueError(f"time went backwards: {now} < {self._now}")
        self._now = now
        out: list[Decision] = []
        while self._events and self._events[0][0] <= now + TIME_EPS:
            time, kind, token, holder = heappop(self._events)
            hold = self._holds.get(holder)
            if kind == _LEASE and hold is not None and hold.gid == token and hold.lease_until == time:
                needs = hold.names()
                units = self._end_hold(holder)
                out.append(Released(holder, units, "expired", needs))
                self._dispatch(units, now, out)
            elif kind == _SLICE and hold is not None and hold.gid == token:
                hold.overtime = True
                self._overtime.add(holder)
                exclusive = [u for u in hold.quantities() if not self._reg.units[u].sharable]
                self._ot_units.update(exclusive)
                self._dispatch(exclusive, now, out)
            elif kind == _RESERVE and holder in self._pending and self._pending[holder].order == token:
                pending = self._pending.pop(holder)
                self._admit(pending.request, now, out, reserved_at=pending.at, since=pending.order)
        return out

    def _finish(self, now: float, out: list[Decision]) -> tuple[Decision, ...]:
        """Break wait-for cycles (only possible while some holder has a waiting descendant)."""
        while self._queue.nested:
            cycle = find_cycle(self._queue.nested, self._successors)
            if cycle is None:
                break
            victim = choose_victim((h for h in cycle if h in self._queue), self._rank)
            wait = self._queue.waits[victim]
            self._queue.remove(wait)
            out.append(Deadlock(cycle, victim))
            self._dispatch((), now, out, (wait.claims,))
        return tuple(out)

    # -- the queue -----------------------------------------------------------------------------

    def _admit(
        self,
        request: Request,
        now: float,
        out: list[Decision],
        *,
        reserved_at: float | None = None,
        since: int | None = None,
    ) -> None:
        order = next(self._order)
        key = (*request.rank, 1, 0.0, order) if reserved_at is None else (*request.rank, 0, reserved_at, order)
        wait = Wait(request, key, order if since is None else since, resumed=False, given={})
        touched = self._try_grant(wait, now, out)
        if touched is not None:
            self._dispatch(touched[0], now, out, touched[1])
            return
        alts, capped = self._reg.alternatives(request.needs, {}, self.max_alternatives)
        if not alts:  # not even on an empty system: say which need and why
            out.append(Unsatisfiable(request.holder, *(self._diagnose(request.needs) or ("", ""))))
            return
        demand = self._enqueue(wait, alts, capped)
        out.append(Waiting(request.holder, tuple(sorted(self._blockers_of(wait, demand)))))

    def _enqueue(self, wait: Wait, alts: list[Solution] | None = None, capped: bool = False) -> dict[str, float]:
        """Queue a request with the units it claims; returns the most it may take of each."""
        if alts is None:
            alts, capped = self._reg.alternatives(wait.request.needs, wait.given, self.max_alternatives)
        demand = self._claims_of(wait, alts, capped)
        self._queue.add(wait, self._claim_set(wait, alts, capped), self._holds)
        return demand

    def _withdraw(self, wait: Wait, reason: ReleaseReason, now: float, out: list[Decision]) -> None:
        self._queue.remove(wait)
        out.append(Released(wait.holder, (), reason))
        self._dispatch((), now, out, (wait.claims,))

    def _claims_of(self, wait: Wait, alts: list[Solution], capped: bool) -> dict[str, float]:
        """The units of all possible assignments, with the most each assignment takes of them (read-only: shared
        by the waiters of equal needs).

        Memoized per list of alternatives (the registry's cache hands the same list to every instance of a
        behavior until a resource changes), with the set of units interned (`_claim_set`), so a thousand waiters
        of one behavior cost one pass over a thousand candidates' units, not a thousand, after each launch."""
        return self._claims(wait, alts, capped)[0]

    def _claim_set(self, wait: Wait, alts: list[Solution], capped: bool) -> frozenset[str]:
        """The units `_claims_of` gives, as one shared frozenset per content, so an unchanged claim is the same
        object (and `WaitQueue.reclaim` has nothing to do)."""
        return self._claims(wait, alts, capped)[1]

    def _claims(self, wait: Wait, alts: list[Solution], capped: bool) -> tuple[dict[str, float], frozenset[str]]:
        key = (id(alts), capped, wait.request.needs)
        memo = self._claims_memo.get(key)
        if memo is not None and memo[0] is alts:
            return memo[1], memo[2]
        if len(self._claims_memo) > 64:
            self._claims_memo.clear()
        demand = self._claims_fresh(wait, alts, capped)
        units = frozenset(demand)
        found = self._interned.get(units)
        if found is None:
            if len(self._interned) > 256:
                self._interned.clear()
            found = self._interned[units] = units
        self._claims_memo[key] = (alts, demand, found)
        return demand, found

    def _claims_fresh(self, wait: Wait, alts: list[Solution], capped: bool) -> dict[str, float]:
        demand: dict[str, float] = {}
        for solution in alts:
            for unit, quantity in solution.totals.items():
                demand[unit] = max(quantity, demand.get(unit, 0.0))
        if capped:  # too many assignments to list: claim every unit of the need types
            every: dict[str, float] = {}
            for need in reversed(wait.request.needs):  # the first need of a type sets the quantity
                every.update(dict.fromkeys(self._reg.units_of_type(need.type), need.quantity))
            every.update(demand)  # an assignment's quantity, where there is one
            return every
        return demand

    def _reconsider(self, holders: Iterable[str], now: float, out: list[Decision], extra: set[str]) -> None:
        """Recompute the claims of waiters after the resources changed, then serve who can be."""
        seen: dict[int, frozenset[str]] = {}  # the claim sets to serve, once each (waiters of a behavior share one)

        def touch(claims: frozenset[str]) -> None:
            seen.setdefault(id(claims), claims)

        # Waiters of one behavior have one needs tuple (`_canonical`): their alternatives and claims are found
        # once here, and each of a thousand waiters costs a dict lookup and an identity test.
        shared: dict[int, tuple[tuple[NeedRequest, ...], list[Solution], frozenset[str]]] = {}
        for holder in holders:
            wait = self._queue.waits[holder]
            needs = wait.request.needs
            touch(wait.claims)
            found = None if wait.given else shared.get(id(needs))
            if found is not None and found[0] is needs:
                alts, claims = found[1], found[2]
            else:
                alts, capped = self._reg.alternatives(needs, wait.given, self.max_alternatives)
                claims = self._claim_set(wait, alts, capped) if alts else frozenset()
                if not wait.given:
                    shared[id(needs)] = (needs, alts, claims)
            if not alts:
                self._queue.remove(wait)
                need, reason = self._gone(needs) or self._diagnose(needs, wait.given) or ("", "")
                out.append(Unsatisfiable(holder, need, reason))
                continue
            self._queue.reclaim(wait, claims)
            touch(wait.claims)
        self._dispatch(extra, now, out, tuple(seen.values()))

    def _gone(self, needs: tuple[NeedRequest, ...]) -> tuple[str, str] | None:
        """(need, reason) when a suspended holder's need is pinned to a resource that no longer exists: it can
        only resume on what was taken from it, so it never will."""
        for need in needs:
            pin = need.where
            if isinstance(pin, Pinned) and pin.id not in self._reg.units and pin.id not in self._reg.aggregates:
                return need.name, f"{pin.id}, which it held when it was suspended, is gone"
        return None

    def _diagnose(self, needs: tuple[NeedRequest, ...],
                  given: Mapping[str, Candidate] | None = None) -> tuple[str, str] | None:
        """`diagnose`, naming the hosts down whose resources would meet the needs (a robot of theirs is not gone for
        good: a mission needing ranger2 while its host is down is told so, not that no Ranger satisfies it)."""
        found = diagnose(needs, self._reg, given)
        if found is None or not self._shelf:
            return found
        down = [host for host, shelved in sorted(self._shelf.items())
                if diagnose(needs, self._reg.including(shelved), given) is None]
        if not down:
            return found
        hosts = f"host {down[0]} is down (its" if len(down) == 1 else f"hosts {', '.join(down)} are down (their"
        return found[0], f"{found[1]} while {hosts} resources are not in the manager)"

    # -- granting ------------------------------------------------------------------------------

    def _room(self, unit_id: str, wait: Wait, preempt: bool) -> float:
        """How much of a unit `wait` may take now (optionally counting preemptible holders)."""
        if unit_id in self._reg.offline:
            return 0.0  # its host is down: no one new gets it, preempting its holder or not
        unit = self._reg.units[unit_id]
        holders = self._reg.used.get(unit_id)
        room = self._reg.free(unit_id)
        if preempt and holders and not unit.sharable:
            if all(self._preemptible(self._holds[h], wait) for h in holders):
                room = unit.capacity
        if room <= EPS:
            return 0.0  # full: no need to look at the queue
        head = self._queue.head(unit_id)
        return 0.0 if head is not None and head[0] < wait.key else room  # a better waiter claims it

    def _preemptible(self, hold: Hold, wait: Wait) -> bool:
        return (
            hold.overtime
            and hold.request.rank >= wait.request.rank
            and not same_owner(hold.request.holder, wait.holder)
        )

    def _try_grant(self, wait: Wait, now: float,
                   out: list[Decision]) -> tuple[set[str], list[frozenset[str]]] | None:
        """Grant `wait` if it can be, revoking overtime holders if needed; the units and claim sets to re-dispatch
        (a claim set given up: its units may now go to the waiters behind)."""
        needs, given = wait.request.needs, wait.given
        if not self._overtime and self._some_need_full(needs):
            return None  # nothing to search: every candidate of some need is full
        solution = first_solution(needs, self._reg, lambda u: self._room(u, wait, False), given)
        if solution is None and self._overtime:
            # Preempt as few holders as possible: free units first, then overtime holders.
            free_first = _FreeFirst(self._reg)
            ranked = islice(solutions(needs, free_first, lambda u: self._room(u, wait, True), given), 64)
            solution = self._least_taken(list(ranked), free_first)
        if solution is None:
            return None
        touched: set[str] = set()
        claims: list[frozenset[str]] = []
        if self._queue.get(wait.holder) is wait:
            self._queue.remove(wait)
            claims.append(wait.claims)
        for victim in self._victims(solution):
            units, requeued = self._revoke(victim, out, by=wait.holder)
            touched.update(units)
            claims.append(requeued)
        self._grant(wait, solution, now, out)
        return touched, claims

    def _some_need_full(self, needs: tuple[NeedRequest, ...]) -> bool:
        """Whether some need has no candidate with room left on all of its units.

        The common case of a request that must wait (every camera held), answered without building the
        search's demands: `first_solution` would find nothing either, since a full unit has no room."""
        reg = self._reg
        full = reg.full
        for need in needs:
            for candidate in reg.candidates(need.type):
                if full.isdisjoint(units_of(candidate)):
                    break
            else:
                return True
        return False

    def _least_taken(self, ranked: list[Solution], free_first: _FreeFirst) -> Solution | None:
        """Of preempting solutions in the search's order, the first of those with the fewest victims, or one that
        takes fewer held units from the same victims with candidates of the same kinds (the same robot types): a
        victim is resumed on its very units only, so taking a unit it did not have to give (its Scout, when only
        its camera was needed) made it wait for that unit while others of its kind stood free (semantics audit 24,
        D1). A candidate of another kind (a Scout's wheels for a Ranger's drive) is never swapped in: the order
        of the search is the preference. The search reads the candidates `free_first`, so that the solutions it
        yields (the first 64) take free units where a kind has them, however many candidates a need has."""
        if not ranked:
            return None
        fewest = min(len(self._victims(s)) for s in ranked)
        best = [s for s in ranked if len(self._victims(s)) == fewest]
        first, victims = free_first.kinds(best[0]), self._victims(best[0])
        used, units = self._reg.used, self._reg.units
        return min((s for s in best if free_first.kinds(s) == first and self._victims(s) == victims),
                   key=lambda s: sum(1 for u in s.units if not units[u].sharable and used.get(u)))

    def _victims(self, solution: Solution) -> list[str]:
        """The holders a solution takes exclusive units from (all preemptible by construction)."""
        units = [u for u in solution.units if not self._reg.units[u].sharable]
        return sorted({h for u in units for h in self._reg.used.get(u, ())})

    def _grant(self, wait: Wait, solution: Solution, now: float, out: list[Decision]) -> None:
        holder = wait.holder
        units = solution.units
        epochs = {unit: self._reg.next_epoch(unit) for unit in units}
        for unit, quantity in solution.totals.items():
            self._reg.set_use(unit, holder, quantity)
        slices = []
        for need in wait.request.needs:
            exclusive = [self._reg.units[u] for u in solution.demand[need.name] if not self._reg.units[u].sharable]
            if exclusive:
                own = [u.slice for u in exclusive if u.slice is not None]
                slices.append(need.slice or (max(own) if own else self.default_slice))
        slice_until = now + max(slices) if slices else now
        hold = Hold(
            request=wait.request,
            gid=next(self._order),
            since=wait.since,
            chosen=dict(solution.chosen),
            alloc={name: dict(demand) for name, demand in solution.demand.items()},
            given=dict(wait.given),
            lease_until=now + self.lease,
            slice_until=slice_until,
            granted_at=now,
        )
        self._holds[holder] = hold
        self._queue.hold_added(holder)
        heappush(self._events, (hold.lease_until, _LEASE, hold.gid, holder))
        if slices:
            heappush(self._events, (slice_until, _SLICE, hold.gid, holder))
        assignment = solution.assignment
        out.append(Granted(holder, assignment, units, epochs, hold.lease_until, slice_until, wait.resumed))

    def _revoke(self, holder: str, out: list[Decision], *, by: str) -> tuple[tuple[str, ...], frozenset[str]]:
        """Suspend a holder: free its units and queue its intact needs again, at the back.

        Returns what to re-dispatch: the units freed, and the claims of the requeued request.
        """
        hold = self._holds[holder]
        units = self._end_hold(holder)
        out.append(Revoked(holder, units, "preempted", by))
        if not hold.alloc:  # every need was (partly) given back: nothing left to resume
            return units, frozenset()
        given = dict(hold.given)
        given.update({name: c for name, c in hold.chosen.items() if name not in hold.alloc})
        needs = tuple(dataclasses.replace(n, where=Pinned(hold.chosen[n.name].id))
                      for n in hold.request.needs if n.name in hold.alloc)  # resumed on what was taken from it
        request = dataclasses.replace(hold.request, needs=needs)
        key = (*request.rank, 1, 0.0, next(self._order))
        wait = Wait(request, key, hold.since, resumed=True, given=given)
        alts, capped = self._reg.alternatives(request.needs, given, self.max_alternatives)
        if not alts:  # what it held is gone (removed with its host): never resumable
            need, reason = self._diagnose(request.needs, given) or ("", "")
            out.append(Unsatisfiable(holder, need, reason))
            return units, frozenset()
        self._enqueue(wait, alts, capped)
        return units, wait.claims  # it may resume at once (what it held is free again)

    def _end_hold(self, holder: str) -> tuple[str, ...]:
        hold = self._holds.pop(holder)
        units = tuple(hold.quantities())
        for unit in units:
            self._reg.set_use(unit, holder, 0.0)
        if holder in self._overtime:
            self._ot_units.difference_update(units)  # an exclusive unit has one holder: this one
            self._overtime.discard(holder)
        self._queue.hold_removed(holder, self._holds)
        self._frees += 1
        return units

    def _release_part(self, hold: Hold, names: set[str]) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """Release needs (by name or candidate id) and units: (units given up, units reduced)."""
        holder = hold.request.holder
        before = hold.quantities()
        hold.give_back(names)
        after = hold.quantities()
        reduced = [u for u, quantity in before.items() if after.get(u, 0.0) < quantity]
        for unit in reduced:
            self._reg.set_use(unit, holder, after.get(unit, 0.0))
        if holder in self._overtime:
            self._ot_units.difference_update(u for u in reduced if u not in after)
        if not after:
            self._end_hold(holder)
        elif reduced:
            self._frees += 1
        return tuple(u for u in reduced if u not in after), tuple(u for u in reduced if u in after)

    def _dispatch(self, units: Iterable[str], now: float, out: list[Decision],
                  claims: Iterable[frozenset[str]] = ()) -> None:
        """Serve the head waiters of units that may have room, best-placed first: of `units` and of every unit
        of each claim set in `claims` (the set a waiter gave up, or a group's).

        Only heads are tried: a head that cannot be granted keeps its units for itself, so the
        waiters behind it on those units could not be granted either. A claim set that is a live group's is
        served by its atoms (`WaitQueue.atoms`: units with the same claimants, hence the same head), so
        giving up 4,000 claimed units looks at a few heads, not 4,000 units.
        """
        todo: list[tuple[Key, str]] = []
        queued: set[tuple[Key, str]] = set()  # in `todo` now: an entry twice would be popped twice in a row
        queue = self._queue

        def push(head: tuple[Key, str] | None) -> None:
            if head is not None and head not in queued:
                queued.add(head)
                heappush(todo, head)

        def seed(unit_ids: Iterable[str]) -> None:
            for unit_id in unit_ids:
                if self._may_open(unit_id):
                    push(queue.head(unit_id))

        def seed_claims(sets: Iterable[frozenset[str]]) -> None:
            done: set[int] = set()
            for claim_set in sets:
                if id(claim_set) in done or not claim_set:
                    continue
                done.add(id(claim_set))
                group = queue.group(claim_set)
                if group is None:  # no one claims exactly these any more: unit by unit
                    seed(claim_set)
                    continue
                for atom, groups in queue.atoms(group):
                    if self._may_open_any(atom):
                        push(queue.best(groups))

        seed(units)
        seed_claims(claims)
        failed: dict[str, int] = {}
        while todo:
            entry = heappop(todo)
            queued.discard(entry)
            key, holder = entry
            wait = self._queue.get(holder)
            if wait is None or wait.key != key or failed.get(holder) == self._frees:
                continue
            touched = self._try_grant(wait, now, out)
            if touched is None:
                failed[holder] = self._frees  # retried only if capacity is given back meanwhile
            else:
                seed(touched[0])
                seed_claims(touched[1])

    def _may_open(self, unit_id: str) -> bool:
        """Whether a unit has room, or an exclusive holder in overtime that could be preempted."""
        reg = self._reg
        if unit_id not in reg.full:
            return unit_id in reg.units
        overtime = self._overtime
        return (bool(overtime) and not reg.units[unit_id].sharable
                and any(h in overtime for h in reg.used.get(unit_id, ())))

    def _may_open_any(self, units: frozenset[str]) -> bool:
        """`_may_open` of some of these registered units, by set operations: not all full, or one held in
        overtime (`_ot_units`: the exclusive units of holders in overtime)."""
        return not units <= self._reg.full or not units.isdisjoint(self._ot_units)

    # -- deadlocks -----------------------------------------------------------------------------

    def _successors(self, node: str) -> list[str]:
        """Wait-for edges: a holder waits for its waiting descendants, a waiter for its blockers."""
        if node in self._holds:
            return sorted(self._queue.descendants(node))
        wait = self._queue.get(node)
        if wait is None:
            return []
        alts, capped = self._reg.alternatives(wait.request.needs, wait.given, self.max_alternatives)
        return list(self._blocking(wait, alts, capped))

    def _blocking(self, wait: Wait, alts: list[Solution], capped: bool) -> tuple[str, ...]:
        """Who stands in the way of every possible assignment of `wait`.

        Only those are wait-for edges: a waiter with another way out is not deadlocked.
        """
        common: set[str] | None = None
        for solution in alts:
            blockers = self._blockers(wait, solution.totals.items())
            common = blockers if common is None else common & blockers
        return () if capped or common is None else tuple(sorted(common))

    def _blockers(self, wait: Wait, demand: Iterable[tuple[str, float]]) -> set[str]:
        """Who keeps `wait` from its demand (unit, quantity): the holders of each unit too full, a better claimant."""
        reg, head = self._reg, self._queue.head
        units, load, used = reg.units, reg.load, reg.used
        found: set[str] = set()
        for unit, quantity in demand:
            if units[unit].capacity - load.get(unit, 0.0) < quantity - EPS:
                found.update(used.get(unit, ()))
            best = head(unit)
            if best is not None and best[0] < wait.key:
                found.add(best[1])
        return found

    def _blockers_of(self, wait: Wait, demand: dict[str, float]) -> set[str]:
        """`_blockers` of a waiter's whole claims (`demand` from `_claims_of`, `wait.claims` its units), for its
        `Waiting` record: the same set, computed per held unit and per atom of its group rather than per unit.

        Only a unit in use has holders to name; which of them are in the way of a claims' demand is memoized
        until the registry changes (a thousand waiters of one behavior queued in a row ask the same)."""
        group = self._queue.group(wait.claims)
        if group is None:
            return self._blockers(wait, demand.items())
        reg = self._reg
        version, memo_demand, held = self._held_memo
        if version != reg.version or memo_demand is not demand:
            units, load, used = reg.units, reg.load, reg.used
            found: set[str] = set()
            for unit in (used if len(used) < len(demand) else demand):
                quantity = demand.get(unit)
                holders = used.get(unit)
                if quantity is not None and holders and units[unit].capacity - load.get(unit, 0.0) < quantity - EPS:
                    found.update(holders)
            held = frozenset(found)
            self._held_memo = (reg.version, demand, held)
        blockers = set(held)
        for _, groups in self._queue.atoms(group):
            best = self._queue.best(groups)
            if best is not None and best[0] < wait.key:
                blockers.add(best[1])
        return blockers

    def _rank(self, holder: str) -> tuple[tuple[int, int], int]:
        wait = self._queue.waits[holder]
        return wait.request.rank, wait.since

    def _canonical(self, request: Request) -> Request:
        """The request with the needs tuple of an equal earlier request, if any: equal needs behave alike (a
        `where` equal to another reads nothing of its node), and one object lets `_reconsider` tell the waiters
        of a behavior alike by identity rather than by hashing their needs each time."""
        needs = self._needs.get(request.needs)
        if needs is None:
            if len(self._needs) > 1024:
                self._needs.clear()
            self._needs[request.needs] = request.needs
            return request
        return request if needs is request.needs else dataclasses.replace(request, needs=needs)

    def _check_new_holder(self, holder: str) -> None:
        if holder in self._holds or holder in self._queue or holder in self._pending:
            raise ValueError(f"{holder} already has a request; release or cancel it first")
