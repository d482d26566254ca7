"""Every check, one bad mission and its exact message: a table tested in one loop.

Like lark's GRAMMAR_ERRORS table, each row pins a message the user sees, its position
(line:column) and, where there is one, a piece of the hint. A message changes only with
this table.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from dsl import compile_file, compile_text
from dsl.catalog import Catalog


def m(body: str, extra: str = "") -> str:
    """A mission around `body` (line 2 onward), with extra declarations after it."""
    return "mission M {\n" + body + "\n}\n" + extra


# (id, source, "line:col message", hint fragment or None)
ERRORS: list[tuple[str, str, str, str | None]] = [
    # ---- syntax
    ("arrow-without-target", m("  needs r: Ranger\n  FollowCorridor ->"), "3:20 syntax: expected a state or "
     "done/fail after ->", None),
    ("unclosed-paren-before-next-item", m("  Wait(duration: 1s\n  Observe(duration: 2s)"),
     "2:20 syntax: expected `)` after `1s`: the `(` on line 2 is never closed", "add `)` at the end of line 2"),
    ("unclosed-paren-before-alias", m("  Wait(duration: 1s as a"),
     "2:20 syntax: expected `)` after `1s`: the `(` on line 2 is never closed", "add `)` before `as`"),
    ("unclosed-paren-before-brace", m("  Wait(duration: 1s"),
     "2:20 syntax: expected `)` after `1s`: the `(` on line 2 is never closed", None),
    ("missing-separator", m("  needs r: Ranger\n  FollowCorridor(speed: 0.5) AvoidObstacles"),
     "3:29 syntax: expected a newline or ; after `)`", "starts a new item"),
    ("glued-keyword", "missionpatrol M {}\n", "1:1 syntax: expected behavior, import or mission, got `missionpatrol`",
     "put a space between mission and patrol"),
    ("reserved-word", m("  var event: int = 0"), "2:7 syntax: expected `name: type = value` after var",
     "event is a reserved word"),
    ("single-quotes", m("  Inspect(label: 'a')", "behavior Inspect(label: str) { Observe }"),
     "2:18 syntax: unexpected character \"'\"", "double quotes"),
    ("day-unit-over-a-year", m("  Wait(duration: 366d)"),
     "2:18 syntax: unknown duration unit d in `366d`: write 250ms, 30s, 5min or 2h", "at most 365 days (8760h)"),
    ("other-languages-type-spelling", m("  var label: string = \"a\"\n  Observe"), "2:14 unknown type string",
     "did you mean str?"),
    ("unterminated-string", m('  Observe -> done / log "no end'),
     "2:25 syntax: unterminated string", 'ends with " on the same line'),
    ("unclosed-brace", "mission M {\n  Observe\n", "1:11 syntax: this `{` of `mission M` is never closed (the file "
     "ends)", "add the `}` that ends this block"),
    ("unclosed-before-declaration", "mission M {\n  Observe\n\nbehavior B {\n  Observe\n}\n",
     "1:11 syntax: this `{` of `mission M` is never closed (`behavior` starts a new declaration on line 4)",
     "before line 4"),
    ("unclosed-inner-block", "mission M {\n  parallel all {\n    Observe\n  Calibrate\n}\nbehavior B { Observe }\n",
     "2:16 syntax: this `{` of `parallel all` is never closed (`behavior` starts a new declaration on line 6)",
     "before line 4"),
    ("unclosed-brace-in-string-ignored", 'mission M {\n  Observe\n  Observe -> done / log "}"\n',
     "1:11 syntax: this `{` of `mission M` is never closed (the file ends)", None),
    ("arguments-on-target", m("  Observe as a\n  Calibrate as b\n  a -> b(duration: 3s)"),
     "4:9 syntax: a transition's target is a state's name, not a call: `-> b(`", "`Type(...) as b`"),
    ("colon-label", m("  a: Observe"), "2:4 syntax: `a:` is not how a child is named", "`Type(...) as a`"),
    ("action-outside-transition", m("  log \"hi\""), "2:3 syntax: expected `}`, a name, constraint, needs, "
     "parallel, plan, shared, start or var, got `log`", "follow a / at the end of a transition"),
    ("after-needs-duration", m("  Observe\n  Observe -> done after\n"),
     "3:24 syntax: expected a duration after after (e.g. 2min)", None),
    ("after-unit", m("  Observe\n  Observe -> done after 5"), "3:25 after expects duration, got int", "write a unit"),
    ("unknown-duration-unit", m("  Observe(duration: 5parsecs)"),
     "2:21 syntax: unknown duration unit parsecs in `5parsecs`: write 250ms, 30s, 5min or 2h", None),
    ("duration-exponent", m("  Wait(duration: 1e3s)"), "2:18 syntax: a duration takes no exponent: `1e3s`",
     "write 1000s"),
    ("duration-exponent-huge", m("  Wait(duration: 1e20s)"), "2:18 syntax: a duration takes no exponent: `1e20s`",
     "at most 365 days"),
    ("duration-unit-word", m("  Observe\n  Observe -> done after 3days"),
     "3:25 syntax: unknown duration unit days in `3days`: write 250ms, 30s, 5min or 2h", "did you mean 72h?"),
    ("bad-escape", m('  Observe\n  Observe -> done / log "a\\qb"'), "3:27 unknown escape \\q in string", None),
    ("unclosed-interpolation", m('  Observe\n  Observe -> done / log "a{b"'), "3:27 unclosed { in string", None),
    ("bad-interpolation", m('  Observe\n  Observe -> done / log "a{1 +}"'),
     "3:30 bad expression in string interpolation: expected `(`, `-`, a duration (e.g. 30s), a name, a number, "
     "a string (\"...\"), an integer, event, false or true, got the end of the expression", None),
    # ---- values checked where they are written (issue #18)
    ("integer-too-long", m("  var n: int = " + "9" * 5000 + "\n  Observe"), "2:16 integer 99999999999999999999999… is "
     "too large (5000 digits, at most 18)", None),
    ("float-too-large", m("  var f: float = 1e400\n  Observe"), "2:18 number 1e400 is too large (at most 1e+15)", None),
    ("duration-too-long", m("  Observe -> done after 999999999h\n  Observe"),
     "2:25 duration 999999999h is too long (at most 365 days)", None),
    ("quantity-negative", m("  needs r: RadioChannel quantity -5\n  Observe"),
     "2:34 quantity -5 asks for nothing: it must be above 0", "leave quantity out"),
    ("quantity-zero", m("  needs r: RadioChannel quantity 0.0\n  Observe"),
     "2:34 quantity 0 asks for nothing: it must be above 0", None),
    ("slice-zero", m("  needs r: Ranger for 0s\n  Observe"),
     "2:23 a time slice of 0s never lets the holder run: it is resumed at one control cycle (0.1s) and preempted at"
     " the next; give at least 200ms", "leave `for` out"),
    ("slice-one-cycle", m("  needs r: Ranger for 100ms\n  Observe"),  # users audit 9, D3: both holders starved
     "2:23 a time slice of 100ms never lets the holder run: it is resumed at one control cycle (0.1s) and"
     " preempted at the next; give at least 200ms", "a slice of 1s or more"),
    ("negative-duration", m("  Wait(duration: -1s)"), "2:8 duration: a duration cannot be negative (-1 s)", None),
    # users audit 9, D11: `after -5s` fired at once, as `after 0s` does
    ("negative-after", m("  start -> W\n  Wait as W\n  W -> done after -5s"),
     "4:19 after -5s: a duration cannot be negative (the source cannot have been active for less than no time)",
     "write `after 0s`"),
    # users audit 9, D12: the hint said to declare a var of the parameter's name, which was then declared twice
    ("set-a-parameter", m("  Inner", "behavior Inner(level: int = 1) {\n  start -> W\n  Wait as W\n"
                                     "  W -> done / set level = 3\n}\n"),
     "7:15 set level: level is a parameter of Inner, which a transition cannot change",
     "var current_level: int = level"),
    ("remainder-by-zero", m("  var n: int = 1\n  Observe\n  Observe -> done / set n = n % 0"),
     "4:33 remainder by zero", "divisor is 0"),
    ("division-by-zero", m("  var x: float = 1.0 / 0\n  Observe"), "2:24 division by zero", None),
    ("too-many-instances", m("  Wait(duration: 1s)[1000000000]"),
     "2:21 multiplicity 1000000000 is above the limit of 1000 instances", "[1..*]"),
    # ---- names
    ("unknown-behavior", m("  DetectDor(min_width: 0.7)"), "2:3 unknown behavior DetectDor",
     "did you mean DetectDoor?"),
    ("unknown-state", m("  needs r: Ranger\n  start -> Calibrate\n  Calibrate -> Finsh"),
     "4:16 unknown state Finsh: no child of M and no behavior has this name", None),
    ("unknown-resource", m("  needs r: Rangr\n  Calibrate"), "2:12 unknown resource type Rangr",
     "did you mean Ranger?"),
    ("unknown-type", m("  var n: integer = 0\n  Calibrate"), "2:10 unknown type integer", None),
    ("unknown-data-type", m("  shared map: OccupancyMapp\n  Calibrate"), "2:15 unknown data type OccupancyMapp",
     "did you mean OccupancyMap?"),
    ("unknown-parameter", m("  FollowCorridor(sped: 0.5)"), "2:18 FollowCorridor has no parameter sped",
     "did you mean speed?"),
    ("missing-parameter", m("  Inspect", "behavior Inspect(label: str) { Observe }"),
     "2:3 Inspect needs parameter label", "Inspect(label: ...)"),
    ("unknown-event", m("  Watch\n  Watch -> done on MotionDetcted"), "3:20 unknown event MotionDetcted",
     "did you mean MotionDetected?"),
    ("unknown-sender", m("  Watch\n  Watch -> done on MotionDetected from Wtch"),
     "3:40 on MotionDetected from Wtch: M has no child Wtch", "did you mean Watch?"),
    ("unknown-name", m("  var n: int = 0\n  Watch\n  Watch -> done when m > 1"), "4:22 unknown name m",
     "did you mean n?"),
    ("unknown-property", m("  needs s: Scout where s.carier == \"x\"\n  Watch"), "2:24 Scout has no property carier",
     "did you mean carrier?"),
    ("unknown-output", m("  start -> DetectDoor\n  DetectDoor -> done [DetectDoor.dor.width > 1]"),
     "3:23 DetectDoor has no output dor", "did you mean door?"),
    ("unknown-field", m("  start -> DetectDoor\n  DetectDoor -> done [DetectDoor.door.widht > 1]"),
     "3:23 door has no field widht", "did you mean width?"),
    ("event-outside-on", m("  Watch\n  Watch -> done when event.area > 1"),
     "3:22 event is only defined in a transition triggered by on EVENT", None),
    ("unknown-function", m("  Watch\n  Watch -> done when cont(Scout) > 1"), "3:22 unknown function cont",
     "did you mean count?"),
    ("count-unknown-type", m("  Watch\n  Watch -> done when count(Scot) > 1"),
     "3:28 unknown resource type Scot", "did you mean Scout?"),
    ("set-unknown-var", m("  Watch\n  Watch -> done / set laps = 1"), "3:19 set laps: M has no var laps",
     "var laps: int = 0"),
    ("set-unknown-float-var", m("  Watch\n  Watch -> done on MotionDetected / set seen = event.area"),
     "3:37 set seen: M has no var seen", "var seen: float = 0.0"),  # the hint declares what is set
    ("release-unknown", m("  needs r: Ranger\n  Calibrate\n  Calibrate -> done / release(ranger)"),
     "4:23 release(ranger): no resource ranger is held here", None),
    ("not-a-behavior", m("  Camera"), "2:3 Camera is a resource, not a behavior", "needs x: Camera"),
    ("data-as-child", m("  DoorLog"), "2:3 DoorLog is a data type, not a behavior", "shared x: DoorLog"),
    ("until-unknown", m("  parallel until Watch { FollowCorridor; Observe }"),
     "2:3 parallel until Watch: no such child in the block", None),
    # ---- types
    ("wrong-type", m("  FollowCorridor(speed: \"fast\")"), "2:25 speed expects float, got str", None),
    ("duration-needs-unit", m("  Watch(duration: 60)"), "2:19 duration expects duration, got int",
     "write a unit"),
    ("guard-not-bool", m("  var n: int = 0\n  Watch\n  Watch -> done [n + 1]"), "4:18 a guard expects bool, got int",
     None),
    ("compare-mismatch", m("  var n: int = 0\n  Watch\n  Watch -> done when n == \"x\""),
     "4:22 cannot compare int with str", None),
    ("arith-mismatch", m("  var n: int = 0\n  Watch\n  Watch -> done / set n = n + \"x\""),
     "4:27 cannot apply + to int and str", None),
    ("var-init", m("  var n: int = true\n  Watch"), "2:16 var n expects int, got bool", None),
    ("param-default", m("  Inspect", "behavior Inspect(n: int = 1.5) { Observe }"),
     "4:27 parameter n expects int, got float", None),
    ("quantity-not-sharable", m("  needs c: Camera quantity 2\n  Observe"),
     "2:28 quantity applies to sharable resources; Camera is not sharable", None),
    ("emit-field-type", m("  Watch\n  Watch -> done / emit MotionDetected(area: \"big\")"),
     "3:45 area expects float, got str", None),
    # ---- structure
    ("several-children", m("  needs r: Ranger\n  Calibrate\n  ReturnToStart"),
     "1:9 M has several children (Calibrate, ReturnToStart) and no way to start", "start -> Calibrate"),
    ("unreachable", m("  needs r: Ranger\n  start -> Calibrate\n  ReturnToStart"),
     "4:3 ReturnToStart is never reached: no transition leads to it", "Calibrate -> ReturnToStart"),
    ("plan-cycle", m("  needs r: Ranger\n  plan { Calibrate < ReturnToStart < Calibrate }"),
     "3:3 plan cycle: Calibrate < ReturnToStart < Calibrate", None),
    ("outside-parallel", m("  needs r: Ranger\n  parallel { Calibrate }\n  ReturnToStart"),
     "4:3 ReturnToStart is outside the parallel block of M", None),
    ("two-plans", m("  needs r: Ranger\n  plan { Calibrate }\n  plan { ReturnToStart }"),
     "4:3 M has more than one parallel block or plan", None),
    ("parallel-sibling-transition", m("  needs r: Ranger\n  parallel { Calibrate; ReturnToStart }\n"
                                      "  Calibrate -> ReturnToStart"),
     "4:16 Calibrate -> ReturnToStart: in a parallel block or concurrent plan a transition leads only to done, "
     "fail or back to its source", None),
    ("recursion", m("  A", "behavior A { B }\nbehavior B { A }"), "4:14 behavior A includes itself: A > B > A", None),
    ("multiplicity-never", m("  Observe[3..1]"), "2:10 multiplicity [3..1] can never hold: the minimum is above "
     "the maximum", None),
    ("multiplicity-negative", m("  Observe[-1..2]"), "2:10 multiplicity -1 can never hold: it must be 0 or more",
     None),
    ("multiplicity-zero", m("  Observe[0]"), "2:10 multiplicity [0] creates no instance", None),
    ("multiplicity-type", m("  Observe[1.5..2]"), "2:11 multiplicity expects int, got float", None),
    ("priority-zero", m("  Observe priority 0"), "2:3 priority must be 1 or more (1 is the highest)", None),
    # ---- duplicates
    ("duplicate-behavior", m("  A", "behavior A { Observe }\nbehavior A { Watch }"),
     "5:10 behavior A is declared twice", None),
    ("behavior-shadows-component", m("  Observe", "behavior Watch { Observe }"),
     "4:10 Watch is already an elementary behavior component", None),
    ("duplicate-declaration", m("  var n: int = 0\n  var n: int = 1\n  Observe"), "3:3 n is declared twice in M",
     None),
    ("duplicate-child", m("  parallel { Observe; Observe }"), "2:23 two children of M are named Observe",
     "give one an alias"),
    ("duplicate-argument", m("  Observe(duration: 1s, duration: 2s)"), "2:25 duration is given twice", None),
    ("two-missions", m("  Observe", "mission N { Observe }"), "4:9 a file holds at most one mission; M came first",
     None),
    # users audit 9, D9: an emitted field was untyped, so comparing a text with a number passed the checker
    ("emitted-field-typed", m("  parallel all { A; B }", "behavior A {\n  Wait as w\n  w -> done / emit Gap(who:"
                                                      ' "x")\n}\nbehavior B {\n  Wait as w\n'
                                                      "  w -> done on Gap [event.who > 5]\n}\n"),
     "10:21 cannot order str and int with >", None),
    # ---- misspelled keywords (users audit 9, D8: "`rig` starts a new item: put it on its own line")
    ("misspelled-needs", m("  need rig: Ranger\n  Calibrate"), "2:7 syntax: expected a newline or ; after `need`",
     "`need` is no keyword: did you mean needs?"),
    ("misspelled-after", m("  start -> Calibrate\n  Calibrate -> Observe afer 5s"),
     "3:23 syntax: expected a newline or ; after `Observe`", "`afer` is no keyword: did you mean after?"),
    ("misspelled-mission", "mision Kw5 {\n  Calibrate\n}\n",
     "1:1 syntax: expected behavior, import or mission, got `mision`", "did you mean mission?"),
    ("parallel-in-parallel", m("  parallel any {\n    Observe\n    parallel all {\n      Calibrate\n    }\n  }"),
     "4:5 syntax: expected `}` or a name, got `parallel`", "declare the inner one in a behavior"),
    ("misspelled-error", m("  start -> Calibrate\n  Calibrate -> Observe on eror"), "3:27 unknown event eror",
     "did you mean error?"),
    ("misspelled-done", m("  start -> Calibrate\n  Calibrate -> dne"),
     "3:16 unknown state dne: no child of M and no behavior has this name", "did you mean done?"),
    # users audit 12, D9: `2 s` was told "`s` starts a new item"
    ("spaced-unit", m("  Wait(duration: 2 s)"),
     "2:20 syntax: a duration's unit follows its number with no space: `2 s`", "write 2s"),
    ("spaced-unit-word", m("  Wait(duration: 5 minutes)"),
     "2:20 syntax: a duration's unit follows its number with no space: `5 minutes`", "write 5min"),
    # reverify audit 14, D3: `5 min` was "did you mean emit?"
    ("spaced-unit-min", m("  Wait(duration: 5 min)"),
     "2:20 syntax: a duration's unit follows its number with no space: `5 min`", "write 5min"),
    # users audit 12, D8: a misspelt start target made every child "never reached", hinting `Inspct -> ...`
    ("misspelt-start-only", m("  start -> Calibrat\n  Calibrate\n  Observe\n  Calibrate -> Observe"),
     "2:12 unknown state Calibrat: no child of M and no behavior has this name", "did you mean Calibrate?"),
    # ---- resources
    ("ambiguous-binding", m("  needs a: Camera\n  needs b: Camera\n  Observe"),
     "4:3 ambiguous resource binding: camera (Camera) could come from a or b", "name one of them camera"),
]


@pytest.mark.parametrize("case", ERRORS, ids=[row[0] for row in ERRORS])
def test_error_table(case: tuple[str, str, str, str | None], catalog: Catalog) -> None:
    _, source, expected, hint = case
    result = compile_text(source, catalog, "t.mission")
    got = [f"{d.span.line}:{d.span.column} {d.message}" for d in result.diagnostics]
    assert expected in got, f"expected {expected!r}, got {got}"
    if hint is not None:
        d = result.diagnostics[got.index(expected)]
        assert d.hint is not None and hint in d.hint, f"hint {d.hint!r} lacks {hint!r}"


def test_table_covers_every_diagnostic_code(catalog: Catalog) -> None:
    codes = set()
    for _, source, _, _ in ERRORS:
        codes |= {d.code for d in compile_text(source, catalog, "t.mission").diagnostics}
    expected = {"syntax", "unknown-behavior", "unknown-state", "unknown-resource", "unknown-type", "unknown-parameter",
                "missing-parameter", "unknown-event", "unknown-name", "type", "not-a-behavior", "quantity",
                "structure", "unreachable", "plan-cycle", "recursion", "multiplicity", "priority", "duplicate",
                "ambiguous-binding"}
    assert expected <= codes, f"no table row for {sorted(expected - codes)}"


def test_a_literal_is_refused_once_however_often_error_recovery_reads_it(catalog: Catalog) -> None:
    got = [d.message for d in compile_text(m("  Wait(duration: 1e20s)"), catalog, "t.mission").diagnostics]
    assert got.count("number 1e20 is too large (at most 1e+15)") == 1, got


def test_all_errors_of_a_file_in_one_run(catalog: Catalog) -> None:
    source = m("  FollowCorridor(speed: \"x\")\n  DetectDor\n  Watch(duraton: 1s)", "")
    result = compile_text(source, catalog, "t.mission")
    assert len([d for d in result.diagnostics if d.severity.value == "error"]) >= 3


def test_several_syntax_errors_in_one_run(catalog: Catalog) -> None:
    result = compile_text(m("  A ->\n  B ->\n  C -> D"), catalog, "t.mission")
    assert [(d.span.line, d.message) for d in result.diagnostics] == [
        (2, "syntax: expected a state or done/fail after ->"),
        (3, "syntax: expected a state or done/fail after ->")]


def test_a_parallel_block_in_a_parallel_block_is_one_error_and_a_later_one_is_still_found(catalog: Catalog) -> None:
    """Users audit 22, #4: after the nested block's error, recovery closed the outer block early, and each `}` after
    it was an error of its own (four errors for one mistake, their carets past the `}` or on the line before). The
    tokens right after a skipped one are the same mistake, and the `}` a repair put in early is the user's own."""
    source = ("mission M {\n    parallel all {\n        Observe\n        parallel any {\n"
              "            Wait(duration: 1s)\n            Wait(duration: 2s)\n        }\n    }\n}\n")
    got = [(d.span.line, d.span.column, d.message) for d in compile_text(source, catalog, "t.mission").diagnostics]
    assert got == [(4, 9, "syntax: expected `}` or a name, got `parallel`")], got
    later = source + "behavior B {\n    Wait(duration 3s)\n}\n"
    got = [(d.span.line, d.message) for d in compile_text(later, catalog, "t.mission").diagnostics]
    assert got == [(4, "syntax: expected `}` or a name, got `parallel`"), (11, "syntax: expected `:`, got `3s`")], got


