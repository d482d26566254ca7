"""The pipe protocol between the Creator and its worker processes (`drd.cluster.workers`), as typed records.

Every message is a frozen dataclass. On the wire it is plain data, pickled: a tuple whose first element is the
message's tag and the others its fields in order (a nested record, `Call`, `Setup` or `CallReply`, is the tuple of
its fields, without a tag). Plain data because a worker runs component code, which may write anything to its
end of the pipe: the Creator reads it with `PlainUnpickler`, which never looks a class up (so nothing a worker
sends can make the Creator build an object), then `decode` checks the tag, the number of fields and the type of
each, and refuses a malformed message by name (`ProtocolError`) instead of mis-indexing it later.

- The Creator sends `Run` (calls of instances of that worker, answered by `Done`), `Drop` (instances to forget,
  no answer), and `Ok` or `Raise` to answer a driver request.
- A worker sends `Ready` once when it starts, then, during a `Run`, any number of driver requests: `DeviceCall`
  and `AttrRead` (each answered `Ok` or `Raise`), `Command` (a setpoint, not answered), and ends with `Done`.

Only `Raise` carries an object (the driver's exception, for the component to see as it would in process). The
Creator is the trusted side: a worker reads what it sends with `decode(data, trusted=True)`, the normal
unpickler. Nothing a worker sends is ever read that way.
"""

from __future__ import annotations

import dataclasses
import io
import pickle
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

PROTOCOL = pickle.HIGHEST_PROTOCOL

#: How a reading read ahead is named on both ends of the pipe (`reading_key`): plain data, hashable.
ReadingKey = tuple[Any, ...]


class ProtocolError(ValueError):
    """A message that is not one of the protocol's: unknown tag, wrong number of fields, a field of a wrong type."""


class PlainUnpickler(pickle.Unpickler):
    """Unpickles plain data only (str, numbers, None, bool, lists, tuples, dicts, sets): never looks a class up."""

    def find_class(self, module: str, name: str) -> Any:
        raise pickle.UnpicklingError(f"{module}.{name}: a component process may send plain data only")


# -- records nested in messages -----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Setup:
    """What a worker needs to build a new instance (sent with its first call): the manifest's entry point, the
    unit bound to each need, and the public methods and the setpoints (sent without waiting) of each need's
    driver, so its device proxy knows what to forward and how."""

    entry_point: str
    resources: dict[str, str]
    methods: dict[str, list[str]]
    commands: dict[str, list[str]]


@dataclass(frozen=True, slots=True)
class Call:
    """One lifecycle call of an instance in a worker (see `drd.cluster.workers.run_calls`): `shared_ids` chain
    shared dicts through a run, `params` come with `start` only, `setup` with an instance's first call, `ahead`
    holds the readings the Creator read ahead of a step (`{reading_key: value}`); `restore`, on a start only:
    `[state]` to give the instance (`Component.restore(state)`, state None: "it was lost") before it starts."""

    path: str
    op: str
    now: float
    status: str
    shared: dict[str, Any] | None
    shared_ids: dict[str, str] | None
    inputs: dict[str, Any] | None
    params: dict[str, Any] | None
    setup: Setup | None
    ahead: dict[ReadingKey, Any] | None
    restore: list[Any] | None = None


@dataclass(frozen=True, slots=True)
class CallReply:
    """What one call did, as `drd.cluster.remote.ComponentReply` carries it; `setup_failed`: the instance could
    not be built (the Creator forgets it); `unused`: the keys of the call's `ahead` it did not read; `snapshot`:
    `[state]` when the instance's snapshot changed since the last one sent (None: unchanged, or not taken);
    `raised`: the `error` is the component's own code raising in the call (any host would run the same code)."""

    status: str = ""
    outputs: dict[str, Any] | None = None
    events: list[list[Any]] = field(default_factory=list)
    logs: list[str] = field(default_factory=list)
    shared: dict[str, Any] | None = None
    dependencies: list[list[Any]] = field(default_factory=list)
    error: str = ""
    setup_failed: bool = False
    unused: list[ReadingKey] = field(default_factory=list)
    snapshot: list[Any] | None = None
    raised: bool = False


# -- the messages ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Run:
    """Creator -> worker: run these calls in order (answered by `Done`); `latest` chains shared dicts across the
    runs of one batch (shared dict id on the controller -> its value after the last step)."""

    calls: tuple[Call, ...]
    latest: dict[str, Any]


