"""`drd.errors.raised`: what a component's exception says, in a dry-run and on a cluster alike (newcomer audit 2:
the file and line were lost everywhere, and `DRD_DEBUG=1` showed no traceback)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from drd.errors import logged, raised


def boom() -> None:
    raise ValueError("boom")


def caught() -> ValueError:
    try:
        boom()
    except ValueError as e:
        return e
    raise AssertionError("boom() did not raise")


def test_it_names_the_line_that_raised(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DRD_DEBUG", raising=False)
    text = raised(caught())
    assert re.fullmatch(r"component raised ValueError: boom \(at \S*test_component_raised\.py:\d+, in boom\)", text)
    line = int(text.rsplit(":", 1)[1].split(",")[0])
    assert Path(__file__).read_text().splitlines()[line - 1].strip() == 'raise ValueError("boom")'
    assert raised(ValueError("never raised")) == "component raised ValueError: never raised"
    assert logged(caught()) == text, "no traceback without DRD_DEBUG"


def test_with_drd_debug_the_log_line_has_the_whole_traceback_and_the_reason_stays_one_line(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Re-verification: the traceback was printed three times (the headline, why it failed, the log), the
    controller's log flattening it into one line."""
    monkeypatch.setenv("DRD_DEBUG", "1")
    assert "\n" not in raised(caught())
    lines = logged(caught(), " in shutdown").splitlines()
    assert lines[0].startswith("component raised ValueError in shutdown: boom (at ")
    assert lines[1] == "Traceback (most recent call last):" and lines[-1] == "ValueError: boom"
    assert any("in caught" in line for line in lines)


def decodes_garbage() -> None:
    from drd.bus.messages import decode

    decode(b"not a message")  # drd raises, inside: this is the component's line


def parses_garbage() -> None:
    import json

    json.loads("{")  # the standard library raises, inside: this is the component's line


def test_it_names_the_components_own_line_not_drds_or_the_standard_librarys() -> None:
    """Own-world audit D3: a mistyped device method was located in drd's device proxy (`ownership.py`), an
    undeclared event in `emits.py`: the author's line was never named."""
    for call in (decodes_garbage, parses_garbage):
        try:
            call()
        except Exception as e:
            text = raised(e)
        else:
            raise AssertionError(f"{call.__name__} did not raise")
        assert re.search(rf"\(at \S*test_component_raised\.py:\d+, in {call.__name__}\)$", text), text
        line = int(text.rsplit(":", 1)[1].split(",")[0])
        assert Path(__file__).read_text().splitlines()[line - 1].endswith("this is the component's line")
