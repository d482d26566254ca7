"""Fuzzing in CI (issue #18), bounded: mutations of every mission the repository ships (and of the normative
examples, where `../shared` is present) and of its hosts file always end in success or located diagnostics, never
an uncaught error, and within a work bound linear in their size (function calls counted, not timed). Hypothesis
shrinks a failure to the smallest mutation that shows it."""

from __future__ import annotations

import sys
import tempfile
import tracemalloc
from pathlib import Path
from types import FrameType
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drd.config import ConfigError
from drd.hosts import load_hosts
from dsl import compile_text
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "examples"
SEEDS = sorted(ROOT.glob("missions/*.mission")) + sorted((ROOT / "tests" / "missions").glob("*.mission")) + sorted(
    SHARED.rglob("*.mission"))
#: Profiler events (calls and returns, Python and C) a compilation may cost: a fixed part and a part per byte. The
#: seeds cost at most 30 a byte; each syntax error costs up to about 50,000 more (its recovery copies the parser
#: state for each token it tries), and recovery stops after 50. So a bound of about 0.4 s of compiling for a small
#: file; `tests/integration/test_costs.py` checks the slope itself on inputs of growing size.
CALLS_FIXED, CALLS_PER_BYTE = 1_000_000, 200
#: Memory a hosts file's load may take at its peak: a fixed part and a part per byte (it is measured at a few KB a
#: byte; an alias that expanded would cost far more).
MEMORY_FIXED, MEMORY_PER_BYTE = 4_000_000, 2_000
PIECES = ["{", "}", "(", ")", "[", "]", ":", ";", "\n", "->", "/", "..", "*", '"', '"{', "}", "0", "-1", "1e999",
          "9" * 30, "mission", "behavior", "needs", "parallel", "plan", "<", "as", "on", "after", "for", "when",
          "quantity", "where", "import", "emit", "log", "set", "release", "start", "done", "fail", "ms", "#", "\t",
          "\x00", "é", "Wait", "Ranger", " "]


@st.composite
def mutations(draw: st.DrawFn, seeds: list[str]) -> str:
    text = draw(st.sampled_from(seeds))
    for _ in range(draw(st.integers(1, 6))):
        at = draw(st.integers(0, len(text)))
        kind = draw(st.sampled_from(["insert", "delete", "duplicate"]))
        if kind == "insert":
            text = text[:at] + draw(st.sampled_from(PIECES)) + text[at:]
        elif kind == "delete":
            text = text[:at] + text[at + draw(st.integers(1, 12)):]
        else:
            end = min(len(text), at + draw(st.integers(1, 40)))
            text = text[:end] + text[at:end] + text[end:]
    return text


MISSIONS = [p.read_text(encoding="utf-8") for p in SEEDS if p.is_file()]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_mutated_mission_compiles_or_is_refused_with_located_errors(data: st.DataObject, catalog: Catalog) -> None:
    text = data.draw(mutations(MISSIONS))
    compile_text(MISSIONS[0], catalog, "warm.mission")  # the parser's tables and the compiler's imports, once
    calls = 0

    def count(frame: FrameType, event: str, arg: Any) -> None:
        nonlocal calls
        calls += 1

    sys.setprofile(count)
    try:
        result = compile_text(text, catalog, "fuzz.mission")  # must not raise
    finally:
        sys.setprofile(None)
    assert calls <= CALLS_FIXED + CALLS_PER_BYTE * len(text), f"{calls} calls for {len(text)} bytes"
    lines = text.split("\n")
    for d in result.diagnostics:
        assert d.span.file == "fuzz.mission" and d.message
        assert 1 <= d.span.line <= len(lines) + 1, (d.span, d.message)
        assert d.span.column >= 1
    assert result.ok or any(d.severity.value == "error" for d in result.diagnostics)


HOSTS = (ROOT / "hosts.yaml").read_text(encoding="utf-8")
YAML_PIECES = [":", " ", "\n", "-", "{", "}", "[", "]", "&a", "*a", "!!python/object:os.system", "'", '"', "#",
               "null", "1e999", "-1", "0", "beams: 1000000000", "slice: 0s", "capacity: -3", "\t", "?", "|"]


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_mutated_hosts_file_loads_or_is_refused_naming_the_file(data: st.DataObject, catalog: Catalog) -> None:
    text = HOSTS
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(text)))
        if data.draw(st.booleans()):
            text = text[:at] + data.draw(st.sampled_from(YAML_PIECES)) + text[at:]
        else:
            text = text[:at] + text[at + data.draw(st.integers(1, 20)):]
    with tempfile.TemporaryDirectory() as folder:  # never in the checkout
        path = Path(folder) / "fuzz-hosts.yaml"
        path.write_text(text, encoding="utf-8")
        tracemalloc.start()
        try:
            load_hosts(path, catalog)  # must not raise anything but a configuration error
        except ConfigError as e:
            assert e.problems and all("fuzz-hosts.yaml" in str(p) for p in e.problems)
        finally:
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
        assert peak <= MEMORY_FIXED + MEMORY_PER_BYTE * len(text), f"{peak} bytes for {len(text)}"