@dataclass(frozen=True, slots=True)
class Drop:
    """Creator -> worker: forget these instances (by path); no answer."""

    paths: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Ok:
    """Creator -> worker: a driver request's result. `changed`: the world changed since the readings of this run
    were read ahead (a launch), so the worker asks for every reading from now on."""

    value: Any
    changed: bool = False


@dataclass(frozen=True, slots=True)
class Raise:
    """Creator -> worker: what a driver request raised, raised again in the component (`changed` as in `Ok`)."""

    error: BaseException
    changed: bool = False


@dataclass(frozen=True, slots=True)
class Ready:
    """Worker -> Creator, once: the worker started and waits for messages."""

    pid: int


@dataclass(frozen=True, slots=True)
class DeviceCall:
    """Worker -> Creator: call method `name` of the device bound to `need` of instance `path`; answered."""

    path: str
    need: str
    name: str
    args: tuple[Any, ...] = ()
    kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class AttrRead:
    """Worker -> Creator: read attribute `name` of the device bound to `need` of instance `path`; answered."""

    path: str
    need: str
    name: str


@dataclass(frozen=True, slots=True)
class Command:
    """Worker -> Creator: a setpoint (`name` is one of the driver's setpoints), sent without waiting: it returns
    nothing, and a refusal fails the step when it ends."""

    path: str
    need: str
    name: str
    args: tuple[Any, ...] = ()
    kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Done:
    """Worker -> Creator: a `Run` is over; a reply per call run (a prefix of the calls: a run stops at a call
    that emitted events, changed dependencies or failed)."""

    replies: tuple[CallReply, ...]


Message = Run | Drop | Ok | Raise | Ready | DeviceCall | AttrRead | Command | Done
#: A driver request from a worker.
DeviceRequest = DeviceCall | AttrRead | Command


# -- reading keys -----------------------------------------------------------------------------------------------


def reading_key(req: DeviceCall | AttrRead) -> ReadingKey | None:
    """How the reading `req` asks for is named, the same on both ends of the pipe (its instance aside); None if
    its arguments are not hashable (it is then always asked)."""
    if isinstance(req, AttrRead):
        key: ReadingKey = (_ATTR, req.need, req.name, (), ())
    else:
        key = (_DEV, req.need, req.name, tuple(req.args), tuple(sorted(req.kwargs.items())) if req.kwargs else ())
    try:
        hash(key)
    except TypeError:
        return None
    return key


def reading_request(path: str, key: ReadingKey) -> DeviceCall | AttrRead:
    """The request of instance `path` that reading `key` names (the Creator reads it ahead of a step)."""
    kind, need, name, args, kwargs = key
    if kind == _ATTR:
        return AttrRead(path, need, name)
    return DeviceCall(path, need, name, tuple(args), dict(kwargs))


# -- the wire -----------------------------------------------------------------------------------------------------

_DEV, _ATTR = "dev", "attr"
_TAGS: dict[type[Any], str] = {Run: "run", Drop: "drop", Ok: "ok", Raise: "raise", Ready: "ready",
                               DeviceCall: _DEV, AttrRead: _ATTR, Command: "cmd", Done: "done"}
_BY_TAG = {tag: cls for cls, tag in _TAGS.items()}
_NAMES: dict[type[Any], tuple[str, ...]] = {
    cls: tuple(f.name for f in dataclasses.fields(cls)) for cls in (*_TAGS, Setup, Call, CallReply)}


def encode(msg: Message) -> bytes:
    """`msg` as sent over a worker's pipe: its tag and fields as a tuple of plain data (nested records too),
    pickled. Raises what pickle raises for a value that cannot be pickled (PicklingError, TypeError...)."""
    match msg:
        case Run(calls, latest):
            wire: tuple[Any, ...] = (_TAGS[Run], [_call_wire(c) for c in calls], latest)
        case Done(replies):
            wire = (_TAGS[Done], [_fields(r) for r in replies])
        case _:
            wire = (_TAGS[type(msg)], *_fields(msg))
    return pickle.dumps(wire, PROTOCOL)