def test_a_stray_close_on_a_line_of_its_own_is_pointed_at() -> None:
    result = compile_text("mission M {\n    Observe\n}\n}\n", Catalog.of([]), "t.mission")
    got = [(d.span.line, d.span.column, d.message) for d in result.diagnostics]
    assert got == [(4, 1, "syntax: expected behavior, import or mission, got `}`")], got


def test_a_paren_left_open_is_one_error_and_the_items_after_it_are_read(catalog: Catalog) -> None:
    """Interfaces audit D1: the `)` forgotten at a line's end was reported as a missing newline, with a hint to
    put the (already separate) next item on its own line, and error recovery then reported a second, spurious
    error inside the next item. Now one error; recovery closes the `(` there, so a real mistake further on is
    still found, and a wrapped argument list is not taken for one."""
    source = m("  Wait(duration: 1s\n  Observe(duration: 2s)\n  Wait(duration 3s)")
    got = [(d.span.line, d.message) for d in compile_text(source, catalog, "t.mission").diagnostics]
    assert got == [(2, "syntax: expected `)` after `1s`: the `(` on line 2 is never closed"),
                   (4, "syntax: expected `:`, got `3s`")], got
    wrapped = m("  Wait(\n      duration: 1s\n  )")
    assert compile_text(wrapped, catalog, "t.mission").diagnostics == []


