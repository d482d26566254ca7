"""Interpolated strings print durations as the language writes them (audit item 11): a duration is a number of
seconds at run time, so the type checker marks which parts are durations."""

from __future__ import annotations

from dsl import ast, compile_text
from dsl.catalog import Catalog
from dsl.evaluate import evaluate

MISSION = """mission M {
    Audit(span: 9s)
}
behavior Audit(span: duration = 6s) {
    var n: int = 3
    var x: float = 9.0
    Observe(duration: span)
    Observe -> done / log "{span} {span * 2} {span + 250ms} {n} {x} {span / 2} {0s} {250ms} {90s} {2h} {event}"
}
"""


def _log(catalog: Catalog, source: str) -> ast.Expr:
    chart = compile_text(source, catalog, "t.mission").raise_for_errors()
    assert chart is not None
    for state in chart.states.values():
        for t in state.transitions:
            for a in t.actions:
                if isinstance(a, ast.LogAction):
                    return a.message
    raise AssertionError("no log action")


def test_durations_print_with_their_unit_numbers_do_not(catalog: Catalog) -> None:
    message = _log(catalog, MISSION.replace(" {event}", ""))
    text = evaluate(message, {"span": 9.0, "n": 3, "x": 9.0})
    assert text == "9s 18s 9.25s 3 9 4.5s 0s 250ms 90s 2h"


def test_a_value_of_unknown_type_prints_as_a_number(catalog: Catalog) -> None:
    source = MISSION.replace("Observe -> done / log", "Observe -> done on MotionDetected / log").replace(
        " {event}", " {event.area}")
    message = _log(catalog, source)
    assert isinstance(message, ast.Interp)
    text = evaluate(message, {"span": 60.0, "n": 3, "x": 9.0, "event": {"area": 0.5}})
    assert text.endswith(" 0.5") and text.startswith("1min 2min ")
