"""Docs are tests: every ```mission block in docs/ compiles, every ```mission-invalid block fails."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from dsl import compile_text
from dsl.catalog import Catalog

DOCS = Path(__file__).resolve().parents[1] / "docs"
BLOCK = re.compile(r"```(mission(?:-invalid)?)\n(.*?)```", re.S)


def _blocks() -> list[tuple[str, str, str]]:
    out = []
    for path in sorted(DOCS.glob("*.md")):
        for i, m in enumerate(BLOCK.finditer(path.read_text(encoding="utf-8"))):
            out.append((f"{path.name}#{i}", m[1], m[2]))
    return out


def test_the_tutorial_has_examples() -> None:
    kinds = {kind for _, kind, _ in _blocks()}
    assert kinds == {"mission", "mission-invalid"}


@pytest.mark.parametrize(("where", "kind", "text"), _blocks(), ids=[b[0] for b in _blocks()])
def test_doc_snippet(where: str, kind: str, text: str, catalog: Catalog) -> None:
    result = compile_text(text, catalog, where)
    if kind == "mission":
        assert result.ok, "\n".join(d.render(result.sources) for d in result.diagnostics)
    else:
        assert not result.ok and result.diagnostics
