"""The one ``Bus`` interface every drd process talks through, shaped after zenoh 1.x.

Two implementations: :class:`drd.bus.local.LocalBus` (in-process, deterministic: dry-runs
and unit tests) and :class:`drd.bus.zenoh_bus.ZenohBus` (every multi-process run). Both pass
``tests/e2e/test_bus_contract.py``. The receive-side rules live here, once, so they cannot
drift: decode on receipt, reject/log/count malformed bytes, turn handler exceptions into
error replies, never let a callback take the bus down.
"""

from __future__ import annotations

import logging
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, fields
from types import TracebackType
from typing import Self, TypeVar

import msgspec

from drd.errors import BusFailure

from .keys import intersects, is_concrete, valid_key
from .messages import ErrorReply, MalformedMessage, Message, decode, encode

M = TypeVar("M", bound=Message)

log = logging.getLogger("drd.bus")

DEFAULT_TIMEOUT = 2.0
#: Seconds between two asks of a call that reached nothing (`Bus.call_reaching`).
REASK = 0.05
#: zenoh's `connect/retry`: dial a lost or not yet started peer again each second, not backing off to zenoh's
#: default of up to 4 s, so a daemon started before the one it dials meets it within a second, and a client
#: following a mission hears a restarted controller within a second of its coming back (it said "back after 7.0 s"
#: for 4.2 s away: faults audit 23, #3). Here, not in `zenoh_bus`, so that naming it imports no zenoh.
RECONNECT_EACH_SECOND: dict[str, object] = {"period_init_ms": 1000, "period_max_ms": 1000, "period_increase_factor": 1}


class BusError(BusFailure):
    """Base of the bus's own errors."""


class BusClosed(BusError):
    """The session was closed; declare a new one."""


class BusTimeout(BusError):
    """No reply arrived before the timeout (nobody serves the key, or it was too slow). `unreached`: the query ended
    well before its timeout, so it reached nothing that answers now (no queryable, or no route to one: a router
    down); a caller may ask again (`after`)."""

    def __init__(self, message: str, unreached: bool = False) -> None:
        super().__init__(message)
        self.unreached = unreached

    @classmethod
    def after(cls, key: str, timeout: float, waited: float) -> BusTimeout:
        """The error of a call to `key` that got no answer after `waited` of its `timeout` seconds."""
        if waited < 0.9 * timeout:
            return cls(f"no reply on {key!r}: nothing answers there now (the query ended after {waited:.1f} s, before"
                       f" its {timeout:g} s timeout)", unreached=True)
        return cls(f"no reply on {key!r} within {timeout:g} s")


