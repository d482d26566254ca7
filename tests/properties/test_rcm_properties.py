"""Random request/release/renew/time/hot-plug sequences against the RCM's invariants (hypothesis).

A model of who holds, waits and is reserved is kept from the decision records alone and compared
with the manager's own state after every step, so a request that vanishes without a record, or a
record without a state change, fails as surely as two holders on one camera.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from drd.rcm import (
    Aggregate,
    Candidate,
    Deadlock,
    Decision,
    Granted,
    NeedRequest,
    Released,
    Renewed,
    Request,
    Reserved,
    ResourceManager,
    Revoked,
    Unit,
    Unsatisfiable,
    Waiting,
    units_of,
)
from drd.rcm.solver import alternatives, demand_of, first_solution


def carried(scout: Candidate, chosen: Mapping[str, Candidate]) -> bool:
    return scout.properties.get("carrier") == chosen["ranger"].id


def first_camera(camera: Candidate, chosen: Mapping[str, Candidate]) -> bool:
    return camera.id == "cam1"


TEMPLATES: dict[str, tuple[NeedRequest, ...]] = {
    "camera": (NeedRequest("camera", "Camera"),),
    "camera+drive": (NeedRequest("camera", "Camera", slice=1.0), NeedRequest("drive", "Drive")),
    "cam1": (NeedRequest("camera", "Camera", where=first_camera),),
    "radio": (NeedRequest("radio", "Radio", quantity=0.5),),
    "big radio": (NeedRequest("radio", "Radio", quantity=1.5),),
    "camera+radio": (NeedRequest("camera", "Camera"), NeedRequest("radio", "Radio", quantity=1.0)),
    "ranger": (NeedRequest("ranger", "Ranger"),),
    "ranger+scout": (NeedRequest("ranger", "Ranger", slice=3.0), NeedRequest("scout", "Scout", where=carried)),
    "two cameras": (NeedRequest("left", "Camera"), NeedRequest("right", "Camera")),
}
HOLDERS = ("M1", "M2", "M3", "M1/a", "M1/b", "M2/a", "M2/a/x", "M3/a")
ROBOT_HOSTS = ("h1", "h2")


def host_units(host: str) -> list[Unit]:
    if host == "base":
        return [Unit("radio", "Radio", sharable=True, capacity=2.0, host="base")]
    n = host[1:]
    return [
        Unit(f"cam{n}", "Camera", host=host),
        Unit(f"drive{n}", "Drive", host=host),
        Unit(f"s{n}", "Scout", properties={"carrier": f"r{n}"}, host=host),
    ]


def host_aggregates(host: str) -> list[Aggregate]:
    n = host[1:]
    parts = {"drive": f"drive{n}", "camera": f"cam{n}", "radio": "radio"}
    return [Aggregate(f"r{n}", "Ranger", parts, {}, host=host)]


def from_snapshot(snap: Mapping[str, Any], cid: str) -> Candidate:
    units: Mapping[str, Mapping[str, Any]] = snap["units"]
    aggregates: Mapping[str, Mapping[str, Any]] = snap["aggregates"]
    if cid in units:
        info = units[cid]
        return Unit(cid, info["type"], info["sharable"], info["capacity"], info["properties"], info["host"])
    info = aggregates[cid]
    return Aggregate(cid, info["type"], info["parts"], info["properties"], info["host"])


class SnapshotCatalog:
    """The solver's view of a snapshot, to ask what *could* be granted from free capacity."""

    def __init__(self, snap: Mapping[str, Any]) -> None:
        ids = sorted([*snap["units"], *snap["aggregates"]])
        self.resources = {cid: from_snapshot(snap, cid) for cid in ids}
        self.free: dict[str, float] = {u: info["capacity"] - info["load"] for u, info in snap["units"].items()}

    def candidates(self, type: str) -> list[Candidate]:
        return [c for c in self.resources.values() if c.type == type]

    def unit(self, unit_id: str) -> Unit:
        unit = self.resources[unit_id]
        assert isinstance(unit, Unit)
        return unit

    def demand(self, candidate: Candidate, need: NeedRequest) -> dict[str, float]:
        return demand_of(self, candidate, need)


