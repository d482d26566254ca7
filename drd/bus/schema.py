"""Compiled converters between JSON values and annotated Python values: the message schema.

A *loader* checks a decoded JSON value against an annotation and builds the Python value; a
*dumper* checks a Python value and builds its JSON form. Each is compiled once per annotation
(message classes get generated straight-line code, as dataclasses does for ``__init__``),
because decoding sits on every request's path: in a busy daemon the interpreter's caches are
cold, and every bytecode saved shows in the latency. Both raise :class:`Mismatch`, which
collects the path to the bad value on its way up, so the happy path formats no string.
"""

from __future__ import annotations

import math
import types
import typing
from collections.abc import Callable
from typing import Any

Convert = Callable[[Any], Any]

SCALARS: dict[Any, str] = {str: "str", int: "int", float: "float", bool: "bool", type(None): "null"}
SCHEMAS: dict[type, tuple[tuple[str, Any], ...]] = {}  # registered message class -> (field, annotation)
#: Message classes whose loader may build an instance by filling its ``__dict__``: their ``__init__`` is the
#: one dataclasses generates (it only sets the fields), without ``__post_init__`` or slots. A frozen
#: dataclass's ``__init__`` sets each field through ``object.__setattr__``: 4x slower, on every decode.
RAW_INIT: set[type] = set()
_LOADERS: dict[Any, Convert] = {}
_DUMPERS: dict[Any, Convert] = {}


class Mismatch(Exception):
    """A value that does not fit its annotation; ``describe`` gives the reason with its path."""

    def __init__(self, problem: str) -> None:
        self.problem, self.path = problem, list[str]()

    def at(self, step: str) -> Mismatch:
        self.path.append(step)
        return self

    def describe(self, root: str) -> str:
        return f"{root}{''.join(reversed(self.path))}: {self.problem}"


def check_annotation(tp: Any, where: str) -> None:
    """Refuse, at class definition, an annotation the wire format cannot carry."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any or tp in SCALARS or tp in (list, dict, tuple) or tp in SCHEMAS:
        return
    if origin in (typing.Union, types.UnionType) or origin is list:
        for arg in args:
            check_annotation(arg, where)
        return
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return check_annotation(args[0], where)
    if origin is dict and args and args[0] is str:
        return check_annotation(args[1], where)
    if isinstance(tp, type) and origin is None:
        raise TypeError(f"{where}: {tp.__name__} is not a registered message type (nor a supported annotation)")
    raise TypeError(f"{where}: unsupported annotation {tp!r}")


def loader(tp: Any) -> Convert:
    fn = _LOADERS.get(tp)
    if fn is None:
        fn = _LOADERS[tp] = _compile(tp, load=True)
    return fn


def dumper(tp: Any) -> Convert:
    fn = _DUMPERS.get(tp)
    if fn is None:
        fn = _DUMPERS[tp] = _compile(tp, load=False)
    return fn


def forget(cls: type) -> None:
    """Drop cached converters of a (re-)registered class."""
    _LOADERS.pop(cls, None)
    _DUMPERS.pop(cls, None)


def kind(value: Any) -> str:
    """A JSON value's kind, as a peer would name it."""
    if value is None:
        return "null"
    return {bool: "bool", int: "int", float: "float", str: "string", list: "list", dict: "object"}.get(
        type(value), type(value).__name__
    )


def name(tp: Any) -> str:
    """An annotation as an error names it: ``str | null``, ``list[int]``, ``dict[str, Any]``."""
    if tp in SCALARS:
        return SCALARS[tp]
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return " | ".join(name(a) for a in args)
    if origin in (list, tuple):
        return f"list[{name(args[0])}]"
    if origin is dict:
        return f"dict[str, {name(args[1])}]"
    return "Any" if tp is Any else getattr(tp, "__name__", str(tp))


def _identity(v: Any) -> Any:
    return v


def _pyname(v: Any) -> str:
    return type(v).__name__


def _compile(tp: Any, *, load: bool) -> Convert:
    """The converter for annotation ``tp`` (``load``: JSON -> Python, else Python -> JSON)."""
    got = kind if load else _pyname
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    sub = loader if load else dumper
    if tp is Any:
        return _identity  # on dump, the JSON encoder refuses what JSON cannot carry
    if tp in (str, bool, int, type(None)):

        def exact(v: Any) -> Any:
            if type(v) is tp:
                return v
            raise Mismatch(f"expected {SCALARS[tp]}, got {got(v)}")

        return exact
    if tp is float:

        def number(v: Any) -> float:
            if type(v) is float:
                if load or math.isfinite(v):
                    return v
                raise Mismatch(f"{v} is not a finite float")
            if type(v) is int:
                return float(v)
            raise Mismatch(f"expected float, got {got(v)}")

        return number
    if origin in (typing.Union, types.UnionType):
        arms, expected = [sub(a) for a in args], name(tp)
        if len(args) == 2 and type(None) in args:  # X | None: most optional fields are None, and a Mismatch costs
            arm = arms[args.index(type(None)) ^ 1]  # an exception; None fits no other arm (Any keeps it: the same)

            def optional(v: Any) -> Any:
                if v is None:
                    return None
                try:
                    return arm(v)
                except Mismatch:
                    raise Mismatch(f"expected {expected}, got {got(v)}") from None

            return optional

        def union(v: Any) -> Any:
            for arm in arms:
                try:
                    return arm(v)
                except Mismatch:
                    continue
            raise Mismatch(f"expected {expected}, got {got(v)}")

        return union
    if tp in (list, tuple) or origin in (list, tuple):
        item = sub(args[0]) if args else _identity
        accepted = (list,) if load else (list, tuple)
        as_tuple = load and tuple in (tp, origin)
        if item is _identity and not as_tuple:  # list[Any]: nothing to check inside, the value itself will do

            def any_sequence(v: Any) -> Any:
                if type(v) not in accepted:
                    raise Mismatch(f"expected list, got {got(v)}")
                return v

            return any_sequence

        def sequence(v: Any) -> Any:
            if type(v) not in accepted:
                raise Mismatch(f"expected list, got {got(v)}")
            out = []
            for i, x in enumerate(v):
                try:
                    out.append(item(x))
                except Mismatch as exc:
                    raise exc.at(f"[{i}]") from None
            return tuple(out) if as_tuple else out

        return sequence
    if tp is dict or origin is dict:
        value = sub(args[1]) if args else _identity
        if value is _identity:  # dict[str, Any]: only the keys to check (and JSON's keys are strings already)

            def any_mapping(v: Any) -> dict[str, Any]:
                if type(v) is not dict:
                    raise Mismatch(f"expected {'object' if load else 'dict'}, got {got(v)}")
                if not load:
                    for k in v:
                        if type(k) is not str:
                            raise Mismatch(f"keys must be str, got {type(k).__name__}")
                return v

            return any_mapping

        def mapping(v: Any) -> dict[str, Any]:
            if type(v) is not dict:
                raise Mismatch(f"expected {'object' if load else 'dict'}, got {got(v)}")
            out = {}
            for k, x in v.items():
                if type(k) is not str:
                    raise Mismatch(f"keys must be str, got {type(k).__name__}")
                try:
                    out[k] = value(x)
                except Mismatch as exc:
                    raise exc.at(f".{k}") from None
            return out

        return mapping
    if tp in SCHEMAS:
        return _message_converter(tp, load)
    raise TypeError(f"unsupported annotation {tp!r}")  # pragma: no cover - refused at definition