class RemoteError(BusError):
    """The queryable answered with an error (its handler raised, or it rejected the request)."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(f"{key}: {reason}")
        self.key, self.reason = key, reason


# --- values handed to user code ---------------------------------------------------------------


# msgspec Structs, not dataclasses: built on every request and reply, in about a sixth of the time (a frozen
# dataclass's __init__ sets each field through object.__setattr__); frozen, compared, hashed and shown alike.


class Sample(msgspec.Struct, frozen=True):
    """A publication as a subscriber sees it: the concrete key and the decoded message."""

    key: str
    payload: Message


class Reply(msgspec.Struct, frozen=True):
    """One answer to a request: ``payload`` on success, ``error`` (a reason) on failure.

    A handler returns ``Reply(payload)`` (or just the message), ``Reply(error=...)`` to refuse,
    or None to stay silent. ``key`` defaults to the query's key (or the queryable's, when the
    query has wildcards); an explicit key must intersect the query's key expression.
    """

    payload: Message | None = None
    key: str | None = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


class Query(msgspec.Struct, frozen=True):
    """A request as a queryable sees it; ``payload`` is None for a request without one."""

    key: str
    payload: Message | None
    queryable: str

    def reply(self, payload: Message, key: str | None = None) -> Reply:
        return Reply(payload, key)

    def error(self, reason: str) -> Reply:
        return Reply(error=reason)


Handler = Callable[[Query], "Reply | Message | None"]


def typed_handler(want: type[M], handle: Callable[[M], Message], refused: tuple[type[Exception], ...] = (),
                  *, exact: bool = True) -> Handler:
    """A handler for one request type: a query by a wildcard key (`exact`) or with another payload is answered with
    an error saying what to send, and an exception of `refused` (the request's own fault) becomes the error reply;
    anything else propagates to the bus's containment."""
    def serve(query: Query) -> Reply | Message:
        if exact and not is_concrete(query.key):
            return query.error(f"ask {query.queryable} by its exact key")
        if not isinstance(query.payload, want):
            return query.error(f"expected a {want.TYPE}")
        try:
            return handle(query.payload)
        except refused as e:
            return query.error(str(e))
    return serve
SampleCallback = Callable[[Sample], None]
TokenCallback = Callable[[str, bool], None]


class Declaration:
    """Something declared on a bus (subscription, queryable, token); ``close()`` is idempotent."""

    def __init__(self, key_expr: str, undeclare: Callable[[], None]) -> None:
        self.key_expr = key_expr
        self._undeclare: Callable[[], None] | None = undeclare
        self._lock = threading.Lock()

    @property
    def closed(self) -> bool:
        return self._undeclare is None

    def close(self) -> None:
        with self._lock:
            undeclare, self._undeclare = self._undeclare, None
        if undeclare is not None:
            undeclare()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.key_expr!r}{', closed' if self.closed else ''})"


class Subscription(Declaration):
    """A subscriber (to publications or to liveliness changes)."""


class Queryable(Declaration):
    """A served key expression."""


class Token(Declaration):
    """A liveliness token: alive while declared and while its session lives."""


@dataclass
class BusStats:
    """Counters a daemon exposes in ``status``; updated from any thread."""

    malformed: int = 0
    handler_errors: int = 0
    callback_errors: int = 0

    def __post_init__(self) -> None:
        self._lock = threading.Lock()

    def bump(self, name: str) -> None:
        with self._lock:
            setattr(self, name, getattr(self, name) + 1)

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


# --- the interface -----------------------------------------------------------------------------


