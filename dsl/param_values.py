"""The one rule a component's parameter value must pass, wherever the value comes from (issue #14).

The checker applies it to the constants a mission writes (located errors), the Load Balancer to the parameters a
placement is asked for (`drd.placement.check_params`); the interpreter applies its range part to the values
expressions give when a state is entered (`drd.runtime.interpreter.out_of_range`). Pure.
"""

from __future__ import annotations

import math

from dsl.catalog import ParamSpec

#: Which Python values each scalar parameter type takes (a bool is not a number; an int is a float).
_KINDS: dict[str, tuple[type, ...]] = {"int": (int,), "float": (int, float), "duration": (int, float),
                                       "bool": (bool,), "str": (str,)}
NUMERIC = ("int", "float", "duration")


def refuses(spec: ParamSpec, value: object) -> str:
    """Why `value` cannot be parameter `spec` ('' when it can): a value of another scalar type, then what
    `out_of_bounds` says. Resource and data types (ids the executive chooses) are not judged here."""
    kinds = _KINDS.get(spec.type)
    if kinds is None:
        return ""
    if not isinstance(value, kinds) or (isinstance(value, bool) and spec.type != "bool"):
        return f"expects {spec.type}, got {type(value).__name__} {repr(value)[:40]}"
    return out_of_bounds(spec, value) if isinstance(value, int | float) and spec.type in NUMERIC else ""


def out_of_bounds(spec: ParamSpec, value: float) -> str:
    """Why a number of the right type cannot be parameter `spec` ('' when it can): a negative duration, a number
    that is not finite, or one outside the manifest's range (`Limit.refuses`)."""
    if spec.type == "duration" and value < 0:
        return f"a duration cannot be negative ({value:g} s)"
    if spec.limit is not None:
        return spec.limit.refuses(value)
    if isinstance(value, float) and not math.isfinite(value):
        return f"{value} is not a finite number"
    return ""
