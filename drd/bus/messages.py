"""Versioned, schema-checked bus messages.

Every message is a frozen dataclass registered under a ``type`` name and a ``version``
with the :func:`message` decorator. On the wire it is UTF-8 JSON::

    {"v": 1, "type": "drd.load", "body": {"host": "ranger1", ...}}

where ``v`` is the version of that type's schema. :func:`decode` checks everything a peer
could get wrong (JSON syntax, envelope, type, version, field names and types, size) and
raises :class:`MalformedMessage` with a readable reason, so a bad peer costs a log line,
never a crash. :func:`encode` applies the same checks, so a sender cannot emit what a
receiver would reject.
"""

from __future__ import annotations

import dataclasses
import json
import math
import typing
from collections.abc import Callable
from typing import Any, ClassVar, TypeVar, dataclass_transform

from .schema import RAW_INIT, SCHEMAS, Convert, Mismatch, check_annotation, dumper, forget, kind, loader

MAX_SIZE = 1 << 20  # 1 MiB: bigger payloads belong in a file or a stream, not a bus message.

M = TypeVar("M", bound="Message")


class MalformedMessage(ValueError):
    """A message that fails the schema; ``reason`` says what is wrong, for the log."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class Message:
    """Base class of every bus message (subclass it and decorate with :func:`message`)."""

    TYPE: ClassVar[str]
    VERSION: ClassVar[int]


_REGISTRY: dict[tuple[str, int], type[Message]] = {}
_ENVELOPE = frozenset({"v", "type", "body"})
# Per class and per (type, version), built on first use: what encode and decode need in one lookup.
_ENCODERS: dict[type, tuple[Convert, bytes]] = {}  # class -> (dumper, the envelope's bytes up to the body)
_DECODERS: dict[tuple[str, int], Convert] = {}  # (type, version) -> the class's loader


@dataclass_transform(frozen_default=True)
def message(type_name: str, version: int = 1) -> Callable[[type[M]], type[M]]:
    """Make ``cls`` a frozen dataclass and register it as ``type_name`` at ``version``.

    Field annotations are the schema: str, int, float, bool, None, list[X], tuple[X, ...],
    dict[str, X], X | None (and other unions), Any, and nested registered messages (which
    must be defined before the class that uses them).
    """
    if not type_name or not isinstance(type_name, str):
        raise ValueError("a message type name must be a non-empty string")
    if type(version) is not int or version < 1:
        raise ValueError(f"message version must be a positive int, not {version!r}")

    def register(cls: type[M]) -> type[M]:
        if not issubclass(cls, Message):
            raise TypeError(f"{cls.__name__} must subclass drd.bus.messages.Message")
        generated_init = "__dataclass_fields__" not in cls.__dict__ and "__init__" not in cls.__dict__
        if "__dataclass_fields__" not in cls.__dict__:
            cls = dataclasses.dataclass(frozen=True)(cls)
        hints = typing.get_type_hints(cls)
        fields = dataclasses.fields(cls)  # type: ignore[arg-type]
        schema = tuple((f.name, hints[f.name]) for f in fields)
        for name, annotation in schema:
            check_annotation(annotation, f"{cls.__name__}.{name}")
        old = _REGISTRY.get((type_name, version))
        if old is not None and (old.__module__, old.__qualname__) != (cls.__module__, cls.__qualname__):
            raise ValueError(f"message type {type_name!r} v{version} is already registered by {old.__qualname__}")
        cls.TYPE, cls.VERSION = type_name, version
        _REGISTRY[(type_name, version)] = cls
        SCHEMAS[cls] = schema
        if (generated_init and not hasattr(cls, "__post_init__") and all(f.init for f in fields)
                and not any("__slots__" in c.__dict__ for c in cls.__mro__[:-1])):
            RAW_INIT.add(cls)
        else:
            RAW_INIT.discard(cls)
        forget(cls)
        _ENCODERS.pop(cls, None)
        _DECODERS.pop((type_name, version), None)
        return cls

    return register


def registered() -> dict[tuple[str, int], type[Message]]:
    """All registered (type, version) pairs: for docs, diagnostics and tests."""
    return dict(_REGISTRY)


def encode(msg: Message) -> bytes:
    """The wire bytes of ``msg``; raises MalformedMessage if it breaks its own schema."""
    codec = _ENCODERS.get(type(msg))
    if codec is None:
        codec = _encoder(type(msg))
    try:
        data = codec[1] + _dumps(codec[0](msg)) + b"}"
    except Mismatch as exc:
        raise MalformedMessage(exc.describe("body")) from None
    except (TypeError, ValueError) as exc:  # what JSON cannot carry, inside an ``Any`` field
        raise MalformedMessage(f"body: {exc}") from None
    if len(data) > MAX_SIZE:
        raise MalformedMessage(f"too large: {len(data)} bytes > {MAX_SIZE}")
    return data


def decode(data: bytes | bytearray | memoryview) -> Message:
    """Parse and schema-check wire bytes; raises MalformedMessage(reason) on anything off."""
    if type(data) is not bytes:
        if not isinstance(data, bytes | bytearray | memoryview):
            raise MalformedMessage(f"payload is {type(data).__name__}, not bytes")
        data = bytes(data)
    if len(data) > MAX_SIZE:
        raise MalformedMessage(f"too large: {len(data)} bytes > {MAX_SIZE}")
    try:
        env = _loads(data)
    except (ValueError, RecursionError) as exc:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        raise MalformedMessage(f"bad JSON: {exc}") from None
    try:  # the usual case in a few steps: a known (type, version), an int version, nothing else in the envelope
        version = env["v"]
        convert = _DECODERS[env["type"], version]
        if type(version) is int and len(env) == 3:
            return convert(env["body"])  # type: ignore[no-any-return]
    except (KeyError, TypeError):  # not an object, a key missing, a type not decoded yet: the checks below say
        pass
    except Mismatch as exc:
        raise MalformedMessage(exc.describe("body")) from None
    return _decode_envelope(env)


def _decode_envelope(env: Any) -> Message:
    """`decode` after the JSON parse, every check spelled out: what is wrong with the envelope, or the body's
    first use of its (type, version)."""
    if type(env) is not dict:
        raise MalformedMessage(f"envelope is a JSON {kind(env)}, not an object")
    if env.keys() != _ENVELOPE:
        missing, extra = _ENVELOPE - env.keys(), env.keys() - _ENVELOPE
        raise MalformedMessage(f"envelope keys: missing {sorted(missing)}, unexpected {sorted(extra)}")
    name, version = env["type"], env["v"]
    if type(name) is not str:
        raise MalformedMessage(f"envelope 'type' must be a string, got {kind(name)}")
    if type(version) is not int:
        raise MalformedMessage(f"envelope 'v' must be an int, got {kind(version)}")
    convert = _DECODERS.get((name, version))
    if convert is None:
        convert = _decoder(name, version)
    try:
        result: Message = convert(env["body"])
    except Mismatch as exc:
        raise MalformedMessage(exc.describe("body")) from None
    return result


def _encoder(cls: type) -> tuple[Convert, bytes]:
    """Build and cache the class's (dumper, envelope head): the head is the envelope's bytes as the codec
    writes them, up to the body, so ``head + body + b"}"`` is byte for byte the whole envelope's encoding."""
    if cls not in SCHEMAS:
        raise MalformedMessage(f"{cls.__name__} is not a registered message type")
    envelope = _dumps({"v": cls.VERSION, "type": cls.TYPE, "body": None})  # type: ignore[attr-defined]
    if not envelope.endswith(b"null}"):  # pragma: no cover - every JSON codec writes null as null
        raise AssertionError(f"unexpected envelope encoding {envelope!r}")
    codec = _ENCODERS[cls] = (dumper(cls), envelope[: -len(b"null}")])
    return codec