def _message_converter(cls: type, load: bool) -> Convert:
    """Generated straight-line code for one message class: scalar fields checked inline."""
    fields = SCHEMAS[cls]
    ns: dict[str, Any] = {"cls": cls, "Mismatch": Mismatch, "kind": kind, "isfinite": math.isfinite}
    if load:  # as many keys as fields, each found: the very keys (cheaper than comparing key sets)
        ns["fields_error"] = _fields_error(cls, fields)
        lines = [
            "def convert(v):",
            "    if type(v) is not dict:",
            f"        raise Mismatch('expected object ({cls.__name__}), got ' + kind(v))",
            f"    if len(v) != {len(fields)}:",
            "        fields_error(v)",
        ]
        if fields:
            lines += ["    try:", *(f"        x{i} = v[{field!r}]" for i, (field, _) in enumerate(fields)),
                      "    except KeyError:", "        fields_error(v)"]
    else:
        lines = [
            "def convert(v):",
            "    if not isinstance(v, cls):",
            f"        raise Mismatch('expected {cls.__name__}, got ' + type(v).__name__)",
        ]
    for i, (field, tp) in enumerate(fields):
        x, step = f"x{i}", repr(f".{field}")
        if not load:
            lines.append(f"    {x} = v.{field}")
        kind_of = f"kind({x})" if load else f"type({x}).__name__"
        if tp in (str, int, bool):
            lines += [
                f"    if type({x}) is not {tp.__name__}:",
                f"        raise Mismatch('expected {SCALARS[tp]}, got ' + {kind_of}).at({step})",
            ]
        elif tp is float:
            lines += [
                f"    if type({x}) is not float:",
                f"        if type({x}) is not int:",
                f"            raise Mismatch('expected float, got ' + {kind_of}).at({step})",
                f"        {x} = float({x})",
            ]
            if not load:
                lines += [
                    f"    elif not isfinite({x}):",
                    f"        raise Mismatch(str({x}) + ' is not a finite float').at({step})",
                ]
        elif tp is not Any:
            ns[f"c{i}"] = loader(tp) if load else dumper(tp)
            pad = ""
            if _optional(tp):  # most optional fields are None: skip the call
                lines.append(f"    if {x} is not None:")
                pad = "    "
            lines += [
                f"{pad}    try:",
                f"{pad}        {x} = c{i}({x})",
                f"{pad}    except Mismatch as exc:",
                f"{pad}        raise exc.at({step}) from None",
            ]
    pairs = [(field, f"x{i}") for i, (field, _) in enumerate(fields)]
    if load and cls in RAW_INIT:
        ns["new"] = object.__new__
        lines += ["    o = new(cls)", f"    o.__dict__.update({{{', '.join(f'{f!r}: {x}' for f, x in pairs)}}})",
                  "    return o"]
    elif load:
        lines.append(f"    return cls({', '.join(f'{f}={x}' for f, x in pairs)})")
    else:
        lines.append(f"    return {{{', '.join(f'{f!r}: {x}' for f, x in pairs)}}}")
    exec("\n".join(lines), ns)  # noqa: S102 - code built from a registered class's field names only
    fn: Convert = ns["convert"]
    return fn


def _optional(tp: Any) -> bool:
    """``X | None`` (or a wider union with None): None converts to None whatever the other arms are."""
    return typing.get_origin(tp) in (typing.Union, types.UnionType) and type(None) in typing.get_args(tp)


def _fields_error(cls: type, fields: tuple[tuple[str, Any], ...]) -> Callable[[dict[str, Any]], None]:
    names = {n for n, _ in fields}
    type_name = getattr(cls, "TYPE", cls.__name__)

    def fields_error(v: dict[str, Any]) -> None:
        if missing := [n for n, _ in fields if n not in v]:
            raise Mismatch(f"missing field {missing[0]!r} of {type_name}")
        raise Mismatch(f"unexpected field {sorted(v.keys() - names)[0]!r} for {type_name}")

    return fields_error
