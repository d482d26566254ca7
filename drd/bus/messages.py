"""Versioned, schema-checked bus messages.

Every message is a frozen ``msgspec.Struct`` (subclass :class:`Message`) registered under a ``type`` name and a
``version`` with the :func:`message` decorator. On the wire it is UTF-8 JSON::

    {"v": 1, "type": "drd.load", "body": {"host": "ranger1", ...}}

where ``v`` is the version of that type's schema. :func:`decode` checks everything a peer
could get wrong (JSON syntax, envelope, type, version, field names and types, size) and
raises :class:`MalformedMessage` with a readable reason, so a bad peer costs a log line,
never a crash. :func:`encode` applies the same checks, so a sender cannot emit what a
receiver would reject.

The codec is msgspec's, compiled, and takes one call each way for the bytes a drd peer writes: decode reads the
whole envelope straight into the registered class (every field, no other: a field with a default must be sent
too, see :class:`_Default`), encode writes the body and checks the envelope it makes against the wire struct of
:mod:`drd.bus.schema` (a Struct's fields are not checked when it is built, so this check is what keeps a
sender from emitting what a receiver would refuse). orjson writes the bytes of a class that may hold a dict: it
refuses, as JSON does, a key that is not a string, wherever it hides (msgspec would write it as one). The reason
of a refusal is found in Python, after the fact, by :func:`drd.bus.schema.check`.

Messages keep the dataclasses protocol (``__dataclass_fields__``, from a shadow dataclass): ``dataclasses.fields``,
``replace`` and ``asdict`` work on them as they did when they were dataclasses, and orjson writes them.
"""

from __future__ import annotations

import dataclasses
import sys
import typing
from collections import Counter
from collections.abc import Callable
from typing import Any, ClassVar, Literal, TypeVar, Union, dataclass_transform

import msgspec
import orjson

from .schema import (
    BUILDING,
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


_FIELD = type(msgspec.field())  # what ``msgspec.field(...)`` makes


#: The code of the functions that decode bytes into message classes: a default asked for by one of them is a field
#: the peer did not send (see `_Default`). Filled once they are defined.
_DECODING: set[object] = set()


class _Default:
    """A message field's default, as the ``default_factory`` msgspec calls when the field is not given.

    Built by ``Foo(...)``, a message takes its defaults as a dataclass would; decoded, it must carry every field, a
    defaulted one too (other peers and recordings may differ on the default). msgspec has no such option (it fills a
    missing field from its default), so the default refuses to be taken by a decoder of this module: msgspec asks
    for it from C, so the calling Python frame is the decoding function's. Nothing of this runs when every field is
    given or sent: the frame is read only when a default is used.
    """

    __slots__ = ("value", "factory")

    def __init__(self, value: Any, factory: Callable[[], Any] | None) -> None:
        self.value, self.factory = value, factory

    def __call__(self) -> Any:
        if sys._getframe(1).f_code in _DECODING:
            raise MalformedMessage("a field with a default was not sent")  # decode finds which, and says it
        return self.value if self.factory is None else self.factory()

    @staticmethod
    def of(value: Any, where: str) -> _Default:
        """The default of a field whose class body says ``= value`` (a plain value or ``msgspec.field(...)``)."""
        if isinstance(value, _FIELD):
            if value.name is not None:
                raise TypeError(f"{where}: a message field cannot be renamed on the wire")
            if value.default_factory is not msgspec.NODEFAULT:
                return _Default(None, value.default_factory)
            value = value.default
        if isinstance(value, list | dict | set | bytearray):
            if value:  # as msgspec: a shared mutable default would leak between messages
                raise TypeError(f"{where}: a mutable default must be empty (or a default_factory)")
            return _Default(None, type(value))
        return _Default(value, None)


def _is_classvar(annotation: Any) -> bool:
    if isinstance(annotation, str):
        return annotation.startswith(("ClassVar", "typing.ClassVar"))
    return typing.get_origin(annotation) is ClassVar


@dataclass_transform(frozen_default=True, field_specifiers=(msgspec.field,))
class _MessageMeta(msgspec.StructMeta):
    """The metaclass of messages: a Struct whose defaults are :class:`_Default`s (nothing else changes; building
    and decoding a message run in msgspec's C code)."""

    def __new__(mcls, name: str, bases: tuple[type, ...], namespace: dict[str, Any], **kwargs: Any) -> Any:
        own = namespace.get("__annotations__", {})
        for field, annotation in own.items():
            if field in namespace and not _is_classvar(annotation) and not _wrapped(namespace[field]):
                default = _Default.of(namespace[field], f"{name}.{field}")
                namespace[field] = msgspec.field(default_factory=default)
        return super().__new__(mcls, name, bases, namespace, **kwargs)


def _wrapped(value: Any) -> bool:
    return isinstance(value, _FIELD) and isinstance(value.default_factory, _Default)


class Message(msgspec.Struct, frozen=True, forbid_unknown_fields=True, metaclass=_MessageMeta):
    """Base class of every bus message (subclass it and decorate with :func:`message`): a frozen Struct,
    equal by type and fields, hashable when its fields are."""

    TYPE: ClassVar[str]
    VERSION: ClassVar[int]
    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]


