"""Shared fixtures: the standard catalog and the normative examples beside the checkout."""

from __future__ import annotations

import functools
from pathlib import Path

import pytest

from drd.manifests import load_catalog
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parents[1]
SHARED_EXAMPLES = ROOT.parent / "shared" / "examples"


#: What makes a test module end-to-end: it starts real processes (the CLI, daemons, workers).
_E2E = ("subprocess", "cluster_support", "MISSIONCTL", "Popen", "WorkerPool")


@functools.cache
def kind_of(path: Path) -> str:
    """`e2e`, `properties` or `unit`, from what the test module uses (its source, read once)."""
    source = path.read_text(encoding="utf-8")
    if any(word in source for word in _E2E):
        return "e2e"
    return "properties" if "hypothesis" in source else "unit"


#: The folders of tests/, one per kind: `pytest tests/unit` (or `-m unit`) runs the fast set.
KINDS = ("unit", "properties", "e2e")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark every test by its folder's kind (`kind_of` for a module outside them): `pytest -m unit` runs the fast
    set, `-m "not e2e"` skips processes."""
    for item in items:
        path = Path(str(item.path))
        kind = path.parent.name if path.parent.name in KINDS else kind_of(path)
        item.add_marker(getattr(pytest.mark, kind))


@pytest.fixture(scope="session")
def catalog() -> Catalog:
    return load_catalog()


def shared_examples() -> Path:
    """The normative examples folder, or a skip that says where it was looked for."""
    if not SHARED_EXAMPLES.is_dir():
        pytest.skip(f"normative examples not found at {SHARED_EXAMPLES} (the shared/ folder beside the checkout)")
    return SHARED_EXAMPLES
