"""The one loader of `package.module:Name` entry points (components' and drivers' classes, from manifests).

Everything that turns a manifest's `entry_point` into a class comes here, so the format is checked one way and
a failure says which of the three things went wrong: the module is not there, it is there but its own import
failed (`MissingDependency` when what it imports is not installed), or it has no such name.
"""

from __future__ import annotations

import importlib
import re
import traceback
from typing import Any

from drd.errors import ComponentFailure, shown_path

#: `package.module:Name` (what a manifest's `entry_point` must look like).
ENTRY_POINT = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*", re.ASCII)


class EntryPointError(ComponentFailure):
    """An entry point cannot be loaded; the message says whether the module is missing, broken, or lacks the
    name."""


class MissingDependency(EntryPointError):
    """The entry point's module is there but imports one that is not installed (`dependency`): a host without a
    library a component needs, which is not a mistake in its manifest (`drd start` then does not offer it)."""

    def __init__(self, message: str, dependency: str) -> None:
        super().__init__(message)
        self.dependency = dependency


def split(entry: str) -> tuple[str, str]:
    """`package.module:Name` -> (`package.module`, `Name`), or EntryPointError for anything else."""
    if not ENTRY_POINT.fullmatch(entry):
        raise EntryPointError(f"expected 'package.module:Name', got {entry!r}")
    module, _, name = entry.partition(":")
    return module, name


def load(entry: str) -> Any:
    """Import the module of `entry` (once: Python caches it) and return its attribute."""
    module_name, name = split(entry)
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        if e.name is None:
            raise EntryPointError(f"module {module_name} failed to import: {e}") from e
        if module_name == e.name or module_name.startswith(e.name + "."):  # the module itself, not one of its imports
            raise EntryPointError(f"no module {module_name} (for {entry})") from e
        if e.name.partition(".")[0] == module_name.partition(".")[0]:  # a module of its own package: broken
            raise EntryPointError(f"module {module_name} failed to import: {e}") from e
        raise MissingDependency(f"module {module_name} failed to import: {e}", e.name) from e
    except SyntaxError as e:  # where, as a mission's error says it: file:line:column, and the line
        raise EntryPointError(f"module {module_name} failed to import: {located(e)}") from e
    except Exception as e:  # a module that raises at import is broken, not missing
        raise EntryPointError(f"module {module_name} failed to import: {type(e).__name__}: {e}{where(e)}") from e
    try:
        return getattr(module, name)
    except AttributeError:
        raise EntryPointError(f"module {module_name} has no {name} (for {entry})") from None


def located(e: SyntaxError) -> str:
    """A syntax error of a component's module as `path:line:column: SyntaxError: message`, and the line it is in:
    `(fuse.py, line 5)` named neither the folder nor the column (users audit 18, #5). One line: a configuration
    error's renderer prefixes every line."""
    head = f"{shown_path(e.filename or '?')}:{e.lineno or 0}:{e.offset or 0}: {type(e).__name__}: {e.msg}"
    line = (e.text or "").strip()
    return f"{head}, in `{line}`" if line else head


def where(e: BaseException) -> str:
    """` (at path:line)`: the innermost frame of the module that raised at import, so the author finds the line."""
    frames = [f for f in traceback.extract_tb(e.__traceback__) if "importlib" not in f.filename]
    return f" (at {shown_path(frames[-1].filename)}:{frames[-1].lineno})" if frames else ""
