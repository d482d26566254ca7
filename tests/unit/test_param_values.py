"""One parameter checker (issue #14): the Load Balancer's `check_params` and the mission checker judge a value by
the same rule (`dsl.param_values`), so a value the compiler refuses is not placed either, and the other way round."""

from __future__ import annotations

import pytest

from drd.manifests import load_catalog
from drd.placement import check_params
from dsl import compile_text
from dsl.catalog import ComponentType

CATALOG = load_catalog()


def typed(name: str) -> ComponentType:
    found = CATALOG.get(name)
    assert found is not None, name
    return found

# component, parameter, value as a Python value, the same as the mission language writes it, refused?
CASES = [
    ("FollowCorridor", "speed", 0.3, "0.3", False),
    ("FollowCorridor", "speed", 50, "50", True),
    ("FollowCorridor", "speed", -1.0, "-1.0", True),
    ("Wait", "duration", 5.0, "5s", False),
    ("Wait", "duration", -5.0, "-5s", True),
    ("Wait", "duration", 360000.0, "100h", True),
    ("Calibrate", "samples", 10, "10", False),
    ("Calibrate", "samples", -3, "-3", True),
]


def compiled_errors(component: str, param: str, literal: str) -> list[str]:
    needs = "" if component == "Wait" else "    needs ranger: Ranger\n"
    source = f"mission M {{\n{needs}    {component}({param}: {literal})\n}}\n"
    result = compile_text(source, CATALOG, "m.mission")
    return [d.message for d in result.diagnostics if d.severity == "error"]


@pytest.mark.parametrize(("component", "param", "value", "literal", "refused"), CASES)
def test_the_checker_and_the_load_balancer_agree(component: str, param: str, value: object, literal: str,
                                                 refused: bool) -> None:
    placed = check_params(typed(component), {param: value})
    compiled = compiled_errors(component, param, literal)
    assert bool(placed) == bool(compiled) == refused, (placed, compiled)


def test_the_load_balancer_names_the_rule_it_applied() -> None:
    assert check_params(typed("FollowCorridor"), {"speed": 50}) == ["parameter speed 50 is out of range: 0..2 m/s"]
    assert check_params(typed("Wait"), {"duration": -5}) == ["parameter duration a duration cannot be negative (-5 s)"]
    assert check_params(typed("FollowCorridor"), {"speed": float("inf")}) == [
        "parameter speed inf is not a finite number (expected 0..2 m/s)"]
    assert check_params(typed("Calibrate"), {"samples": 2.0}) == ["parameter samples expects int, got float 2.0"]
    assert check_params(typed("Calibrate"), {"samples": True}) == ["parameter samples expects int, got bool True"]
