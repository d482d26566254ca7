"""The compiled statechart: the runtime's input, pure data.

A mission compiles to a tree of states. Behaviors become compound or parallel states,
elementary components become leaves, `Name[a..b]` becomes a multiplicity state whose
single child is the template that the runtime instantiates on entry (instance ids replace
`[*]` by `[0]`, `[1]`, ...). `done` and `fail` are final children of the behavior that
names them. Transitions always join siblings, so the runtime's exit set for a transition
is the active subtree of its source (or of every region, when the target is final in a
parallel state) and its entry set is the target: both follow from `Transition.domain`,
computed once here.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from enum import StrEnum

from dsl import ast
from dsl.catalog import Limit
from dsl.dataflow import InputBinding
from dsl.errors import NOWHERE, Span
from dsl.limits import DEFAULT_INSTANCES


class StateKind(StrEnum):
    COMPOUND = "compound"
    """One active child at a time; transitions move between them."""
    PARALLEL = "parallel"
    """All children active at once (regions), ended by the completion policy."""
    MULTI = "multi"
    """A multiplicity: instances of the template child created on entry."""
    LEAF = "leaf"
    """An elementary behavior: a component instance."""
    FINAL = "final"
    """`done` (success) or `fail` of the enclosing behavior."""


@dataclass(frozen=True, slots=True)
class ResourceNeed:
    """A resource a state holds while active.

    `bound_to` is `(ancestor state id, ancestor need name, part or None)` when an ancestor
    already holds it; otherwise the state asks the Resource Controller Manager on entry.
    `reuse`: for a requested need with a `where`, the parts of ancestors' robots it takes
    instead, the first that satisfies the `where` on entry (the mission would otherwise wait
    for a resource it holds itself); when none does, the manager is asked.
    """

    name: str
    type: str
    where: ast.Expr | None = None
    quantity: ast.Expr | float | None = None
    slice: float | None = None
    bound_to: tuple[str, str, str | None] | None = None
    span: Span = field(default=NOWHERE, compare=False, repr=False)
    reuse: tuple[tuple[str, str, str], ...] = ()

    @property
    def requested(self) -> bool:
        return self.bound_to is None


@dataclass(frozen=True, slots=True)
class Transition:
    """An outgoing transition of `source`; `domain` is the state whose children both ends are."""

    source: str
    target: str
    domain: str
    kind: ast.TriggerKind
    event: str | None = None
    condition: ast.Expr | None = None
    delay: float | ast.Expr | None = None  # seconds, or an expression in the declaring scope
    guard: ast.Expr | None = None
    actions: tuple[ast.Action, ...] = ()
    generated: bool = False  # made by the compiler (plans, implicit completion), not written
    preallocate: bool = False  # entering the source reserves the target's needs
    sender: str | None = None  # `on E from X`: the sibling (its name in the domain) whose subtree's events count
    span: Span = field(default=NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class State:
    id: str
    name: str
    kind: StateKind
    parent: str | None
    depth: int
    children: tuple[str, ...] = ()
    initial: str | None = None
    starts: tuple[Transition, ...] = ()  # several or guarded `start ->`: the first enabled one wins
    component: str | None = None  # leaf: component type; compound/parallel: behavior name
    args: tuple[ast.Arg, ...] = ()  # evaluated in the parent's scope on entry
    defaults: tuple[ast.Arg, ...] = ()  # declared parameter defaults, constants, applied before args
    needs: tuple[ResourceNeed, ...] = ()
    shared: tuple[tuple[str, str], ...] = ()
    vars: tuple[ast.Var, ...] = ()
    priority: int = 1
    policy: ast.Policy | None = None
    until: str | None = None
    after: tuple[str, ...] = ()  # concurrent plans: siblings that must be done before this starts
    constraints: tuple[ast.Constraint, ...] = ()  # hold while the state is active (checked every control cycle)
    inputs: tuple[InputBinding, ...] = ()  # leaf: what each declared input reads (dsl.dataflow)
    #: leaf: the manifest's range of each parameter whose argument is an expression, checked as it is evaluated on
    #: entry (a constant one was checked by the compiler)
    ranges: tuple[tuple[str, Limit], ...] = ()
    entry: tuple[str, ...] = ()  # parallel: the children in the order they are entered and stepped (producers
    #                              first); empty: declaration order
    multiplicity: ast.Multiplicity | None = None
    success: bool | None = None  # final states
    transitions: tuple[Transition, ...] = ()
    span: Span = field(default=NOWHERE, compare=False, repr=False)


def waits_to_start(state: State) -> bool:
    """Whether `state` is the `start` state the compiler adds to a behavior with a `start -> X when/after/on`
    (`start` is a keyword: no child of a mission has that name)."""
    return state.name == "start" and state.kind is StateKind.COMPOUND and state.component is None


@dataclass(frozen=True)
class Statechart:
    """Every state by id, the root, and the source it came from."""

    name: str
    root: str
    states: Mapping[str, State]
    file: str = "<string>"
    #: The mission's rank against other missions sharing the team (`mission Name priority N`), 1 the highest.
    priority: int = 1
    #: The most instances a multiplicity may create at run time: the limit it was compiled with (`dsl.limits`).
    max_instances: int = DEFAULT_INSTANCES

    def __getitem__(self, state_id: str) -> State:
        return self.states[state_id]

    def children(self, state_id: str) -> Iterator[State]:
        return (self.states[c] for c in self.states[state_id].children)

    def ancestors(self, state_id: str) -> list[str]:
        """Ids from the parent up to the root."""
        out = []
        parent = self.states[state_id].parent
        while parent is not None:
            out.append(parent)
            parent = self.states[parent].parent
        return out

    def descendants(self, state_id: str) -> list[str]:
        """Ids below `state_id`, parents before children."""
        out: list[str] = []
        stack = list(reversed(self.states[state_id].children))
        while stack:
            sid = stack.pop()
            out.append(sid)
            stack.extend(reversed(self.states[sid].children))
        return out

    def walk(self) -> Iterator[State]:
        """Every state, parents before children, in declaration order."""
        yield self.states[self.root]
        for sid in self.descendants(self.root):
            yield self.states[sid]

    def leaves(self) -> list[State]:
        return [s for s in self.walk() if s.kind is StateKind.LEAF]

    def transitions(self) -> Iterator[Transition]:
        for s in self.walk():
            yield from s.transitions
