"""The rooms a mission names as text in `inside(robot, "n1")`, checked against a world's before it runs.

Only the world knows its rooms, so the compiler cannot tell a typo (`"hallway_nope"`) from a room of another
building; at run time such a constraint "cannot be measured" and guards nothing (users audit 9, D6: a geofence
with a misspelled room let the Ranger drive the whole corridor, and the mission succeeded). Whoever has the
world (the dry-run, the controller) asks here first. Pure: a statechart and a set of names in, diagnostics out.
"""

from __future__ import annotations

from collections.abc import Collection, Iterator

from dsl import ast
from dsl.errors import Diagnostic, did_you_mean
from dsl.statechart import Statechart


def unknown_rooms(chart: Statechart, rooms: Collection[str], world: str) -> list[Diagnostic]:
    """A located error for each room name written as text in an `inside(...)` of a constraint or a guard of
    `chart` that is not among `rooms` (the rooms of `world`), each place once."""
    out: list[Diagnostic] = []
    seen = set()
    for expr in _conditions(chart):
        for node in ast.walk(expr):
            if not (isinstance(node, ast.Call) and node.func == "inside"):
                continue
            for arg in node.args[1:]:
                if isinstance(arg, ast.Literal) and isinstance(arg.value, str) and arg.value not in rooms \
                        and arg.span not in seen:
                    seen.add(arg.span)
                    hint = did_you_mean(arg.value, rooms) or f"its rooms: {', '.join(sorted(rooms)) or 'none'}"
                    out.append(Diagnostic("unknown-room", f"no room named {arg.value} in world {world}", arg.span,
                                          hint))
    return out


def _conditions(chart: Statechart) -> Iterator[ast.Expr]:
    """Every constraint's condition and every guard of the chart."""
    for state in chart.states.values():
        yield from (c.condition for c in state.constraints)
        yield from (t.guard for t in (*state.starts, *state.transitions) if t.guard is not None)