@pytest.mark.parametrize(("body", "expected"), [
    ("  Wait(duration: (1s\n  Wait(duration: 2s) as b", [(2, "syntax: expected `)` after `1s`: the `(` on line 2 is"
                                                             " never closed")]),
    ("  Wait(duration: 1s priority 2\n  Wait(duration: 2s)", [(2, "syntax: expected `)` after `1s`: the `(` on line 2"
                                                                 " is never closed")]),
    ("  Wait(duration: 1s,\n       priority: 2)\n  Wait(duration: 2s)",
     [(3, "syntax: expected a name, got `priority`")]),
], ids=["nested", "priority-on-its-line", "reserved-word-in-a-wrapped-list"])
def test_brackets_left_open_give_one_error_each(body: str, expected: list[tuple[int, str]], catalog: Catalog) -> None:
    """Re-verification R3: nested brackets were closed one at a time (two spurious errors followed), `as` or
    `priority` after an open `(` were taken for a new item, and a reserved word in a wrapped list added an error on
    the next, correct line."""
    got = [(d.span.line, d.message) for d in compile_text(m(body), catalog, "t.mission").diagnostics]
    assert got == expected


def test_an_unknown_behavior_says_where_behaviors_come_from_and_nothing_about_its_outputs(catalog: Catalog) -> None:
    """Newcomer audit 6: `unknown behavior Spin` (a manifest folder not given) had no hint, and `Spin has no output
    spun` followed, noise once Spin is unknown."""
    result = compile_text(m("  Spin(turns: 2) as spin\n  spin -> done when spin.spun.turns > 1"), catalog, "t.mission")
    assert [d.message for d in result.diagnostics] == ["unknown behavior Spin"]
    assert result.diagnostics[0].hint is not None and "-C DIR or $DRD_COMPONENTS" in result.diagnostics[0].hint
    assert "on a cluster, to the controller's `drd start`" in result.diagnostics[0].hint  # `run` takes no -C (users
    # audit 21, #4: the hint sent to `missionctl run` said -C DIR, which it does not take)


