"""All errors of a file in one run, binding errors included (audit item 3): the builder runs on a file the checker
found errors in, on what is sound, and a library's behaviors are built as a mission's children that hold nothing."""

from __future__ import annotations

from dsl import compile_text
from dsl.catalog import Catalog

AMBIGUOUS = "ambiguous resource binding: camera (Camera) could come from a or b"


def _errors(catalog: Catalog, source: str) -> list[str]:
    result = compile_text(source, catalog, "t.mission")
    return [f"{d.span.line}:{d.span.column} {d.message}" for d in result.diagnostics if d.severity.value == "error"]


def test_an_ambiguous_binding_is_reported_with_an_unknown_name(catalog: Catalog) -> None:
    source = ("mission M {\n  needs a: Camera\n  needs b: Camera\n  Peeker\n}\n"
              "behavior Peeker {\n  Observe(duration: 1s)\n  Observe -> done when nothing_here > 1\n}\n")
    assert _errors(catalog, source) == [f"7:3 {AMBIGUOUS}", "8:24 unknown name nothing_here"]


def test_a_cyclic_plan_with_a_type_error_still_reports_the_binding(catalog: Catalog) -> None:
    source = ("mission M {\n  needs a: Camera\n  needs b: Camera\n  plan {\n    Calibrate < Observe\n"
              "    Observe < Calibrate\n  }\n  Calibrate(samples: \"lots\")\n}\n")
    errors = _errors(catalog, source)
    assert "4:3 plan cycle: Calibrate < Observe < Calibrate" in errors
    assert "8:22 samples expects int, got str" in errors
    assert f"5:17 {AMBIGUOUS}" in errors


def test_recursive_behaviors_are_not_expanded_the_rest_is_checked(catalog: Catalog) -> None:
    source = ("mission M {\n  needs a: Camera\n  needs b: Camera\n  parallel all { Loop; Observe }\n}\n"
              "behavior Loop { Again }\nbehavior Again { Loop }\n")
    errors = _errors(catalog, source)
    assert any("includes itself" in e for e in errors)
    assert f"4:24 {AMBIGUOUS}" in errors


def test_an_unknown_producer_does_not_make_its_consumers_input_missing(catalog: Catalog) -> None:
    source = "mission M {\n  needs r: Ranger\n  start -> DetectDor\n  DetectDor -> AlignRanger\n}\n"
    errors = _errors(catalog, source)
    assert len(errors) == 1 and "unknown state DetectDor" in errors[0]


def test_a_clean_file_with_a_missing_input_still_reports_it(catalog: Catalog) -> None:
    errors = _errors(catalog, "mission M {\n  needs r: Ranger\n  AlignRanger\n}\n")
    assert len(errors) == 1 and "AlignRanger needs input door" in errors[0]


def test_a_library_whose_binding_is_ambiguous_wherever_it_is_used_is_rejected(catalog: Catalog) -> None:
    source = "behavior TwoEyes {\n  needs left: Camera\n  needs right: Camera\n  Observe(duration: 1s)\n}\n"
    assert _errors(catalog, source) == [
        "4:3 ambiguous resource binding: camera (Camera) could come from left or right"]


def test_a_library_may_leave_to_its_user_what_an_ancestor_provides(catalog: Catalog) -> None:
    """An input fed by the user's shared data or sibling, a resource the user's mission holds: valid out of context."""
    source = ("behavior Aligner {\n  AlignRanger\n}\nbehavior Reads(label: str) {\n  DetectDoor(visited: doors)\n}\n"
              "behavior Eye { Observe(duration: 1s) }\n")
    result = compile_text(source, catalog, "lib.mission")
    assert result.ok, [str(d) for d in result.diagnostics]
    assert result.statechart is None


def test_a_library_used_by_a_mission_reports_once(catalog: Catalog) -> None:
    source = ("mission M { TwoEyes }\n"
              "behavior TwoEyes {\n  needs left: Camera\n  needs right: Camera\n  Observe(duration: 1s)\n}\n")
    assert _errors(catalog, source) == [
        "5:3 ambiguous resource binding: camera (Camera) could come from left or right"]


def test_a_missing_import_hides_only_what_the_missing_file_may_have_declared(catalog: Catalog) -> None:
    """Users audit 15, D7: an import that could not be read was the file's only error, though its own needs and
    transitions had others; what the missing file may declare (behaviors, their events) is still not reported."""
    source = ('import "nowhere.mission"\nmission M {\n  needs r: Ranger where r.batery > 0.5\n  start -> Sweep\n'
              '  Sweep -> done on SweepDone\n  Sweep(speed: 1s)\n  Wait(duration: 3)\n  needs c: Camra\n}\n')
    errors = compile_text(source, catalog, "t.mission", imports={}).diagnostics
    codes = [d.code for d in errors if d.severity.value == "error"]
    assert codes[0] == "io" and "nowhere.mission" in errors[0].message
    assert "Ranger has no property batery" in [d.message for d in errors]
    assert not {"unknown-behavior", "unknown-event", "unknown-state"} & set(codes)
    assert "duration expects duration, got int" in [d.message for d in errors]  # Wait's, a component it knows
    assert "unknown-resource" in codes  # a type: no mission file declares one (review)
