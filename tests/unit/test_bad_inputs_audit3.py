"""Robustness audit 3 (bad input), the pure parts: --param values by the language's literal limits (D10), the
DRD_WORKERS range (D4), a malformed zenoh endpoint as a BusError (D3), the controller's rendered diagnostics read
back into `validate --json`'s shape (D5), config files that are not text (D11) and YAML 1.2 exponent floats (D11).
Each fails on the code before the fix."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from drd.bus import BusError
from drd.bus.zenoh_bus import make_config
from drd.cli.cluster import located
from drd.cluster.creator import MAX_WORKERS, pool_size
from drd.cluster.workers import DEFAULT_SIZE
from drd.config import load_yaml
from drd.hosts import HostsError, load_endpoints
from dsl import compile_text
from dsl.catalog import Catalog
from dsl.errors import Diagnostic, Span
from dsl.params import ParamError, apply_params
from dsl.statechart import Statechart

PARAMS = """mission P {
    var n: int = 1
    var f: float = 0.5
    var d: duration = 1s
    Wait(duration: d)
}
"""


def chart(catalog: Catalog) -> Statechart:
    result = compile_text(PARAMS, catalog, "p.mission")
    assert result.statechart is not None
    return result.statechart


@pytest.mark.parametrize(("param", "why"), [
    ("f=nan", "not a number"), ("f=inf", "too large (at most 1e+15)"), ("f=1e400", "too large (at most 1e+15)"),
    ("f=-2e15", "too large"), ("n=1234567890123456789", "19 digits, at most 18"),
    ("n=-99999999999999999999999999999999999999", "38 digits"), ("d=999999999h", "at most 365 days")])
def test_a_param_beyond_the_language_s_literal_limits_is_refused(param: str, why: str, catalog: Catalog) -> None:
    name, _, value = param.partition("=")
    with pytest.raises(ParamError) as e:
        apply_params(chart(catalog), {name: value})
    assert str(e.value).startswith(f"--param {param}: ") and why in str(e.value)


def test_a_param_within_the_limits_is_taken(catalog: Catalog) -> None:
    out = apply_params(chart(catalog), {"f": "1e15", "n": "-123456789012345678", "d": "8760h"})
    values = {v.name: getattr(v.value, "value", getattr(v.value, "seconds", None))
              for v in out.states[out.root].vars}
    assert values == {"n": -123456789012345678, "f": 1e15, "d": 365 * 86400.0}


@pytest.mark.parametrize("text", ["-1", "65", "100000", " -3 "])
def test_drd_workers_out_of_range_warns_and_uses_the_default(text: str, monkeypatch: pytest.MonkeyPatch,
                                                               caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setenv("DRD_WORKERS", text)
    with caplog.at_level(logging.WARNING, "drd.cluster.creator"):
        assert pool_size(None) == DEFAULT_SIZE
    assert f"out of range (0 to {MAX_WORKERS} idle workers)" in caplog.text


@pytest.mark.parametrize(("text", "size"), [("0", 0), ("64", 64), ("5", 5), ("", DEFAULT_SIZE)])
def test_drd_workers_in_range_is_taken(text: str, size: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DRD_WORKERS", text)
    assert pool_size(None) == size
    assert pool_size(7) == 7  # an explicit size is the caller's


def test_a_malformed_endpoint_is_a_bus_error_without_rust_paths() -> None:
    with pytest.raises(BusError) as e:
        make_config(connect=["garbage"])
    assert "connect/endpoints" in str(e.value) and "garbage" in str(e.value) and ".rs:" not in str(e.value)


def test_a_rendered_diagnostic_reads_back_as_validate_json_says_it() -> None:
    d = Diagnostic("syntax", "expected a state", Span("dir:a/m.mission", 5, 22, 5, 23), hint="write one",
                   notes=(("declared here", Span("dir:a/m.mission", 2, 3, 2, 4)),))
    whole = d.to_dict()
    got = located(d.render({"dir:a/m.mission": "a\nb\nc\nd\n    x -> 1\n"}))
    assert got == {k: whole[k] for k in ("severity", "message", "file", "line", "column", "hint", "notes")}
    assert located("--param f=nan: not a number") == {"severity": "error", "message": "--param f=nan: not a number",
                                                       "hint": None, "notes": []}


@pytest.mark.parametrize(("data", "line", "what"), [
    (b"cluster:\n  name: x\n  world: caf\xe9\n", 3, "not UTF-8 text (byte 0xe9) at column 13"),
    (b"cluster:\n  name: x\x00\n", 2, "a NUL byte at column 10")])
def test_a_config_file_that_is_not_text_names_its_line(data: bytes, line: int, what: str, tmp_path: Path) -> None:
    path = tmp_path / "hosts.yaml"
    path.write_bytes(data)
    with pytest.raises(HostsError) as e:
        load_endpoints(path)
    assert f"hosts.yaml:{line}: {what}" in str(e.value) and "position" not in str(e.value)


def test_an_exponent_without_a_dot_is_a_float_as_in_yaml_1_2() -> None:
    assert load_yaml("a: 1e300\nb: -2E-3\nc: 1_0e2\nd: '1e3'\ne: v1e3\nf: 12\n") == {
        "a": 1e300, "b": -0.002, "c": 1000.0, "d": "1e3", "e": "v1e3", "f": 12}
