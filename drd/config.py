"""What every configuration file shares: problems named by file, line and key path.

Manifests and `hosts.yaml` are checked the same way: every problem is collected, then
raised once, so a broken configuration is fixed in one pass.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from dsl.errors import did_you_mean


@dataclass(frozen=True, slots=True)
class ConfigProblem:
    """One problem. `key` is a dotted path such as `params.speed.type` or `hosts.ranger1.devices`."""

    file: str
    key: str
    message: str
    line: int | None = None

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}" if self.line else self.file
        return ": ".join(part for part in (where, self.key, self.message) if part)


class ConfigError(Exception):
    """A configuration has problems; carries all of them."""

    def __init__(self, problems: Iterable[ConfigProblem]) -> None:
        self.problems = tuple(problems)
        super().__init__("\n".join(map(str, self.problems)))

    def __reduce__(self) -> tuple[type[ConfigError], tuple[tuple[ConfigProblem, ...]]]:
        return type(self), (self.problems,)  # picklable, so it can cross a process boundary


class ConfigReader:
    """Base of the configuration readers: collects problems; each typed reader reports and goes on."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.problems: list[ConfigProblem] = []

    def fail(self, key: str, message: str) -> None:
        self.problems.append(ConfigProblem(self.source, key, message))

    # -- how a file's messages are worded (each format keeps its own)

    def describe(self, value: object) -> str:
        """How a wrong value is shown in `got ...`."""
        return repr(value)

    def key_hint(self, key: str, allowed: Sequence[str]) -> str:
        """What follows `unknown key`: ` (did you mean X?)` or nothing."""
        hint = did_you_mean(key, allowed)
        return f" ({hint})" if hint else ""

    # -- readers shared by every format

    def keys(self, data: Mapping[Any, Any], key: str, allowed: Sequence[str], required: Sequence[str] = ()) -> None:
        """Unknown keys and missing required ones, each a problem."""
        for k in data:
            if k not in allowed:
                self.fail(join_key(key, str(k)), f"unknown key{self.key_hint(str(k), allowed)}")
        for k in required:
            if k not in data:
                self.fail(join_key(key, k), "required key missing")

    def mapping(self, value: object, key: str) -> dict[Any, Any]:
        if isinstance(value, dict):
            return value
        self.fail(key, f"expected a mapping, got {self.describe(value)}")
        return {}

    def text(self, value: object, key: str) -> str:
        if isinstance(value, str) and value:
            return value
        self.fail(key, f"expected a non-empty string, got {self.describe(value)}")
        return ""


def join_key(prefix: str, key: str) -> str:
    """`params` + `speed` -> `params.speed`; an empty prefix adds nothing."""
    return f"{prefix}.{key}" if prefix else key
