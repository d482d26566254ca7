"""The import rules of docs/architecture.md, checked on the source: who may import whom, where the I/O
libraries may appear, and that no module reads another's private names."""

from __future__ import annotations

import ast
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import NamedTuple

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("drd", "dsl", "components")


def modules() -> Iterator[tuple[str, ast.Module]]:
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
            yield name, ast.parse(path.read_text(encoding="utf-8"), str(path))


def imports(nodes: Iterable[ast.AST], module: str) -> Iterator[tuple[str, list[str]]]:
    """Every imported module (absolute, relative ones resolved) with the names taken from it."""
    package = module.split(".")
    for node in nodes:
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, []
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[:len(package) - node.level] + ([base] if base else []))
            names = [a.name for a in node.names]
            submodules = [f"{base}.{n}" for n in names if f"{base}.{n}" in KNOWN]
            yield from ((sub, []) for sub in submodules)
            if len(submodules) < len(names):
                yield base, [n for n in names if f"{base}.{n}" not in KNOWN]


KNOWN = {".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
         for package in PACKAGES for p in (ROOT / package).rglob("*.py")}


class Source(NamedTuple):
    """What the checks read of a module: its imports. Only this is kept, not the syntax tree: the trees of every
    module are some 430,000 objects that would slow every garbage collection of the test session that follows (each
    of pytest's five at its end took 0.25 s with them)."""

    imports: list[tuple[str, list[str]]]


def summary(tree: ast.Module, module: str) -> Source:
    return Source(list(imports(ast.walk(tree), module)))


SOURCES = {module: summary(tree, module) for module, tree in modules()}


def under(module: str, *prefixes: str) -> bool:
    return any(module == p or module.startswith(p + ".") for p in prefixes)


def breaches(sources: list[str], forbidden: tuple[str, ...], allowed: tuple[str, ...] = (),
             exempt: tuple[str, ...] = ()) -> list[str]:
    """What the modules under `sources` (but not under `exempt`) import from under `forbidden` (but not under
    `allowed`)."""
    return [f"{m} imports {i}" for m, source in SOURCES.items() if under(m, *sources) and not under(m, *exempt)
            for i, _names in source.imports if under(i, *forbidden) and not under(i, *allowed)]


PURE_CORES = ["drd.rcm", "drd.placement", "drd.trader", "drd.explain", "drd.inject", "drd.tracecheck"]
IO_LIBRARIES = ("zenoh", "rich", "typer", "psutil", "pymunk")

EVERYTHING = list(PACKAGES)

# (rule, modules under, except those under, may not import from under, except from under)
RULES: list[tuple[str, list[str], tuple[str, ...], tuple[str, ...], tuple[str, ...]]] = [
    ("the error root depends on nothing", ["drd.errors"], (), ("drd", "dsl", "components"), ()),
    ("the language is pure", ["dsl"], (), ("drd", "components", *IO_LIBRARIES), ("drd.errors",)),
    ("decision cores are pure", PURE_CORES, (), ("drd", "components", *IO_LIBRARIES),
     ("drd.errors", "drd.hosts", "drd.config", "drd.manifests", "drd.rcm", "drd.runtime.records")),
    ("the interpreter runs anywhere", ["drd.runtime"], (),
     ("drd.bus", "drd.daemon", "drd.cluster", "drd.cli", "drd.dryrun", "drd.sim"), ()),
    ("cluster execution uses the interpreter's public API", ["drd.cluster"], (), ("drd.daemon", "drd.cli"), ()),
    ("the shells are leaves", EVERYTHING, ("drd.cli", "drd.daemon"), ("drd.cli", "drd.daemon"), ()),
    ("the daemon does not use the CLI", ["drd.daemon"], (), ("drd.cli",), ()),
    ("one place prints", EVERYTHING, ("drd.cli",), ("rich", "typer"), ()),
    ("one transport seam", EVERYTHING, ("drd.bus",), ("zenoh",), ()),
    ("components are plug-ins", ["components"], (), ("drd", "dsl"),
     ("drd.errors", "drd.runtime", "drd.hw", "drd.sim", "drd.hosts", "drd.bus.ros2")),
]


@pytest.mark.parametrize(("rule", "sources", "exempt", "forbidden", "allowed"), RULES, ids=[r[0] for r in RULES])
def test_import_rule(rule: str, sources: list[str], exempt: tuple[str, ...], forbidden: tuple[str, ...],
                     allowed: tuple[str, ...]) -> None:
    assert breaches(sources, forbidden, allowed, exempt) == [], rule


