"""Run a compiled statechart: run-to-completion steps over a tree of active instances.

`Interpreter.step()` is one macro step at the clock's current time: apply the Resource
Controller Manager's decisions (slice boundaries, lease expiry), step every running
component once, then take transitions (completion, error, change, timeout, event) until
nothing more is enabled. Taking a transition exits the source (children first: each
component gets `terminate`, each grant is released), runs the actions, then enters the
target. A failure with no `on error` propagates to the parent like an exception; a
multiplicity fails only when fewer than its minimum instances succeeded. The
interpreter never sleeps and never reads the wall clock; it reports through listeners.
"""

from __future__ import annotations

import collections
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from drd.rcm import (
    Deadlock,
    Granted,
    NeedRequest,
    Released,
    ReleaseReason,
    Request,
    ResourceManager,
    Revoked,
    Unsatisfiable,
)
from drd.rcm import Waiting as WaitingDecision
from drd.runtime import records as rec
from drd.runtime.broker import ResourceBroker
from drd.runtime.clock import Clock
from drd.runtime.component import Component, Context, Registry, Status
from drd.runtime.fence import Arbiter, Fenced
from drd.runtime.pool import ResourcePool, ResourceView
from dsl import ast
from dsl.evaluate import EvalError, evaluate, format_value, truthy
from dsl.export import trigger_label
from dsl.statechart import ResourceNeed, State, Statechart, StateKind, Transition

_FINAL_STATUS = {"success": Status.SUCCESS, "failure": Status.FAILURE}

#: Transitions one macro step may take before the chart is declared livelocked.
MAX_MICROSTEPS = 10_000

Listener = Callable[[rec.Record], None]


class Phase(StrEnum):
    WAITING = "waiting"
    """Entered, waiting for the Resource Controller Manager to grant its needs."""
    ACTIVE = "active"
    """Running: children entered, component stepping."""
    SUSPENDED = "suspended"
    """A resource was taken away at a slice boundary; resumes when granted again."""
    DONE = "done"
    """Exited (successfully, failed or stopped)."""


# Enum members as module constants, which this module compares against: on CPython 3.11 each
# `Phase.DONE` or `StateKind.LEAF` is a metaclass attribute lookup (~0.1 µs), and a transition made a dozen.
_WAITING, _ACTIVE, _SUSPENDED, _DONE = Phase.WAITING, Phase.ACTIVE, Phase.SUSPENDED, Phase.DONE
_LEAF, _COMPOUND, _PARALLEL, _MULTI, _FINAL = (StateKind.LEAF, StateKind.COMPOUND, StateKind.PARALLEL,
                                                StateKind.MULTI, StateKind.FINAL)
_RUNNING, _SUCCESS, _FAILURE = Status.RUNNING, Status.SUCCESS, Status.FAILURE


class _Plan:
    """What entering and exiting a state needs to know, worked out once per chart, not per entry."""

    __slots__ = ("requested", "on_event", "timed", "defaults")

    def __init__(self, state: State):
        self.requested = tuple(n for n in state.needs if n.requested)  # asked of the manager on entry
        by_event: dict[str, list[Transition]] = {}
        for t in state.transitions:
            if t.kind is ast.TriggerKind.EVENT and t.event:
                by_event.setdefault(t.event, []).append(t)
        self.on_event = {k: tuple(v) for k, v in by_event.items()}  # event name -> its `on` transitions
        self.timed = any(t.kind in (ast.TriggerKind.TIMEOUT, ast.TriggerKind.CHANGE) for t in state.transitions)
        self.defaults: dict[str, Any] | None = None  # parameter defaults, evaluated at the first entry


@dataclass(eq=False, slots=True, init=False)
class Node:
    """One active instance of a state."""

    state: State
    path: str
    parent: Node | None
    entered: float
    plan: _Plan
    phase: Phase
    scope: dict[str, Any]  # params, vars, shared, resources
    outputs: dict[str, Any]  # finished children's outputs by name
    children: list[Node]
    finished: set[str]  # ids of children that succeeded (parallel)
    component: Component | None
    context: Context | None
    assignment: dict[str, str]  # requested need -> resource id
    epochs: dict[str, int]  # unit id -> fencing epoch of its grant
    requested: bool
    lease_until: float
    instances: int  # multi: created so far
    succeeded: int
    failed: int
    bounds: tuple[int, int]
    reserved_by: str  # a preallocation made when this (future) node's predecessor was entered
    last_failure: str  # multi: why the most recent instance failed, for the report

    def __init__(self, state: State, path: str, parent: Node | None, entered: float, plan: _Plan,
                 scope: dict[str, Any], reserved_by: str = ""):
        # Written out: a node is made on every entry, and the generated __init__ (six default
        # factories, defaults checked one by one) cost twice as much. `scope` is taken, not copied.
        self.state, self.path, self.parent, self.entered, self.plan = state, path, parent, entered, plan
        self.phase = _WAITING
        self.scope = scope
        self.outputs, self.children, self.finished = {}, [], set()
        self.component, self.context = None, None
        self.assignment, self.epochs = {}, {}
        self.requested, self.lease_until = False, 0.0
        self.instances = self.succeeded = self.failed = 0
        self.bounds = (0, 0)
        self.reserved_by, self.last_failure = reserved_by, ""


