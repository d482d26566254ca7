"""What every configuration file shares: problems named by file, line and key path.

Manifests and `hosts.yaml` are checked the same way: every problem is collected, then
raised once, so a broken configuration is fixed in one pass.
"""

from __future__ import annotations

import re
import stat
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn, TypeVar

import yaml

from drd.errors import ConfigurationError
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


class ConfigError(ConfigurationError):
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


class StrictLoader(yaml.SafeLoader):
    """A SafeLoader that rejects duplicate keys, which PyYAML would silently overwrite: one YAML dialect for
    every configuration file."""


class _FastStrictLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """`StrictLoader` on libyaml's parser when PyYAML was built with it (a 1,000-robot hosts file: 0.5 s instead
    of 3 s, on every daemon start and `missionctl --config`): the same constructors, so the same data."""


def _construct_mapping(loader: StrictLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    seen: set[Hashable] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node)
        if not isinstance(key, Hashable):
            continue  # SafeLoader reports unhashable keys itself
        if key in seen:
            raise yaml.constructor.ConstructorError(None, None, f"duplicate key {key!r}", key_node.start_mark)
        seen.add(key)
    mapping: dict[Any, Any] = loader.construct_mapping(node)
    return mapping


StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
_FastStrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
#: A number with an exponent and no dot (`1e300`, `-2E-3`) is a float, as YAML 1.2 reads it; PyYAML's YAML 1.1 reads
#: it as the string '1e300', which a number field then refused as "expected a number, got '1e300'" (docs/design.md).
EXPONENT_FLOAT = re.compile(r"^[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+$")
for _loader in (StrictLoader, _FastStrictLoader):
    _loader.add_implicit_resolver("tag:yaml.org,2002:float", EXPONENT_FLOAT, list("-+0123456789"))


def display_path(path: Path, cwd: Path | None = None) -> str:
    """The path as the user sees it: relative to the working directory when inside it."""
    absolute, cwd = path.absolute(), cwd or Path.cwd()
    return (absolute.relative_to(cwd) if absolute.is_relative_to(cwd) else path).as_posix()


E = TypeVar("E", bound=ConfigError)


#: A configuration file larger than this is refused unread (hosts files of 1,000 robots are about 400 KiB).
MAX_CONFIG_BYTES = 4 * 1024 * 1024
#: YAML aliases and nesting a configuration may use: a few anchors are handy, thousands are an attack (each alias
#: is one more reference a checker walks: "billion laughs").
MAX_ALIASES, MAX_DEPTH = 100, 32
#: The most nodes a file may stand for once its aliases are expanded: about what 4 MiB of plain YAML can hold. A
#: billion-laughs file has few aliases (9 levels of 9: 81) and stands for 387 million nodes; every walk of it (a
#: check, a message showing a value) would run out of memory.
MAX_NODES = 1_000_000


def read_config_text(path: Path) -> str:
    """A configuration file's text: a regular file only (a FIFO would block, a device never end), at most
    `MAX_CONFIG_BYTES`. OSError (FileNotFoundError for a missing one) or ValueError saying what is wrong."""
    mode = path.stat().st_mode
    if not stat.S_ISREG(mode):
        raise ValueError("a directory, not a file" if stat.S_ISDIR(mode) else "not a regular file (a FIFO, a device?)")
    with path.open("rb") as fh:
        data = fh.read(MAX_CONFIG_BYTES + 1)
    if len(data) > MAX_CONFIG_BYTES:
        raise ValueError(f"larger than {MAX_CONFIG_BYTES // 2**20} MiB")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise TextError(data, e.start, f"not UTF-8 text (byte 0x{data[e.start]:02x})") from None
    if "\0" in text:  # valid UTF-8 that YAML refuses, with a byte offset for a place
        raise TextError(data, data.index(b"\0"), "a NUL byte")
    return text


class TextError(ConfigurationError, ValueError):
    """A configuration file whose bytes are no text YAML reads (not UTF-8, a NUL byte): its message and `line`
    (1-based) say where, as every other problem of a file does (a byte offset says nothing to a user)."""

    def __init__(self, data: bytes, offset: int, what: str) -> None:
        self.line = data.count(b"\n", 0, offset) + 1
        column = offset - (data.rfind(b"\n", 0, offset) + 1) + 1
        super().__init__(f"{what} at column {column}: save the file as UTF-8 text")


def load_yaml(text: str) -> object:
    """YAML in the one dialect of every configuration file (`StrictLoader`), with aliases, nesting and the size
    the aliases expand to bounded (yaml.YAMLError, with a mark where it can, for anything else). Read with libyaml
    where PyYAML has it; a file it refuses is read again by PyYAML's own parser, so an error says the same words
    on every machine."""
    try:
        return _load_yaml(text, _FastStrictLoader)
    except yaml.YAMLError:
        if _FastStrictLoader.__mro__[1] is yaml.SafeLoader:
            raise
        return _load_yaml(text, StrictLoader)


def _load_yaml(text: str, loader: type[Any]) -> object:
    aliases = 0
    sizes: dict[str, int] = {}  # each anchor's node, in nodes once expanded
    open_: list[tuple[str | None, int]] = [(None, 0)]  # the collections being read: (anchor, nodes so far)

    def refuse(problem: str, event: yaml.Event) -> NoReturn:
        raise yaml.MarkedYAMLError(problem=problem, problem_mark=event.start_mark)  # type: ignore[arg-type]

    def add(nodes: int, anchor: str | None, event: yaml.Event) -> None:
        if anchor is not None:
            sizes[anchor] = nodes
        name, inside = open_[-1]
        open_[-1] = (name, inside + nodes)
        if sum(n for _, n in open_) > MAX_NODES:
            refuse(f"its aliases expand to more than {MAX_NODES:,} values (a billion-laughs file?)", event)

    for event in yaml.parse(text, Loader=loader):
        if isinstance(event, yaml.AliasEvent):
            aliases += 1
            if aliases > MAX_ALIASES:
                refuse(f"more than {MAX_ALIASES} aliases (*name)", event)
            add(sizes.get(event.anchor or "", 1), None, event)
        elif isinstance(event, yaml.CollectionStartEvent):
            open_.append((event.anchor, 1))
            if len(open_) - 1 > MAX_DEPTH:
                refuse(f"nested deeper than {MAX_DEPTH} levels", event)
        elif isinstance(event, yaml.CollectionEndEvent):
            anchor, nodes = open_.pop()
            add(nodes, anchor, event)
        elif isinstance(event, yaml.ScalarEvent):
            add(1, event.anchor, event)
    return yaml.load(text, Loader=loader)


def read_yaml(path: Path, source: str, error: type[E]) -> object:
    """A configuration file's YAML, or `error` naming the file: missing, unreadable, or invalid (with the line)."""
    try:
        text = read_config_text(path)
    except FileNotFoundError:
        raise error([ConfigProblem(source, "", "no such file")]) from None
    except TextError as e:
        raise error([ConfigProblem(source, "", str(e), e.line)]) from None
    except (OSError, ValueError) as e:  # UnicodeDecodeError is a ValueError
        raise error([ConfigProblem(source, "", f"cannot read: {e}")]) from e
    try:
        return load_yaml(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None) or getattr(e, "context_mark", None)
        message = getattr(e, "problem", None) or getattr(e, "context", None) or str(e)
        raise error([ConfigProblem(source, "", f"invalid YAML: {message}", mark and mark.line + 1)]) from e
