"""The compiled statechart: structure, bindings, priorities, plans; and the expression evaluator."""

from __future__ import annotations

import pytest

from dsl import compile_text
from dsl.ast import Name
from dsl.catalog import Catalog
from dsl.evaluate import EvalError, evaluate, truthy
from dsl.parser import parse_expression
from dsl.statechart import Statechart, StateKind


def chart(text: str, catalog: Catalog) -> Statechart:
    result = compile_text(text, catalog, "t.mission")
    assert result.ok, "\n".join(d.render(result.sources) for d in result.diagnostics)
    assert result.statechart is not None
    return result.statechart


def test_sequential_plan_follows_declaration_order_on_ties(catalog: Catalog) -> None:
    c = chart("mission M {\n needs r: Ranger\n plan { Calibrate < ReturnToStart; TurnToWatch < ReturnToStart }\n}",
              catalog)
    root = c["M"]
    assert root.kind is StateKind.COMPOUND and root.initial == "M/Calibrate"
    nxt = {t.source: t.target for t in c.transitions() if t.generated}
    order, state = [], root.initial
    while state in nxt:
        order.append(state)
        state = nxt[state]
    assert order + [state] == ["M/Calibrate", "M/TurnToWatch", "M/ReturnToStart", "M/done"]


def test_concurrent_plan_is_parallel_with_predecessors(catalog: Catalog) -> None:
    c = chart("mission M {\n needs r: Ranger\n"
              " plan concurrent { Calibrate < ReturnToStart; TurnToWatch < ReturnToStart }\n}", catalog)
    assert c["M"].kind is StateKind.PARALLEL
    assert c["M/ReturnToStart"].after == ("M/Calibrate", "M/TurnToWatch")
    assert c["M/Calibrate"].after == ()


def test_written_transitions_come_before_generated_ones(catalog: Catalog) -> None:
    c = chart("mission M {\n needs r: Ranger\n start -> Calibrate\n Calibrate -> fail on error\n"
              " Calibrate -> ReturnToStart [1 > 0]\n ReturnToStart\n}", catalog)
    ts = c["M/Calibrate"].transitions
    assert [(t.kind.value, t.target, t.generated) for t in ts] == [
        ("error", "M/fail", False), ("completion", "M/ReturnToStart", False), ("completion", "M/done", True)]


def test_priorities_inherit_and_override(catalog: Catalog) -> None:
    c = chart("mission M {\n parallel { A as a; A as b priority 3 }\n}\n"
              "behavior A priority 2 { needs c: Camera\n Observe }", catalog)
    assert c["M"].priority == 1
    assert c["M/a"].priority == 2 and c["M/a/Observe"].priority == 2
    assert c["M/b"].priority == 3 and c["M/b/Observe"].priority == 3


def test_multiplicity_wraps_a_template(catalog: Catalog) -> None:
    c = chart("mission M {\n Room[1..count(Scout where scout.battery > 0.5)]\n}\n"
              "behavior Room { needs s: Scout\n Watch }", catalog)
    multi = c["M/Room"]
    assert multi.kind is StateKind.MULTI and multi.children == ("M/Room[*]",)
    assert c["M/Room[*]"].needs[0].requested
    camera = next(n for n in c["M/Room[*]/Watch"].needs if n.name == "camera")
    assert camera.bound_to == ("M/Room[*]", "s", "camera")


def test_binding_by_name_by_type_by_part_or_own_request(catalog: Catalog) -> None:
    c = chart("mission M {\n needs ranger: Ranger\n needs cam: Camera\n"
              " parallel { FollowCorridor; Observe; B }\n}\nbehavior B { needs ranger: Ranger\n Calibrate }", catalog)
    drive = {n.name: n.bound_to for n in c["M/FollowCorridor"].needs}
    assert drive == {"drive": ("M", "ranger", "drive"), "ranges": ("M", "ranger", "ranges")}
    assert c["M/Observe"].needs[0].bound_to == ("M", "cam", None)  # a direct Camera beats a part
    assert c["M/B"].needs[0].bound_to == ("M", "ranger", None)  # composite need reuses the ancestor's
    alone = chart("mission M { Observe }", catalog)
    assert alone["M/Observe"].needs[0].requested


