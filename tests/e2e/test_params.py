"""`--param NAME=VALUE`: a mission's own variables set by the operator (dsl.params), and the CLI around it."""

from __future__ import annotations

import json
import subprocess

import pytest

from drd.manifests import load_catalog
from dsl import ast, compile_text
from dsl.params import ParamError, apply_params, parse_assignments
from tests.conftest import ROOT

SOURCE = """mission Tune {
    var laps: int = 0
    var speed: float = 0.5
    var fast: bool = false
    var label: str = "a"
    var wait: duration = 10s
    FollowCorridor(speed: 0.3)
}
"""


@pytest.fixture(scope="module")
def chart():  # type: ignore[no-untyped-def]
    result = compile_text(SOURCE, load_catalog(), "tune.mission")
    assert result.ok and result.statechart is not None
    return result.statechart


def initial(chart, name):  # type: ignore[no-untyped-def]
    return next(v.value for v in chart.states[chart.root].vars if v.name == name)


def test_each_type_is_read_as_its_variable_declares(chart) -> None:  # type: ignore[no-untyped-def]
    out = apply_params(chart, parse_assignments(["laps=3", "speed = 0.8", "fast=true", "label=b c", "wait=2min"]))
    assert initial(out, "laps") == ast.Literal(3) and initial(out, "speed") == ast.Literal(0.8)
    assert initial(out, "fast") == ast.Literal(True) and initial(out, "label") == ast.Literal("b c")
    assert initial(out, "wait") == ast.Duration(120.0, "2min")
    assert initial(chart, "laps") == ast.Literal(0), "the compiled chart itself is left as it was"


@pytest.mark.parametrize(("texts", "message"), [
    (["lap=1"], "mission Tune has no variable 'lap' to set (did you mean laps?"),
    (["laps=1.5"], "--param laps=1.5: laps is an int, and '1.5' is not one"),
    (["fast=yes"], "fast is a bool, and 'yes' is not one"),
    (["wait=10"], "wait is a duration, and '10' is not one"),
])
def test_a_param_that_does_not_fit_says_why(chart, texts: list[str], message: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ParamError) as e:
        apply_params(chart, parse_assignments(texts))
    assert message in str(e.value)


def test_assignments_are_read_and_every_bad_one_reported() -> None:
    assert parse_assignments(["a=1", " b = x y "]) == {"a": "1", "b": "x y"}
    with pytest.raises(ParamError) as e:
        parse_assignments(["a", "a=1", "a=2", "=3"])
    assert len(str(e.value).splitlines()) == 3


CHOOSE = """mission Choose {
    var ok: bool = false
    Wait(duration: 1s)
    Wait -> done [ok]
    Wait -> fail [not ok]
}
"""


@pytest.mark.parametrize(("args", "code", "outcome"), [((), 1, "failure"), (("--param", "ok=true"), 0, "success")])
def test_dry_run_starts_the_mission_with_the_value_given(tmp_path, args, code: int, outcome: str) -> None:  # type: ignore[no-untyped-def]
    mission = tmp_path / "choose.mission"
    mission.write_text(CHOOSE)
    r = subprocess.run(["missionctl", "dry-run", str(mission), "--json", *args], cwd=ROOT, capture_output=True,
                       text=True, timeout=120, check=False)
    assert r.returncode == code, r.stderr[-2000:]
    assert json.loads(r.stdout)["outcome"] == outcome


def test_a_param_naming_no_variable_is_invalid_input() -> None:
    cmd = ["missionctl", "dry-run", "missions/corridor_surveillance.mission", "--param", "nope=1"]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 2 and "has no variable 'nope' to set" in r.stderr and "Traceback" not in r.stderr
