"""docs/reference.md is the whole language, kept exact: every reserved word and every function the compiler
knows is in it, every syntax example in it parses, and the rules it states hold in the compiler."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from dsl import compile_text
from dsl.ast import KEYWORDS
from dsl.catalog import Catalog
from dsl.exprtypes import FUNCTIONS
from dsl.parser import parse

REFERENCE = Path(__file__).resolve().parents[2] / "docs" / "reference.md"
TEXT = REFERENCE.read_text(encoding="utf-8")
BLOCKS = re.findall(r"```\n(.*?)```", TEXT, re.S)


def test_every_reserved_word_is_in_the_reference() -> None:
    words = set(re.findall(r"[A-Za-z_]+", " ".join(re.findall(r"`([^`]*)`", TEXT)) + " ".join(BLOCKS)))
    assert sorted(KEYWORDS - words) == []


def test_every_function_is_in_the_reference_with_its_arguments() -> None:
    rows = [line for line in TEXT.splitlines() if line.startswith("| `")]
    assert [f for f in FUNCTIONS if not any(f"`{f}(" in row for row in rows)] == []


def test_the_declarations_example_parses() -> None:
    block = next(b for b in BLOCKS if b.startswith("import"))
    _tree, errors = parse(block.replace("{ BODY }", "{ Observe }"), "reference.md")
    assert errors == []


def test_every_body_item_example_parses() -> None:
    block = next(b for b in BLOCKS if b.startswith("needs"))
    items = [line for line in block.splitlines() if line.strip() and "…" not in line]
    assert len(items) > 20
    _tree, errors = parse("mission M {\n" + "\n".join(items) + "\n}\n", "reference.md")
    assert [f"{e.span}: {e.message}" for e in errors] == []


@pytest.mark.parametrize(("rule", "source", "fragment"), [
    ("a var is local to its behavior", "mission M {\n    start -> B\n    B -> done when tries > 0\n}\n"
     "behavior B {\n    var tries: int = 0\n    Observe\n}\n", "unknown name tries"),
    ("several children need a start", "mission M {\n    Observe\n    Calibrate\n}\n", "no way to start"),
    ("a plan cycle names every step", "mission M {\n    plan { Observe < Calibrate; Calibrate < Observe }\n}\n",
     "Observe"),
])
def test_a_rule_the_reference_states_holds(rule: str, source: str, fragment: str, catalog: Catalog) -> None:
    result = compile_text(source, catalog, "rule.mission")
    assert not result.ok, rule
    assert any(fragment in d.message for d in result.diagnostics), [d.message for d in result.diagnostics]


def test_shared_data_is_visible_to_descendants(catalog: Catalog) -> None:
    source = ("mission M {\n    shared doors: DoorLog\n    Inner\n}\n"
              "behavior Inner {\n    Watch\n    Watch -> done when len(doors) >= 0\n}\n")
    result = compile_text(source, catalog, "shared.mission")
    assert result.ok, [d.message for d in result.diagnostics]


def test_the_limits_the_reference_states_are_the_compilers_and_the_interpreters() -> None:
    """Wedge audit D7: the limits were in docs/design.md only."""
    from drd.runtime.interpreter import MAX_BEHAVIOR_TURNS, MAX_MICROSTEPS, MAX_REPEATS
    from dsl.checker import MAX_BEHAVIOR_DEPTH
    from dsl.parser import MAX_DURATION, MAX_EXPR_DEPTH, MAX_INT_DIGITS

    limits = TEXT[TEXT.index("A mission\nthat never lets time pass"):TEXT.index("## Errors")]
    stated = {int(n.replace(",", "")) for n in re.findall(r"\b\d[\d,]*\b", limits)}
    assert {MAX_REPEATS, MAX_BEHAVIOR_TURNS, MAX_MICROSTEPS, MAX_BEHAVIOR_DEPTH, MAX_EXPR_DEPTH,
            int(MAX_DURATION // 86400), MAX_INT_DIGITS} <= stated, stated