def test_parallel_policies(catalog: Catalog) -> None:
    c = chart("mission M {\n needs r: Ranger\n parallel until DetectDoor { FollowCorridor; DetectDoor }\n}", catalog)
    assert c["M"].kind is StateKind.PARALLEL and c["M"].policy.value == "until"
    assert c["M"].until == "M/DetectDoor"


def test_imports_bring_behaviors(tmp_path: object, catalog: Catalog) -> None:
    from pathlib import Path

    from dsl import compile_file

    base = Path(str(tmp_path))
    (base / "lib.mission").write_text("behavior Look { needs c: Camera\n Observe(duration: 2s) }\n")
    (base / "main.mission").write_text('import "lib.mission"\nmission M { Look }\n')
    result = compile_file(base / "main.mission", catalog)
    assert result.ok and result.statechart is not None
    assert result.statechart["M/Look/Observe"].kind is StateKind.LEAF
    (base / "bad.mission").write_text('import "missing.mission"\nmission M { Observe }\n')
    bad = compile_file(base / "bad.mission", catalog)
    missing = base / "missing.mission"
    assert [d.message.split(":")[0] for d in bad.diagnostics] == [f"cannot read imported file {missing}"]


def test_a_file_reached_again_through_dotdot_is_the_same_file(tmp_path: object, catalog: Catalog) -> None:
    """Users audit 9, D2: `sub/../sub/a.mission` was another name for `sub/a.mission`, so a cycle through `..` was
    never seen: a RecursionError (exit 70), or a file name kilobytes long. Each file is read once, as any cycle is;
    a chain of imports deeper than the limit is a located error."""
    from pathlib import Path

    from dsl import compile_file
    from dsl.loader import MAX_IMPORT_DEPTH

    base = Path(str(tmp_path))
    (base / "lib").mkdir()
    (base / "lib" / "moves.mission").write_text('import "../lib/more.mission"\nbehavior Shuffle { Wait }\n')
    (base / "lib" / "more.mission").write_text('import "../lib/moves.mission"\nbehavior Blink { Wait }\n')
    (base / "main.mission").write_text('import "lib/moves.mission"\nmission M {\n start -> Blink\n'
                                       ' Blink -> Shuffle\n}\n')
    result = compile_file(base / "main.mission", catalog)
    assert result.ok, [d.message for d in result.diagnostics]
    assert sorted(Path(name).resolve() for name in result.sources) == sorted(
        p.resolve() for p in (base / "main.mission", base / "lib" / "moves.mission", base / "lib" / "more.mission"))
    for i in range(MAX_IMPORT_DEPTH + 2):  # a chain c0 -> c1 -> ... one file too deep
        (base / f"c{i}.mission").write_text(f'import "c{i + 1}.mission"\nbehavior C{i} {{ Wait }}\n')
    (base / f"c{MAX_IMPORT_DEPTH + 2}.mission").write_text("behavior End { Wait }\n")
    (base / "deep.mission").write_text('import "c0.mission"\nmission D { C0 }\n')
    deep = compile_file(base / "deep.mission", catalog)
    assert [d.message for d in deep.diagnostics] == [f"imports nest more than {MAX_IMPORT_DEPTH} files deep"]


def expr(text: str) -> object:
    """The expression's tree, by the shared parser (building a parser of its own cost each case 50 ms)."""
    tree = parse_expression(text)
    assert tree is not None, f"{text!r} does not parse"
    return tree


@pytest.mark.parametrize(("text", "names", "value"), [
    ("1 + 2 * 3", {}, 7),
    ("(1 + 2) * 3", {}, 9),
    ("7 / 2", {}, 3.5),
    ("7 % 4", {}, 3),
    ("-x + 1", {"x": 2}, -1),
    ("2min + 30s", {}, 150.0),
    ("a < b and not c", {"a": 1, "b": 2, "c": False}, True),
    ("false or a.width > 0.5", {"a": {"width": 0.8}}, True),
    ('"seen {n} of {m}"', {"n": 2, "m": 3.5}, "seen 2 of 3.5"),
    ("min(3, x, 2) + max(1, 4) + abs(-2)", {"x": 1}, 7),
    ("len(doors)", {"doors": [1, 2]}, 2),
])
def test_evaluator(text: str, names: dict[str, object], value: object) -> None:
    assert evaluate(expr(text), names) == value  # type: ignore[arg-type]


