"""What the checker and the evaluator say of missions a user wrote (users audit 25, D4, D6, D7, D8): a hint that can
be written as given, a type error before the run rather than an action failing in it, a syntax error said once, and
a variable with no value named in the language's words."""

from __future__ import annotations

import pytest

from dsl import ast, compile_text
from dsl.catalog import Catalog
from dsl.evaluate import EvalError, evaluate


def problems(catalog: Catalog, text: str) -> list[tuple[str, int, int, str, str]]:
    return [(d.code, d.span.line, d.span.column, d.message, d.hint or "")
            for d in compile_text(text, catalog, "mine.mission").diagnostics]


def test_the_hint_for_a_child_never_reached_is_a_transition_one_can_write(catalog: Catalog) -> None:
    found = problems(catalog, "mission Early {\n    start -> done\n    Wait(duration: 1s) as a\n}\n")
    [(code, _line, _col, message, hint)] = [p for p in found if p[0] == "unreachable"]
    assert message.startswith("a is never reached") and "`start -> a`" in hint, hint  # not `done -> a`


@pytest.mark.parametrize("arg", ["n", "2.5", "3s", "true"])
def test_len_of_a_number_a_duration_or_a_bool_is_a_type_error(catalog: Catalog, arg: str) -> None:
    found = problems(catalog, "mission Lens {\n    var n: int = 5\n    Wait(duration: 1s)\n"
                              f'    Wait -> done / log "len {{len({arg})}}"\n}}\n')
    assert [p[0] for p in found] == ["type"] and found[0][3].startswith("len expects a text or shared data"), found
    assert not problems(catalog, 'mission Lens {\n    var s: str = "abc"\n    Wait(duration: 1s)\n'
                                 '    Wait -> done / log "len {len(s)}"\n}\n')


def test_one_unclosed_brace_in_a_string_is_said_once(catalog: Catalog) -> None:
    found = problems(catalog, 'mission Twice {\n    var s: str = "x"\n    Wait(duration: 1s)\n'
                              '    Wait -> done / log "{s + "y"}"\n}\n')
    assert len(found) == len(set(found)), found
    assert sum(p[3] == "unclosed { in string" for p in found) == 1, found


def test_a_variable_not_set_yet_is_named_not_shown_as_none() -> None:
    x = ast.Name("x")
    with pytest.raises(EvalError, match="x has no value yet$"):
        evaluate(ast.Binary(">", x, ast.Literal(0)), {"x": None})


def test_a_plans_warning_is_located_at_the_plan_and_said_once(catalog: Catalog) -> None:
    """D5: "nothing to preallocate" pointed at the line where the behavior is used (each use: twice for two)."""
    text = ("mission P {\n    needs ranger: Ranger\n    Inner as a\n    Inner as b\n    start -> a\n    a -> b\n}\n"
            "behavior Inner {\n    plan preallocate { Calibrate < Observe }\n}\n")
    found = problems(catalog, text)
    assert [(p[0], p[1], p[2]) for p in found] == [("preallocate", 9, 36)], found