class Interpreter:
    """Executes one mission. Drive it with `start()`, then `step()` whenever time advances."""

    def __init__(self, chart: Statechart, registry: Registry, rcm: ResourceManager | ResourceBroker, clock: Clock, *,
                 pool: ResourcePool | None = None, mission: str = "", services: Mapping[str, Any] | None = None,
                 lease: float = 3.0, preallocate: bool = False):
        self.chart = chart
        self.registry = registry
        self.clock = clock
        self.pool = pool or ResourcePool(rcm)
        self.rcm = self.pool.broker  # every decision reaches every mission sharing the manager
        self.mission = mission or chart.name
        self.services = dict(services or {})
        self.lease = lease
        self.preallocate = preallocate
        self._reservations: dict[str, Node] = {}  # holder -> provisional node of a state not yet entered
        self.listeners: list[Listener] = []
        self.root: Node | None = None
        self.outcome: str | None = None
        self.reason = ""
        self.events: collections.deque[rec.Event] = collections.deque()
        self.holders: dict[str, Node] = {}  # request holder path -> node
        self._finishing: list[tuple[Node, bool, str]] = []
        self.rcm.attach(self._apply)
        self._states = chart.states
        self._plans = {sid: _Plan(st) for sid, st in chart.states.items()}  # per state, not per entry
        # Indices kept in step with entry and exit, so a step never walks the whole tree.
        self._running: dict[Node, None] = {}  # leaves with a component, in entry order
        self._timed: dict[Node, None] = {}  # nodes with `after`/`when` transitions
        self._listening: dict[str, dict[Node, None]] = {  # event name -> nodes with `on` transitions
            event: {} for plan in self._plans.values() for event in plan.on_event}
        self._components: dict[str, tuple[Component, Context, _Resolved]] = {}  # reused per instance path
        self._last_tick = -1.0
        self._settling = False
        self._arbiter = Arbiter()  # one control cycle's actuator commands, multiplexed by priority
        self._rank = {sid: i for i, sid in enumerate(s.id for s in chart.walk())}  # declaration order
        # What a state's descendants may read of it: its shared data and resources.
        self._visible = {sid: frozenset(n for n, _ in st.shared) | frozenset(n.name for n in st.needs)
                         for sid, st in chart.states.items()}

    # ------------------------------------------------------------- public API
    def attach(self, listener: Listener) -> None:
        self.listeners.append(listener)

    def start(self) -> None:
        """Enter the root state (and, through grants, everything below it)."""
        if self.root is not None:
            raise RuntimeError("this interpreter has already started")
        root_state = self._states[self.chart.root]
        self._enter(root_state, root_state.id, None, {})
        self._settle()
        self._flush()

    def step(self) -> None:
        """One macro step at `clock.now()`."""
        if self.outcome is not None:
            return
        now = self.clock.now()
        if now != self._last_tick:  # nothing can fall due without time passing
            self._last_tick = now
            self.rcm.tick(now)
            self._renew(now)
        for node in list(self._running):
            comp = node.component
            if node.phase is not _ACTIVE or comp is None:
                continue
            try:
                status = comp.step(now)
            except Exception as e:  # component code is not ours to trust
                self._component_failed(node, e)
                continue
            if status is _SUCCESS or status is _FAILURE:
                self._finish(node, status is _SUCCESS, "" if status is _SUCCESS else "failed")
        if self._arbiter.best:  # most cycles of most charts command nothing: no call then
            self._flush()
        self._settle()
        if self._arbiter.best:  # what exits and entries commanded (a terminate's stop, a start's first move)
            self._flush()

    def emit(self, name: str, source: str = "operator", **fields: Any) -> None:
        """Queue an event (from a component, an action or the operator)."""
        record = rec.Event(self.clock.now(), source, name, fields)  # `**fields` is already a fresh dict
        if self.listeners:
            self._notify(record)
        self.events.append(record)
        if not self._settling and self.root is not None:  # from outside a step: run to completion now
            self._settle()

    def stop(self, reason: str = "stopped by operator") -> None:
        """Shut everything down, children first; idempotent."""
        if self.root is not None and self.root.phase is not _DONE:
            self._exit(self.root, "stopped")
            self._flush()  # the terminates' last commands (stop the drive) still reach the hardware
        if self.outcome is None:
            self._end("stopped", reason)

    def add_resources(self, resources: Iterable[Any]) -> None:
        """Hot-plug: new units and aggregates; running multiplicities may grow."""
        self.pool.add(resources, self.clock.now())
        self._grow_multis()
        self._settle()

    def remove_host(self, host: str) -> None:
        """A host vanished: its grants are freed and the behaviors that held them fail (or degrade)."""
        self.pool.remove_host(host, self.clock.now())
        self._settle()

    def remove_resources(self, resource_ids: Iterable[str], reason: ReleaseReason = "resource lost") -> None:
        """Resources vanished (a lost robot): as for a host, only for these."""
        self.pool.remove(resource_ids, self.clock.now(), reason)
        self._settle()

    def _dependency(self, rid: str, key: str, value: object) -> None:
        """From a component, mid-cycle: record it now; the step settles its consequences."""
        self.pool.set_property(rid, key, value, self.clock.now())

    def set_property(self, rid: str, key: str, value: object) -> None:
        """Change a static dependency at run time (constraints and counts see it)."""
        self.pool.set_property(rid, key, value, self.clock.now())
        self._settle()

    @property
    def finished(self) -> bool:
        return self.outcome is not None

    def active(self) -> list[Node]:
        """Every live node, parents first."""
        out: list[Node] = []
        stack = [self.root] if self.root is not None and self.root.phase is not _DONE else []
        while stack:
            n = stack.pop()
            out.append(n)
            stack.extend(reversed(n.children))
        return out

    def snapshot(self) -> dict[str, Any]:
        """The active state tree, for status views and JSON."""
        def tree(n: Node) -> dict[str, Any]:
            return {"path": n.path, "kind": n.state.kind.value, "phase": n.phase.value,
                    "resources": dict(n.assignment), "children": [tree(c) for c in n.children]}
        return {"mission": self.mission, "outcome": self.outcome, "reason": self.reason,
                "time": self.clock.now(), "tree": tree(self.root) if self.root else None}

    # ------------------------------------------------------------- entering
    def _enter(self, state: State, path: str, parent: Node | None, scope: dict[str, Any]) -> Node:
        """Enter `state` at `path`; `scope` (its parameters) becomes the node's own, not a copy."""
        plan = self._plans[state.id]
        node = Node(state, path, parent, self.clock.now(), plan, scope)
        if parent is not None:
            parent.children.append(node)
        else:
            self.root = node  # before anything can call stop()
        if self.listeners:
            self._notify(rec.Entered(node.entered, path, state.id))
        if plan.timed:
            self._timed[node] = None
        for event in plan.on_event:
            self._listening[event][node] = None
        for name, _type in state.shared:
            node.scope[name] = {}
        try:
            for var in state.vars:
                node.scope[var.name] = evaluate(var.value, self._names(node), self.pool.count) if var.value else None
        except EvalError as e:
            self._finish(node, False, e.message)
            return node
        if self.preallocate and parent is not None:
            self._preallocate(node)
        if plan.requested:  # a state whose needs are all bound above never talks to the manager
            self._request(node, plan.requested)
        else:
            self._activate(node)
        return node

    def _request(self, node: Node, needs: tuple[ResourceNeed, ...]) -> None:
        try:
            reqs = tuple(self._need_request(node, n) for n in needs)
        except EvalError as e:
            self._finish(node, False, e.message)
            return
        node.requested = True
        holder = self._holder(node)
        self.holders[holder] = node
        early = self._reservations.pop(holder, None)
        if early is not None:  # preallocated ahead of need: adopt what was granted (or keep waiting)
            if early.assignment:
                self._granted(node, early.assignment)
            return
        if self.listeners:
            self._notify(rec.Waiting(self.clock.now(), node.path, tuple(f"{n.name}: {n.type}" for n in needs)))
        self.rcm.request(Request(self._holder(node), node.state.priority, reqs, self.mission), self.clock.now())

    def _need_request(self, node: Node, need: ResourceNeed) -> NeedRequest:
        quantity = need.quantity
        if isinstance(quantity, ast.Expr):
            value = evaluate(quantity, self._names(node), self.pool.count)
            quantity = float(value) if isinstance(value, int | float) else 1.0
        where = None
        if need.where is not None:
            expr, base = need.where, node

            def where(cand: Any, chosen: Mapping[str, Any]) -> bool:
                names = self._names(base)
                names.update({k: ResourceView(v, self.pool) for k, v in chosen.items()})
                names[need.name] = ResourceView(cand, self.pool)
                try:
                    return truthy(expr, names, self.pool.count)
                except EvalError:
                    return False
        return NeedRequest(need.name, need.type, float(quantity or 1.0), need.slice, where)

    def _granted(self, node: Node, assignment: Mapping[str, str]) -> None:
        node.assignment = dict(assignment)
        for need, rid in assignment.items():
            node.scope[need] = self.pool.view(rid)
        if node.phase is _WAITING:
            self._activate(node)

    def _preallocate(self, node: Node) -> None:
        """Reserve, now, what the state after `node` will need (paper 4.3 c): it starts without waiting."""
        parent = node.parent
        if parent is None or parent.state.kind is not _COMPOUND:
            return
        nxt = next((t for t in node.state.transitions
                    if t.kind is ast.TriggerKind.COMPLETION and t.guard is None), None)
        if nxt is None:
            return
        target = self._states[nxt.target]
        needs = [n for n in target.needs if n.requested]
        if not needs or target.kind not in (_COMPOUND, _PARALLEL, _LEAF):
            return
        future = Node(target, f"{parent.path}/{target.name}", parent, self.clock.now(), self._plans[target.id], {},
                      reserved_by=node.path)
        holder = self._holder(future)
        if holder in self.holders or holder in self._reservations:
            return
        try:
            future.scope.update({a.name: evaluate(a.value, self._names(parent), self.pool.count) for a in target.args})
            reqs = tuple(self._need_request(future, n) for n in needs)
        except EvalError:
            return  # it will simply ask on entry
        self._reservations[holder] = self.holders[holder] = future
        now = self.clock.now()
        self.rcm.reserve(Request(holder, target.priority, reqs, self.mission), now, now)

    def _drop_reservations(self, made_by: str, keep: str = "") -> None:
        """Cancel preallocations made for the successor of `made_by` (except the one being entered)."""
        for holder, future in list(self._reservations.items()):
            if (future.reserved_by == made_by or future.reserved_by.startswith(made_by + "/")) and holder != keep:
                del self._reservations[holder]
                self.holders.pop(holder, None)
                self.rcm.cancel(holder, self.clock.now())

    def _activate(self, node: Node) -> None:
        if self.outcome is not None or node.phase is _DONE:
            return
        node.phase = _ACTIVE
        state = node.state
        kind = state.kind
        if kind is _LEAF:
            self._start_component(node)
        elif kind is _COMPOUND:
            target = self._initial(node)
            if target is not None:
                self._enter_child(node, target)
        elif kind is _PARALLEL:
            for cid in state.children:
                child = self._states[cid]
                if child.kind is not _FINAL and not child.after:
                    self._enter_child(node, child)
        elif kind is _MULTI:
            self._start_multi(node)

    def _initial(self, node: Node) -> State | None:
        for t in node.state.starts:
            if self._enabled_guard(node, t, None):
                self._take_actions(node, t, None)
                return self._states[t.target]
        return self._states[node.state.initial] if node.state.initial else None

    def _enter_child(self, parent: Node, state: State, index: int | None = None, why: str = "") -> Node | None:
        if self.outcome is not None or parent.phase is _DONE:  # stopped meanwhile (e.g. by a listener)
            return None
        if state.kind is _FINAL:
            self._finish(parent, bool(state.success), "" if state.success else (why or "reached fail"))
            return None
        path = f"{parent.path}[{index}]" if index is not None else f"{parent.path}/{state.name}"
        params: dict[str, Any] = {}
        if state.args:
            domain = parent.parent if parent.state.kind is _MULTI else parent
            try:
                params = {a.name: evaluate(a.value, self._names(domain), self.pool.count) for a in state.args} \
                    if domain is not None else {}
            except EvalError as e:
                self._notify(rec.Log(self.clock.now(), path, f"cannot enter: {e.message}"))
                self._finish(parent, False, e.message)
                return None
        plan = self._plans[state.id]
        defaults = plan.defaults
        if defaults is None:
            defaults = plan.defaults = {a.name: evaluate(a.value, {}) for a in state.defaults}
        return self._enter(state, path, parent, defaults | params)  # a new dict: the node's scope

    def _start_multi(self, node: Node) -> None:
        m = node.state.multiplicity
        assert m is not None
        names = self._names(node.parent) if node.parent else {}
        try:
            low = int(evaluate(m.low, names, self.pool.count))  # type: ignore[call-overload]
            high = low if m.exact else (
                int(evaluate(m.high, names, self.pool.count)) if m.high is not None  # type: ignore[call-overload]
                else max(low, self._capacity(node)))
        except (EvalError, TypeError, ValueError) as e:
            self._finish(node, False, f"multiplicity: {e}")
            return
        node.bounds = (low, high)
        if high < low:
            self._finish(node, False, f"{node.state.name} needs at least {low} instances, only {high} possible")
            return
        if high == 0:
            self._finish(node, True)
            return
        self._grow_multi(node)

    def _capacity(self, node: Node) -> int:
        """For `[a..*]`: as many instances as the template's first requested resource type allows."""
        template = self._states[node.state.children[0]]
        need = next((n for n in template.needs if n.requested), None)
        return self.pool.count(need.type, None) if need else 0

    def _grow_multi(self, node: Node) -> None:
        template = self._states[node.state.children[0]]
        while node.instances < node.bounds[1] and node.phase is _ACTIVE:
            index = node.instances
            node.instances += 1
            self._enter_child(node, template, index)

    def _grow_multis(self) -> None:
        for node in self.active():
            m = node.state.multiplicity
            if node.state.kind is _MULTI and m is not None and m.high is not None and not m.exact:
                try:
                    high = int(evaluate(m.high, self._names(node.parent) if node.parent else {},  # type: ignore[call-overload]
                                        self.pool.count))
                except (EvalError, TypeError, ValueError):
                    continue
                if high > node.bounds[1]:
                    node.bounds = (node.bounds[0], high)
                    self._grow_multi(node)

    def _start_component(self, node: Node) -> None:
        """Set a component up once per instance path (py_trees style); start it on every entry."""
        cached = self._components.get(node.path)
        if cached is not None:
            comp, ctx, resolved = cached
            resolved.reset(node)  # the same views, resolved again for this entry
            ctx.params, ctx.outputs = dict(node.scope), {}
        else:
            resolved = _Resolved(self._devices, node)  # most components never ask: resolve on first use
            resources, devices = resolved.view(0), resolved.view(1)
            name = node.state.component or ""
            factory = self.registry.get(name)
            if factory is None:
                self._finish(node, False, f"no implementation of component {name} is available")
                return
            shared: dict[str, Any] = {}
            for anc in self._ancestors(node):
                for k, _ in anc.state.shared:
                    shared.setdefault(k, anc.scope.get(k))
            path = node.path
            ctx = Context(path, dict(node.scope), resources,
                          lambda ev, **f: self.emit(ev, path, **f),
                          lambda text: self._notify(rec.Log(self.clock.now(), path, text)),
                          self.clock.now, devices=devices,
                          services={**self.services, "shared": shared, "dependencies": self._dependency,
                                    "siblings": node.parent.outputs if node.parent else {}})
            try:
                comp = factory()
                comp.setup(ctx)
            except Exception as e:  # component code is not ours to trust
                self._component_failed(node, e)
                return
            self._components[node.path] = (comp, ctx, resolved)
        node.component, node.context = comp, ctx
        try:
            comp.start()
        except Exception as e:
            self._component_failed(node, e)
            return
        self._running[node] = None

    def _flush(self) -> None:
        self._arbiter.flush(self._command_failed)

    def _command_failed(self, owner: object, e: Exception) -> None:
        """A driver refused the winning command of a cycle: its proposer (a node) fails."""
        if isinstance(owner, Node):
            self._component_failed(owner, e)

    def _component_failed(self, node: Node, e: Exception) -> None:
        self._notify(rec.Log(self.clock.now(), node.path, f"component raised {type(e).__name__}: {e}"))
        self._finish(node, False, f"component raised {type(e).__name__}: {e}")

    def _devices(self, node: Node) -> tuple[dict[str, str], dict[str, Any]]:
        """Each need's resource id, and its driver (a robot's own part driver when bound through a part)."""
        drivers = self.services.get("drivers")
        resources: dict[str, str] = {}
        devices: dict[str, Any] = {}
        for need in node.state.needs:
            holder, rid, robot, part = node, node.assignment.get(need.name), None, None
            if rid is None and need.bound_to is not None:
                state_id, name, part = need.bound_to
                holder = next((a for a in self._ancestors(node) if a.state.id == state_id), node)
                robot = holder.assignment.get(name)
                rid = self.pool.part(robot, part) if robot else None
            if not rid:
                continue
            resources[need.name] = rid
            if drivers is not None:
                by_robot = getattr(drivers, "robots", {}).get(robot, {}) if robot and part else {}
                driver = by_robot.get(part) or getattr(drivers, "devices", {}).get(rid)
                if driver is not None:
                    rank = (-node.state.priority, self._rank.get(node.state.id, 0))
                    devices[need.name] = Fenced(driver, _current_epoch(holder, rid), self._arbiter, rank, node)
        return resources, devices

    # ------------------------------------------------------------- finishing and transitions
    def _finish(self, node: Node, success: bool, reason: str = "") -> None:
        """A node completed (or failed): let its parent react, after the current call returns."""
        self._finishing.append((node, success, reason))

    def _settle(self) -> None:
        """Run to completion: finish nodes and take enabled transitions until quiet."""
        if self._settling:
            return
        if not (self._finishing or self._timed or self.events):
            return  # nothing to finish, no change or timeout to check, no event: quiet already
        self._settling = True
        try:
            self._run_to_completion()
        finally:
            self._settling = False

    def _run_to_completion(self) -> None:
        for _ in range(MAX_MICROSTEPS):
            if self.outcome is not None:
                return
            if self._finishing:
                node, ok, why = self._finishing.pop(0)
                if node.phase is not _DONE or node is self.root:
                    self._complete(node, ok, why)
                continue
            if self._timed and self._fire_one():
                continue
            if self.events:
                self._dispatch(self.events.popleft())
                continue
            return
        if self.root is not None:
            self._exit(self.root, "failure")
        self._end("failure", f"livelock: more than {MAX_MICROSTEPS} transitions without time passing")

    def _complete(self, node: Node, ok: bool, why: str) -> None:
        parent = node.parent
        if parent is None:
            self._exit(node, "success" if ok else "failure")
            self._end("success" if ok else "failure", why)
            return
        if node.phase is not _DONE:
            self._exit(node, "success" if ok else "failure")
        if node.state.kind is _LEAF and node.context is not None:
            parent.outputs[node.state.name] = dict(node.context.outputs)
        elif node.outputs:  # a composite's outputs are its finished children's, merged (FindNewDoor.door)
            parent.outputs[node.state.name] = {k: v for child in node.outputs.values() for k, v in child.items()}
        kind = ast.TriggerKind.COMPLETION if ok else ast.TriggerKind.ERROR
        for t in node.state.transitions:
            if t.kind is kind and self._enabled_guard(parent, t, None):
                self._take(node, t, None, why)
                return
        pk = parent.state.kind
        if pk is _MULTI:
            self._instance_done(parent, ok, why)
        elif not ok:
            self._finish(parent, False, why or f"{node.path} failed")
        elif pk is _PARALLEL:
            parent.finished.add(node.state.id)
            self._region_done(parent, node)
        elif pk is _COMPOUND:
            self._finish(parent, True)

    def _region_done(self, parent: Node, node: Node) -> None:
        state = parent.state
        regions = [c for c in state.children if self._states[c].kind is not _FINAL]
        if state.policy is ast.Policy.ANY or (state.policy is ast.Policy.UNTIL and node.state.id == state.until):
            self._finish(parent, True)
            return
        if all(r in parent.finished for r in regions):
            self._finish(parent, True)
            return
        running = {c.state.id for c in parent.children if c.phase is not _DONE}
        for rid in regions:
            child = self._states[rid]
            if child.after and rid not in running and rid not in parent.finished \
                    and all(a in parent.finished for a in child.after):
                self._enter_child(parent, child)

    def _instance_done(self, multi: Node, ok: bool, why: str) -> None:
        if ok:
            multi.succeeded += 1
        else:
            multi.failed += 1
            multi.last_failure = why
            self._notify(rec.Log(self.clock.now(), multi.path, f"an instance failed: {why}"))
        low, _ = multi.bounds
        running = [c for c in multi.children if c.phase is not _DONE]
        if multi.succeeded + len(running) < low:
            last = f" (last failure: {multi.last_failure})" if multi.last_failure else ""
            self._finish(multi, False, f"only {multi.succeeded} of at least {low} instances of "
                         f"{multi.state.name} can succeed{last}")
        elif not running:
            self._finish(multi, True)

    def _fire_one(self) -> bool:
        """Take the first enabled change or timeout transition, if any."""
        if not self._timed:
            return False
        now = self.clock.now()
        for node in list(self._timed):
            if node.parent is None or node.phase is _DONE:
                continue
            domain = node.parent
            for t in node.state.transitions:
                if t.kind is ast.TriggerKind.TIMEOUT:
                    delay = self._delay(domain, t)
                    if delay is None or now - node.entered < delay:
                        continue
                elif t.kind is ast.TriggerKind.CHANGE:
                    if t.condition is None or not self._truthy(domain, t.condition, None):
                        continue
                else:
                    continue
                if self._enabled_guard(domain, t, None):
                    self._take(node, t, None)
                    return True
        return False

    def _delay(self, domain: Node, t: Transition) -> float | None:
        """A timeout in seconds: a constant, or its expression in the scope that declares it."""
        if not isinstance(t.delay, ast.Expr):
            return t.delay
        try:
            value = evaluate(t.delay, self._names(domain), self.pool.count)
        except EvalError as e:
            self._notify(rec.Log(self.clock.now(), domain.path, f"timeout error: {e.message}"))
            return None
        return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None

    def _dispatch(self, event: rec.Event) -> None:
        listening = self._listening.get(event.name)
        if not listening:
            return
        for node in list(listening):  # a copy: taking a transition changes who listens
            domain = node.parent
            if domain is None or node.phase is _DONE:
                continue
            for t in node.plan.on_event[event.name]:
                if t.guard is None or self._truthy(domain, t.guard, event):
                    self._take(node, t, event)
                    break

    def _take(self, node: Node, t: Transition, event: rec.Event | None, why: str = "") -> None:
        domain = node.parent  # the node whose body declares the transition (a multi's parent for instances)
        assert domain is not None
        target = self._states[t.target]
        if self.listeners:
            self._notify(rec.Taken(self.clock.now(), node.path, _target_path(domain, target), t.kind.value,
                                   trigger_label(t)))
        if node.phase is not _DONE:
            self._exit(node, "stopped")
        if self._reservations:
            self._drop_reservations(node.path, keep=f"{self.mission}/{domain.path}/{target.name}")
        final = target.kind is _FINAL
        if final and domain.state.kind is _PARALLEL:
            for c in list(domain.children):
                if c.phase is not _DONE:
                    self._exit(c, "stopped")
        if t.actions:
            self._take_actions(domain, t, event)
        if domain.phase is not _DONE:
            if not why and final and not target.success and t.kind is not ast.TriggerKind.COMPLETION:
                why = f"{node.state.name}: {trigger_label(t)}"  # say why the behavior failed
            self._enter_child(domain, target, why=why)

    def _take_actions(self, domain: Node, t: Transition, event: rec.Event | None) -> None:
        for a in t.actions:
            try:
                self._action(domain, a, event)
            except EvalError as e:
                self._notify(rec.Log(self.clock.now(), domain.path, f"action failed: {e.message}"))

    def _action(self, domain: Node, a: ast.Action, event: rec.Event | None) -> None:
        names = self._names(domain, event)
        match a:
            case ast.SetAction(name=n, value=v):
                domain.scope[n] = evaluate(v, names, self.pool.count)
            case ast.EmitAction(event=ev, args=args):
                fields = {arg.name: evaluate(arg.value, names, self.pool.count) for arg in args or ()}
                self.emit(ev, domain.path, **fields)
            case ast.ReleaseAction(resource=r):
                self._release_need(domain, r)
            case ast.LogAction(message=m):
                self._notify(rec.Log(self.clock.now(), domain.path, format_value(evaluate(m, names, self.pool.count))))

    def _release_need(self, domain: Node, name: str) -> None:
        holder = next((n for n in [domain, *self._ancestors(domain)] if name in n.assignment), None)
        if holder is None:
            return
        self.rcm.release(self._holder(holder), self.clock.now(), [name])  # by need name: exact even on shared units

    # ------------------------------------------------------------- exiting
    def _exit(self, node: Node, status: str) -> None:
        """Exit children first, terminate the component, give resources back."""
        if node.phase is _DONE:
            if node.parent is not None and node in node.parent.children:
                node.parent.children.remove(node)
            return
        while node.children:
            self._exit(node.children[-1], "stopped")
        comp = node.component
        if comp is not None:
            self._running.pop(node, None)
            try:
                comp.terminate(_FINAL_STATUS.get(status, _RUNNING))
            except Exception as e:  # the node is leaving anyway: just say so
                self._notify(rec.Log(self.clock.now(), node.path, f"component raised {type(e).__name__}: {e}"))
        node.phase = _DONE
        if self._reservations and node.state.children:
            self._drop_reservations(node.path)  # reservations for states inside it
        plan = node.plan
        if plan.timed:
            self._timed.pop(node, None)
        for event in plan.on_event:
            self._listening[event].pop(node, None)
        if node.requested:
            self.holders.pop(self._holder(node), None)
            now = self.clock.now()
            if node.assignment:
                self.rcm.release(self._holder(node), now)
            else:
                self.rcm.cancel(self._holder(node), now)
        parent = node.parent
        if parent is not None and parent.children and parent.children[-1] is node:
            parent.children.pop()
        elif parent is not None and node in parent.children:
            parent.children.remove(node)
        if self.listeners:
            self._notify(rec.Exited(self.clock.now(), node.path, node.state.id, status))

    def _end(self, outcome: str, reason: str) -> None:
        self.rcm.detach(self._apply)
        if self.outcome is None:
            self.outcome, self.reason = outcome, reason
            self._notify(rec.Finished(self.clock.now(), self.chart.root, outcome, reason))

    # ------------------------------------------------------------- resources
    def _apply(self, decisions: Iterable[object]) -> None:
        for d in decisions:
            holder = getattr(d, "holder", None) or getattr(d, "victim", None)
            node = self.holders.get(holder) if isinstance(holder, str) else None
            if node is None:
                continue
            now = self.clock.now()
            match d:
                case Granted():
                    node.lease_until = d.lease_until
                    node.epochs = dict(d.epochs)
                    if self.listeners:
                        self._notify(rec.Granted(now, node.path, dict(d.assignment), dict(d.epochs)))
                    if node.reserved_by:
                        node.assignment = dict(d.assignment)  # held for a state not entered yet
                    elif node.phase is _SUSPENDED:
                        node.assignment = dict(d.assignment)
                        self._suspend(node, False)
                    else:
                        self._granted(node, d.assignment)
                case Revoked():
                    self._notify(rec.Revoked(now, node.path, d.units, f"preempted by {d.by}"))
                    self._suspend(node, True)
                case Released(reason="release"):
                    self._notify(rec.Released(now, node.path, d.units, "release"))
                case Released():
                    self._notify(rec.Released(now, node.path, d.units, d.reason))
                    if node.phase is not _DONE:
                        self._finish(node, False, f"lost its resources ({d.reason})")
                case Unsatisfiable():
                    self._finish(node, False, f"resource need {d.need} can never be satisfied: {d.reason}")
                case Deadlock():
                    self._finish(node, False, f"cancelled to break a resource deadlock: {' -> '.join(d.cycle)}")
                case WaitingDecision():
                    self._notify(rec.Waiting(now, node.path, (), d.blocked_by))

    def _suspend(self, node: Node, suspend: bool) -> None:
        node.phase = _SUSPENDED if suspend else _ACTIVE
        self._notify((rec.Suspended if suspend else rec.Resumed)(self.clock.now(), node.path))
        stack = list(node.children)
        while stack:
            n = stack.pop()
            stack.extend(n.children)
            if n.component is not None and n.phase is not _DONE:
                comp = n.component
                self._guard_call(n, comp.suspend if suspend else comp.resume)
                n.phase = _SUSPENDED if suspend else _ACTIVE
        if node.component is not None:
            comp = node.component
            self._guard_call(node, comp.suspend if suspend else comp.resume)

    def _renew(self, now: float) -> None:
        for holder, node in list(self.holders.items()):
            if node.assignment and node.lease_until - now < self.lease / 2:
                for d in self.rcm.renew(holder, now):
                    until = getattr(d, "lease_until", None)
                    if until is not None:
                        node.lease_until = until

    # ------------------------------------------------------------- helpers
    def _holder(self, node: Node) -> str:
        """The manager's name for a node: unique across missions sharing it, prefixes kept."""
        return f"{self.mission}/{node.path}"

    def _names(self, node: Node | None, event: rec.Event | None = None) -> dict[str, Any]:
        if node is None:
            return {}
        names: dict[str, Any] = {}
        for anc in reversed(self._ancestors(node)):
            shown = self._visible[anc.state.id]
            names.update((k, v) for k, v in anc.scope.items() if k in shown)
        names.update(node.scope)
        names.update(node.outputs)
        if event is not None:
            names["event"] = event.fields
        return names

    @staticmethod
    def _ancestors(node: Node) -> list[Node]:
        out = []
        p = node.parent
        while p is not None:
            out.append(p)
            p = p.parent
        return out

    def _truthy(self, node: Node, expr: ast.Expr, event: rec.Event | None) -> bool:
        try:
            return truthy(expr, self._names(node, event), self.pool.count)
        except EvalError as e:
            self._notify(rec.Log(self.clock.now(), node.path, f"condition error: {e.message}"))
            return False

    def _enabled_guard(self, domain: Node, t: Transition, event: rec.Event | None) -> bool:
        return t.guard is None or self._truthy(domain, t.guard, event)

    def _guard_call(self, node: Node, fn: Callable[[], Any], on_error: bool = True) -> Any:
        """Call component code; an exception fails the node, never the executive."""
        try:
            return fn()
        except Exception as e:  # component code is not ours to trust
            self._notify(rec.Log(self.clock.now(), node.path, f"component raised {type(e).__name__}: {e}"))
            if on_error:
                self._finish(node, False, f"component raised {type(e).__name__}: {e}")
            return None

    def _notify(self, record: rec.Record) -> None:
        for listener in self.listeners:
            listener(record)


