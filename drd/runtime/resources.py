"""One mission's side of the Resource Controller Manager: requests, grants, bindings and the gates they open.

A node that declares needs of its own is a *holder*: it asks the manager under `<mission>/<path>` and holds
what it is granted (`Node.grant`, `Node.epochs`). A component's needs are *bound*: each resolves through the
binding chain to the holder whose grant provides it (its own, or an ancestor's by name, then by type, through
a part of an aggregate: `dsl.build`), and becomes a `drd.runtime.ownership.Binding` live at that grant's epoch.
The client keeps the devices' gates in step: a grant opens them to the holder, the end of a hold closes them,
and an unbound component's setpoint is stopped (`drd.runtime.ownership`).

The interpreter decides what a decision means for the statechart (activate, suspend, fail); this module only
keeps the books and talks to the manager and the gates.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import replace
from typing import Any

from drd.errors import MissionInputError
from drd.rcm import Aggregate, Candidate, NeedRequest, Request, Unit
from drd.runtime.broker import ResourceBroker
from drd.runtime.ownership import Arbiter, Binding, Gates, LocalGates
from drd.runtime.pool import LIVE, ResourcePool, ResourceView
from drd.runtime.tree import DONE, LEAF, Node
from dsl import ast
from dsl.evaluate import EvalError, evaluate, truthy
from dsl.statechart import ResourceNeed

Names = Callable[[Node], dict[str, Any]]


class BindingError(MissionInputError):
    """A need cannot be bound: what the binding chain leads to is not held (released, or never granted)."""


class ResourceClient:
    """Requests, grants and bindings of one mission's nodes (see the module docstring)."""

    def __init__(self, broker: ResourceBroker, pool: ResourcePool, mission: str, gates: Gates, arbiter: Arbiter,
                 clock: Callable[[], float], names: Names, mission_priority: int = 1) -> None:
        self.broker = broker
        self.pool = pool
        self.mission = mission
        self.gates = gates
        self.arbiter = arbiter
        self.now = clock
        self.names = names
        self.mission_priority = mission_priority
        self.holders: dict[str, Node] = {}  # request holder -> node
        self.pins: dict[str, dict[str, str]] = {}  # holder -> need -> the resource its next request must get
        #: requests made in this instant's run to completion, not yet asked: `flush` asks them best rank first
        self.deferred: dict[str, Request] = {}
        self.flushing = False  # a grant made by `flush` must not start another one inside it

    # -------------------------------------------------------------- requests
    def holder(self, node: Node) -> str:
        """The manager's name for a node: unique across missions sharing it, path prefixes kept."""
        return f"{self.mission}/{node.path}"

    def request(self, node: Node, needs: Iterable[ResourceNeed], *, at: float | None = None) -> None:
        """Ask for `needs` (all or nothing); with `at`, a preallocation that queues first from then.

        Raises:
            EvalError: a `quantity` or a parameter could not be evaluated (the node fails, nothing is asked).
        """
        holder = self.holder(node)
        pins = self.pins.pop(holder, None)
        needs = tuple(needs)
        reqs = tuple(self.need_request(node, n, pins.get(n.name) if pins else None,
                                       earlier=[m.name for m in needs[:i]]) for i, n in enumerate(needs))
        node.requested = True
        self.holders[holder] = node
        request = Request(holder, node.state.priority, reqs, self.mission, self.mission_priority)
        if at is None:
            self.deferred[holder] = request
        else:
            self.broker.reserve(request, self.now(), at)

    def flush(self) -> bool:
        """Ask the manager for the requests deferred since the last flush, best rank first and, among equals, in
        the order they were made: requests of one instant are granted by priority (spec "Resources"), not by who
        asked first. Grants may enter states that ask again: those wait for the next flush. Whether any was asked.
        """
        if self.flushing or not self.deferred:
            return False
        self.flushing = True
        try:
            while self.deferred:
                batch = sorted(self.deferred.items(), key=lambda item: item[1].rank)  # stable: equals keep their order
                for holder, _ in batch:
                    request = self.deferred.pop(holder, None)  # None: withdrawn by a grant made just before
                    if request is not None:
                        self.broker.request(request, self.now())
        finally:
            self.flushing = False
        return True

    def need_request(self, node: Node, need: ResourceNeed, pinned: str | None = None,
                     earlier: Collection[str] | None = None) -> NeedRequest:
        """`pinned`: the resource it must be (a mission resumed after its controller was lost asks for what it
        held, whatever its `where` says of the resource now). `earlier`: the needs asked before this one in the
        same request (the solver binds them first), when known: a `where` reading only those is the same for
        every instance of the behavior (`Where`)."""
        quantity = need.quantity
        if isinstance(quantity, ast.Expr):
            value = evaluate(quantity, self.names(node), self.pool.count)
            quantity = float(value) if isinstance(value, int | float) and not isinstance(value, bool) else 1.0
        where = self.where(node, need, earlier) if pinned is None else (lambda cand, chosen: cand.id == pinned)
        return NeedRequest(need.name, need.type, float(quantity or 1.0), need.slice, where)

    def where(self, node: Node, need: ResourceNeed, earlier: Collection[str] | None = None) -> Any:
        """The need's `where` as the solver calls it (`Where`), or None."""
        if need.where is None:
            return None
        return Where(need.where, need.name, self.pool, self.names, node, earlier)

    def release(self, node: Node, names: Iterable[str] | None = None) -> None:
        """Give back the whole grant (None) or these needs; the manager's decisions follow through the broker."""
        holder = self.holder(node)
        if names is None and self.deferred.pop(holder, None) is not None:
            return  # never asked: nothing to give back
        self.broker.release(holder, self.now(), None if names is None else list(names))

    def cancel(self, node: Node) -> None:
        """Withdraw a request still waiting (or a reservation); a grant in force is given back."""
        holder = self.holder(node)
        if self.deferred.pop(holder, None) is None:
            self.broker.cancel(holder, self.now())

    def forget(self, node: Node) -> None:
        holder = self.holder(node)
        self.holders.pop(holder, None)
        self.deferred.pop(holder, None)

    def renew(self, now: float, lease: float) -> None:
        for holder, node in list(self.holders.items()):
            if node.grant and node.lease_until - now < lease / 2:
                for d in self.broker.renew(holder, now):
                    until = getattr(d, "lease_until", None)
                    if until is not None:
                        node.lease_until = until

    # -------------------------------------------------------------- grants
    def took(self, node: Node, assignment: Mapping[str, str], epochs: Mapping[str, int], units: Iterable[str],
             lease_until: float) -> None:
        """A grant is in force: book it, open the gates to the holder, show the resources in its scope."""
        node.grant = dict(assignment)
        node.epochs = dict(epochs)  # its own (a new node shares an empty one)
        node.units = tuple(units)
        node.lease_until = lease_until
        node.revoked = False
        holder, now = self.holder(node), self.now()
        for unit, epoch in node.epochs.items():
            self.gates.grant(unit, holder, epoch, now)
        for need, rid in node.grant.items():
            node.scope[need] = self.pool.view(rid)

    def lost(self, node: Node, units: Iterable[str], reason: str, needs: Iterable[str] = (),
             cause: Collection[str] = ()) -> tuple[str, ...]:
        """Units left a holder (revoked, released, lost): close their gates and forget the needs given back whole
        (`needs`, or every need once nothing is left); returns the resource ids that ended (those needs'
        resources, those in `cause` first: the lost robot before what went with it; then the units), as the
        `released` record lists them."""
        units = tuple(units)
        gone = set(units)
        grant = node.grant or {}
        left = [u for u in node.units if u not in gone]
        names = list(grant) if not left else [n for n in needs if n in grant]
        ids = sorted((grant.pop(n) for n in names), key=lambda r: r not in cause)  # stable: grant order after
        for n in names:
            node.scope.pop(n, None)
        holder, now = self.holder(node), self.now()
        if units and node.epochs:
            node.epochs = {u: e for u, e in node.epochs.items() if u not in gone}
        for unit in units:
            self.gates.clear(unit, holder, now, reason)
        node.units = tuple(left)
        if not left:
            node.grant = None
        return tuple(dict.fromkeys([*ids, *units]))

    def resources_of(self, assignment: Mapping[str, str]) -> tuple[dict[str, str], dict[str, str]]:
        """What a `granted` record lists: each need's resource id, and each part of an aggregate as `need.part`,
        split into what is held (exclusive units, aggregates) and what is shared (sharable units)."""
        named = dict(assignment)
        for need, rid in assignment.items():
            cand = self.pool.candidates.get(rid)
            if isinstance(cand, Aggregate):
                named.update({f"{need}.{part}": unit for part, unit in cand.parts.items()})
        held: dict[str, str] = {}
        shared: dict[str, str] = {}
        for name, rid in named.items():
            cand = self.pool.candidates.get(rid)
            (shared if isinstance(cand, Unit) and cand.sharable else held)[name] = rid
        return held, shared

    # -------------------------------------------------------------- bindings
    def resolve(self, node: Node, need: ResourceNeed) -> tuple[Node, str, str, str]:
        """(holder node, resource id, robot, part) of a need, through the binding chain.

        Raises:
            BindingError: the holder the chain leads to does not hold that resource now.
        """
        holder, name, part = _chain(node, need)
        rid = (holder.grant or {}).get(name)
        if rid is None:
            why = (f"{holder.path} released it" if name in holder.released else
                   f"{holder.path} lost it at a slice boundary" if holder.revoked else "it is not held")
            raise BindingError(unbound_reason(need, "its own" if holder is node else f"{name} of {holder.path}", why))
        if part is None:
            return holder, rid, "", ""
        return holder, self.pool.part(rid, part), rid, part

    def released_under(self, leaf: Node) -> str | None:
        """Why a leaf being entered cannot bind a need, when its chain leads to a resource its holder released
        (the reference: the behavior that needs it fails, naming the release), else None. Other leaves bind when
        their component first reads a need, as before."""
        for need in leaf.state.needs:
            holder, name, _part = _chain(leaf, need)
            if name in holder.released and (holder.grant or {}).get(name) is None:
                return released_reason(need, name, holder)
        return None

    def needing(self, holder: Node, name: str) -> list[tuple[Node, ResourceNeed]]:
        """The live leaves below `holder` with a need whose chain leads to its `name`, bound yet or not: what
        `release(name)` leaves with nothing to bind (asked before the release)."""
        out = []
        for n in holder.subtree():
            if n.state.kind is not LEAF or n.phase is DONE or n.closing:
                continue
            out += [(n, need) for need in n.state.needs if _chain(n, need)[:2] == (holder, name)]
        return out

    def adopt(self, node: Node) -> None:
        """A node's needs that an ancestor holds (a re-declared need, or one bound by type or through a part):
        each resolves through the binding chain, shows under its own name in the node's scope, and must satisfy
        the node's own `where`.

        Raises:
            BindingError: what the chain leads to is not held, or does not satisfy the `where`.
        """
        for need in node.state.needs:
            if need.requested:
                continue
            holder, rid, robot, _part = self.resolve(node, need)
            view = self.pool.view(rid)
            if need.where is not None:
                scope = self.names(node)
                scope[need.name] = view
                try:
                    ok = truthy(need.where, scope, self.pool.count)
                except EvalError as e:
                    raise BindingError(f"need {need.name}: its where cannot be evaluated: {e.message}") from None
                if not ok:
                    raise BindingError(f"need {need.name} ({need.type}) is {rid}, held by {holder.path}, which does"
                                       f" not satisfy its where")
            node.scope[need.name] = view

    def reuse(self, node: Node, needs: tuple[ResourceNeed, ...]) -> tuple[ResourceNeed, ...]:
        """Of `needs` (asked of the manager), those no ancestor's robot serves: a need with a `where` takes the first
        part of an ancestor's robot (`ResourceNeed.reuse`) that satisfies it now, as a need bound to it would
        (`resolve` follows it), instead of asking the manager for what its own mission holds (a deadlock)."""
        left = []
        for need in needs:
            via = next((v for v in need.reuse if self._serves(node, need, v)), None)
            if via is None:
                left.append(need)
            else:
                node.reused = {**node.reused, need.name: via}
        return tuple(left)

    def _serves(self, node: Node, need: ResourceNeed, via: tuple[str, str, str]) -> bool:
        try:
            _holder, rid, _robot, _part = self.resolve(node, replace(need, bound_to=via))
        except BindingError:
            return False
        view = self.pool.view(rid)
        scope = self.names(node)
        scope[need.name] = view
        try:
            ok = truthy(need.where, scope, self.pool.count)
        except EvalError:
            return False
        if ok:
            node.scope[need.name] = view
        return ok

    def bind(self, leaf: Node) -> dict[str, Binding]:
        """Bind every need of a leaf, live at the grants' epochs (raises BindingError)."""
        out: dict[str, Binding] = {}
        for need in leaf.state.needs:
            holder, unit, robot, part = self.resolve(leaf, need)
            out[need.name] = Binding(need.name, unit, self.holder(holder), holder.epochs.get(unit), robot=robot,
                                     part=part)
        self._attach(out.values())
        leaf.bindings = out
        return out

    def rebind(self, leaf: Node) -> None:
        """A resumed leaf: its bindings live again at the current grants (a resumed grant may name other units)."""
        for need in leaf.state.needs:
            binding = leaf.bindings.get(need.name)
            if binding is None:
                continue
            holder, unit, robot, part = self.resolve(leaf, need)
            binding.unit, binding.holder, binding.robot, binding.part = unit, self.holder(holder), robot, part
            binding.epoch = holder.epochs.get(unit)
        self._attach(leaf.bindings.values())

    def _attach(self, bindings: Iterable[Binding]) -> None:
        gates = self.gates
        if isinstance(gates, LocalGates):
            for b in bindings:
                found = gates.bound(b.unit, b.robot, b.part)
                b.gate, b.driver = found if found is not None else (None, None)

    def unbind(self, leaf: Node, reason: str, needs: Iterable[str] | None = None) -> None:
        """The leaf (or these of its needs) may no longer command: its pending setpoints are dropped and a setpoint
        of its in force is stopped by the gate."""
        issuer = self.holder(leaf)
        now = self.now()
        chosen = leaf.bindings.values() if needs is None else [leaf.bindings[n] for n in needs if n in leaf.bindings]
        self.arbiter.drop(issuer, {b.unit for b in chosen})
        for b in chosen:
            if b.epoch is None:
                continue
            b.epoch = None
            self.gates.unbind(b.unit, issuer, now, reason)

    def bound_through(self, holder: Node, need: str) -> list[tuple[Node, list[str]]]:
        """The leaves below `holder` with needs bound to its `need` (what a `release(need)` unbinds)."""
        qualified = self.holder(holder)
        units = set(self.pool.units((holder.grant or {}).get(need, ""))) | {(holder.grant or {}).get(need, "")}
        out = []
        for n in holder.subtree():
            hit = [b.need for b in n.bindings.values() if b.holder == qualified and b.unit in units]
            if hit:
                out.append((n, hit))
        return out


