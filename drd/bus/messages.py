"""Versioned, schema-checked bus messages.

Every message is a frozen dataclass registered under a ``type`` name and a ``version``
with the :func:`message` decorator. On the wire it is UTF-8 JSON::

    {"v": 1, "type": "drd.load", "body": {"host": "ranger1", ...}}

where ``v`` is the version of that type's schema. :func:`decode` checks everything a peer
could get wrong (JSON syntax, envelope, type, version, field names and types, size) and
raises :class:`MalformedMessage` with a readable reason, so a bad peer costs a log line,
never a crash. :func:`encode` applies the same checks, so a sender cannot emit what a
receiver would reject.

The codec is msgspec's, compiled: the envelope and the body are checked against structs built from the
annotations (:mod:`drd.bus.schema`), and only the registered message classes are ever built. orjson writes
the bytes: it refuses, as JSON does, a dict key that is not a string, wherever it hides (msgspec would write
it as one). The reason of a refusal is found in Python, after the fact, by :func:`drd.bus.schema.check`.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Callable
from typing import Any, ClassVar, Literal, NamedTuple, TypeVar, dataclass_transform

import msgspec
import orjson

from .schema import (
    SCHEMAS,
    Mismatch,
    check,
    check_annotation,
    define_wire,
    holds_mapping,
    kind,
    nullable_float,
    wire_struct,
)

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


class _Envelope(msgspec.Struct, forbid_unknown_fields=True):
    """The envelope as msgspec checks it; the body is kept as its bytes, for the decoder of its (type, version)."""

    v: int
    type: str
    body: msgspec.Raw


class _Codec(NamedTuple):
    """What encode and decode need for one class, built on its first use."""

    head: bytes  # the envelope's bytes up to the body, as encode writes them: head + body + b"}" is the envelope
    write: Callable[[Any], bytes]  # the body's bytes: msgspec's writer, or orjson's where a dict may hide a key
    check: Callable[[bytes], Any]  # the whole envelope (that v, that type, the body: every field, no other)
    check_body: Callable[[bytes], Any]  # the body alone (the wire struct)
    build: Callable[[bytes], Any]  # the body into the dataclass (its ``__post_init__`` runs)
    walk: bool  # encode checks in Python first: a non-finite float where null is allowed would pass as null


_REGISTRY: dict[tuple[str, int], type[Message]] = {}
_ENVELOPE = frozenset({"v", "type", "body"})
_decode_envelope = msgspec.json.Decoder(_Envelope).decode
_write = msgspec.json.Encoder().encode
_dumps: Callable[[Any], bytes] = orjson.dumps
# Built on first use: per class, per (type, version), and per envelope head (decode's shortcut, for the bytes
# a drd peer writes).
_CODECS: dict[type, _Codec] = {}
_BY_KEY: dict[tuple[str, int], _Codec] = {}
_BY_HEAD: dict[bytes, _Codec] = {}


@dataclass_transform(frozen_default=True)
def message(type_name: str, version: int = 1) -> Callable[[type[M]], type[M]]:
    """Make ``cls`` a frozen dataclass and register it as ``type_name`` at ``version``.

    Field annotations are the schema: str, int, float, bool, None, list[X], tuple[X, ...],
    dict[str, X], X | None (and other unions of different JSON kinds), Any, and nested registered
    messages (which must be defined before the class that uses them). Every field is on the wire,
    defaults or not, and no other.
    """
    if not type_name or not isinstance(type_name, str):
        raise ValueError("a message type name must be a non-empty string")
    if type(version) is not int or version < 1:
        raise ValueError(f"message version must be a positive int, not {version!r}")

    def register(cls: type[M]) -> type[M]:
        if not issubclass(cls, Message):
            raise TypeError(f"{cls.__name__} must subclass drd.bus.messages.Message")
        if "__dataclass_fields__" not in cls.__dict__:
            cls = dataclasses.dataclass(frozen=True)(cls)
        hints = typing.get_type_hints(cls)
        schema = tuple((f.name, hints[f.name]) for f in dataclasses.fields(cls))  # type: ignore[arg-type]
        for name, annotation in schema:
            check_annotation(annotation, f"{cls.__name__}.{name}")
            if name.startswith("_"):  # orjson writes a dataclass's public attributes only
                raise TypeError(f"{cls.__name__}.{name}: a message field's name cannot start with '_'")
        old = _REGISTRY.get((type_name, version))
        if old is not None and (old.__module__, old.__qualname__) != (cls.__module__, cls.__qualname__):
            raise ValueError(f"message type {type_name!r} v{version} is already registered by {old.__qualname__}")
        define_wire(cls, schema)
        cls.TYPE, cls.VERSION = type_name, version
        _REGISTRY[(type_name, version)] = cls
        _forget(cls, (type_name, version))
        return cls

    return register


def registered() -> dict[tuple[str, int], type[Message]]:
    """All registered (type, version) pairs, every module of the catalog loaded: for docs, diagnostics, tests."""
    from drd.bus import catalog

    catalog.load()
    return dict(_REGISTRY)


def encode(msg: Message) -> bytes:
    """The wire bytes of ``msg``; raises MalformedMessage if it breaks its own schema."""
    codec = _CODECS.get(type(msg)) or _codec(type(msg))
    try:
        if codec.walk:
            check(msg, type(msg), load=False)
        data = codec.head + codec.write(msg) + b"}"
        codec.check(data)  # what the receiver checks, on the very bytes it will get
    except Mismatch as exc:
        raise MalformedMessage(exc.describe("body")) from None
    except (TypeError, ValueError) as exc:  # msgspec's ValidationError is a ValueError, orjson's error a TypeError
        raise MalformedMessage(_encode_reason(msg, exc)) from None
    if len(data) > MAX_SIZE:
        raise MalformedMessage(f"too large: {len(data)} bytes > {MAX_SIZE}")
    return data


def decode(data: bytes | bytearray | memoryview) -> Message:
    """Parse and schema-check wire bytes; raises MalformedMessage(reason) on anything off.

    The bytes a drd peer writes take a shortcut: their envelope's head names the class, one check covers the
    envelope and the body, and the body is built from its slice of the bytes. Anything else (another layout of
    the envelope, a malformed message) takes the long way, which decodes the envelope first, then the body.
    """
    if type(data) is not bytes:
        if not isinstance(data, bytes | bytearray | memoryview):
            raise MalformedMessage(f"payload is {type(data).__name__}, not bytes")
        data = bytes(data)
    if len(data) > MAX_SIZE:
        raise MalformedMessage(f"too large: {len(data)} bytes > {MAX_SIZE}")
    start = data.find(b'"body":', 0, 128) + 7
    codec = _BY_HEAD.get(data[:start])
    if codec is not None:
        try:
            codec.check(data)
            shortcut: Message = codec.build(data[start:-1])  # fails unless the body is all of the rest but the "}"
            return shortcut
        except (ValueError, RecursionError):
            pass  # the long way says what is wrong, or decodes a repeated key as it should (the last one counts)
    try:
        env = _decode_envelope(data)
        codec = _BY_KEY.get((env.type, env.v)) or _codec(_registered(env.type, env.v))
        codec.check_body(env.body)
        result: Message = codec.build(env.body)
        return result
    except (ValueError, RecursionError) as exc:  # msgspec's errors, and UnicodeDecodeError, are ValueErrors
        raise MalformedMessage(_decode_reason(data, exc)) from None


def _encode_reason(msg: Message, exc: Exception) -> str:
    """Why ``msg`` could not be encoded: the field at fault, else what the JSON encoder or msgspec said (about
    what an ``Any`` field holds)."""
    try:
        check(msg, type(msg), load=False)
    except Mismatch as mismatch:
        return mismatch.describe("body")
    return f"body: {exc}"


def _decode_reason(data: bytes, exc: Exception) -> str:
    """Why msgspec refused ``data``, every check spelled out: the JSON, the envelope, the (type, version), then
    the body's first field at fault (msgspec's own words if none is: what the annotations cannot say)."""
    try:
        env = msgspec.json.decode(data)
    except (ValueError, RecursionError) as bad:  # msgspec's DecodeError, or UnicodeDecodeError
        return f"bad JSON: {bad}"
    if type(env) is not dict:
        return f"envelope is a JSON {kind(env)}, not an object"
    if env.keys() != _ENVELOPE:
        missing, extra = _ENVELOPE - env.keys(), env.keys() - _ENVELOPE
        return f"envelope keys: missing {sorted(missing)}, unexpected {sorted(extra)}"
    name, version = env["type"], env["v"]
    if type(name) is not str:
        return f"envelope 'type' must be a string, got {kind(name)}"
    if type(version) is not int:
        return f"envelope 'v' must be an int, got {kind(version)}"
    try:
        check(env["body"], _registered(name, version), load=True)
    except Mismatch as mismatch:
        return mismatch.describe("body")
    except MalformedMessage as unknown:
        return unknown.reason
    return f"body: {exc}"


def _codec(cls: type) -> _Codec:
    """Build and cache the codec of a registered class."""
    if cls not in SCHEMAS:
        raise MalformedMessage(f"{cls.__name__} is not a registered message type")
    name, version = cls.TYPE, cls.VERSION  # type: ignore[attr-defined]
    envelope = _dumps({"v": version, "type": name, "body": None})
    if not envelope.endswith(b"null}"):  # pragma: no cover - every JSON codec writes null as null
        raise AssertionError(f"unexpected envelope encoding {envelope!r}")
    schema, wire = SCHEMAS[cls], wire_struct(cls)
    whole = msgspec.defstruct(
        f"{cls.__name__}Envelope", [("v", Literal[version]), ("type", Literal[name]), ("body", wire)],
        forbid_unknown_fields=True, module=cls.__module__,
    )
    codec = _Codec(
        head=envelope[: -len(b"null}")],
        write=_dumps if any(holds_mapping(tp) for _, tp in schema) else _write,
        check=msgspec.json.Decoder(whole).decode,
        check_body=msgspec.json.Decoder(wire).decode,
        build=msgspec.json.Decoder(cls).decode,
        walk=any(nullable_float(tp) for _, tp in schema),
    )
    _CODECS[cls] = _BY_KEY[(name, version)] = _BY_HEAD[codec.head] = codec
    return codec


def _forget(cls: type, key: tuple[str, int]) -> None:
    """Drop the codecs of a (re-)registered class and of its (type, version)."""
    for codec in (_CODECS.pop(cls, None), _BY_KEY.pop(key, None)):
        if codec is not None:
            _BY_HEAD.pop(codec.head, None)


def _registered(name: str, version: int) -> type[Message]:
    """The class registered as (type, version); MalformedMessage names what is known. A type not known yet
    loads every message module of the catalog first (`drd.bus.catalog`), so what decodes never depends on what
    the process happened to import."""
    cls = _REGISTRY.get((name, version))
    if cls is None:
        from drd.bus import catalog  # the catalog imports the modules that import this one

        catalog.load()
        cls = _REGISTRY.get((name, version))
    if cls is None:
        known = sorted(v for (t, v) in _REGISTRY if t == name)
        if not known:
            raise MalformedMessage(f"unknown message type {name!r}")
        raise MalformedMessage(f"unsupported version {version} of {name!r} (supported: {known})")
    return cls


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
