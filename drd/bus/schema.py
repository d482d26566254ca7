"""The message schema: field annotations, their wire form for msgspec, and the located reasons of a mismatch.

A registered message class is a frozen ``msgspec.Struct``; its field annotations are the schema. msgspec does the
work on every message (see :mod:`drd.bus.messages`): each class also gets a *wire struct*, a ``msgspec.Struct``
with the same fields and annotations but every field required, no default and no ``__post_init__``, against
which encode checks the body it wrote, in C, building nothing the caller sees.

When msgspec refuses something, :func:`check` walks the value against the annotations in Python, off the hot
path, to say where and what: ``body.reports[0].cpu: expected float, got string``. It reads the schema as its
docstring in ``messages.message`` states it; ``tests/properties/test_schema_properties.py`` holds both to one reading.
"""

from __future__ import annotations

import math
import threading
import types
import typing
from typing import Any, Union

import msgspec

#: Held while msgspec builds a decoder of messages (or a wire struct). msgspec builds a class's type information the
#: first time a decoder needs it and publishes it on the class before it is complete (it calls Python meanwhile, so
#: another thread may run): a second thread building a decoder then takes the unfinished information, and decoding
#: with it crashes the process (seen as SIGSEGV in daemons whose zenoh threads decoded their first messages at once).
BUILDING = threading.RLock()
SCALARS: dict[Any, str] = {str: "str", int: "int", float: "float", bool: "bool", type(None): "null"}
SCHEMAS: dict[type, tuple[tuple[str, Any], ...]] = {}  # registered message class -> (field, annotation)
_WIRE: dict[type, type[msgspec.Struct]] = {}  # registered message class -> its wire struct


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


def define_wire(cls: type, schema: tuple[tuple[str, Any], ...]) -> type[msgspec.Struct]:
    """Register ``cls``'s schema and build its wire struct; a TypeError names an annotation msgspec cannot decode
    (a union of two lists, or of two objects: msgspec picks a union's arm by the JSON kind alone)."""
    with BUILDING:
        wire = msgspec.defstruct(
            f"{cls.__name__}Wire", [(field, wire_type(tp)) for field, tp in schema], forbid_unknown_fields=True,
            module=cls.__module__,
        )
        try:
            msgspec.json.Decoder(wire)  # msgspec checks the annotations here: at definition, not on first use
        except TypeError as exc:
            raise TypeError(f"{cls.__name__}: unsupported annotation: {exc}") from None
    SCHEMAS[cls], _WIRE[cls] = schema, wire
    return wire


def wire_struct(cls: type) -> type[msgspec.Struct]:
    return _WIRE[cls]


def wire_type(tp: Any) -> Any:
    """The annotation msgspec checks for ``tp``: the same, with each message class replaced by its wire struct."""
    if tp in _WIRE:
        return _WIRE[tp]
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return Union[tuple(wire_type(a) for a in args)]  # noqa: UP007 - built from a tuple
    if origin is list:
        return list[wire_type(args[0])]  # type: ignore[misc]
    if origin is tuple:
        return tuple[wire_type(args[0]), ...]  # type: ignore[misc]
    if origin is dict:
        return dict[str, wire_type(args[1])]  # type: ignore[misc]
    return tp


def nullable_float(tp: Any, nullable: bool = False) -> bool:
    """Does ``tp`` hold a float where null is allowed too? There a non-finite float would be written as null and
    read back as None, so encode checks such a message in Python first (see ``messages.encode``)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is float:
        return nullable
    if origin in (typing.Union, types.UnionType):
        return any(nullable_float(a, nullable or type(None) in args) for a in args)
    if origin in (list, tuple, dict):
        return bool(args) and nullable_float(args[-2 if origin is tuple else -1])
    return tp in SCHEMAS and any(nullable_float(a) for _, a in SCHEMAS[tp])


def holds_mapping(tp: Any) -> bool:
    """May a value of ``tp`` hold a dict (a ``dict`` or ``Any`` anywhere in it)? msgspec would write a key that
    is not a string as one, where JSON (and orjson) refuse it: such a message is written by orjson."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any or tp is dict or origin is dict:
        return True
    if tp in SCHEMAS:
        return any(holds_mapping(a) for _, a in SCHEMAS[tp])
    return any(holds_mapping(a) for a in args if a is not Ellipsis)


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


