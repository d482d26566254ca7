"""`--param NAME=VALUE`: the operator sets a mission's top-level `var` before it runs. Pure.

`missionctl run sweep.mission --param laps=1` starts `mission Sweep { var laps: int = 0 ... }` with
`laps` at 1: the variable's initial value is replaced by the literal, read as the variable's declared
type (`int`, `float`, `bool`, `str`, `duration`). Only the mission's own variables can be set, so a
mission file says what an operator may tune.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Iterable, Mapping

from drd.errors import MissionInputError
from dsl import ast
from dsl.ast import parse_duration
from dsl.errors import did_you_mean
from dsl.parser import MAX_DURATION, MAX_INT_DIGITS, MAX_NUMBER
from dsl.statechart import Statechart

_ASSIGN = re.compile(r"^\s*(?P<name>[A-Za-z_][A-Za-z0-9_]*)\s*=(?P<value>.*)$", re.S)


class ParamError(MissionInputError, ValueError):
    """A `--param` that cannot be applied; the message says which and why (all problems, one per line)."""


def parse_assignments(texts: Iterable[str]) -> dict[str, str]:
    """`["laps=1", "speed = 0.3"]` -> {"laps": "1", "speed": "0.3"}; ParamError lists every bad one."""
    out: dict[str, str] = {}
    problems = []
    for text in texts:
        m = _ASSIGN.match(text)
        if m is None:
            problems.append(f"cannot read --param {text!r}: write NAME=VALUE, e.g. --param laps=1")
        elif m["name"] in out:
            problems.append(f"--param {m['name']} is given twice")
        else:
            out[m["name"]] = m["value"].strip()
    if problems:
        raise ParamError("\n".join(problems))
    return out


def apply_params(chart: Statechart, params: Mapping[str, str]) -> Statechart:
    """`chart` with the root's variables named in `params` starting at those values (ParamError if any is
    unknown or not of its variable's type; every problem is reported together)."""
    if not params:
        return chart
    root = chart.states[chart.root]
    declared = {v.name: v for v in root.vars}
    problems, values = [], {}
    for name, text in params.items():
        var = declared.get(name)
        if var is None:
            known = ", ".join(declared) or "none"
            hint = did_you_mean(name, declared)
            problems.append(f"mission {chart.name} has no variable {name!r} to set"
                            f" ({hint + '; ' if hint else ''}its variables: {known})")
            continue
        literal = _literal(var.type.name, text)
        if literal is None:
            article = "an" if var.type.name[:1] in "aeiou" else "a"
            problems.append(f"--param {name}={text}: {name} is {article} {var.type.name}, and {text!r} is not one")
        elif (why := beyond_limits(literal)) is not None:
            problems.append(f"--param {name}={text}: {why}, as in a mission")
        else:
            values[name] = literal
    if problems:
        raise ParamError("\n".join(problems))
    new_vars = tuple(dataclasses.replace(v, value=values[v.name]) if v.name in values else v for v in root.vars)
    states = dict(chart.states)
    states[chart.root] = dataclasses.replace(root, vars=new_vars)
    return dataclasses.replace(chart, states=states)


def beyond_limits(literal: ast.Expr) -> str | None:
    """Why a value is refused by the bounds the mission language puts on its literals (`dsl.parser`'s MAX_INT_DIGITS,
    MAX_NUMBER, MAX_DURATION), or None: an operator's value may not be what the mission could not say (NaN, inf)."""
    if isinstance(literal, ast.Duration):
        if not literal.seconds <= MAX_DURATION:
            return f"duration {literal.text} is too long (at most {MAX_DURATION // 86400:g} days)"
        return None
    value = literal.value if isinstance(literal, ast.Literal) else None
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    if isinstance(value, int):
        digits = len(str(abs(value)))
        return (f"integer {value} is too large ({digits} digits, at most {MAX_INT_DIGITS})"
                if digits > MAX_INT_DIGITS else None)
    if not math.isfinite(value) or abs(value) > MAX_NUMBER:
        return "not a number" if math.isnan(value) else f"number {value:g} is too large (at most {MAX_NUMBER:g})"
    return None


def _literal(type_name: str, text: str) -> ast.Expr | None:
    """`text` as a literal of the variable's type, or None."""
    try:
        if type_name == "int":
            return ast.Literal(int(text))
        if type_name == "float":
            return ast.Literal(float(text))
    except ValueError:
        return None
    if type_name == "bool":
        return ast.Literal(text == "true") if text in ("true", "false") else None
    if type_name == "str":
        return ast.Literal(text)
    if type_name == "duration":
        seconds = parse_duration(text)
        return ast.Duration(seconds, text) if seconds is not None else None
    return None  # resource and data types are not the operator's to set
