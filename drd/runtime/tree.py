"""The state tree of a running mission: one `Node` per active instance of a state.

Pure data with the few walks the interpreter needs. A node is made on every entry and never reused (a node
that exited stays exited for anyone still holding it). Three parts of the runtime read and write it: the
interpreter (statechart semantics), the resource client (requests, grants, bindings) and the component host
(the leaf's component). Each owns its own fields, named in `Node`'s comments.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from enum import StrEnum
from types import MappingProxyType
from typing import Any

from drd.runtime.component import Component, Context
from drd.runtime.ownership import Binding
from dsl import ast
from dsl.statechart import State, StateKind, Transition


class Phase(StrEnum):
    WAITING = "waiting"
    """Entered, waiting for the Resource Controller Manager to grant its needs."""
    ACTIVE = "active"
    """Running: children entered, component stepping."""
    SUSPENDED = "suspended"
    """Frozen: its own grant was revoked, or an ancestor's was. Nothing below it steps, takes a transition or
    commands a device until every holder above it holds again."""
    DONE = "done"
    """Exited (successfully, failed or stopped)."""


# Enum members as module constants, which the runtime compares against: on CPython 3.11 each `Phase.DONE` or
# `StateKind.LEAF` is a metaclass attribute lookup (~0.1 µs), and a transition made a dozen.
WAITING, ACTIVE, SUSPENDED, DONE = Phase.WAITING, Phase.ACTIVE, Phase.SUSPENDED, Phase.DONE
LEAF, COMPOUND, PARALLEL, MULTI, FINAL = (StateKind.LEAF, StateKind.COMPOUND, StateKind.PARALLEL, StateKind.MULTI,
                                          StateKind.FINAL)


# Shared by every node until it has its own (a node is made on every entry: two allocations fewer each).
_NO_BINDINGS: Mapping[str, Binding] = MappingProxyType({})
_NO_EPOCHS: dict[str, int] = {}  # never written: `took` gives a node a dict of its own
_NO_REUSE: Mapping[str, tuple[str, str, str]] = MappingProxyType({})


class StatePlan:
    """What entering and exiting a state needs to know, worked out once per chart, not per entry."""

    __slots__ = ("requested", "adopted", "on_event", "timed", "defaults", "reserves", "starting")

    def __init__(self, state: State):
        self.requested = tuple(n for n in state.needs if n.requested)  # asked of the manager on entry
        # a behavior's needs an ancestor holds (a leaf's are bound with its component)
        self.adopted = state.kind is not StateKind.LEAF and any(not n.requested for n in state.needs)
        by_event: dict[str, list[Transition]] = {}
        for t in state.transitions:
            if t.kind is ast.TriggerKind.EVENT and t.event:
                by_event.setdefault(t.event, []).append(t)
        self.on_event = {k: tuple(v) for k, v in by_event.items()}  # event name -> its `on` transitions
        self.timed = any(t.kind in (ast.TriggerKind.TIMEOUT, ast.TriggerKind.CHANGE) for t in state.transitions)
        self.defaults: dict[str, Any] | None = None  # parameter defaults, evaluated at the first entry
        # the completion transitions that preallocate their target's needs when this state is entered
        self.reserves = tuple(t for t in state.transitions
                              if t.kind is ast.TriggerKind.COMPLETION and t.preallocate)
        # a behavior's waiting `start` state (dsl.build): its `after`s count from the behavior's entry
        self.starting = state.parent is not None and state.id == f"{state.parent}/start"


@dataclass(eq=False, slots=True, init=False)
class Node:
    """One active instance of a state."""

    # -- the interpreter's
    state: State
    path: str
    parent: Node | None
    entered: float
    plan: StatePlan
    phase: Phase
    scope: dict[str, Any]  # params, vars, shared, resources
    outputs: dict[str, Any]  # finished children's outputs by name
    children: list[Node]
    finished: set[str]  # ids of children that succeeded (parallel)
    instances: int  # multi: created so far
    succeeded: int
    failed: int
    bounds: tuple[int, int]
    last_failure: str  # multi: why the most recent instance failed, for the report
    pending: bool  # granted while an ancestor was suspended: activated when it resumes
    closing: bool  # being exited: nothing inside is granted, activated or takes a transition any more
    # -- the resource client's
    requested: bool  # it asked the manager (it is a holder, under `<mission>/<path>`)
    grant: dict[str, str] | None  # need -> resource id while its grant is in force
    epochs: dict[str, int]  # unit id -> fencing epoch of the grant in force
    units: tuple[str, ...]  # the units of the grant in force
    revoked: bool  # its own grant was taken at a slice boundary: suspended until granted again
    released: frozenset[str]  # needs it gave back early (`release(x)`)
    reused: Mapping[str, tuple[str, str, str]]  # need -> the ancestor's robot part it took (`ResourceNeed.reuse`)
    lease_until: float
    reserved_by: str  # a preallocation made when this (future) node's predecessor was entered
    # -- the component host's
    component: Component | None
    context: Context | None
    bindings: Mapping[str, Binding]  # a leaf's needs, bound to devices under grants (once it asked for them)

    def __init__(self, state: State, path: str, parent: Node | None, entered: float, plan: StatePlan,
                 scope: dict[str, Any], reserved_by: str = ""):
        # Written out: a node is made on every entry, and a generated __init__ with default factories costs twice
        # as much. `scope` is taken, not copied.
        self.state, self.path, self.parent, self.entered, self.plan = state, path, parent, entered, plan
        self.phase = WAITING
        self.scope = scope
        self.outputs, self.children, self.finished = {}, [], set()
        self.instances = self.succeeded = self.failed = 0
        self.bounds = (0, 0)
        self.last_failure = ""
        self.pending = self.closing = False
        self.requested, self.grant, self.epochs, self.units, self.revoked = False, None, _NO_EPOCHS, (), False
        self.released = frozenset()
        self.reused = _NO_REUSE
        self.lease_until = 0.0
        self.reserved_by = reserved_by
        self.component, self.context, self.bindings = None, None, _NO_BINDINGS

    @property
    def blocked(self) -> bool:
        """Whether an ancestor is suspended (then this node is frozen with it)."""
        parent = self.parent
        return parent is not None and parent.phase is SUSPENDED

    def ancestors(self) -> list[Node]:
        """From the parent up to the root."""
        out = []
        p = self.parent
        while p is not None:
            out.append(p)
            p = p.parent
        return out

    def subtree(self) -> Iterator[Node]:
        """This node and every live node below it, parents first, in child order."""
        stack = [self]
        while stack:
            n = stack.pop()
            yield n
            stack.extend(reversed(n.children))

    def children_first(self) -> list[Node]:
        """This node and every node below it, each after its children, the last child first (exit order)."""
        out: list[Node] = []
        stack: list[tuple[Node, bool]] = [(self, False)]
        while stack:
            n, expanded = stack.pop()
            if expanded:
                out.append(n)
                continue
            stack.append((n, True))
            stack.extend((c, False) for c in n.children)  # the last child is popped (exited) first
        return out

    def detach(self) -> None:
        """Leave the parent's list of live children."""
        parent = self.parent
        if parent is not None:
            if parent.children and parent.children[-1] is self:
                parent.children.pop()
            elif self in parent.children:
                parent.children.remove(self)