class _Resolved:
    """A component's resources and devices, worked out the first time it asks for either."""

    __slots__ = ("_resolve", "_node", "_value")

    def __init__(self, resolve: Callable[[Node], tuple[dict[str, str], dict[str, Any]]], node: Node):
        self._resolve = resolve
        self._node = node
        self._value: tuple[dict[str, str], dict[str, Any]] | None = None

    def reset(self, node: Node) -> None:
        """A new entry of the same path: resolve again, for `node`, when next asked."""
        self._node, self._value = node, None

    def get(self, which: int) -> dict[str, Any]:
        if self._value is None:
            self._value = self._resolve(self._node)
        return self._value[which]

    def view(self, which: int) -> _LazyMap:
        return _LazyMap(self, which)


class _LazyMap(Mapping[str, Any]):
    __slots__ = ("_resolved", "_which")

    def __init__(self, resolved: _Resolved, which: int):
        self._resolved, self._which = resolved, which

    def __getitem__(self, key: str) -> Any:
        return self._resolved.get(self._which)[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._resolved.get(self._which))

    def __len__(self) -> int:
        return len(self._resolved.get(self._which))


def _current_epoch(holder: Node, unit: str) -> Callable[[], int | None]:
    """Read at each command: a resumed grant replaces `holder.epochs`, so never bind the dict itself."""
    return lambda: holder.epochs.get(unit)


def _target_path(domain: Node, target: State) -> str:
    return f"{domain.path}/{target.name}"
