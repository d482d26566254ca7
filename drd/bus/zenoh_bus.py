"""``ZenohBus``: the bus of every multi-process run, over eclipse-zenoh 1.x (a peer by default; a client of the
routers, or a router, when the cluster has routers: ``options={"mode": ...}``).

A thin mapping: ``put`` → ``Session.put``, ``subscribe`` → ``declare_subscriber``, ``serve`` →
``declare_queryable`` (complete), ``request`` → ``Querier.get`` (no consolidation, so every reply comes back;
on a concrete key the complete queryables, on a wildcard all that match; a querier declared per key and timeout,
and kept), tokens →
``Session.liveliness()``. Schema checks and error
containment come from :class:`drd.bus.base.Bus`.

Threading: zenoh calls our callbacks from its own threads. zenoh-python runs the
callbacks of one subscriber/queryable/watcher one at a time (in declaration order for a
given peer), but different ones concurrently, and concurrently with the application's
threads: guard shared state with a lock. A handler may call ``request`` (nested requests
work), but a slow callback delays everything queued behind it on that entity: hand long
work to a thread of your own.

Configuration: the session listens only on the endpoints given (none by default, never the
``tcp/[::]:0`` zenoh would pick), connects to the ones given, and scouts by multicast
only when asked. Authentication (TLS, user/password) goes in ``options`` as zenoh config
paths, e.g. ``{"transport/auth/usrpwd/user": "drd"}``.
"""

from __future__ import annotations

import functools
import json
import re
import threading
import time
from collections.abc import Mapping, Sequence
from typing import Any

import zenoh

from .base import (
    DEFAULT_TIMEOUT,
    Bus,
    BusClosed,
    BusError,
    BusTimeout,
    Handler,
    Queryable,
    RemoteError,
    Reply,
    SampleCallback,
    Subscription,
    Token,
    TokenCallback,
    log,
    )
from .keys import check_key_expr, is_concrete
from .messages import MAX_SIZE, MalformedMessage, Message, decode, encode

#: Seconds a bus waits for its zenoh session to close (a frozen peer would hold it 10 s).
CLOSE_WAIT = 1.0
#: Queriers a bus keeps declared, one per (key, timeout) requested (the oldest is dropped past this).
MAX_QUERIERS = 64


@functools.cache
def zenoh_version() -> str:
    """The installed eclipse-zenoh's version (zenoh-python 1.x has no ``zenoh.__version__``)."""
    from importlib.metadata import PackageNotFoundError, version  # 20 ms: only when asked

    try:
        return version("eclipse-zenoh")
    except PackageNotFoundError:  # pragma: no cover - a build from source
        return "unknown"


def zenoh_logs_from_env() -> None:
    """Let `RUST_LOG` (e.g. `RUST_LOG=zenoh=debug`) turn on zenoh's own logs, for a daemon being debugged."""
    zenoh.try_init_log_from_env()  # type: ignore[no-untyped-call]


def __getattr__(name: str) -> str:
    """``ZENOH_VERSION``, read from the package metadata on first use (a CLI call never needs it)."""
    if name == "ZENOH_VERSION":
        return zenoh_version()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: The largest zenoh message a drd bus session takes in (`transport/link/rx/max_message_size`): a drd message is at most
#: MAX_SIZE, plus its key expression and zenoh's framing. zenoh drops a larger one before reassembling it: a peer's
#: 1 GiB query used to be read whole (2 GiB of RSS at the peak, 1 GiB kept) before the codec refused it.
BUS_MAX_MESSAGE = MAX_SIZE + (64 << 10)
#: zenoh's own default, for sessions that carry other protocols' messages (ROS 2 images may be several MB).
ZENOH_MAX_MESSAGE = 1 << 30

#: Handshakes a session accepts at once, and how long one may take (ms): see `make_config`.
ACCEPT_PENDING, ACCEPT_TIMEOUT_MS = 1024, 5000

_ALL = zenoh.QueryTarget.ALL
#: A request on one concrete key goes to the complete queryables only, which every `serve` declares: a peer's
#: queryable on `drd/<cluster>/**` that never answers (a buggy tool's, zenoh's default is not complete) held every
#: controller call for its whole timeout and wedged the missions (wire audit 10, D1). A wildcard request still
#: asks every matching queryable (a complete one must include the whole of the query's key expression).
_COMPLETE = zenoh.QueryTarget.ALL_COMPLETE
_NO_CONSOLIDATION = zenoh.ConsolidationMode.NONE