class ResourcePool(RuleBasedStateMachine):
    #: assignments a waiter's claims are computed from; beyond it, it claims every unit of its need types
    max_alternatives = 256

    def __init__(self) -> None:
        super().__init__()
        self.rm = ResourceManager(lease=5.0, default_slice=1.0, max_alternatives=self.max_alternatives)
        self.now = 0.0
        self.holding: set[str] = set()
        self.waiting: set[str] = set()
        self.pending: set[str] = set()
        self.requests: dict[str, Request] = {}
        self.epochs: dict[str, int] = {}
        self.down: set[str] = set()
        self.offline: set[str] = set()  # hosts seen down, their units kept but granted to no one new
        self.reduced: set[str] = set()  # holders that gave back a need: resumed with fewer needs
        self.held: dict[str, dict[str, str]] = {}  # holder -> need -> the resource its grant named
        self.suspended: dict[str, dict[str, str]] = {}  # a revoked holder -> what it held when suspended
        for host in ("base", *ROBOT_HOSTS):
            self.plug(host)

    # -- model ------------------------------------------------------------------------------

    def plug(self, host: str) -> None:
        for unit in host_units(host):
            self.apply(self.rm.add_unit(unit, self.now))
        if host != "base":
            for aggregate in host_aggregates(host):
                self.apply(self.rm.add_aggregate(aggregate, self.now))

    def active(self, holder: str) -> bool:
        return holder in self.holding or holder in self.waiting or holder in self.pending

    def apply(self, decisions: Iterable[Decision], partial: str = "") -> None:
        snap = self.rm.snapshot()
        for d in decisions:
            if isinstance(d, Granted):
                assert d.holder not in self.holding
                self.check_grant(d, snap)
                if d.resumed:  # spec: resumed when it gets *it* back, not another resource of the type
                    taken = self.suspended.pop(d.holder)
                    assert {n: taken[n] for n in d.assignment} == dict(d.assignment), (taken, d.assignment)
                self.held[d.holder] = dict(d.assignment)
                self.waiting.discard(d.holder)
                self.pending.discard(d.holder)
                self.holding.add(d.holder)
            elif isinstance(d, Waiting):
                assert not self.active(d.holder) or d.holder in self.pending
                self.pending.discard(d.holder)
                self.waiting.add(d.holder)
            elif isinstance(d, Reserved):
                assert not self.active(d.holder)
                self.pending.add(d.holder)
            elif isinstance(d, Revoked):
                self.holding.remove(d.holder)
                self.suspended[d.holder] = self.held.pop(d.holder)
                self.waiting.add(d.holder)
            elif isinstance(d, Released):
                assert self.active(d.holder)
                if d.holder != partial:
                    self.holding.discard(d.holder)
                    self.held.pop(d.holder, None)
                self.suspended.pop(d.holder, None)
                self.waiting.discard(d.holder)
                self.pending.discard(d.holder)
            elif isinstance(d, Deadlock):
                assert d.victim in d.cycle
                self.waiting.remove(d.victim)
                self.suspended.pop(d.victim, None)
            elif isinstance(d, Unsatisfiable):
                self.suspended.pop(d.holder, None)
                self.waiting.discard(d.holder)
                self.pending.discard(d.holder)
            else:
                assert isinstance(d, Renewed) and d.holder in self.holding
        if partial and partial not in self.rm.snapshot()["holds"]:
            self.holding.discard(partial)

    def check_grant(self, grant: Granted, snap: Mapping[str, Any]) -> None:
        """Types, `where` constraints, units and fencing epochs of one grant."""
        request = self.requests[grant.holder]
        chosen: dict[str, Candidate] = {}
        exclusive: list[str] = []
        for need in request.needs:
            if need.name not in grant.assignment:
                continue  # given back before a revocation: not asked again on resume
            candidate = from_snapshot(snap, grant.assignment[need.name])
            assert candidate.type == need.type
            earlier = [n.name for n in request.needs[: request.needs.index(need)]]
            if need.where is not None and all(name in chosen for name in earlier):
                assert need.where(candidate, chosen)
            chosen[need.name] = candidate
            exclusive += [u for u in units_of(candidate) if not snap["units"][u]["sharable"]]
        assert len(exclusive) == len(set(exclusive)), "an exclusive unit assigned twice"
        assert grant.units == tuple(dict.fromkeys(u for c in chosen.values() for u in units_of(c)))
        for unit in grant.units:
            assert snap["units"][unit]["host"] not in self.offline, f"{unit} granted while its host is down"
            assert grant.epochs[unit] > self.epochs.get(unit, 0)
            self.epochs[unit] = grant.epochs[unit]

    # -- rules ------------------------------------------------------------------------------

    @rule(holder=st.sampled_from(HOLDERS), priority=st.integers(1, 3), template=st.sampled_from(sorted(TEMPLATES)))
    def request(self, holder: str, priority: int, template: str) -> None:
        if self.active(holder):
            return
        self.requests[holder] = Request(holder, priority, TEMPLATES[template])
        self.reduced.discard(holder)
        self.apply(self.rm.request(self.requests[holder], self.now))

    @rule(
        holder=st.sampled_from(HOLDERS),
        priority=st.integers(1, 3),
        template=st.sampled_from(sorted(TEMPLATES)),
        delay=st.sampled_from([0.0, 0.5, 2.0, 5.0]),
    )
    def reserve(self, holder: str, priority: int, template: str, delay: float) -> None:
        if self.active(holder):
            return
        self.requests[holder] = Request(holder, priority, TEMPLATES[template])
        self.reduced.discard(holder)
        self.apply(self.rm.reserve(self.requests[holder], self.now, self.now + delay))

    @precondition(lambda self: self.holding)
    @rule(data=st.data())
    def release(self, data: st.DataObject) -> None:
        holder = data.draw(st.sampled_from(sorted(self.holding)))
        self.apply(self.rm.release(holder, self.now))

    @precondition(lambda self: self.holding)
    @rule(data=st.data())
    def release_one_need(self, data: st.DataObject) -> None:
        holder = data.draw(st.sampled_from(sorted(self.holding)))
        held = self.rm.snapshot()["holds"][holder]["assignment"]
        if held:
            need = data.draw(st.sampled_from(sorted(held)))
            self.reduced.add(holder)
            self.apply(self.rm.release(holder, self.now, [need]), partial=holder)

    @precondition(lambda self: self.holding)
    @rule(data=st.data())
    def renew(self, data: st.DataObject) -> None:
        holder = data.draw(st.sampled_from(sorted(self.holding)))
        self.apply(self.rm.renew(holder, self.now))

    @rule(holder=st.sampled_from(HOLDERS))
    def cancel(self, holder: str) -> None:
        self.apply(self.rm.cancel(holder, self.now))

    @rule(dt=st.sampled_from([0.5, 1.0, 2.0, 6.0]))
    def advance(self, dt: float) -> None:
        self.now += dt
        self.apply(self.rm.tick(self.now))

    @rule(host=st.sampled_from(ROBOT_HOSTS))
    def lose_host(self, host: str) -> None:
        if host not in self.down:
            self.down.add(host)
            self.offline.discard(host)
            self.apply(self.rm.remove_host(host, self.now))

    @rule(host=st.sampled_from(ROBOT_HOSTS), offline=st.booleans())
    def host_seen(self, host: str, offline: bool) -> None:
        """Seen down (offline) or back within the lease."""
        if host not in self.down:
            (self.offline.add if offline else self.offline.discard)(host)
            self.apply(self.rm.set_host_offline(host, offline, self.now))

    @rule(host=st.sampled_from(ROBOT_HOSTS))
    def restore_host(self, host: str) -> None:
        if host in self.down:
            self.down.remove(host)
            self.plug(host)

    @rule(scout=st.sampled_from(["s1", "s2"]), carrier=st.sampled_from(["r1", "r2", None]))
    def move_scout(self, scout: str, carrier: str | None) -> None:
        if f"h{scout[1:]}" not in self.down:
            self.apply(self.rm.set_property(scout, "carrier", carrier, self.now))

    @rule()
    def drain(self) -> None:
        """Liveness: once every host is back, every holder lets go and time passes, every waiter is served."""
        for host in sorted(self.offline):
            self.host_seen(host, False)
        for _ in range(500):
            if not self.waiting and not self.pending:
                break
            for holder in sorted(self.holding):
                self.apply(self.rm.release(holder, self.now))
            self.now += 1.0
            self.apply(self.rm.tick(self.now))
        assert not self.waiting and not self.pending, (self.rm.queue(), self.rm.snapshot())

    # -- invariants -------------------------------------------------------------------------

    @invariant()
    def state_matches_the_records(self) -> None:
        snap = self.rm.snapshot()
        assert set(snap["holds"]) == self.holding
        assert set(self.rm.queue()) == self.waiting
        assert set(snap["reservations"]) == self.pending

    @invariant()
    def exclusive_units_have_one_holder_and_capacity_holds(self) -> None:
        units: Mapping[str, Mapping[str, Any]] = self.rm.snapshot()["units"]
        for unit_id, info in units.items():
            holders: Mapping[str, float] = info["holders"]
            if not info["sharable"]:
                assert len(holders) <= 1
            assert sum(holders.values()) <= info["capacity"] + 1e-9
            assert info["epoch"] == self.epochs.get(unit_id, 0)

    @invariant()
    def no_waiter_could_be_served_now(self) -> None:
        """The policy, restated by brute force: the indexes never forget a servable waiter.

        A waiter may take free capacity, and exclusive units of holders in overtime (slice over)
        of no better priority and another owner, but never a unit that a better-placed waiter
        claims (a unit of any of its possible assignments).
        """
        snap = self.rm.snapshot()
        catalog = SnapshotCatalog(snap)
        holds: Mapping[str, Mapping[str, Any]] = snap["holds"]
        units: Mapping[str, Mapping[str, Any]] = snap["units"]
        claimed: set[str] = set()
        for holder in self.rm.queue():
            if holder in self.reduced:
                return  # resumed with fewer needs than it asked: its claims are not known here
            # a suspended holder waits for the very resources taken from it (`Pinned` needs): its queued request
            request = self.rm._queue.waits[holder].request if holder in self.suspended else self.requests[holder]

            def preemptible(other: str, holder: str = holder, priority: int = request.priority) -> bool:
                hold = holds[other]
                return (
                    self.now >= hold["slice_until"]
                    and hold["priority"] >= priority
                    and not (other.startswith(holder + "/") or holder.startswith(other + "/"))
                )

            def room(unit: str) -> float:
                info = units[unit]
                holders: Mapping[str, float] = info["holders"]
                if unit in claimed or info["host"] in self.offline:
                    return 0.0
                if holders and not info["sharable"] and all(preemptible(h) for h in holders):
                    return float(info["capacity"])
                return catalog.free[unit]

            assert first_solution(request.needs, catalog, room) is None, holder
            claimed.update(self.claims(request, catalog))

    def claims(self, request: Request, catalog: SnapshotCatalog) -> set[str]:
        """The units a waiting request claims: those of its possible assignments, or, past `max_alternatives`
        of them, every unit of its need types."""
        found, capped = alternatives(request.needs, catalog, None, self.max_alternatives)
        claimed = {u for solution in found for u in solution.units}
        if capped:
            claimed.update(u for need in request.needs for c in catalog.candidates(need.type) for u in units_of(c))
        return claimed

    @invariant()
    def queue_indexes_match_brute_force(self) -> None:
        """The wait queue's grouped index answers as a scan of every waiter would (white box: the indexes
        are private, and what they must equal is restated here from the waiters themselves)."""
        rm = self.rm
        queue, reg = rm._queue, rm._reg
        for unit_id in reg.units:
            claimants = [(w.key, h) for h, w in queue.waits.items() if unit_id in w.claims]
            assert queue.head(unit_id) == min(claimants, default=None), unit_id
            assert queue.claimants(unit_id) == {h for _, h in claimants}
        for wait in queue.waits.values():
            group = queue.group(wait.claims)
            if group is None:
                assert not wait.claims
                continue
            atoms = queue.atoms(group)
            assert sorted(u for atom, _ in atoms for u in atom) == sorted(wait.claims)  # a partition
            for atom, groups in atoms:
                assert {queue.head(u) for u in atom} == {queue.best(groups)}
                assert rm._may_open_any(atom) == any(rm._may_open(u) for u in atom)
            alts, capped = reg.alternatives(wait.request.needs, wait.given, rm.max_alternatives)
            demand = rm._claims_of(wait, alts, capped)
            assert rm._blockers_of(wait, demand) == rm._blockers(wait, demand.items())
        overtime = {u for u in reg.full if not reg.units[u].sharable
                    and any(h in rm._overtime for h in reg.used.get(u, ()))}
        assert rm._ot_units == overtime

    def teardown(self) -> None:
        self.drain()


ResourcePool.TestCase.settings = settings(max_examples=100, stateful_step_count=40, deadline=None)
TestResourcePool = ResourcePool.TestCase


class CappedResourcePool(ResourcePool):
    """The same, with claims capped at one assignment: waiters of a type claim all its units, so they share
    claim sets (the manager's groups) as the 950 RoomSurveillance instances of a 1,000-robot building do."""

    max_alternatives = 1


CappedResourcePool.TestCase.settings = settings(max_examples=100, stateful_step_count=40, deadline=None)
TestCappedResourcePool = CappedResourcePool.TestCase
