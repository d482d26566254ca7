"""``Ros2Session``: a zenoh session that speaks rmw_zenoh, the counterpart of an rmw context.

Followed, in rmw_zenoh_cpp (the zenoh 1.x code of Jazzy): ``src/detail/rmw_context_impl_s.cpp`` (one entity
counter per session, from 0, shared by its nodes, publishers and subscriptions: the ids in the tokens) and
``src/detail/zenoh_router_check.cpp`` (a ROS 2 node wants a zenoh *router*: a session that ROS 2 nodes and tools
connect to, :meth:`Ros2Session.listen`, runs in router mode). The session itself is a :class:`ZenohBus`, opened
and closed (bounded) as every drd bus is; one can be borrowed from a daemon.
"""

from __future__ import annotations

import itertools
import logging
import queue
import threading
import weakref
from collections.abc import Callable, Iterator, Mapping, Sequence
from types import TracebackType
from typing import Any, Self

import zenoh

from drd.bus.base import BusError
from drd.bus.zenoh_bus import ZENOH_MAX_MESSAGE, ZenohBus, zenoh_text

from .msgtypes import MessageTypes, jazzy
from .names import ADMIN_SPACE, GraphEntity, parse_token

#: A ROS 2 session takes in what ROS 2 nodes send (an image may be several MB), not drd's 1 MiB bus messages.
ROS2_OPTIONS: dict[str, Any] = {"transport/link/rx/max_message_size": ZENOH_MAX_MESSAGE}

log = logging.getLogger("drd.bus.ros2")

#: One entity counter per zenoh session, as per rmw context: ids in tokens never repeat within a zid.
_COUNTERS: weakref.WeakKeyDictionary[ZenohBus, Iterator[int]] = weakref.WeakKeyDictionary()
_COUNTERS_LOCK = threading.Lock()


def zenoh_call(what: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Call zenoh, turning its errors (a closed session, a refused key) into BusError."""
    try:
        return fn(*args, **kwargs)
    except zenoh.ZError as exc:
        raise BusError(f"{what}: {zenoh_text(exc)}") from exc


def undeclare(entity: Any) -> None:
    """Undeclare a zenoh entity, once or after its session: never raises."""
    try:
        entity.undeclare()
    except zenoh.ZError:
        pass  # already undeclared, or its session closed first


class Dispatcher:
    """Runs a session's subscription callbacks, in arrival order, on one Python thread of its own.

    zenoh-python's default runs each subscriber's callbacks on a thread per subscriber (a robot's 30 topics: 30
    threads woken per control cycle, each waiting for the GIL); here zenoh's receiving thread only queues the sample
    (`handler`, never blocking on a lock of ours) and one thread takes them in turn: one wake-up per burst.
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self._queue: queue.SimpleQueue[tuple[Callable[[Any], None], Any] | None] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._closed = False

    def handler(self, callback: Callable[[Any], None]) -> zenoh.handlers.Callback[Any]:
        """A zenoh handler that queues `callback(sample)` for this dispatcher's thread (started on first use)."""
        with self._lock:
            if self._thread is None and not self._closed:
                self._thread = threading.Thread(target=self._run, name=f"drd ros2 {self.name}", daemon=True)
                self._thread.start()
        put = self._queue.put
        return zenoh.handlers.Callback(lambda sample: put((callback, sample)), indirect=False)

    def _run(self) -> None:
        get = self._queue.get
        while (item := get()) is not None:
            callback, sample = item
            try:
                callback(sample)
            except Exception:  # a callback's own error: logged, the others still run
                key = str(getattr(sample, "key_expr", ""))
                log.exception("ros2 %s: a subscription callback raised on %s", self.name, key,
                              extra={"subject": key})  # the log's limit is per key

    def close(self) -> None:
        """Stop the thread once the samples already queued have run (not waited for: a callback may be the closer)."""
        with self._lock:
            self._closed = True
            thread, self._thread = self._thread, None
        if thread is not None:
            self._queue.put(None)


class Ros2Session:
    """A zenoh session speaking rmw_zenoh (the counterpart of an rmw context); holds or borrows a ZenohBus."""

    def __init__(self, bus: ZenohBus, *, owned: bool = False, types: MessageTypes | None = None,
                 one_thread: bool = False) -> None:
        self.bus = bus
        self.owned = owned
        self.types = types if types is not None else jazzy()
        with _COUNTERS_LOCK:
            self._ids = _COUNTERS.setdefault(bus, itertools.count())
        #: `one_thread`: the subscriptions' callbacks run on one thread of the session (`Dispatcher`), for a process
        #: whose every callback is short and never waits (the dry-run's lockstep); else on zenoh's thread per
        #: subscription, so a callback that waits (a read waiting for a first message) holds up no other topic.
        self.dispatcher = Dispatcher(bus.name or "session") if one_thread else None

    @classmethod
    def connect(cls, endpoints: str | Sequence[str], *, options: Mapping[str, Any] | None = None,
                types: MessageTypes | None = None, one_thread: bool = False) -> Ros2Session:
        """A client session of the robot's zenoh router (e.g. ``tcp/192.168.1.20:7447``), as drd's drivers use."""
        connect = [endpoints] if isinstance(endpoints, str) else list(endpoints)
        bus = ZenohBus(connect=connect, options={"mode": "client", **ROS2_OPTIONS, **(options or {})},
                       name="ros2 client")
        return cls(bus, owned=True, types=types, one_thread=one_thread)

    @classmethod
    def listen(cls, endpoints: str | Sequence[str], *, mode: str = "router",
               options: Mapping[str, Any] | None = None, types: MessageTypes | None = None,
               one_thread: bool = False) -> Ros2Session:
        """A session that ROS 2 nodes and tools connect to, as to a robot's router (the served simulator)."""
        listen = [endpoints] if isinstance(endpoints, str) else list(endpoints)
        bus = ZenohBus(listen=listen, options={"mode": mode, **ROS2_OPTIONS, **(options or {})}, name=f"ros2 {mode}")
        return cls(bus, owned=True, types=types, one_thread=one_thread)

    @property
    def session(self) -> zenoh.Session:
        return self.bus.session

    @property
    def zid(self) -> str:
        """The session id as tokens carry it (zenoh's own text form of the id, as ``zenoh::Id::to_string``)."""
        return str(self.bus.session.zid())

    def next_id(self) -> int:
        with _COUNTERS_LOCK:
            return next(self._ids)

    def graph(self, domain_id: int = 0, timeout: float = 1.0) -> list[GraphEntity]:
        """Every node, publisher and subscription of a ROS domain (a liveliness query, as ``ros2 topic list``)."""
        replies = zenoh_call("graph query", self.session.liveliness().get, f"{ADMIN_SPACE}/{domain_id}/**",
                             timeout=timeout)
        entities = (parse_token(str(r.ok.key_expr)) for r in replies if r.ok is not None)
        return [e for e in entities if e is not None]

    def close(self) -> None:
        """Stop the callbacks' thread; close the zenoh session if this object opened it (bounded, as ZenohBus
        closes)."""
        if self.dispatcher is not None:
            self.dispatcher.close()
        if self.owned:
            self.bus.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        self.close()
