"""Parameter defaults come only from the manifests: no behavior repeats one in code.

The runtime hands a component its parameters with the manifest's defaults applied (the compiled state's
`defaults`, a rig's `Rig.start`), so a behavior reads `ctx.params["speed"]`. A fallback in code
(`params.get("speed", 0.4)`) is a second copy of the default that can drift from the manifest; a value no
manifest declares is no parameter at all (no mission can set it) and belongs in a named module constant.
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

from drd.manifests import load_catalog

ROOT = Path(__file__).resolve().parents[1]


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