def test_rendered_error_shows_line_and_caret(catalog: Catalog) -> None:
    result = compile_text(m("  DetectDor(min_width: 0.7)"), catalog, "t.mission")
    text = result.diagnostics[0].render(result.sources)
    assert text.splitlines() == [
        "t.mission:2:3: error: unknown behavior DetectDor",
        "    2 |   DetectDor(min_width: 0.7)",
        "      |   ^^^^^^^^^^^^^^^^^^^^^^^^^",
        "  hint: did you mean DetectDoor?",
    ]


def test_a_file_saved_with_a_byte_order_mark_compiles(tmp_path: Path, catalog: Catalog) -> None:
    """Some editors write UTF-8 with a BOM first: it is not a character of the mission (spec audit 7)."""
    path = tmp_path / "bom.mission"
    path.write_bytes("\ufeffmission M { Observe }\n".encode())
    result = compile_file(path, catalog)
    assert result.ok, [d.message for d in result.diagnostics]


def test_a_bad_byte_after_a_byte_order_mark_is_located_as_the_editor_shows_it(tmp_path: Path, catalog: Catalog) -> None:
    """The mark is not counted: the line and column are those after it, and the byte named is the bad one (the
    `utf-8-sig` codec's error positions were relative to the text after the mark, this error's to the file's)."""
    path = tmp_path / "bom.mission"
    path.write_bytes(b"\xef\xbb\xbf\n\nX\xff\n")
    (d,) = [d for d in compile_file(path, catalog).diagnostics if d.code == "encoding"]
    assert (d.span.line, d.span.column) == (3, 2) and "byte 0xff" in d.message, d