def released_reason(need: ResourceNeed, name: str, holder: Node) -> str:
    """Why `need` cannot be bound: its chain leads to `name` of `holder`, which `release(name)` gave back."""
    return unbound_reason(need, f"{name} of {holder.path}", f"{holder.path} released it")


def unbound_reason(need: ResourceNeed, where: str, why: str) -> str:
    """The one wording of a need whose binding chain ends at nothing held: where it is bound, and why not held."""
    return f"need {need.name} ({need.type}) is bound to {where}, but {why}"


def _chain(node: Node, need: ResourceNeed) -> tuple[Node, str, str | None]:
    """Where a need's binding chain ends: (the holder node, its need's name there, the part of it, if any)."""
    holder, name, part = node, need.name, None
    bound = need.bound_to or node.reused.get(name)
    while bound is not None:
        state_id, name, inner = bound
        holder = next((a for a in holder.ancestors() if a.state.id == state_id), holder)
        if inner is not None:
            part = inner if part is None else part
        spec = next((n for n in holder.state.needs if n.name == name), None)
        bound = (spec.bound_to if spec is not None else None) or holder.reused.get(name)
    return holder, name, part


class Where:
    """A need's `where`, evaluated in its node's scope with the candidate (and the earlier needs' choices) under
    their need names: what the solver calls for each candidate.

    Two are equal when neither can depend on its node: the expression reads only the candidate and needs bound
    before it, no live value (`x`, `battery`) and no call. The manager's alternatives, cached per needs, then
    serve every instance of a behavior at once: a thousand waiting RoomSurveillance instances enumerate their
    assignments once per resource change, not a thousand times. Such a `where` is also evaluated without
    building the node's scope. Others are equal only to themselves, as the closures they replace were.

    `narrow` gives the solver a cheaper set to try: with `scout.carrier == ranger` among its top-level `and`s,
    only the Scouts whose `carrier` is the chosen Ranger (from the pool's index) and those the index cannot tell
    about; the expression still decides for each. Rejected: compiling `where` to Python (a second evaluator).
    """

    __slots__ = ("expr", "need", "pool", "names", "node", "key", "join", "_hash")

    def __init__(self, expr: ast.Expr, need: str, pool: ResourcePool, names: Names, node: Node,
                 earlier: Collection[str] | None) -> None:
        self.expr, self.need, self.pool, self.names, self.node = expr, need, pool, names, node
        refs = _free_names(expr)
        shared = earlier is not None and refs is not None and refs <= {need, *earlier}
        self.key: tuple[ast.Expr, str, int] | None = (expr, need, id(pool)) if shared else None
        self._hash = hash(self.key) if self.key is not None else id(self)
        self.join = _join(expr, need)

    def __call__(self, cand: Candidate, chosen: Mapping[str, Candidate]) -> bool:
        pool = self.pool
        scope: dict[str, Any] = {} if self.key is not None else self.names(self.node)
        for k, v in chosen.items():
            scope[k] = ResourceView(v, pool)
        scope[self.need] = ResourceView(cand, pool)
        try:
            return truthy(self.expr, scope, pool.count)
        except EvalError:
            return False

    def narrow(self, cands: Iterable[Candidate], chosen: Mapping[str, Candidate]) -> Iterable[Candidate]:
        """The candidates, in their order, less those whose joined property names another resource than the one
        chosen (they can never satisfy the expression)."""
        if self.join is None:
            return cands
        prop, other = self.join
        target = chosen.get(other)
        return cands if target is None else self.pool.having(cands, prop, target.id)

    def __eq__(self, other: object) -> bool:
        if self.key is None or not isinstance(other, Where):
            return self is other
        return self.key == other.key

    def __hash__(self) -> int:
        return self._hash


