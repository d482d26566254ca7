"""Constraints in force: which behaviors declare which, measured each control cycle, and the gates' guard.

A behavior's `constraint` items hold while it is active. `ConstraintGuard` keeps those of every mission sharing
the gates and answers a gate before it lets a command through: a command from the declaring behavior's subtree
to a robot the constraint names is refused when, where the command would take the robot within the guard's
horizon (`drd.hw.motion.predict`), the constraint would break and be worse off than now
(`drd.rcm.constraints.refuses`). Measuring each cycle and reacting to a violation is the interpreter's
(`Interpreter._monitor`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from drd.hw.motion import predict
from drd.rcm import Aggregate
from drd.rcm.constraints import Measure, refuses, shown, text_of
from drd.runtime.ownership import DeviceGate, under
from drd.runtime.pool import ResourcePool, ResourceView
from dsl import ast
from dsl.evaluate import EvalError

#: Seconds ahead a command is judged by: two control cycles, so a robot stops before its boundary, not past it.
HORIZON = 0.2
#: Seconds a constraint may go unmeasured (a stale or NaN battery, a pose the robot does not know, a robot not read
#: yet at the first instant on a cluster) before it counts as broken (ROS 2 audit 17, D1: a robot drove on).
UNMEASURED = 2.0


@dataclass(eq=False)
class Active:
    """One constraint of one active behavior (`holder`: its `<mission>/<path>`)."""

    holder: str
    path: str
    name: str
    condition: ast.Expr
    robots: tuple[str, ...]  # the robots it names
    measure: Callable[[], Measure]  # in the declaring behavior's scope
    refused: Callable[[Measure], None] = lambda m: None  # a command was refused: where it would have led
    names: Callable[[], Mapping[str, object]] = dict  # the declaring behavior's scope (what a host guard is sent)
    violated: bool = False  # broken, or a command refused, since it last held with nothing refused
    refused_at: float = -1.0
    unmeasured_since: float | None = None  # when it last became impossible to measure (None: measured)
    text: str = field(default="", init=False)

    def __post_init__(self) -> None:
        self.text = text_of(self.condition)


@dataclass(frozen=True, slots=True)
class Breach:
    """A command refused by the constraint `name` of `holder` at a gate elsewhere (a device's host on a cluster):
    where the command would have led. The holder's interpreter takes it as its own gate's refusal."""

    holder: str
    name: str
    measure: Measure


def robots_named(condition: ast.Expr, names: Mapping[str, object]) -> tuple[str, ...]:
    """The robots (aggregates) a condition names, directly or as the owner of a part (`scout.radio`)."""
    found: dict[str, None] = {}
    for node in walk(condition):
        if isinstance(node, ast.Name):
            value = names.get(node.id)
            if isinstance(value, ResourceView) and isinstance(value.candidate, Aggregate):
                found[value.id] = None
    return tuple(found)


def walk(e: ast.Expr) -> Iterable[ast.Expr]:
    """Every sub-expression of `e`, `e` first."""
    stack: list[Any] = [e]
    while stack:
        node = stack.pop()
        yield node
        for f in dataclasses.fields(node):
            value = getattr(node, f.name)
            if isinstance(value, ast.Expr):
                stack.append(value)
            elif isinstance(value, tuple):
                stack.extend(v for v in value if isinstance(v, ast.Expr))


class ConstraintGuard:
    """The gates' guard (`drd.runtime.ownership.LocalGates.guard`) over the constraints of every mission."""

    def __init__(self, pool: ResourcePool, horizon: float = HORIZON) -> None:
        self.pool = pool
        self.horizon = horizon
        self.active: list[Active] = []

    def add(self, constraint: Active) -> None:
        self.active.append(constraint)

    def remove(self, holder: str) -> None:
        self.active = [a for a in self.active if a.holder != holder]

    def breached(self, breach: Breach) -> None:
        """A gate elsewhere refused a command for one of these constraints: its behavior hears it as if here."""
        for a in self.active:
            if a.holder == breach.holder and a.name == breach.name:
                a.refused(breach.measure)

    def __call__(self, gate: DeviceGate, issuer: str, method: str, args: tuple[Any, ...],
                 kwargs: Mapping[str, Any]) -> str:
        if not gate.robot or not self.active:
            return ""
        robot = gate.moved(method, args, kwargs) or gate.robot  # a launch moves the Scout it throws, from the
        relevant = [a for a in self.active if robot in a.robots and under(issuer, a.holder)]  # launcher's pose
        if not relevant:
            return ""
        pose = self.pool.pose(gate.robot)
        then = predict(gate.kind, method, args, kwargs, pose, self.horizon) if pose is not None else None
        if then is None:
            return ""
        for a in relevant:
            try:
                before = a.measure()
                with self.pool.predicting(robot, then):
                    after = a.measure()
            except EvalError:
                continue  # a condition that cannot be read now: the monitor reports it, the gate does not guess
            if refuses(before, after):
                a.refused(after)
                said = shown(after)
                return f"constraint {a.name} ({a.text}) would not hold" + (f": {said}" if said else "")
        return ""