class _Envelope(msgspec.Struct, forbid_unknown_fields=True):
    """The envelope as msgspec checks it; the body is kept as its bytes, for the decoder of its (type, version)."""

    v: int
    type: str
    body: msgspec.Raw


#: What encode needs of a class, built on its first use: a plain tuple, unpacked in one step (each attribute read of
#: a NamedTuple costs more than the whole unpacking, on a path that runs cold between two round trips).
_Encoder = tuple[
    bytes,  # the envelope's bytes up to the body, as encode writes them: head + body + b"}" is the envelope
    Callable[[Any], bytes],  # the body's bytes: msgspec's writer, or orjson's where a dict may hide a key
    Callable[[bytes], Any],  # the body against the wire struct: what a receiver checks of it (nothing is built)
]

_REGISTRY: dict[tuple[str, int], type[Message]] = {}
_ENVELOPE = frozenset({"v", "type", "body"})
_decode_envelope = msgspec.json.Decoder(_Envelope).decode
_write = msgspec.json.Encoder().encode
_dumps: Callable[[Any], bytes] = orjson.dumps
# Built on first use: encode's per class, the long way's body decoders per (type, version).
_ENCODERS: dict[type, _Encoder] = {}
_BUILDERS: dict[tuple[str, int], Callable[[bytes | msgspec.Raw], Any]] = {}


def message(type_name: str, version: int = 1) -> Callable[[type[M]], type[M]]:
    """Register ``cls`` (a subclass of :class:`Message`) as ``type_name`` at ``version``.

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
        if not (isinstance(cls, type) and issubclass(cls, Message)):
            raise TypeError(f"{getattr(cls, '__name__', cls)!r} must subclass drd.bus.messages.Message")
        hints = typing.get_type_hints(cls)
        schema = tuple((name, hints[name]) for name in cls.__struct_fields__)
        for name, annotation in schema:
            check_annotation(annotation, f"{cls.__name__}.{name}")
            if name.startswith("_"):  # orjson writes a dataclass's public attributes only
                raise TypeError(f"{cls.__name__}.{name}: a message field's name cannot start with '_'")
        old = _REGISTRY.get((type_name, version))
        if old is not None and (old.__module__, old.__qualname__) != (cls.__module__, cls.__qualname__):
            raise ValueError(f"message type {type_name!r} v{version} is already registered by {old.__qualname__}")
        define_wire(cls, schema)
        cls.TYPE, cls.VERSION = type_name, version
        cls.__dataclass_fields__ = _dataclass_fields(cls, schema)
        _REGISTRY[(type_name, version)] = cls
        _forget(cls, (type_name, version))
        return cls

    return register


def _dataclass_fields(cls: type[Message], schema: tuple[tuple[str, Any], ...]) -> dict[str, dataclasses.Field[Any]]:
    """The fields of a dataclass shaped as ``cls`` (same names, types and defaults): what ``dataclasses.fields``,
    ``replace`` and ``asdict``, and orjson, read."""
    defaults = dict(zip(cls.__struct_fields__[len(cls.__struct_fields__) - len(cls.__struct_defaults__):],
                        cls.__struct_defaults__, strict=True))
    specs: list[tuple[str, Any, Any]] = []
    for name, annotation in schema:
        if name not in defaults:
            specs.append((name, annotation, dataclasses.field()))
        else:  # msgspec's holder of our _Default
            default: _Default = defaults[name].factory
            field = dataclasses.field(default=default.value) if default.factory is None else dataclasses.field(
                default_factory=default.factory)
            specs.append((name, annotation, field))
    # only the fields are wanted: no methods generated (their code is compiled per class, five times the cost, at
    # every process start that loads the messages)
    shadow = dataclasses.make_dataclass(cls.__name__, specs, init=False, repr=False, eq=False)
    return dict(shadow.__dataclass_fields__)  # type: ignore[attr-defined]


def registered() -> dict[tuple[str, int], type[Message]]:
    """All registered (type, version) pairs, every module of the catalog loaded: for docs, diagnostics, tests."""
    from drd.bus import catalog

    catalog.load()
    return dict(_REGISTRY)


def encode(msg: Message) -> bytes:
    """The wire bytes of ``msg``; raises MalformedMessage if it breaks its own schema."""
    try:
        head, write, verify = _ENCODERS[type(msg)]
    except KeyError:
        head, write, verify = _encoder(type(msg))
    try:
        body = write(msg)
        verify(body)  # what the receiver checks of the body, on the very bytes it will get (the head is ours)
    except Mismatch as exc:
        raise MalformedMessage(exc.describe("body")) from None
    except (TypeError, ValueError) as exc:  # msgspec's ValidationError is a ValueError, orjson's error a TypeError
        raise MalformedMessage(_encode_reason(msg, exc)) from None
    data = head + body + b"}"
    if len(data) > MAX_SIZE:
        raise MalformedMessage(f"too large: {len(data)} bytes > {MAX_SIZE}")
    return data


def decode(data: bytes | bytearray | memoryview) -> Message:
    """Parse and schema-check wire bytes; raises MalformedMessage(reason) on anything off.

    One call of msgspec's takes the bytes a drd peer writes: a decoder of every registered (type, version) reads
    the envelope and builds the message. Anything else (another payload type, a type it does not know yet, a
    malformed message) takes the long way, which says what is wrong.
    """
    if type(data) is bytes and len(data) <= MAX_SIZE:
        try:
            msg: Message = _read(data).body
            return msg
        except (ValueError, RecursionError):
            pass  # the long way says what is wrong, or decodes what it should (a type registered since)
    return _decode_long(data)


def _decode_long(data: bytes | bytearray | memoryview) -> Message:
    """``decode``'s long way: the envelope first, then the body with the decoder of its (type, version)."""
    if type(data) is not bytes:
        if not isinstance(data, bytes | bytearray | memoryview):
            raise MalformedMessage(f"payload is {type(data).__name__}, not bytes")
        data = bytes(data)
    if len(data) > MAX_SIZE:
        raise MalformedMessage(f"too large: {len(data)} bytes > {MAX_SIZE}")
    try:
        env = _decode_envelope(data)
        build = _BUILDERS.get((env.type, env.v)) or _builder(_registered(env.type, env.v))
        result: Message = build(env.body)
        return result
    except (ValueError, RecursionError) as exc:  # msgspec's errors, and UnicodeDecodeError, are ValueErrors
        raise MalformedMessage(_decode_reason(data, exc)) from None


