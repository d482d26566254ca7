"""What every configuration file shares: problems named by file, line and key path.

Manifests and `hosts.yaml` are checked the same way: every problem is collected, then
raised once, so a broken configuration is fixed in one pass.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass


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


def join_key(prefix: str, key: str) -> str:
    """`params` + `speed` -> `params.speed`; an empty prefix adds nothing."""
    return f"{prefix}.{key}" if prefix else key
