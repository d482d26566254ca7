"""What the behaviors' sources may not do: repeat a manifest's parameter default, or keep state in their module.

The runtime hands a component its parameters with the manifest's defaults applied (the compiled state's
`defaults`, a rig's `Rig.start`), so a behavior reads `ctx.params["speed"]`. A fallback in code
(`params.get("speed", 0.4)`) is a second copy of the default that can drift from the manifest; a value no
manifest declares is no parameter at all (no mission can set it) and belongs in a named module constant.

A dict, a list or an `lru_cache` at module (or class) level outlives the component instance and the mission that
filled it: state belongs to the instance (`ScanMemo`), a constant mapping is read-only (`MappingProxyType`).
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

import pytest

from drd.manifests import load_catalog

ROOT = Path(__file__).resolve().parents[2]


def behavior_modules() -> dict[Path, set[str]]:
    """Each behavior module under components/behaviors, with the parameters its manifests declare."""
    out: dict[Path, set[str]] = {}
    for ct in load_catalog().components.values():
        if not ct.entry_point or not ct.entry_point.startswith("components.behaviors."):
            continue
        spec = importlib.util.find_spec(ct.entry_point.partition(":")[0])
        assert spec is not None and spec.origin is not None, ct.entry_point
        out.setdefault(Path(spec.origin), set()).update(p.name for p in ct.params)
    return out


def _params_names(tree: ast.AST) -> set[str]:
    """The names bound to a component's parameters (`p = self.ctx.params`), and `params` itself."""
    names = {"params"}
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Attribute) and node.value.attr == "params":
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
    return names


def _is_params(node: ast.expr, aliases: set[str]) -> bool:
    return (isinstance(node, ast.Attribute) and node.attr == "params") or (
        isinstance(node, ast.Name) and node.id in aliases)


def _key(node: ast.expr) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def repeated_defaults(source: str, declared: set[str]) -> list[str]:
    """What in `source` reads a parameter other than as its manifest says: a `.get` with a fallback on the
    parameters (or of a declared parameter's name, on anything), or a subscript of an undeclared one."""
    tree = ast.parse(source)
    aliases = _params_names(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get" \
                and len(node.args) + len(node.keywords) >= 2 and node.args:
            key = _key(node.args[0])
            if _is_params(node.func.value, aliases) or key in declared:
                found.append(f"line {node.lineno}: {ast.unparse(node)} repeats a default in code")
        elif isinstance(node, ast.Subscript) and _is_params(node.value, aliases):
            key = _key(node.slice)
            if key is not None and key not in declared:
                found.append(f"line {node.lineno}: {ast.unparse(node)} reads a parameter no manifest declares")
    return found


def test_no_behavior_repeats_a_manifest_default() -> None:
    modules = behavior_modules()
    assert len(modules) >= 12, "every standard behavior is checked"
    found = {str(path.relative_to(ROOT)): bad for path, declared in sorted(modules.items())
             if (bad := repeated_defaults(path.read_text(encoding="utf-8"), declared))}
    assert found == {}


def test_every_behavior_parameter_has_its_default_in_the_manifest() -> None:
    """What `ctx.params[name]` relies on: every parameter a behavior declares has a default to apply."""
    for ct in load_catalog().components.values():
        if ct.entry_point and ct.entry_point.startswith("components.behaviors."):
            assert all(not p.required and p.default is not None for p in ct.params), ct.name


def test_the_check_finds_what_it_forbids() -> None:
    declared = {"speed"}
    assert repeated_defaults('v = float(self.ctx.params.get("speed", 0.4))', declared)
    assert repeated_defaults('p = self.ctx.params\nn = int(p.get("n_regions", 16))', declared)
    assert repeated_defaults('v = options.get("speed", 0.5)', declared)  # a declared name, on anything
    assert repeated_defaults('n = int(self.ctx.params["n_regions"])', declared)  # no manifest declares it
    assert repeated_defaults('v = float(self.ctx.params["speed"])', declared) == []
    assert repeated_defaults('h = self.ctx.params.get("heading")\nd = self.ctx.services.get("x")', declared) == []


#: Calls that make a mutable container, and decorators that keep results between calls.
MUTABLE_CALLS = {"dict", "list", "set", "defaultdict", "OrderedDict", "Counter", "deque", "WeakKeyDictionary",
                 "WeakValueDictionary", "bytearray"}
CACHES = {"lru_cache", "cache", "cached_property"}


def _name(node: ast.expr) -> str:
    node = node.func if isinstance(node, ast.Call) else node
    return node.attr if isinstance(node, ast.Attribute) else node.id if isinstance(node, ast.Name) else ""


def _mutable(value: ast.expr | None) -> bool:
    return isinstance(value, ast.Dict | ast.List | ast.Set | ast.DictComp | ast.ListComp | ast.SetComp) or (
        isinstance(value, ast.Call) and _name(value) in MUTABLE_CALLS)


def module_state(source: str) -> list[str]:
    """Where `source` keeps state beyond an instance: mutable containers bound at module or class level, caching
    decorators, `global` statements."""
    tree = ast.parse(source)
    found = []
    bodies = [tree.body] + [n.body for n in ast.walk(tree) if isinstance(n, ast.ClassDef)]
    for stmt in (s for body in bodies for s in body):
        if isinstance(stmt, ast.Assign | ast.AnnAssign) and _mutable(stmt.value):
            found.append(f"line {stmt.lineno}: {ast.unparse(stmt)[:80]}")
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            found += [f"line {node.lineno}: {node.name} is cached by @{_name(d)}" for d in node.decorator_list
                      if _name(d) in CACHES]
        elif isinstance(node, ast.Global):
            found.append(f"line {node.lineno}: global {', '.join(node.names)}")
    return found


BEHAVIORS = sorted((ROOT / "components" / "behaviors").glob("*.py"))


@pytest.mark.parametrize("path", BEHAVIORS, ids=[p.stem for p in BEHAVIORS])
def test_no_behavior_module_keeps_state_between_instances(path: Path) -> None:
    assert module_state(path.read_text(encoding="utf-8")) == []


def test_the_state_check_finds_what_it_forbids() -> None:
    assert len(BEHAVIORS) >= 14 and any(p.stem == "scan" for p in BEHAVIORS)
    assert module_state("_DERIVED: dict[int, object] = {}")
    assert module_state("SEEN = set()")
    assert module_state("class C:\n    cache = {}")
    assert module_state("import functools\n@functools.lru_cache(maxsize=8)\ndef f(x): return x")
    assert module_state("def f():\n    global N\n    N = 1")
    assert module_state("K = (1, 2)\nS = frozenset({1})\nM = MappingProxyType({1: 2})\n"
                        "def f():\n    seen = {}\n    return seen") == []