def _read_all(data: bytes) -> Any:
    """``decode``'s reader until the first decode after a registration: builds the one that knows every
    registered (type, version), then reads ``data`` with it."""
    global _read
    with BUILDING:
        seen = _registrations
        reader = _reader()
    if seen == _registrations:  # else a class registered meanwhile: the next decode builds it anew
        _read = reader
    return reader(data)


_read: Callable[[bytes], Any] = _read_all
_DECODING.update({decode.__code__, _decode_long.__code__, _read_all.__code__})


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


def _encoder(cls: type) -> _Encoder:
    """Build and cache what encode needs of a registered class."""
    if cls not in SCHEMAS:
        raise MalformedMessage(f"{cls.__name__} is not a registered message type")
    name, version = cls.TYPE, cls.VERSION  # type: ignore[attr-defined]
    envelope = _dumps({"v": version, "type": name, "body": None})
    if not envelope.endswith(b"null}"):  # pragma: no cover - every JSON codec writes null as null
        raise AssertionError(f"unexpected envelope encoding {envelope!r}")
    schema = SCHEMAS[cls]
    write = _dumps if any(holds_mapping(tp) for _, tp in schema) else _write
    if any(nullable_float(tp) for _, tp in schema):  # a non-finite float there would be written as null
        write = _walking(write)
    with BUILDING:
        verify = msgspec.json.Decoder(wire_struct(cls)).decode
    codec = _ENCODERS[cls] = (envelope[: -len(b"null}")], write, verify)
    return codec


def _walking(write: Callable[[Any], bytes]) -> Callable[[Any], bytes]:
    """``write``, after a check in Python (which raises Mismatch): for a class with a float where null is
    allowed too."""

    def checked(msg: Any) -> bytes:
        check(msg, type(msg), load=False)
        return write(msg)

    return checked


def _builder(cls: type[Message]) -> Callable[[bytes | msgspec.Raw], Any]:
    """The long way's decoder of a body into ``cls`` (registered), cached."""
    with BUILDING:
        build: Callable[[bytes | msgspec.Raw], Any] = msgspec.json.Decoder(cls).decode
    _BUILDERS[(cls.TYPE, cls.VERSION)] = build
    return build


def _reader() -> Callable[[bytes], Any]:
    """One decoder of the envelopes of every registered (type, version): a union tagged by ``type``, each arm the
    envelope of one class (that ``v``, its body). A type registered at two versions is left to the long way (a
    tag names one arm)."""
    registry = list(_REGISTRY.items())
    versions = Counter(name for (name, _), _ in registry)
    arms = tuple(
        msgspec.defstruct(f"{cls.__name__}Envelope", [("v", Literal[version]), ("body", cls)], tag_field="type",
                          tag=name, forbid_unknown_fields=True, module=cls.__module__)
        for (name, version), cls in registry if versions[name] == 1
    )
    if not arms:
        return _read_none
    return msgspec.json.Decoder(Union[arms]).decode  # noqa: UP007 - built from a tuple


def _read_none(data: bytes) -> Any:
    raise ValueError("no message type is registered")  # the long way says why ``data`` is refused


_registrations = 0  # how many registrations so far (decode's reader is built for one count)


def _forget(cls: type, key: tuple[str, int]) -> None:
    """Drop what was built for a (re-)registered class and its (type, version); decode's reader is rebuilt."""
    global _read, _registrations
    _ENCODERS.pop(cls, None)
    _BUILDERS.pop(key, None)
    _registrations += 1
    _read = _read_all


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