def test_a_distance_in_metres_is_not_told_to_be_minutes(catalog: Catalog) -> None:
    """Review: `<= 6 m` was told "write 6min" (the unit words had `m` for minutes)."""
    source = m("  needs r: Ranger\n  constraint near: distance(r, point(0, 0)) <= 6 m\n  Calibrate")
    hints = [d.hint or "" for d in compile_text(source, catalog, "t.mission").diagnostics]
    assert hints and not any("min" in h for h in hints), hints


def test_a_misspelt_start_target_is_one_error_not_every_child_never_reached(catalog: Catalog) -> None:
    """Users audit 12, D8: each child was also "never reached", its hint naming the misspelt state."""
    source = m("  start -> Calibrat\n  Calibrate\n  Observe\n  Calibrate -> Observe")
    result = compile_text(source, catalog, "t.mission")
    assert [d.code for d in result.diagnostics] == ["unknown-state"]


def test_an_unknown_behavior_is_never_offered_the_behavior_it_is_written_in(catalog: Catalog) -> None:
    """Users audit 18, #4: `Liar` in `mission Lies` suggested `Lies`, which then included itself; a sibling behavior
    of a close name is still offered."""
    lies = compile_text("mission Lies {\n    start -> Fib\n    Liar as Fib\n}\n", catalog, "t.mission")
    assert [d.message for d in lies.diagnostics] == ["unknown behavior Liar"]
    assert "did you mean" not in (lies.diagnostics[0].hint or "")
    other = compile_text("mission Lies {\n    Liar\n}\nbehavior Lier {\n    Wait(duration: 1s)\n}\n", catalog,
                         "t.mission")
    assert other.diagnostics[0].hint == "did you mean Lier?"