class Bus(ABC):
    """A session on the drd bus: publish/subscribe, query/reply, liveliness.

    Payloads are :class:`~drd.bus.messages.Message` objects, encoded on send and decoded
    (schema-checked) on receipt. Callbacks and handlers must be quick: hand long work to
    a thread of your own. See docs/bus.md for threading and key layout.
    """

    def __init__(self, name: str = "") -> None:
        self.name = name
        self.stats = BusStats()
        self._closed = False

    # -- publish/subscribe
    def put(self, key: str, payload: Message) -> None:
        """Publish ``payload`` on ``key`` to every matching subscriber (fire and forget)."""
        self.put_raw(key, encode(payload))

    @abstractmethod
    def put_raw(self, key: str, data: bytes) -> None:
        """Publish bytes unchecked: for tools and fault-injection tests; receivers still check."""

    @abstractmethod
    def subscribe(self, key_expr: str, callback: SampleCallback) -> Subscription:
        """Call ``callback(Sample)`` for every well-formed publication matching ``key_expr``."""

    # -- query/reply
    @abstractmethod
    def serve(self, key_expr: str, handler: Handler) -> Queryable:
        """Answer requests matching ``key_expr`` with ``handler(Query)``."""

    def request(self, key: str, payload: Message | None = None, timeout: float = DEFAULT_TIMEOUT) -> list[Reply]:
        """All replies from every matching queryable that arrive within ``timeout`` seconds."""
        return self.request_raw(key, None if payload is None else encode(payload), timeout)

    @abstractmethod
    def request_raw(self, key: str, data: bytes | None, timeout: float = DEFAULT_TIMEOUT) -> list[Reply]:
        """``request`` with unchecked bytes: for tools and fault-injection tests."""

    def call(self, key: str, payload: Message | None = None, timeout: float = DEFAULT_TIMEOUT) -> Message:
        """The one answer to a request: the first successful reply.

        Raises RemoteError if a queryable answered with an error, BusTimeout if none answered. Asks through
        ``request_raw`` as ``request`` does, one step fewer on every call (a subclass changes ``request_raw``).
        """
        answer: Message | None = None
        asked = time.monotonic()
        for reply in self.request_raw(key, None if payload is None else encode(payload), timeout):
            if reply.error is not None:  # any error wins, the first one in arrival order
                raise RemoteError(reply.key or key, reply.error)
            if answer is None:
                answer = reply.payload
        if answer is None:
            raise BusTimeout.after(key, timeout, time.monotonic() - asked)
        return answer

    def call_reaching(self, key: str, payload: Message | None, timeout: float,
                      gone: Callable[[], bool] = lambda: False) -> Message:
        """`call`, asked again every `REASK` seconds while it reaches nothing (`BusTimeout.unreached`: no route
        now; with two routers, the one on the way was lost and the routes come back through the other in a
        moment), until `timeout` or until `gone()` (the cluster view has the callee down: its token vanished
        where no router brings it back). Asking again does nothing twice: nothing saw the query."""
        deadline = time.monotonic() + timeout
        left, asks = timeout, 1
        while True:
            try:
                return self.call(key, payload, timeout=left)
            except BusTimeout as e:
                if not e.unreached or gone():
                    raise
                if time.monotonic() + 2 * REASK > deadline:
                    raise BusTimeout(f"no reply on {key!r}: nothing answered there for {timeout:g} s (asked {asks}"
                                     " times: no route to it)", unreached=True) from None
            time.sleep(REASK)
            asks += 1
            left = deadline - time.monotonic()

    # -- liveliness
    @abstractmethod
    def declare_token(self, key: str) -> Token:
        """Announce presence on ``key`` (concrete, unique in the cluster) until closed."""

    @abstractmethod
    def watch_tokens(self, key_expr: str, on_change: TokenCallback, history: bool = True) -> Subscription:
        """Call ``on_change(key, alive)`` when tokens matching ``key_expr`` appear or vanish.

        With ``history`` the tokens alive now are replayed first as ``alive=True``.
        """

    @abstractmethod
    def alive(self, key_expr: str, timeout: float = 1.0) -> list[str]:
        """The keys of the tokens alive now matching ``key_expr``, sorted."""

    # -- lifetime
    @abstractmethod
    def close(self) -> None:
        """Undeclare everything this session declared (its tokens vanish); idempotent."""

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise BusClosed(f"bus session {self.name or id(self)} is closed")

    # -- receive-side rules shared by the implementations
    def _reject(self, where: str, key: str, reason: str) -> None:
        self.stats.bump("malformed")
        log.warning("bus %s: rejected malformed %s on %r: %s", self.name, where, key, reason,
                    extra={"subject": key})  # the log's limit is per key (drd.daemon.logs.RateLimit)

    def _on_sample(self, callback: SampleCallback, key: str, data: bytes) -> None:
        """Decode a publication and hand it to the callback; never raises."""
        try:
            msg = decode(data)
        except MalformedMessage as exc:
            self._reject("publication", key, exc.reason)
            return
        try:
            callback(Sample(key, msg))
        except Exception:
            self.stats.bump("callback_errors")
            log.exception("bus %s: subscriber callback on %r raised", self.name, key, extra={"subject": key})

    def _on_token(self, callback: TokenCallback, key: str, alive: bool) -> None:
        try:
            callback(key, alive)
        except Exception:
            self.stats.bump("callback_errors")
            log.exception("bus %s: token watcher on %r raised", self.name, key, extra={"subject": key})

    def _answer(self, handler: Handler, query_key: str, queryable: str, data: bytes | None) -> Answer | None:
        """Run a handler on raw request bytes; the answer to send back, or None for silence.

        Never raises: malformed requests and handler exceptions become error answers. On every
        request's path: a handler's plain message reply takes the fewest steps.
        """
        default_key = query_key if "*" not in query_key or "*" in queryable else queryable
        try:
            payload = None if data is None else decode(data)
        except MalformedMessage as exc:
            self._reject("request", query_key, exc.reason)
            return Answer.failure(default_key, f"malformed request: {exc.reason}")
        try:
            result = handler(Query(query_key, payload, queryable))
        except Exception as exc:
            self.stats.bump("handler_errors")
            log.exception("bus %s: handler for %r raised on %r", self.name, queryable, query_key,
                          extra={"subject": query_key})
            return Answer.failure(default_key, f"{type(exc).__name__}: {exc}")
        key = default_key
        if not isinstance(result, Message):
            if result is None:
                return None
            if isinstance(result, Reply):
                key = result.key or default_key
                if result.error is not None:
                    return Answer.failure(key, result.error)
                if result.key is not None and not (valid_key(result.key) and intersects(result.key, query_key)):
                    return Answer.failure(key, f"reply key {result.key!r} does not match the query {query_key!r}")
                result = result.payload
            if not isinstance(result, Message):
                self.stats.bump("handler_errors")
                return Answer.failure(key, f"handler returned {type(result).__name__}, not a message")
        try:
            return Answer(key, encode(result), False)
        except MalformedMessage as exc:
            self.stats.bump("handler_errors")
            return Answer.failure(key, f"handler returned a malformed reply: {exc.reason}")

    def _received_reply(self, key: str, data: bytes, is_error: bool) -> Reply:
        """Decode a reply's bytes into a Reply; malformed ones become error replies, counted."""
        try:
            msg = decode(data)
        except MalformedMessage as exc:
            self._reject("error reply" if is_error else "reply", key, exc.reason)
            return Reply(key=key, error=f"malformed reply: {exc.reason}")
        if is_error:
            return Reply(key=key, error=msg.reason if isinstance(msg, ErrorReply) else repr(msg))
        return Reply(msg, key)


