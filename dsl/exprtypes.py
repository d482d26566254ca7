"""Static types of expressions, where they are known.

Types are strings (`int float bool str duration`, a resource or data type name, or
`any` when unknown), a `RecordSpec` (a component output or an event), or a `ChildRef`
(a child state, whose outputs are read as `DetectDoor.door.width`). Unknown stays
permissive: an `any` never causes an error, so only real mismatches are reported.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from dsl import ast
from dsl.catalog import SCALAR_TYPES, Catalog, Kind, RecordSpec
from dsl.errors import Reporter, did_you_mean


@dataclass(frozen=True, slots=True)
class ChildRef:
    """A child state by its component or behavior name."""

    component: str


Type = str | RecordSpec | ChildRef
ANY = "any"
NUMBERS = ("int", "float")
FUNCTIONS = ("count", "min", "max", "abs", "len", "point", "distance", "inside")
#: A place in the world's frame: `point(x, y)`, or a robot's pose.
POINT = "point"


def show(t: Type) -> str:
    """A type in the user's words."""
    if isinstance(t, RecordSpec):
        return f"record {t.name}"
    if isinstance(t, ChildRef):
        return f"child {t.component}"
    return t


def assignable(expected: str, actual: Type) -> bool:
    """May a value of type `actual` be used where `expected` is declared?"""
    if expected == ANY or actual == ANY:
        return True
    if expected == "float" and actual == "int":
        return True
    return expected == actual


def snake(name: str) -> str:
    """`RadioChannel` -> `radio_channel`: how `count(RadioChannel where ...)` names its candidate."""
    return "".join("_" + c.lower() if c.isupper() and i else c.lower() for i, c in enumerate(name))


@dataclass
class Scope:
    """The names an expression may use, with their types.

    `event` is the record of the event that triggered the transition (None: an event
    whose fields are unknown), or False where `event` is not defined at all.
    `open` makes unknown names acceptable (a library behavior, checked out of context).
    """

    names: Mapping[str, Type]
    children: Mapping[str, str] = field(default_factory=dict)
    event: RecordSpec | None | bool = False
    open: bool = False
    #: names declared in the behavior that this expression may not read, each with why and what to do instead (a
    #: `var` in a need's `where`: "unknown name" was wrong for a name declared two lines above)
    hidden: Mapping[str, tuple[str, str]] = field(default_factory=dict)

    def with_names(self, extra: Mapping[str, Type]) -> Scope:
        return Scope({**self.names, **extra}, self.children, self.event, self.open, self.hidden)