def decode(data: bytes, *, trusted: bool = False) -> Message:
    """The message `data` encodes. Plain data only (`PlainUnpickler`: pickle.UnpicklingError for anything that
    names a class), unless `trusted`: for a worker reading what the Creator sent (a `Raise` carries an exception
    object), never for what a worker sent. ProtocolError for an unknown tag, a wrong number of fields or a field
    of a wrong type."""
    wire = pickle.loads(data) if trusted else PlainUnpickler(io.BytesIO(data)).load()
    if not isinstance(wire, tuple) or not wire or not isinstance(wire[0], str):
        raise ProtocolError(f"not a message (a tuple starting with its tag): {_short(wire)}")
    cls = _BY_TAG.get(wire[0])
    if cls is None:
        raise ProtocolError(f"unknown tag {_short(wire[0])}")
    msg: Message = _record(cls, wire[1:], repr(wire[0]))
    return msg


def _fields(record: Any) -> tuple[Any, ...]:
    return tuple(getattr(record, name) for name in _NAMES[type(record)])


def _call_wire(call: Call) -> tuple[Any, ...]:
    setup = _fields(call.setup) if call.setup is not None else None
    return (call.path, call.op, call.now, call.status, call.shared, call.shared_ids, call.inputs, call.params,
            setup, call.ahead, call.restore)


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _record(cls: type[Any], values: Any, where: str) -> Any:
    """A record of class `cls` from its fields on the wire, each checked (and converted) by `_CHECKS[cls]`."""
    names, checks = _NAMES[cls], _CHECKS[cls]
    if not isinstance(values, tuple) or len(values) != len(names):
        count = f"{len(values)} fields" if isinstance(values, tuple) else type(values).__name__
        raise ProtocolError(f"{where} takes {len(names)} fields ({', '.join(names)}), got {count}")
    return cls(*(check(value, f"{where} {name}") for check, name, value in zip(checks, names, values, strict=True)))


# A check takes a field's wire value and where it is (for the error), and returns the field's value.
Check = Callable[[Any, str], Any]


def _is(*types: type) -> Check:
    """The value as it is, if an instance of one of `types`."""
    def check(value: Any, where: str) -> Any:
        if not isinstance(value, types):
            raise ProtocolError(f"{where} must be {' or '.join(_type_name(t) for t in types)},"
                                f" not {type(value).__name__}")
        return value
    return check


def _type_name(t: type) -> str:
    return "None" if t is type(None) else t.__name__


def _seq(*types: type) -> Check:
    """A list or tuple whose items are instances of `types`, as a tuple."""
    item = _is(*types)

    def check(value: Any, where: str) -> tuple[Any, ...]:
        return tuple(item(v, f"{where}[{i}]") for i, v in enumerate(_SEQUENCE(value, where)))
    return check


def _records(cls: type[Any]) -> Check:
    """A list or tuple of records of class `cls`, each as the tuple of its fields."""
    def check(value: Any, where: str) -> tuple[Any, ...]:
        return tuple(_record(cls, v, f"{where}[{i}]") for i, v in enumerate(_SEQUENCE(value, where)))
    return check


def _optional_record(cls: type[Any]) -> Check:
    def check(value: Any, where: str) -> Any:
        return None if value is None else _record(cls, value, where)
    return check


_NONE = type(None)
_ANY, _STR, _BOOL, _DICT, _LIST = _is(object), _is(str), _is(bool), _is(dict), _is(list)
_OPT_DICT, _OPT_LIST, _SEQUENCE = _is(dict, _NONE), _is(list, _NONE), _is(list, tuple)
_CHECKS: dict[type[Any], tuple[Check, ...]] = {
    Setup: (_STR, _DICT, _DICT, _DICT),
    Call: (_STR, _STR, _is(int, float), _STR, _OPT_DICT, _OPT_DICT, _OPT_DICT, _OPT_DICT, _optional_record(Setup),
           _OPT_DICT, _OPT_LIST),
    CallReply: (_STR, _OPT_DICT, _LIST, _LIST, _OPT_DICT, _LIST, _STR, _BOOL, _LIST, _OPT_LIST, _BOOL),
    Run: (_records(Call), _DICT),
    Drop: (_seq(str),),
    Ok: (_ANY, _BOOL),
    Raise: (_is(BaseException), _BOOL),
    Ready: (_is(int),),
    DeviceCall: (_STR, _STR, _STR, _seq(object), _DICT),
    AttrRead: (_STR, _STR, _STR),
    Command: (_STR, _STR, _STR, _seq(object), _DICT),
    Done: (_records(CallReply),),
}