def make_config(
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    *,
    multicast_scouting: bool = False,
    lease_ms: int | None = None,
    options: Mapping[str, Any] | None = None,
) -> zenoh.Config:
    """A peer-mode zenoh config listening and connecting exactly where told.

    Raises:
        BusError: zenoh refuses a setting (a malformed endpoint, a bad option), its text without Rust paths.
    """
    config = zenoh.Config()
    settings: dict[str, Any] = {
        "mode": "peer",
        "listen/endpoints": list(listen),
        "connect/endpoints": list(connect),
        "scouting/multicast/enabled": multicast_scouting,
        # No shared-memory transport: each session's pool (16 MB) is mapped by every process on the machine that
        # a large message passes through, a router most of all (+34 MB PSS with 25 clients), for a copy saved on
        # messages that are small and at most 1 MiB (docs/design.md "Load reports in step").
        "transport/shared_memory/enabled": False,
        "transport/link/rx/max_message_size": BUS_MAX_MESSAGE,
        # A TCP connection that never completes a handshake holds one of these slots until the timeout: with zenoh's
        # 100 for 10 s, 110 idle connections from anyone, credentials or not, locked every client and peer out of a
        # daemon (wire audit 25, D1). More slots, held half as long: the bar is raised, not removed (a per-source
        # connection limit in front of the endpoint removes it, docs/security.md).
        "transport/unicast/accept_pending": ACCEPT_PENDING,
        "transport/unicast/accept_timeout": ACCEPT_TIMEOUT_MS,
    }
    if lease_ms is not None:  # how long a silently vanished peer (power cut) keeps its tokens
        settings["transport/link/tx/lease"] = lease_ms
    settings.update(options or {})
    for path, value in settings.items():
        try:
            config.insert_json5(path, json.dumps(value))
        except zenoh.ZError as exc:  # a malformed endpoint or option: the caller's input, not a bug of ours
            raise BusError(f"invalid zenoh setting {path}: {zenoh_text(exc)}") from exc
    return config


