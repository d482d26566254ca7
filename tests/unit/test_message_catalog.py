"""Message registration in one place (issue #14): every module that defines a bus message is in
`drd.bus.catalog.MESSAGE_MODULES`, so a decoder knows every drd message whatever its process imported."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import drd
from drd.bus import catalog
from drd.bus.messages import MalformedMessage, decode, registered

ROOT = Path(drd.__file__).parent


def _defines_a_message(tree: ast.Module) -> list[tuple[str, int]]:
    """The (type, version) of each `@message("type", version)` class of a module, read from its source."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.ClassDef):
            continue
        for deco in node.decorator_list:
            if isinstance(deco, ast.Call) and getattr(deco.func, "id", None) == "message":
                args = [a.value for a in deco.args if isinstance(a, ast.Constant)]
                found.append((str(args[0]), int(args[1]) if len(args) > 1 else 1))
    return found


@functools.cache
def _message_modules() -> dict[str, list[tuple[str, int]]]:
    """Read once for both tests below (parsing drd costs about 0.4 s); only the findings are kept, not the trees."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        text = path.read_text()
        if "message" not in text:  # no `@message(...)` without the word: half of drd need not be parsed
            continue
        defined = _defines_a_message(ast.parse(text, str(path)))
        if defined:
            parts = path.relative_to(ROOT.parent).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = defined
    return out


def test_every_module_that_defines_a_message_is_in_the_catalog() -> None:
    modules = _message_modules()
    assert len(modules) >= 8  # the scan finds them (a broken scan would pass the next line with nothing)
    assert sorted(modules) == sorted(catalog.MESSAGE_MODULES)


def test_the_catalog_registers_every_message_the_source_defines() -> None:
    defined = {pair for pairs in _message_modules().values() for pair in pairs}
    assert defined <= set(registered())
    assert any(t == "drd.daemon.trader-request" for t, _ in defined)  # a message far from the bus package


def test_an_unknown_type_is_still_refused_after_the_catalog_is_loaded() -> None:
    try:
        decode(b'{"v":1,"type":"drd.no-such-message","body":{}}')
    except MalformedMessage as refused:
        assert refused.reason == "unknown message type 'drd.no-such-message'"
    else:
        raise AssertionError("an unknown type decoded")
