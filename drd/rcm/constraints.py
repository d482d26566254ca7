"""Constraints on held resources (the paper's goals d and e, monitoring and enforcement): how far a condition is
from breaking, and whether a command may go.

A constraint is a condition of the mission language over the resources a behavior reaches
(`distance(ranger, point(0, 0)) <= 12`, `inside(ranger, "n1", "n2")`, `ranger.battery >= 0.2`). Beyond true or
false, `measure` gives it a *margin*: how much room is left before it breaks (metres, charge...), negative once
it is broken. The margin is what makes enforcement directional: a command is refused when the robot, where the
command would take it, would break the constraint *and* be worse off than now (`refuses`). So a robot at its
geofence stops at the boundary, and one outside it may still drive back in; a robot under its battery floor may
stop but not drive on.

Margins: `a <= b`, `a < b`: b - a; `a >= b`, `a > b`: a - b; `and`: the smaller; `or`: the larger; `not`: the
opposite; `inside(r, rooms...)`: how deep r is inside them (minus how far outside); any other condition: 0 when
it holds, -1 when not. Pure: the names (with the robots' poses) are given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dsl import ast
from dsl.evaluate import CountFn, EvalError, PlaceFn, coordinates, evaluate, format_value, signed_depth, truthy
from dsl.printer import expr as text_of

__all__ = ["Measure", "measure", "refuses", "text_of"]

#: Margins this close count as equal (a robot standing still is not "worse off").
EPS = 1e-9


@dataclass(frozen=True, slots=True)
class Measure:
    """A constraint now: whether it holds, its margin, and the value and limit a user reads (`12.4 <= 12`)."""

    holds: bool
    margin: float
    value: float
    limit: float
    kind: str = "compare"  # what value and limit are: a comparison's sides, "depth" in rooms (limit 0), or "bool";
    #: "unknown": it could not be measured (`note` says why), value and limit NaN
    note: str = ""

    @staticmethod
    def unknown(why: str) -> Measure:
        """A constraint that could not be measured for too long: broken, for `why`."""
        return Measure(False, -math.inf, math.nan, math.nan, "unknown", why)


def measure(condition: ast.Expr, names: dict[str, object], count: CountFn | None = None,
            place: PlaceFn | None = None) -> Measure:
    """How `condition` stands with `names` in scope.

    Raises:
        EvalError: the condition cannot be evaluated (an unknown room, a robot with no position...).
    """
    holds = truthy(condition, names, count, place)
    margin, value, limit, kind = _margin(condition, names, count, place)
    return Measure(holds, margin, value, limit, kind)


def shown(m: Measure) -> str:
    """How far from holding a constraint stands, in its own terms, for a reason a user reads: `6.05 against 6` for
    a comparison, `3.64 m outside` for `inside(...)` (its margin is a signed depth, and "-3.64 against 0" read as
    nonsense for a yes/no condition: users audit 12, D7), nothing for a plain condition; of an `and` or `or`, the
    part that decided (reverify audit 14, D4)."""
    if m.kind == "unknown":
        return f"not measured: {m.note}"
    if m.kind == "depth":
        return f"{abs(m.value):.2f} m {'inside' if m.value >= 0 else 'outside'}"
    return f"{m.value:.3g} against {m.limit:.3g}" if m.kind == "compare" else ""


def refuses(now: Measure, then: Measure) -> bool:
    """Whether a command taking the constraint from `now` to `then` must be refused: it breaks it and is worse."""
    return not then.holds and then.margin < now.margin - EPS


def _margin(e: ast.Expr, names: dict[str, object], count: CountFn | None,
            place: PlaceFn | None) -> tuple[float, float, float, str]:
    match e:
        case ast.Binary(op="<" | "<=" | ">" | ">=" as op, left=lhs, right=rhs):
            a, b = _number(lhs, names, count, place), _number(rhs, names, count, place)
            return (b - a if op in ("<", "<=") else a - b), a, b, "compare"
        case ast.Binary(op="and" | "or" as op, left=lhs, right=rhs):
            # a side that cannot be measured does not decide: the condition held or broke by the other (`measure`
            # has its truth from the short-circuit evaluation; a holding `x or unknown` is not broken: review)
            parts: list[tuple[float, float, float, str]] = []
            unknown: list[EvalError] = []
            for side in (lhs, rhs):
                try:
                    parts.append(_margin(side, names, count, place))
                except EvalError as err:
                    unknown.append(err)
            if not parts:
                raise unknown[0]
            return min(parts, key=_first) if op == "and" else max(parts, key=_first)
        case ast.Unary(op="not", operand=x):
            m, v, lim, kind = _margin(x, names, count, place)
            return -m, v, lim, kind
        case ast.Call(func="inside", args=args) if args:
            where = coordinates(evaluate(args[0], names, count, place))
            if where is None:
                raise EvalError("inside(...) needs a robot with a position", args[0].span)
            rects = []
            for room in args[1:]:
                name = format_value(evaluate(room, names, count, place))
                rect = place(name) if place is not None else None
                if rect is None:
                    raise EvalError(f"no room named {name} in this world", room.span)
                rects.append(rect)
            depth = signed_depth(*where, rects)
            return depth, depth, 0.0, "depth"
    held = truthy(e, names, count, place)
    return (0.0 if held else -1.0), (1.0 if held else 0.0), 1.0, "bool"


def _first(part: tuple[float, float, float, str]) -> float:
    return part[0]


def _number(e: ast.Expr, names: dict[str, object], count: CountFn | None, place: PlaceFn | None) -> float:
    value = evaluate(e, names, count, place)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise EvalError(f"expected a number, got {format_value(value)}", e.span)
    return float(value)