class ZenohBus(Bus):
    """A zenoh session (peer by default) behind the Bus interface."""

    def __init__(
        self,
        *,
        listen: Sequence[str] = (),
        connect: Sequence[str] = (),
        multicast_scouting: bool = False,
        lease_ms: int | None = None,
        options: Mapping[str, Any] | None = None,
        config: zenoh.Config | None = None,
        name: str = "",
    ) -> None:
        if config is None:
            config = make_config(
                listen, connect, multicast_scouting=multicast_scouting, lease_ms=lease_ms, options=options
            )
        try:
            self.session = zenoh.open(config)
        except zenoh.ZError as exc:  # a bad endpoint, a port in use, a bad option
            raise BusError(f"cannot open a zenoh session: {zenoh_text(exc)}") from exc
        super().__init__(name or str(self.session.zid()))
        self._lock = threading.Lock()
        self._declared: dict[int, Any] = {}  # keeps zenoh entities referenced (they undeclare when dropped)
        self._queriers: dict[tuple[str, float], zenoh.Querier] = {}  # by (key, timeout), oldest first

    # -- publish/subscribe
    def put_raw(self, key: str, data: bytes) -> None:
        self._check_open()
        check_key_expr(key)
        self._zcall(self.session.put, key, bytes(data))

    def subscribe(self, key_expr: str, callback: SampleCallback) -> Subscription:
        self._check_open()
        check_key_expr(key_expr)

        def on_sample(sample: zenoh.Sample) -> None:
            if sample.kind == zenoh.SampleKind.PUT:
                self._on_sample(callback, str(sample.key_expr), sample.payload.to_bytes())

        sub = self._zcall(self.session.declare_subscriber, key_expr, on_sample)
        return Subscription(key_expr, self._keep(sub))

    # -- query/reply
    def serve(self, key_expr: str, handler: Handler) -> Queryable:
        self._check_open()
        check_key_expr(key_expr)

        def on_query(query: zenoh.Query) -> None:
            try:  # each zenoh property read builds a new object: each is read once
                query_key_expr = query.key_expr
                query_key = str(query_key_expr)
                payload = query.payload
                answer = self._answer(handler, query_key, key_expr, None if payload is None else payload.to_bytes())
                if answer is None:
                    return
                if answer.is_error:
                    query.reply_err(answer.data)
                else:  # the query's own key expression when it is the reply's: zenoh need not parse it again
                    query.reply(query_key_expr if answer.key == query_key else answer.key, answer.data)
            except Exception:  # a closing session, a reply key zenoh refuses: log, never crash
                log.exception("bus %s: could not answer a query on %r", self.name, key_expr,
                              extra={"subject": key_expr})  # the log's limit is per key
            finally:
                query.drop()  # type: ignore[no-untyped-call]  # finalize now, so the requester is not left waiting for a GC

        queryable = self._zcall(self.session.declare_queryable, key_expr, on_query, complete=True)
        return Queryable(key_expr, self._keep(queryable))

    def request_raw(self, key: str, data: bytes | None, timeout: float = DEFAULT_TIMEOUT) -> list[Reply]:
        out: list[Reply] = []
        for item in self._ask(key, data, timeout):
            if isinstance(item, bytes):
                out.append(self._received_reply(key, item, True))
                continue
            reply_key, body = str(item.key_expr), item.payload.to_bytes()
            try:  # a well-formed answer, on the spot; a malformed one through the shared rules
                out.append(Reply(decode(body), reply_key))
            except MalformedMessage:
                out.append(self._received_reply(reply_key, body, False))
        return out

    def call(self, key: str, payload: Message | None = None, timeout: float = DEFAULT_TIMEOUT) -> Message:
        """``Bus.call``, the same answer and errors, without a Reply per answer nor reading its key unless it
        is refused (the call's own path, every step of it cold between two round trips)."""
        answer: Message | None = None
        refused: Reply | None = None  # the first error in arrival order; every answer is still decoded and counted
        asked = time.monotonic()  # for the message of a call nobody answered (40 ns)
        for item in self._ask(key, None if payload is None else encode(payload), timeout):
            if isinstance(item, bytes):
                reply = self._received_reply(key, item, True)
            else:
                body = item.payload.to_bytes()
                try:
                    msg = decode(body)
                except MalformedMessage:  # counted and logged as request_raw does
                    reply = self._received_reply(str(item.key_expr), body, False)
                else:
                    if answer is None:
                        answer = msg
                    continue
            if refused is None:
                refused = reply
        if refused is not None:
            raise RemoteError(refused.key or key, refused.error or "")
        if answer is None:
            raise BusTimeout.after(key, timeout, time.monotonic() - asked)
        return answer

    def _ask(self, key: str, data: bytes | None, timeout: float) -> list[zenoh.Sample | bytes]:
        """The answers to a request on ``key``, in arrival order: each a sample, or an error reply's bytes."""
        if self._closed:  # every step of a request runs cold, between two round trips: the fewest calls
            self._check_open()
        try:
            querier = self._queriers.get((key, timeout))
        except TypeError:  # an unhashable key: refused as a bad key by `_querier`
            querier = None
        if querier is None:
            querier = self._querier(key, timeout)
        try:
            replies = querier.get(payload=data)  # `querier` stays referenced until every reply is read
        except zenoh.ZError as exc:  # the bus closed meanwhile (its queriers are undeclared)
            raise BusError(zenoh_text(exc)) from exc
        arrived: list[zenoh.Sample | bytes] = []
        for reply in replies:  # blocks (GIL released) until every queryable answered or the timeout
            sample = reply.ok
            if sample is not None:
                arrived.append(sample)
                continue
            err = reply.err  # read once: each read builds a new object
            if err is not None:
                body = err.payload.to_bytes()
                if body != b"Timeout":  # zenoh's own marker (encoding varies) for "not all answered in time";
                    arrived.append(body)  # our error replies are always JSON, so this cannot hide one
        # decoded by the caller, once the query is finished: an in-process queryable needs the GIL to finalize it
        return arrived

    def _querier(self, key: str, timeout: float) -> zenoh.Querier:
        """Declare (and keep, at most MAX_QUERIERS) the querier of requests on ``key`` with ``timeout``: zenoh
        parses the key once, not on every request, and the request's options are set once."""
        check_key_expr(key)
        if timeout <= 0:
            raise ValueError(f"timeout must be positive, not {timeout!r}")
        querier: zenoh.Querier = self._zcall(
            self.session.declare_querier, key, target=_COMPLETE if is_concrete(key) else _ALL,
            consolidation=_NO_CONSOLIDATION, timeout=timeout
        )
        evicted = []  # let go once the lock is released: zenoh undeclares a querier when it is no longer referenced
        with self._lock:
            if not self._closed:
                kept = self._queriers.get((key, timeout))
                if kept is not None:  # another thread's, declared meanwhile: ours goes when this returns
                    return kept
                while len(self._queriers) >= MAX_QUERIERS:  # the oldest; a request still using it keeps it
                    evicted.append(self._queriers.pop(next(iter(self._queriers))))
                self._queriers[(key, timeout)] = querier
                return querier
        _undeclare_querier(querier)  # the bus closed meanwhile
        raise BusClosed(f"bus session {self.name} is closed")

    # -- liveliness
    def declare_token(self, key: str) -> Token:
        self._check_open()
        check_key_expr(key, concrete=True)
        token = self._zcall(self.session.liveliness().declare_token, key)
        return Token(key, self._keep(token))

    def watch_tokens(self, key_expr: str, on_change: TokenCallback, history: bool = True) -> Subscription:
        self._check_open()
        check_key_expr(key_expr)

        def on_sample(sample: zenoh.Sample) -> None:
            self._on_token(on_change, str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

        sub = self._zcall(self.session.liveliness().declare_subscriber, key_expr, on_sample, history=history)
        return Subscription(key_expr, self._keep(sub))

    def alive(self, key_expr: str, timeout: float = 1.0) -> list[str]:
        self._check_open()
        check_key_expr(key_expr)
        replies = self._zcall(self.session.liveliness().get, key_expr, timeout=timeout)
        return sorted({str(r.ok.key_expr) for r in replies if r.ok is not None})

    # -- lifetime
    def close(self) -> None:
        """Undeclare everything and close the zenoh session (peers see our tokens vanish)."""
        self.close_within(CLOSE_WAIT)

    def close_within(self, wait: float) -> None:
        """`close`, waiting at most `wait` seconds for the session's close (a client within its `--timeout`: the
        process exits right after, and the OS closes its links anyway)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            declared, self._declared = list(self._declared.values()), {}
            queriers, self._queriers = list(self._queriers.values()), {}
        for querier in queriers:
            _undeclare_querier(querier)
        for entity in reversed(declared):
            try:
                entity.undeclare()
            except zenoh.ZError:
                pass  # already undeclared, or the session went first
        # zenoh's close waits on every peer (10 s, then ZError, for a frozen one): bounded here, so no command and
        # no daemon's stop is held up by a peer that does not answer; the session goes with the process anyway
        closer = threading.Thread(target=self._close_session, name=f"close {self.name}", daemon=True)
        _CLOSERS.append(closer)
        closer.start()
        closer.join(max(0.0, wait))
        if closer.is_alive():
            log.info("bus %s: the session's close still waits on a peer after %g s: going on", self.name, wait)

    def _close_session(self) -> None:
        try:
            self.session.close()  # type: ignore[no-untyped-call]
        except zenoh.ZError as e:  # a peer that never answered: nothing left to do
            log.info("bus %s: closing the session: %s", self.name, e)

    def __repr__(self) -> str:
        return f"ZenohBus({self.name!r}{', closed' if self._closed else ''})"


    # -- helpers
    def _keep(self, entity: Any) -> Any:
        """Hold a zenoh entity until it is closed; the returned closer undeclares it once."""
        with self._lock:
            self._declared[id(entity)] = entity

        def undeclare() -> None:
            with self._lock:
                if self._declared.pop(id(entity), None) is None:
                    return  # the session closed it already
            try:
                entity.undeclare()
            except zenoh.ZError:
                pass

        return undeclare

    def _zcall(self, fn: Any, *args: Any, **kwargs: Any) -> Any:
        """Call zenoh, turning its errors into BusError (ZError means a closed session or a bad key)."""
        try:
            return fn(*args, **kwargs)
        except zenoh.ZError as exc:
            raise BusError(zenoh_text(exc)) from exc


def zenoh_text(error: BaseException) -> str:
    """zenoh's error text without the Rust source locations it appends (` at /root/.cargo/...rs:62.`): a
    BusError's message reaches users and logs, where those say nothing."""
    return re.sub(r"\s+at /\S+\.rs:\d+\.?", "", str(error)).strip()


def _undeclare_querier(querier: zenoh.Querier) -> None:
    try:
        querier.undeclare()  # type: ignore[no-untyped-call]
    except (zenoh.ZError, RuntimeError):  # the session went first; or a request in another thread still sends on
        pass  # it (pyo3's "Already borrowed"): zenoh undeclares it when that request drops it


#: The threads closing sessions (`ZenohBus.close` waits for each at most `CLOSE_WAIT`).
_CLOSERS: list[threading.Thread] = []


def still_closing() -> bool:
    """Whether a session's close still runs in zenoh (a peer that does not answer): a process that ends now must
    end with `os._exit`, or the interpreter's shutdown tears that thread down inside zenoh and the process aborts
    ("FATAL: exception not rethrown")."""
    _CLOSERS[:] = [t for t in _CLOSERS if t.is_alive()]
    return bool(_CLOSERS)
