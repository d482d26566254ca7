"""The mission AST: frozen dataclasses, each keeping its source span.

Spans are excluded from equality so that `parse(pretty(ast)) == ast` holds even though
the printed text lays things out differently. Nodes are built directly by the parser's
inline transformer (no intermediate parse tree), and walked iteratively where depth is
unbounded, so deeply nested input cannot exhaust the Python stack.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from enum import StrEnum

from dsl.errors import NOWHERE, Span

# Every node keeps its span, keyword-only and ignored by equality (NOWHERE when built by hand).

#: Reserved words: never accepted as names (a keyword glued to a name is a name, not the keyword).
KEYWORDS = frozenset(
    "import mission behavior priority needs where quantity for shared var as parallel all any until "
    "start done fail when on error after set emit release log plan concurrent true false and or not "
    "event constraint preallocate from".split()
)

#: Seconds per duration unit, as written in the language (`250ms 30s 5min 2h`).
DURATION_UNITS = {"ms": 0.001, "s": 1.0, "min": 60.0, "h": 3600.0}
_DURATION = re.compile(r"(\d+(?:\.\d+)?)(ms|s|min|h)")


def parse_duration(text: str) -> float | None:
    """Seconds in a duration literal such as `5min`, or None if it is not one."""
    m = _DURATION.fullmatch(text.strip())
    return float(m.group(1)) * DURATION_UNITS[m.group(2)] if m else None


# ---------------------------------------------------------------- expressions


@dataclass(frozen=True, slots=True)
class Expr:
    """Base of every expression node: each knows where it was written."""

    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class Literal(Expr):
    """An int, float, bool or a string without interpolation."""

    value: int | float | bool | str


@dataclass(frozen=True, slots=True)
class Duration(Expr):
    """`250ms 30s 5min 2h`; kept as written (`text`) and in seconds."""

    seconds: float
    text: str


@dataclass(frozen=True, slots=True)
class Interp(Expr):
    """A string with `{expr}` interpolation: literal parts and expressions, in order.

    `durations`: the indices of the parts typed `duration`, which print as the language writes durations (`9s`,
    not `9`). A duration is a number of seconds at run time, so only the type checker can tell (`dsl.exprtypes`
    notes them here, once per compile, as it infers the string).
    """

    parts: tuple[str | Expr, ...]
    durations: frozenset[int] = field(default=frozenset(), compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Name(Expr):
    """A parameter, variable, shared datum, resource, child or `event`."""

    id: str


@dataclass(frozen=True, slots=True)
class Attr(Expr):
    """`obj.attr`: a resource property, a child output or an event field."""

    obj: Expr
    attr: str


@dataclass(frozen=True, slots=True)
class Call(Expr):
    """`count(Scout where scout.carrier == ranger)`, `min(a, b)`, `len(x)`."""

    func: str
    args: tuple[Expr, ...]
    where: Expr | None = None


@dataclass(frozen=True, slots=True)
class Unary(Expr):
    op: str  # "-" or "not"
    operand: Expr


@dataclass(frozen=True, slots=True)
class Binary(Expr):
    op: str  # and or == != < <= > >= + - * / %
    left: Expr
    right: Expr


# ---------------------------------------------------------------- body items


@dataclass(frozen=True, slots=True)
class TypeRef:
    name: str
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class Param:
    name: str
    type: TypeRef
    default: Expr | None = None
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class Arg:
    name: str
    value: Expr
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class Need:
    """`needs name: Type [where cond] [quantity q] [for slice]`."""

    name: str
    type: TypeRef
    where: Expr | None = None
    quantity: Expr | None = None
    slice: Duration | None = None
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class Shared:
    """`shared name: DataType`: created on entry, visible to descendants."""

    name: str
    type: TypeRef
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class Var:
    name: str
    type: TypeRef
    value: Expr | None = None
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class Multiplicity:
    """`[n]` (high is None, exact), `[a..b]`, or `[a..*]` (unbounded)."""

    low: Expr
    high: Expr | None = None
    unbounded: bool = False
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)

    @property
    def exact(self) -> bool:
        return self.high is None and not self.unbounded


@dataclass(frozen=True, slots=True)
class Child:
    """A child state: an elementary component or a behavior, with its arguments.

    `args is None` means no parentheses were written; `()` gives an empty tuple.
    """

    name: str
    args: tuple[Arg, ...] | None = None
    mult: Multiplicity | None = None
    alias: str | None = None
    priority: int | None = None
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)

    @property
    def key(self) -> str:
        """The name this child is known by in transitions and plans."""
        return self.alias or self.name


class Policy(StrEnum):
    ALL = "all"
    """A parallel block is done when every child is done (the default)."""
    ANY = "any"
    """A parallel block is done as soon as one child is done."""
    UNTIL = "until"
    """A parallel block is done when the named child is done."""


@dataclass(frozen=True, slots=True)
class Parallel:
    policy: Policy
    children: tuple[Child, ...]
    until: str | None = None
    explicit: bool = True  # `parallel all` written out, or just `parallel`
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


class TriggerKind(StrEnum):
    COMPLETION = "completion"
    """The source finished successfully."""
    CHANGE = "change"
    """`when COND`: as soon as the condition holds."""
    EVENT = "event"
    """`on Event`: an event was emitted."""
    ERROR = "error"
    """`on error`: the source failed."""
    TIMEOUT = "timeout"
    """`after D`: D has passed since the source was entered."""


@dataclass(frozen=True, slots=True)
class SetAction:
    name: str
    value: Expr
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class EmitAction:
    event: str
    args: tuple[Arg, ...] | None = None
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class ReleaseAction:
    resource: str
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class LogAction:
    message: Expr  # Literal(str) or Interp
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


Action = SetAction | EmitAction | ReleaseAction | LogAction


@dataclass(frozen=True, slots=True)
class Transition:
    """`SRC -> DST [trigger] [guard] [/ actions]`. `source` may be "start"; `target` "done"/"fail"."""

    source: str
    target: str
    kind: TriggerKind = TriggerKind.COMPLETION
    event: str | None = None
    condition: Expr | None = None
    delay: Expr | None = None  # a duration: a literal, a parameter, an expression
    guard: Expr | None = None
    actions: tuple[Action, ...] = ()
    #: `A -> B preallocate`: entering A reserves B's needs, so B starts without waiting when A completes.
    preallocate: bool = field(default=False, kw_only=True)
    #: `on E from X`: only events emitted inside the sibling X (X's subtree, in the same instance of the body).
    sender: str | None = field(default=None, kw_only=True)
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)
    source_span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)
    target_span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)
    event_span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)  # `on E`'s E
    sender_span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)  # `from X`'s X


@dataclass(frozen=True, slots=True)
class PlanStep:
    name: str
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class Plan:
    """`plan [concurrent] [preallocate] { A < B < C; A < D }`: chains of precedence."""

    concurrent: bool
    chains: tuple[tuple[PlanStep, ...], ...]
    preallocate: bool = field(default=False, kw_only=True)  # each step reserves the next one's needs
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class Constraint:
    """`constraint name: condition`: while the behavior is active, the condition must hold of the resources it
    reaches (`distance(ranger, point(0, 0)) <= 12`, `ranger.battery >= 0.2`, `inside(ranger, "n1")`)."""

    name: str
    condition: Expr
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


Item = Need | Shared | Var | Child | Parallel | Transition | Plan | Constraint


# ---------------------------------------------------------------- declarations


@dataclass(frozen=True, slots=True)
class Behavior:
    """A `mission` (the root, `is_mission`) or a `behavior` declaration.

    A behavior's `priority` is its default priority among the behaviors of its mission; a mission's ranks it
    against the other missions sharing the team (both: 1 is the highest)."""

    name: str
    params: tuple[Param, ...]
    body: tuple[Item, ...]
    priority: int | None = None
    is_mission: bool = False
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)
    name_span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class Import:
    path: str
    span: Span = field(default=NOWHERE, compare=False, repr=False, kw_only=True)


@dataclass(frozen=True, slots=True)
class MissionFile:
    """One parsed file: its imports and declarations, in source order."""

    imports: tuple[Import, ...]
    behaviors: tuple[Behavior, ...]
    path: str = field(default="<string>", compare=False)

    @property
    def mission(self) -> Behavior | None:
        return next((b for b in self.behaviors if b.is_mission), None)


def children_of(expr: Expr) -> tuple[Expr, ...]:
    """The direct sub-expressions of `expr`, for iterative walks."""
    match expr:
        case Attr(obj=o):
            return (o,)
        case Call(args=a, where=w):
            return a + ((w,) if w is not None else ())
        case Unary(operand=o):
            return (o,)
        case Binary(left=lhs, right=rhs):
            return (lhs, rhs)
        case Interp(parts=p):
            return tuple(x for x in p if isinstance(x, Expr))
    return ()


def walk(expr: Expr) -> list[Expr]:
    """Every node of `expr`, pre-order, without recursion."""
    out: list[Expr] = []
    stack = [expr]
    while stack:
        node = stack.pop()
        out.append(node)
        stack.extend(reversed(children_of(node)))
    return out
