"""Reading a trace (`drd.tracecheck.read_trace`): a line that is not a record of docs/trace.md is an error at its
line, never a pass or a crash; and docs/trace.md's table, the reader's fields and the records drd writes agree."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import Any

import pytest

from drd.runtime import records as rec
from drd.runtime.trace import trace_line
from drd.tracecheck import KINDS, KINDS_OPTIONAL, TraceError, check, read_trace, record_problem

TRACE_MD = Path(__file__).resolve().parents[2] / "docs" / "trace.md"

#: A value of each field type drd writes, by the dataclass field's annotation.
SAMPLES: dict[str, Any] = {"str": "x", "float": 1.5, "int | None": 3, "bool": True, "tuple[str, ...]": ("a: B",),
                           "dict[str, str]": {"cam": "r1.cam"}, "dict[str, int]": {"r1.cam": 2},
                           "dict[str, Any]": {"area": 0.5},
                           "dict[str, dict[str, str]]": {"Other-1/M/B": {"cam": "r1.cam"}}}


def record_classes() -> dict[str, type[rec.Record]]:
    """Every kind drd.runtime.records writes, from its public names."""
    return {cls.__name__.lower(): cls for cls in vars(rec).values()
            if isinstance(cls, type) and issubclass(cls, rec.Record) and cls is not rec.Record}


def documented_kinds() -> dict[str, set[str]]:
    """docs/trace.md's "Kinds" table: kind -> its fields."""
    table = TRACE_MD.read_text(encoding="utf-8").split("## Kinds", 1)[1].split("\n\n", 2)[1]
    rows = [line.split("|") for line in table.splitlines() if line.startswith("| `")]
    return {row[1].strip(" `"): set(re.findall(r"`([a-z_]+)`", row[2])) for row in rows}


def lines(*texts: str) -> list[bytes]:
    return [t.encode("utf-8") + b"\n" for t in texts]


def test_every_kind_drd_writes_is_documented_with_exactly_its_fields_and_read_with_them() -> None:
    written = {kind: {f.name for f in dataclasses.fields(cls)} - {"at", "path"}
               for kind, cls in record_classes().items()}
    assert "reserved" in written and documented_kinds() == written
    assert {kind: set(KINDS[kind]) | set(KINDS_OPTIONAL.get(kind, {})) for kind in KINDS} == written


def test_every_record_drd_writes_reads_back() -> None:
    written = []
    for cls in record_classes().values():
        values = {f.name: SAMPLES[str(f.type)] for f in dataclasses.fields(cls)}
        written.append(trace_line(cls(**values), "M-1"))
    assert len(read_trace(lines(*written), "t.jsonl")) == len(written)


@pytest.mark.parametrize(("text", "message"), [
    ('{"kind":"granted","at":"x","path":"M","resources":{},"epochs":{}}',
     '`granted` record: `at` is "x", not a number'),
    ('{"kind":"command"}', "`command` record without `at`"),
    ('{"kind":"command","at":1,"path":"M/a","method":"stop","epoch":1,"accepted":true,"reason":""}',
     "`command` record without `device`"),
    ('{"kind":"command","at":1,"path":"M/a","device":"d","method":"stop","epoch":"1","accepted":true,"reason":""}',
     '`epoch` is "1", not an integer or null'),
    ('{"kind":"granted","at":1,"path":"M","resources":{"r":"r1"},"epochs":{"r1":1.5}}',
     "`epochs` is {\"r1\": 1.5}, not an object of integers"),
    ('{"kind":"released","at":1,"path":"M","resources":"r1","reason":"exit"}', "`resources` is \"r1\", not a list"),
    ('{"kind":"entered","at":NaN,"path":"M","state":"M"}', "`at` is NaN, not a number"),
    ('{"kind":"entered","at":1,"path":"M","state":"M","seq":true}', "`seq` is true, not an integer"),
    ('[1, 2]', "a record is a JSON object, not a list"),
    ('{"kind": "command", "at": 1', "not a JSON record: Expecting ',' delimiter (column 28)"),
])
def test_a_line_that_is_not_a_record_is_an_error_at_its_line(text: str, message: str) -> None:
    good = '{"kind":"entered","at":0,"path":"M","state":"M"}'
    with pytest.raises(TraceError, match=re.escape(message)) as e:
        read_trace(lines(good, "", good, text, good), "run.jsonl")
    assert e.value.where == "run.jsonl:4"  # the blank line counts: it is the file's line 4


def test_bytes_that_are_not_utf8_are_an_error_at_their_line() -> None:
    with pytest.raises(TraceError, match="not UTF-8") as e:
        read_trace([b'{"kind":"log","at":0,"path":"M","text":"\xff"}'], "t.jsonl")
    assert e.value.where == "t.jsonl:1"


def test_what_a_newer_or_older_writer_leaves_out_or_adds_is_read() -> None:
    """docs/trace.md "Stability": a kind it does not know (common fields only), a field it does not know, and
    `exited` without its later `reason`."""
    got = read_trace(lines('{"kind":"teleported","at":1,"path":"M/a","to":[1,2]}',
                           '{"kind":"exited","at":2,"path":"M/a","state":"M/a","status":"success","extra":1}'), "t")
    assert [r["kind"] for r in got] == ["teleported", "exited"]
    assert record_problem({"kind": "teleported", "at": 1}) == "record without `path` (its fields: `kind`, `at`, " \
                                                               "`path`; docs/trace.md)"


def test_a_read_trace_is_what_the_checker_counts() -> None:
    """A `command` without its fields once counted as a refused command (a pass): read first, it never gets there."""
    got = read_trace(lines(
        '{"kind":"granted","at":0,"path":"M/a","resources":{"d":"d1"},"epochs":{"d1":1},"mission":"M-1"}',
        '{"kind":"command","at":1,"path":"M/a","device":"d1","method":"stop","epoch":1,"accepted":true,'
        '"reason":"","mission":"M-1"}',
        '{"kind":"released","at":2,"path":"M/a","resources":["d1"],"reason":"exit","mission":"M-1"}'), "t")
    report = check(got)
    assert (report.commands, report.accepted, report.ok) == (1, 1, True)


@pytest.mark.parametrize(("line", "why"), [(b"[" * 100_000 + b"]" * 100_000, "nested too deeply"),
                                           (b'{"seq": ' + b"7" * 5000 + b"}", "4300")],
                         ids=["nesting", "digits"])
def test_a_line_json_takes_but_python_cannot_hold_is_the_files_error_at_its_line(line: bytes, why: str) -> None:
    """Records audit 26, D4: `check-trace` exited 70 (RecursionError, and the 4,300-digit limit's ValueError)."""
    with pytest.raises(TraceError) as e:
        read_trace([b'{"kind": "log", "at": 0, "path": "M", "text": "x"}', line], "t.jsonl")
    said = str(e.value)
    assert e.value.where == "t.jsonl:2" and said.startswith("not a JSON record drd reads") and why in said, said


def test_a_very_long_line_is_cut_to_what_its_lines_show() -> None:
    """Records audit 26, D6: a 10 MB log line was wrapped whole (quadratic in textwrap) before 3 lines were kept."""
    from drd.cli.common import wrap_cut

    assert wrap_cut("x" * 10_000_000, 80, 3) == ["x" * 80, "x" * 80, "x" * 79 + "…"]
    assert wrap_cut("word " * 100, 20, 3) == ["word word word word"] * 2 + ["word word word word…"]
    assert wrap_cut("a b c", 80, 3) == ["a b c"]