def _free_names(expr: ast.Expr) -> set[str] | None:
    """The names an expression reads, or None when it calls a function or reads a live value (both may change
    without any resource changing)."""
    match expr:
        case ast.Literal() | ast.Duration():
            return set()
        case ast.Name(id=n):
            return {n}
        case ast.Attr(obj=o, attr=a):
            return None if a in LIVE else _free_names(o)
        case ast.Unary(operand=x):
            return _free_names(x)
        case ast.Binary(left=lhs, right=rhs):
            left, right = _free_names(lhs), _free_names(rhs)
            return None if left is None or right is None else left | right
        case ast.Interp(parts=parts):
            found: set[str] = set()
            for part in parts:
                if not isinstance(part, str):
                    names = _free_names(part)
                    if names is None:
                        return None
                    found |= names
            return found
    return None


def _join(expr: ast.Expr, need: str) -> tuple[str, str] | None:
    """(property, other need) when `expr` is, or has among its top-level `and`s, `need.property == other` (either
    way round): a candidate whose stored property is a different id can never satisfy it."""
    match expr:
        case ast.Binary(op="and", left=lhs, right=rhs):
            return _join(lhs, need) or _join(rhs, need)
        case ast.Binary(op="==", left=lhs, right=rhs):
            for a, b in ((lhs, rhs), (rhs, lhs)):
                if (isinstance(a, ast.Attr) and isinstance(a.obj, ast.Name) and a.obj.id == need
                        and isinstance(b, ast.Name) and b.id != need and a.attr not in LIVE
                        and a.attr not in ("id", "host")):
                    return a.attr, b.id
    return None
