"""Shared fixtures: the standard catalog and the normative examples beside the checkout."""

from __future__ import annotations

import ast
import fnmatch
import functools
import sys
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

import pytest

from drd.manifests import load_catalog
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parents[1]
SHARED_EXAMPLES = ROOT.parent / "shared" / "examples"


#: What makes a test module end-to-end: it starts real processes (the CLI, daemons, workers, etcd).
_E2E = ("subprocess", "cluster_support", "MISSIONCTL", "Popen", "WorkerPool", "etcd_support")

#: What makes an in-process test module an integration test, by what it imports (patterns of `module` or
#: `module.name`): it runs a whole mission or robot through time (a dry-run, the executive), opens a real transport
#: (ROS 2 over loopback zenoh), or measures the compiler's cost with an instrument that slows every line it watches.
_INTEGRATION = ("drd.dryrun", "drd.dryrun.run", "drd.dryrun.run_many", "drd.executive", "drd.executive.Executive",
                "tests.ros2_support*", "tracemalloc", "tests.runtime_support.traced_dry_run")


def _imported(tree: ast.Module) -> set[str]:
    """Every module imported whole (`import a.b`, `from a import b`: `a.b`), every `module.name` taken from one."""
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return found


@functools.cache
def kind_of(path: Path) -> str:
    """`e2e`, `properties`, `integration` or `unit`, from what the test module uses (its source, read once)."""
    source = path.read_text(encoding="utf-8")
    if any(word in source for word in _E2E):
        return "e2e"
    if "hypothesis" in source:
        return "properties"
    imported = _imported(ast.parse(source, str(path)))
    runs_a_lot = any(fnmatch.fnmatchcase(name, pattern) for name in imported for pattern in _INTEGRATION)
    return "integration" if runs_a_lot else "unit"


#: The folders of tests/, one per kind: `pytest tests/unit` (or `-m unit`) runs the fast set (pure, in process, a
#: few seconds); `tests/integration` the in-process runs of whole missions, robots over ROS 2, cost measurements.
KINDS = ("unit", "integration", "properties", "e2e")


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


def lines_executed(call: Callable[[], object]) -> int:
    """The Python lines (and calls) `call` executes: a measure of work that a busy machine does not change (the cost
    tests compare two input sizes by it; no timing in tests)."""
    count = 0

    def tracer(frame: FrameType, event: str, arg: Any) -> Any:
        nonlocal count
        count += 1
        return tracer

    sys.settrace(tracer)
    try:
        call()
    finally:
        sys.settrace(None)
    return count
