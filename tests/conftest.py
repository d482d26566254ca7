"""Shared fixtures: the standard catalog and the normative examples beside the checkout."""

from __future__ import annotations

from pathlib import Path

import pytest

from drd.manifests import load_catalog
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parents[1]
SHARED_EXAMPLES = ROOT.parent / "shared" / "examples"


@pytest.fixture(scope="session")
def catalog() -> Catalog:
    return load_catalog()


def shared_examples() -> Path:
    """The normative examples folder, or a skip that says where it was looked for."""
    if not SHARED_EXAMPLES.is_dir():
        pytest.skip(f"normative examples not found at {SHARED_EXAMPLES} (the shared/ folder beside the checkout)")
    return SHARED_EXAMPLES