def _decoder(name: str, version: int) -> Convert:
    """Build and cache the loader of a registered (type, version); MalformedMessage names what is known."""
    cls = _REGISTRY.get((name, version))
    if cls is None:
        known = sorted(v for (t, v) in _REGISTRY if t == name)
        if not known:
            raise MalformedMessage(f"unknown message type {name!r}")
        raise MalformedMessage(f"unsupported version {version} of {name!r} (supported: {known})")
    convert = _DECODERS[(name, version)] = loader(cls)
    return convert


def _no_constant(token: str) -> Any:
    raise ValueError(f"{token} is not a number")


def _finite(token: str) -> float:
    value = float(token)
    if math.isinf(value):
        raise ValueError(f"{token} is out of range")
    return value


def _json_codec() -> tuple[Callable[[Any], bytes], Callable[[bytes], Any]]:
    """orjson when installed (parsing is ~8x faster, and on a request path that matters), else json.

    Both refuse NaN/Infinity, bad UTF-8 and deep nesting, and keep the last of duplicate keys.
    """
    try:
        import orjson
    except ImportError:  # pragma: no cover - depends on the machine
        encoder = json.JSONEncoder(separators=(",", ":"), ensure_ascii=False, allow_nan=False)
        decoder = json.JSONDecoder(parse_constant=_no_constant, parse_float=_finite)
        return (lambda obj: encoder.encode(obj).encode()), (lambda data: decoder.decode(data.decode()))
    return orjson.dumps, orjson.loads


_dumps, _loads = _json_codec()


# --- core messages ---------------------------------------------------------------------------


@message("drd.error", 1)
class ErrorReply(Message):
    """What a queryable answers when it fails: the requester raises RemoteError(reason)."""

    reason: str


@message("drd.ping", 1)
class Ping(Message):
    """Liveness and latency probe; ``sent_at`` is the sender's clock (seconds)."""

    nonce: int = 0
    sent_at: float = 0.0


@message("drd.pong", 1)
class Pong(Message):
    """Answer to Ping: echoes the nonce and names the answering host."""

    nonce: int = 0
    host: str = ""


@message("drd.load", 1)
class LoadReport(Message):
    """A host's load, published every period by the Load Reporter (cpu/memory in %)."""

    host: str
    cpu: float
    memory: float
    load1: float
    instances: int
    at: float
