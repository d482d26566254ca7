"""The expression evaluator: our own, never Python's `eval`.

Values are Python ints, floats, bools and strings; durations evaluate to seconds (float).
Names come from a mapping the caller builds (parameters, variables, shared data,
resources, child outputs, `event`); attributes read mappings by key and objects by
public attribute; `count(Type where ...)` is answered by a callback, because only the
runtime knows which resources exist.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sized
from typing import NamedTuple

from dsl import ast
from dsl.errors import Span
from dsl.exprtypes import snake

#: The digits of the language's integers, as of its literals (`dsl.parser.MAX_INT_DIGITS`): a result beyond them is
#: an error, not a number that grows (users audit 9, D4: squared 40 times, one big integer held the run for ever).
INT_DIGITS = 18
INT_LIMIT = 10 ** INT_DIGITS

#: `count(type_name, predicate)`: how many known resources of a type satisfy the predicate.
CountFn = Callable[[str, Callable[[object], bool] | None], int]
#: `place(name)`: the rectangle (x0, y0, x1, y1) of a named region of the world (a room), or None.
PlaceFn = Callable[[str], tuple[float, float, float, float] | None]


class Point(NamedTuple):
    """`point(x, y)`: a place in the world's frame, in metres."""

    x: float
    y: float

    def __str__(self) -> str:
        return f"({self.x:g}, {self.y:g})"


def coordinates(value: object) -> tuple[float, float] | None:
    """Where a value is: a `Point`, or a robot (a mapping with `x` and `y`, as a resource's pose)."""
    if isinstance(value, Point):
        return value.x, value.y
    if isinstance(value, Mapping):
        try:
            x, y = value["x"], value["y"]
        except KeyError:
            return None
        if isinstance(x, int | float) and isinstance(y, int | float) and not isinstance(x, bool):
            return float(x), float(y)
    return None


def signed_depth(x: float, y: float, rects: list[tuple[float, float, float, float]]) -> float:
    """How deep (x, y) is inside the union of `rects` (metres to the nearest edge of the one it is in), or minus how
    far it is from the nearest of them when it is outside: > 0 inside, < 0 outside."""
    best = -math.inf
    for x0, y0, x1, y1 in rects:
        dx, dy = max(x0 - x, 0.0, x - x1), max(y0 - y, 0.0, y - y1)
        best = max(best, min(x - x0, x1 - x, y - y0, y1 - y) if dx == 0.0 and dy == 0.0 else -math.hypot(dx, dy))
    return best


class EvalError(Exception):
    """An expression could not be evaluated (unknown name, division by zero, bad operand)."""

    def __init__(self, message: str, span: Span, missing: bool = False):
        super().__init__(f"{span}: {message}")
        self.message = message
        self.span = span
        self.missing = missing  # a value without the property asked of it (`scout3 has no carrier`)


def evaluate(expr: ast.Expr, names: Mapping[str, object], count: CountFn | None = None,
             place: PlaceFn | None = None) -> object:
    """The value of `expr` with `names` in scope (`place` answers `inside(...)`'s room names)."""
    return _Evaluator(names, count, place).eval(expr)


def truthy(expr: ast.Expr | None, names: Mapping[str, object], count: CountFn | None = None,
           place: PlaceFn | None = None) -> bool:
    """A guard or condition: absent means true; anything but a bool is an error."""
    if expr is None:
        return True
    value = evaluate(expr, names, count, place)
    if not isinstance(value, bool):
        raise EvalError(f"a condition must be true or false, got {format_value(value)}", expr.span)
    return value


