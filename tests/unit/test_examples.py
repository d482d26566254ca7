"""Conformance: every file in ../shared/examples validates; every invalid one fails as its comment says.

An invalid example's first line reads `# error: MESSAGE (line N[, more])` or
`(lines A/B/C)`: the checker must report exactly MESSAGE at one of those lines, and any
extra words in the parenthesis (a did-you-mean) must appear in the rendered output.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import SHARED_EXAMPLES, shared_examples

HEADER = re.compile(r"#\s*error:\s*(?P<message>.*?)\s*\((?P<where>lines?\s+[\d/]+)(?:,\s*(?P<extra>.*))?\)\s*$")


def _files(pattern: str) -> list[Path]:
    return sorted(SHARED_EXAMPLES.glob(pattern)) if SHARED_EXAMPLES.is_dir() else []


def test_examples_folder_is_present() -> None:
    folder = shared_examples()
    assert list(folder.glob("*.mission")), f"no examples in {folder}"
    assert list(folder.glob("invalid/*.mission")), f"no invalid examples in {folder}"


@pytest.mark.parametrize("path", _files("*.mission"), ids=lambda p: p.name)
def test_valid_example_compiles(path: Path, catalog: Catalog) -> None:
    result = compile_file(path, catalog)
    assert result.ok, "\n".join(d.render(result.sources) for d in result.diagnostics)
    assert result.statechart is not None
    assert result.statechart.leaves(), "a mission with no elementary behavior cannot run"


@pytest.mark.parametrize("path", _files("invalid/*.mission"), ids=lambda p: p.name)
def test_invalid_example_is_rejected_as_its_comment_says(path: Path, catalog: Catalog) -> None:
    header = path.read_text(encoding="utf-8").splitlines()[0]
    m = HEADER.match(header)
    assert m, f"{path.name}: first line is not `# error: MESSAGE (line N)`: {header!r}"
    lines = {int(x) for x in re.findall(r"\d+", m["where"])}
    result = compile_file(path, catalog)
    assert not result.ok
    matching = [d for d in result.diagnostics if d.message == m["message"]]
    assert matching, f"expected {m['message']!r}; got {[d.message for d in result.diagnostics]}"
    assert any(d.span.line in lines for d in matching), (
        f"{m['message']!r} reported at line {[d.span.line for d in matching]}, expected one of {sorted(lines)}")
    if m["extra"]:
        rendered = "\n".join(d.render(result.sources) for d in matching)
        assert m["extra"] in rendered