class Typer:
    """Infers expression types and reports mismatches through the shared Reporter."""

    def __init__(self, catalog: Catalog, report: Reporter):
        self.catalog = catalog
        self.report = report

    def expect(self, expr: ast.Expr, expected: str, scope: Scope, what: str) -> Type:
        """Infer `expr` and report `WHAT expects EXPECTED, got ACTUAL` on a mismatch."""
        actual = self.infer(expr, scope)
        if not assignable(expected, actual):
            hint = None
            if expected == "duration" and actual in NUMBERS:
                hint = "write a unit: 250ms, 30s, 5min or 2h"
            self.report.error("type", f"{what} expects {expected}, got {show(actual)}", expr.span, hint)
        return actual

    def infer(self, expr: ast.Expr, scope: Scope) -> Type:
        match expr:
            case ast.Literal(value=v):
                return {bool: "bool", int: "int", float: "float", str: "str"}[type(v)]
            case ast.Duration():
                return "duration"
            case ast.Interp(parts=parts):
                marks = frozenset(i for i, p in enumerate(parts)
                                  if isinstance(p, ast.Expr) and self.infer(p, scope) == "duration")
                if marks != expr.durations:  # an annotation of the checked tree, not a new node to put back in it
                    object.__setattr__(expr, "durations", marks)
                return "str"
            case ast.Name(id=name):
                return self._name(expr, name, scope)
            case ast.Attr(obj=obj, attr=attr):
                return self._attr(expr, self.infer(obj, scope), attr)
            case ast.Call():
                return self._call(expr, scope)
            case ast.Unary(op="not", operand=x):
                self.expect(x, "bool", scope, "not")
                return "bool"
            case ast.Unary(op="-", operand=x):
                t = self.infer(x, scope)
                if t not in (*NUMBERS, "duration", ANY):
                    self.report.error("type", f"cannot negate {show(t)}", expr.span)
                return t
            case ast.Binary():
                return self._binary(expr, scope)
        return ANY

    def _name(self, expr: ast.Expr, name: str, scope: Scope) -> Type:
        if name == "event":
            if scope.event is False:
                self.report.error("unknown-name", "event is only defined in a transition triggered by on EVENT",
                                  expr.span)
                return ANY
            return scope.event if isinstance(scope.event, RecordSpec) else ANY
        if name in scope.names:
            return scope.names[name]
        if name in scope.children:
            return ChildRef(scope.children[name])
        if scope.open:
            return ANY
        if name in scope.hidden:
            why, hint = scope.hidden[name]
            self.report.error("unknown-name", why, expr.span, hint)
            return ANY
        self.report.error("unknown-name", f"unknown name {name}", expr.span,
                          did_you_mean(name, [*scope.names, *scope.children]))
        return ANY

    def _attr(self, expr: ast.Expr, base: Type, attr: str) -> Type:
        if base == ANY:
            return ANY
        if isinstance(base, RecordSpec):
            if attr in base.fields:
                return base.fields[attr]
            self.report.error("unknown-name", f"{base.name} has no field {attr}", expr.span,
                              did_you_mean(attr, base.fields))
            return ANY
        if isinstance(base, ChildRef):
            ct = self.catalog.get(base.component)
            if ct is None:  # an unknown behavior, reported where it is named: its outputs are unknown too
                return ANY
            out = ct.output(attr)
            if out is not None:
                return out
            outputs = [o.name for o in ct.outputs]
            listed = f"its outputs: {', '.join(outputs)}" if outputs else None
            self.report.error("unknown-name", f"{base.component} has no output {attr}", expr.span,
                              did_you_mean(attr, outputs) or listed)
            return ANY
        ct = self.catalog.get(base)
        if ct is not None and ct.kind in (Kind.RC, Kind.ARC):
            props = self.catalog.properties(base)
            if attr in props:
                return props[attr]
            self.report.error("unknown-name", f"{base} has no property {attr}", expr.span,
                              did_you_mean(attr, props))
            return ANY
        self.report.error("type", f"{show(base)} has no fields (.{attr})", expr.span)
        return ANY

    def _call(self, expr: ast.Call, scope: Scope) -> Type:
        if expr.func not in FUNCTIONS:
            self.report.error("unknown-name", f"unknown function {expr.func}", expr.span,
                              did_you_mean(expr.func, FUNCTIONS) or f"functions: {', '.join(FUNCTIONS)}")
            return ANY
        if expr.where is not None and expr.func != "count":
            self.report.error("type", f"where is only allowed in count(Type where ...), not in {expr.func}",
                              expr.where.span)
        if expr.func == "count":
            return self._count(expr, scope)
        if expr.func in ("point", "distance", "inside"):
            return self._spatial(expr, scope)
        arity = {"abs": (1, 1), "len": (1, 1), "min": (1, 99), "max": (1, 99)}[expr.func]
        if not arity[0] <= len(expr.args) <= arity[1]:
            self.report.error("type", f"{expr.func} takes {arity[0]} argument" if arity[0] == arity[1]
                              else f"{expr.func} takes at least one argument", expr.span)
        types = [self.infer(a, scope) for a in expr.args]
        if expr.func == "len":
            for a, t in zip(expr.args, types, strict=True):
                if t in (*NUMBERS, "duration", "bool"):  # a text or shared data has entries; a number has none
                    self.report.error("type", f"len expects a text or shared data, got {show(t)}", a.span)
            return "int"
        for a, t in zip(expr.args, types, strict=True):
            if t not in (*NUMBERS, "duration", ANY):
                self.report.error("type", f"{expr.func} expects numbers, got {show(t)}", a.span)
        if "float" in types:
            return "float"
        return types[0] if types and all(t == types[0] for t in types) else ANY

    def _spatial(self, expr: ast.Call, scope: Scope) -> Type:
        """`point(x, y)`, `distance(a, b)` (robots or points, metres) and `inside(robot, "room", ...)`."""
        func, args = expr.func, expr.args
        types = [self.infer(a, scope) for a in args]
        if func == "point":
            if len(args) != 2:
                self.report.error("type", "point takes two numbers: point(x, y), in metres", expr.span)
            for a, t in zip(args, types, strict=False):
                if t not in (*NUMBERS, ANY):
                    self.report.error("type", f"point expects numbers, got {show(t)}", a.span)
            return POINT
        if func == "distance":
            if len(args) != 2:
                self.report.error("type", "distance takes two places: distance(ranger, point(2, 0)) or "
                                  "distance(scout, ranger)", expr.span)
            for a, t in zip(args, types, strict=False):
                if not self._place(t):
                    self.report.error("type", f"distance expects a robot or a point, got {show(t)}", a.span)
            return "float"
        if not args or len(args) < 2:
            self.report.error("type", 'inside takes a robot and room names: inside(ranger, "n1", "corridor")',
                              expr.span)
            return "bool"
        if not self._place(types[0]) or types[0] == POINT:
            self.report.error("type", f"inside expects a robot first, got {show(types[0])}", args[0].span)
        for a, t in zip(args[1:], types[1:], strict=True):
            if t not in ("str", ANY):
                self.report.error("type", f"inside expects room names (strings), got {show(t)}", a.span)
        return "bool"

    def _place(self, t: Type) -> bool:
        if t in (POINT, ANY):
            return True
        ct = self.catalog.get(t) if isinstance(t, str) else None
        return ct is not None and ct.kind is Kind.ARC

    def _count(self, expr: ast.Call, scope: Scope) -> Type:
        if len(expr.args) != 1 or not isinstance(expr.args[0], ast.Name):
            self.report.error("type", "count takes one resource type: count(Scout) or count(Scout where ...)",
                              expr.span)
            return "int"
        tname = expr.args[0].id
        ct = self.catalog.get(tname)
        if ct is None or not ct.is_resource:
            self.report.error("unknown-type", f"unknown resource type {tname}", expr.args[0].span,
                              did_you_mean(tname, self.catalog.names(Kind.RC, Kind.ARC)))
            return "int"
        if expr.where is not None:
            self.expect(expr.where, "bool", scope.with_names({snake(tname): tname}), "where")
        return "int"

    def _binary(self, expr: ast.Binary, scope: Scope) -> Type:
        op = expr.op
        if op in ("and", "or"):
            self.expect(expr.left, "bool", scope, op)
            self.expect(expr.right, "bool", scope, op)
            return "bool"
        lt, rt = self.infer(expr.left, scope), self.infer(expr.right, scope)
        if ANY in (lt, rt):
            return "bool" if op in ("==", "!=", "<", "<=", ">", ">=") else ANY
        if op in ("==", "!="):
            if not (assignable(show(lt), rt) or assignable(show(rt), lt)):
                self.report.error("type", f"cannot compare {show(lt)} with {show(rt)}", expr.span)
            return "bool"
        if op in ("<", "<=", ">", ">="):
            ok = (lt in NUMBERS and rt in NUMBERS) or (lt == rt and lt in ("duration", "str"))
            if not ok:
                self.report.error("type", f"cannot order {show(lt)} and {show(rt)} with {op}", expr.span)
            return "bool"
        return self._arith(expr, lt, rt)

    def _arith(self, expr: ast.Binary, lt: Type, rt: Type) -> Type:
        op = expr.op
        if op in ("/", "%") and constant(expr.right) == 0:
            self.report.error("division", f"{'division' if op == '/' else 'remainder'} by zero", expr.right.span,
                              "the divisor is 0 whatever the mission does")
        if lt in NUMBERS and rt in NUMBERS:
            if op == "/":
                return "float"
            return "float" if "float" in (lt, rt) else "int"
        if op == "+" and lt == rt == "str":
            return "str"
        if lt == rt == "duration" and op in "+-":
            return "duration"
        if op in "*/" and lt == "duration" and rt in NUMBERS:
            return "duration"
        if op == "*" and rt == "duration" and lt in NUMBERS:
            return "duration"
        self.report.error("type", f"cannot apply {op} to {show(lt)} and {show(rt)}", expr.span)
        return ANY


def constant(e: ast.Expr | None) -> float | None:
    """The value of a constant number or duration (`5`, `-0.5`, `30s`), else None: checked where written."""
    if isinstance(e, ast.Literal) and isinstance(e.value, int | float) and not isinstance(e.value, bool):
        return float(e.value)
    if isinstance(e, ast.Duration):
        return e.seconds
    if isinstance(e, ast.Unary) and e.op == "-":
        v = constant(e.operand)
        return -v if v is not None else None
    return None


def declared_type(name: str, catalog: Catalog) -> str | None:
    """The type a declaration names, or None if unknown."""
    if name in SCALAR_TYPES or catalog.get(name) is not None:
        return name
    return None


def literal_type(value: object) -> str:
    """The language type of a manifest default (a Python value)."""
    return {bool: "bool", int: "int", float: "float", str: "str"}.get(type(value), ANY)