class BusWrapper(Bus):
    """A bus that hands everything to `inner` but what a subclass changes (a controller's fenced bus, the
    executive's serialized one). Closing it does not close `inner`: whoever made `inner` owns it."""

    def __init__(self, inner: Bus) -> None:
        super().__init__(inner.name)
        self.inner = inner
        self.stats = inner.stats

    def put_raw(self, key: str, data: bytes) -> None:
        self.inner.put_raw(key, data)

    def subscribe(self, key_expr: str, callback: SampleCallback) -> Subscription:
        return self.inner.subscribe(key_expr, callback)

    def serve(self, key_expr: str, handler: Handler) -> Queryable:
        return self.inner.serve(key_expr, handler)

    def request_raw(self, key: str, data: bytes | None, timeout: float = DEFAULT_TIMEOUT) -> list[Reply]:
        return self.inner.request_raw(key, data, timeout)

    def declare_token(self, key: str) -> Token:
        return self.inner.declare_token(key)

    def watch_tokens(self, key_expr: str, on_change: TokenCallback, history: bool = True) -> Subscription:
        return self.inner.watch_tokens(key_expr, on_change, history)

    def alive(self, key_expr: str, timeout: float = 1.0) -> list[str]:
        return self.inner.alive(key_expr, timeout)

    def close(self) -> None:
        self._closed = True


class Answer(msgspec.Struct, frozen=True, gc=False):
    """The wire form of a handler's reply: what the implementations send back (built on every request; holds no
    container, so the garbage collector need not track it)."""

    key: str
    data: bytes
    is_error: bool

    @staticmethod
    def failure(key: str, reason: str) -> Answer:
        if len(reason) > 4096:
            reason = reason[:4093] + "..."
        return Answer(key, encode(ErrorReply(reason)), True)