def format_value(v: object) -> str:
    """How values appear in interpolated strings and messages."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _show(v: object, duration: bool) -> str:
    """An interpolated value; a duration as the language writes it (`9s`, `250ms`, `5min`)."""
    if duration and isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v):
        return duration_literal(float(v))
    return format_value(v)


def duration_literal(seconds: float) -> str:
    """Seconds as a duration literal: in the largest unit that writes them whole (`2h`, `5min`, `90s`), else in
    seconds (`9.25s`), under a second in milliseconds (`250ms`)."""
    for unit, size in (("h", 3600.0), ("min", 60.0), ("s", 1.0)):
        count = seconds / size
        if abs(count) >= 1 and abs(count - round(count)) < 1e-9:
            return f"{round(count)}{unit}"
    if seconds == 0:
        return "0s"
    return f"{seconds:g}s" if abs(seconds) >= 1 else f"{seconds * 1000:g}ms"


class _Evaluator:
    def __init__(self, names: Mapping[str, object], count: CountFn | None, place: PlaceFn | None = None):
        self.names = names
        self.count = count
        self.place = place

    def eval(self, e: ast.Expr) -> object:
        match e:
            case ast.Literal(value=v):
                return v
            case ast.Duration(seconds=s):
                return s
            case ast.Interp(parts=parts, durations=durations):
                return "".join(p if isinstance(p, str) else _show(self.eval(p), i in durations)
                               for i, p in enumerate(parts))
            case ast.Name(id=n):
                if n not in self.names:
                    raise EvalError(f"{n} has no value here", e.span)
                value = self.names[n]
                if value is None:  # a `var x: int` not set yet (users audit 25, D8: "cannot apply > to None and 0")
                    raise EvalError(f"{n} has no value yet", e.span)
                return value
            case ast.Attr(obj=o, attr=a):
                return _attribute(self.eval(o), a, e.span)
            case ast.Call():
                return self._call(e)
            case ast.Unary(op="not", operand=x):
                return not self._bool(x)
            case ast.Unary(operand=x):
                return -self._number(x)
            case ast.Binary(op="and", left=lhs, right=rhs):
                return self._bool(lhs) and self._bool(rhs)
            case ast.Binary(op="or", left=lhs, right=rhs):
                return self._bool(lhs) or self._bool(rhs)
            case ast.Binary():
                return self._binary(e)
        raise EvalError(f"cannot evaluate {type(e).__name__}", getattr(e, "span", Span("?", 1, 1, 1, 1)))

    def _bool(self, e: ast.Expr) -> bool:
        v = self.eval(e)
        if not isinstance(v, bool):
            raise EvalError(f"expected true or false, got {format_value(v)}", e.span)
        return v

    def _number(self, e: ast.Expr) -> int | float:
        v = self.eval(e)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise EvalError(f"expected a number, got {format_value(v)}", e.span)
        return v

    def _binary(self, e: ast.Binary) -> object:
        value = self._apply(e)
        if type(value) is int and not -INT_LIMIT < value < INT_LIMIT:
            raise EvalError(f"{e.op} gives an integer of more than {INT_DIGITS} digits (the language's integers have"
                            f" at most {INT_DIGITS})", e.span)
        return value

    def _apply(self, e: ast.Binary) -> object:
        lhs, rhs = self.eval(e.left), self.eval(e.right)
        op = e.op
        try:
            match op:
                case "==":
                    return lhs == rhs
                case "!=":
                    return lhs != rhs
                case "<":
                    return lhs < rhs  # type: ignore[operator]
                case "<=":
                    return lhs <= rhs  # type: ignore[operator]
                case ">":
                    return lhs > rhs  # type: ignore[operator]
                case ">=":
                    return lhs >= rhs  # type: ignore[operator]
                case "+":
                    return lhs + rhs  # type: ignore[operator]
                case "-":
                    return lhs - rhs  # type: ignore[operator]
                case "*":
                    if isinstance(lhs, str) or isinstance(rhs, str):
                        raise TypeError("no string repetition")
                    return lhs * rhs  # type: ignore[operator]
                case "/":
                    return lhs / rhs  # type: ignore[operator]
                case "%":
                    return lhs % rhs  # type: ignore[operator]
        except ZeroDivisionError:
            raise EvalError("division by zero", e.span) from None
        except TypeError:
            raise EvalError(f"cannot apply {op} to {format_value(lhs)} and {format_value(rhs)}", e.span) from None
        raise EvalError(f"unknown operator {op}", e.span)

    def _call(self, e: ast.Call) -> object:
        if e.func == "count":
            if self.count is None or not e.args or not isinstance(e.args[0], ast.Name):
                raise EvalError("count(...) is not available here", e.span)
            type_name = e.args[0].id
            pred = None
            if e.where is not None:
                where, var = e.where, snake(type_name)

                def pred(candidate: object) -> bool:
                    try:
                        return truthy(where, {**self.names, var: candidate}, self.count, self.place)
                    except EvalError as err:  # a resource without the property does not satisfy the condition
                        if err.missing:  # (as for `needs x: T where ...`): a Scout on the floor has no carrier
                            return False
                        raise
            return self.count(type_name, pred)
        values = [self.eval(a) for a in e.args]
        if e.func == "point":
            return Point(float(self._number(e.args[0])), float(self._number(e.args[1])))
        if e.func == "distance":
            (ax, ay), (bx, by) = (self._where(v, a) for v, a in zip(values, e.args, strict=True))
            return math.hypot(ax - bx, ay - by)
        if e.func == "inside":
            x, y = self._where(values[0], e.args[0])
            return signed_depth(x, y, self._rooms(values[1:], e)) >= 0.0
        if e.func == "len":
            if not isinstance(values[0], Sized):
                raise EvalError(f"len of {format_value(values[0])}", e.span)
            return len(values[0])
        if e.func == "abs":
            return abs(self._number(e.args[0]))
        if e.func in ("min", "max"):
            nums = [self._number(a) for a in e.args]
            return min(nums) if e.func == "min" else max(nums)
        raise EvalError(f"unknown function {e.func}", e.span)

    def _where(self, value: object, e: ast.Expr) -> tuple[float, float]:
        found = coordinates(value)
        if found is None:
            raise EvalError(f"{format_value(value)} has no position (a robot or point(x, y) has)", e.span)
        return found

    def _rooms(self, names: list[object], e: ast.Call) -> list[tuple[float, float, float, float]]:
        rects = []
        for name in names:
            rect = self.place(str(name)) if self.place is not None else None
            if rect is None:
                raise EvalError(f"no room named {format_value(name)} in this world", e.span)
            rects.append(rect)
        return rects


def _attribute(obj: object, attr: str, span: Span) -> object:
    if isinstance(obj, Mapping):
        if attr in obj:
            return obj[attr]
    elif not attr.startswith("_") and hasattr(obj, attr):
        value = getattr(obj, attr)
        if not callable(value):
            return value
    raise EvalError(f"{format_value(obj)} has no {attr}", span, missing=True)


__all__ = ["CountFn", "EvalError", "PlaceFn", "Point", "coordinates", "evaluate", "format_value", "signed_depth",
           "truthy"]