def test_no_module_imports_another_modules_private_names() -> None:
    found = [f"{m} imports {name} from {i}" for m, source in SOURCES.items() for i, names in source.imports
             for name in names if name.startswith("_") and not name.startswith("__") and i != m]
    assert found == []


def test_the_rules_are_checked_on_real_modules() -> None:
    """The checker sees the tree (a wrong root would make every rule pass vacuously)."""
    assert len(SOURCES) > 80 and "drd.runtime.interpreter" in SOURCES and "dsl.parser" in SOURCES
    assert breaches(["drd.cli.missionctl"], ("typer",)) != []  # it does import typer: the checker would see a breach


#: Functions still over the limit, as `file:function`, each with why (none since the msgspec bus codec, #14).
LONG_FUNCTIONS: set[str] = set()
MAX_FUNCTION_LINES = 60
#: Where the limit holds: the product packages, the benchmarks and the tests alike.
LENGTH_CHECKED = (*PACKAGES, "bench", "tests")


def function_lengths() -> Iterator[tuple[str, str, int]]:
    """(file, function, lines) of every function and method under LENGTH_CHECKED. Each tree is dropped once read
    (see Source)."""
    for folder in LENGTH_CHECKED:
        for path in sorted((ROOT / folder).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
            file = path.relative_to(ROOT).as_posix()
            yield from ((file, node.name, (node.end_lineno or node.lineno) - node.lineno + 1)
                        for node in ast.walk(tree) if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef))


def test_no_function_is_over_60_lines() -> None:
    lengths = list(function_lengths())
    assert {file.split("/", 1)[0] for file, _name, _lines in lengths} == set(LENGTH_CHECKED)  # no folder missed
    long = [f"{file}:{name}:{lines} lines" for file, name, lines in lengths
            if lines > MAX_FUNCTION_LINES and f"{file}:{name}" not in LONG_FUNCTIONS]
    assert long == []


def test_every_test_module_is_in_the_folder_of_its_kind() -> None:
    """tests/unit holds what is pure and runs in seconds, tests/integration what runs in process but a lot (a whole
    dry-run, the executive, ROS 2 over loopback zenoh, the compiler's cost counted), tests/properties the property
    tests, tests/e2e what starts processes (`tests/conftest.kind_of` reads it from the module's source): a module in
    the wrong folder would run in the wrong set."""
    from tests.conftest import KINDS, kind_of

    tests = ROOT / "tests"
    misplaced = [f"{p.relative_to(tests)} is {kind_of(p)}" for kind in KINDS
                 for p in sorted((tests / kind).glob("test_*.py")) if kind_of(p) != kind]
    assert misplaced == []
    assert not list(tests.glob("test_*.py")), "a test module outside the folders of tests/conftest.KINDS"
    assert [p.name for p in tests.glob("*/test_*.py") if p.parent.name not in KINDS] == []


def test_test_modules_have_distinct_names_across_the_folders() -> None:
    """pytest imports test modules by their base name (the folders are no packages): two `test_x.py` in two folders
    run alone, but `pytest` of the whole tree stops at collection (`import file mismatch`)."""
    names = [p.name for p in (ROOT / "tests").glob("*/test_*.py")]
    assert sorted({n for n in names if names.count(n) > 1}) == []


@pytest.mark.parametrize(("source", "kind"), [
    ("from drd.dryrun import DryRun, run\n", "integration"),
    ("from drd.dryrun import Mission, run_many\n", "integration"),
    ("from drd import dryrun\n", "integration"),
    ("from drd.executive import EntryPoints, Executive\n", "integration"),
    ("from tests.ros2_support import eventually\n", "integration"),
    ("import tracemalloc\n", "integration"),
    ("from drd.dryrun import SimulationClock\nfrom drd.executive import EntryPoints\n", "unit"),
    ("# a dry-run is described here, drd.dryrun.run is not imported\nimport sys\n", "unit"),
    # the words split, so that this module's own source does not read as e2e or properties
    ("from etcd" "_support import etcd_cluster\nfrom drd.dryrun import run\n", "e2e"),
    ("from hypo" "thesis import given\nfrom drd.executive import Executive\n", "properties"),
])
def test_a_module_s_kind_follows_what_it_imports(source: str, kind: str, tmp_path: Path) -> None:
    """The rule, on modules written for it: a unit module that starts running whole missions moves out of the fast
    set by itself (the test above then names it)."""
    from tests.conftest import kind_of

    module = tmp_path / "test_x.py"
    module.write_text(source)
    assert kind_of(module) == kind