def test_a_var_read_in_a_needs_where_is_told_it_is_a_var_and_how_to_pass_it(catalog: Catalog) -> None:
    """Users audit 21, #7: `unknown name lane_name` for a var declared two lines above, with no hint."""
    text = 'mission M {\n    var lane_name: str = "west"\n    needs rig: Ranger where rig.id == lane_name\n' \
           "    Wait(duration: 1s)\n}\n"
    [d] = compile_text(text, catalog, "t.mission").diagnostics
    assert d.message == "var lane_name cannot be read in a need's where" and str(d.span) == "t.mission:3:39"
    assert d.hint is not None and "behavior Child(lane_name: str)" in d.hint


def test_a_string_in_an_interpolation_is_written_escaped_and_a_quote_of_another_kind_is_told_so(
        catalog: Catalog) -> None:
    """Users audit 21, #5: no spelling of a string inside `{...}` worked, and the error was lark's own words ("No
    terminal matches '\\' ... at line 1 col 40") with a hint about braces."""
    ok = compile_text(m('  Wait(duration: 1s) as w\n  w -> done / log "n: {count(Ranger where ranger.id =='
                        ' \\"ranger1\\")}"'), catalog, "t.mission")
    assert ok.ok, [d.message for d in ok.diagnostics]
    bad = compile_text(m("  Wait(duration: 1s) as w\n  w -> done / log \"n: {count(Ranger where ranger.id =="
                         " 'ranger1')}\""), catalog, "t.mission")
    [d] = bad.diagnostics
    assert d.message == "bad expression in string interpolation: unexpected character `'`", d.message
    assert d.hint is not None and 'escaped double quotes' in d.hint and "line 1 col" not in d.message