def test_count_uses_the_callback_with_a_predicate() -> None:
    scouts = [{"carrier": "r1"}, {"carrier": "r2"}, {"carrier": "r1"}]

    def count(type_name: str, pred: object) -> int:
        assert type_name == "Scout"
        return sum(1 for s in scouts if pred is None or pred(s))  # type: ignore[operator]

    assert evaluate(expr('count(Scout where scout.carrier == r)'), {"r": "r1"}, count) == 2
    assert evaluate(expr("count(Scout)"), {}, count) == 3


@pytest.mark.parametrize(("text", "names", "message"), [
    ("x + 1", {}, "x has no value here"),
    ("1 / 0", {}, "division by zero"),
    ('1 + "a"', {}, "cannot apply + to 1 and a"),
    ("a.b", {"a": {}}, "has no b"),
    ("a.__class__", {"a": 1}, "1 has no __class__"),
    # users audit 9, D4: an integer grew without bound (squared 40 times, the run never came back)
    ("big * big", {"big": 10 ** 9}, "* gives an integer of more than 18 digits"),
    ("big + 1", {"big": 10 ** 18 - 1}, "+ gives an integer of more than 18 digits"),
    ("0 - big - 1", {"big": 10 ** 18 - 1}, "- gives an integer of more than 18 digits"),
])
def test_evaluator_errors_are_located(text: str, names: dict[str, object], message: str) -> None:
    with pytest.raises(EvalError) as e:
        evaluate(expr(text), names)  # type: ignore[arg-type]
    assert message in e.value.message and e.value.span.line == 1


def test_integers_up_to_18_digits_and_floats_of_any_size_are_numbers() -> None:
    assert evaluate(expr("big * 9"), {"big": 10 ** 17}) == 9 * 10 ** 17
    assert evaluate(expr("big * big"), {"big": 1e200}) == float("inf")  # floats overflow as floats do
    assert evaluate(expr("0 - big"), {"big": 10 ** 18 - 1}) == 1 - 10 ** 18


def test_guard_must_be_boolean() -> None:
    assert truthy(None, {}) is True
    with pytest.raises(EvalError, match="must be true or false"):
        truthy(Name("n"), {"n": 1})


def test_mermaid_draws_a_parallel_states_finals_and_edges_outside_its_regions(catalog: Catalog) -> None:
    from dsl.export import to_mermaid

    c = chart("mission M {\n needs r: Ranger\n parallel until DetectDoor { FollowCorridor; DetectDoor }\n"
              " FollowCorridor -> fail on error\n}", catalog)
    lines = to_mermaid(c).splitlines()
    close = lines.index("  }")
    assert lines.index('  state "fail" as s3') > close
    assert lines.index("  s1 --> s3 : on error") > close
    assert lines[lines.index("    --") - 1].strip().startswith('state "FollowCorridor')


def test_an_emitted_duration_prints_as_a_duration_where_it_is_caught(catalog: Catalog) -> None:
    """Users audit 9, D9: `emit Gap(span: pause + 1s)` then `log "{event.span}"` printed `10`, not `10s` (the field
    was untyped, and a duration is a number of seconds at run time)."""
    from dsl import ast

    chart = compile_text("mission M {\n  parallel all { A; B }\n}\nbehavior A {\n  var pause: duration = 9s\n"
                         "  Wait as w\n  w -> done / emit Gap(span: pause + 1s)\n}\nbehavior B {\n  Wait as w\n"
                         '  w -> done on Gap / log "span {event.span}"\n}\n', catalog, "t.mission")
    assert chart.statechart is not None, [d.message for d in chart.diagnostics]
    logs = [a.message for s in chart.statechart.states.values() for t in s.transitions for a in t.actions
            if isinstance(a, ast.LogAction)]
    assert len(logs) == 1 and isinstance(logs[0], ast.Interp) and logs[0].durations == frozenset({1})