# --- the located reasons ------------------------------------------------------------------------------------


def check(v: Any, tp: Any, *, load: bool) -> None:
    """Raise :class:`Mismatch` if ``v`` does not fit ``tp``: a decoded JSON value (``load``), else a Python value
    about to be encoded. Slow on purpose: it runs only to explain what msgspec refused."""
    origin = typing.get_origin(tp)
    if tp is Any:
        return  # on encode, the JSON encoder refuses what JSON cannot carry
    if tp in (str, bool, int, type(None)):
        if type(v) is not tp:
            raise Mismatch(f"expected {SCALARS[tp]}, got {_got(v, load)}")
    elif tp is float:
        _check_float(v, load)
    elif origin in (typing.Union, types.UnionType):
        _check_union(v, tp, load)
    elif tp in (list, tuple) or origin in (list, tuple):
        _check_sequence(v, tp, load)
    elif tp is dict or origin is dict:
        _check_mapping(v, tp, load)
    elif tp in SCHEMAS:
        _check_message(v, tp, load)
    else:  # pragma: no cover - refused at definition
        raise TypeError(f"unsupported annotation {tp!r}")


def _got(v: Any, load: bool) -> str:
    return kind(v) if load else type(v).__name__


def _check_float(v: Any, load: bool) -> None:
    if type(v) is float:
        if not (load or math.isfinite(v)):
            raise Mismatch(f"{v} is not a finite float")
    elif type(v) is not int:
        raise Mismatch(f"expected float, got {_got(v, load)}")


def _check_union(v: Any, tp: Any, load: bool) -> None:
    """One arm must fit; the reason names the union, not the arms' own reasons (None fits only the null arm)."""
    for arm in typing.get_args(tp):
        try:
            check(v, arm, load=load)
            return
        except Mismatch:
            continue
    raise Mismatch(f"expected {name(tp)}, got {_got(v, load)}")


def _check_sequence(v: Any, tp: Any, load: bool) -> None:
    if type(v) not in ((list,) if load else (list, tuple)):
        raise Mismatch(f"expected list, got {_got(v, load)}")
    args = typing.get_args(tp)
    for i, x in enumerate(v if args else ()):
        try:
            check(x, args[0], load=load)
        except Mismatch as exc:
            raise exc.at(f"[{i}]") from None


def _check_mapping(v: Any, tp: Any, load: bool) -> None:
    if type(v) is not dict:
        raise Mismatch(f"expected {'object' if load else 'dict'}, got {_got(v, load)}")
    args = typing.get_args(tp)
    for k, x in v.items():
        if type(k) is not str:
            raise Mismatch(f"keys must be str, got {type(k).__name__}")
        try:
            check(x, args[1] if args else Any, load=load)
        except Mismatch as exc:
            raise exc.at(f".{k}") from None


def _check_message(v: Any, cls: type, load: bool) -> None:
    """A body: an object with every field and no other (``load``), or an instance of the class."""
    fields = SCHEMAS[cls]
    if load and type(v) is not dict:
        raise Mismatch(f"expected object ({cls.__name__}), got {kind(v)}")
    if not load and not isinstance(v, cls):
        raise Mismatch(f"expected {cls.__name__}, got {type(v).__name__}")
    if load and v.keys() != {f for f, _ in fields}:
        type_name = getattr(cls, "TYPE", cls.__name__)
        if missing := [f for f, _ in fields if f not in v]:
            raise Mismatch(f"missing field {missing[0]!r} of {type_name}")
        raise Mismatch(f"unexpected field {sorted(v.keys() - {f for f, _ in fields})[0]!r} for {type_name}")
    for field, tp in fields:
        try:
            check(v[field] if load else getattr(v, field), tp, load=load)
        except Mismatch as exc:
            raise exc.at(f".{field}") from None
