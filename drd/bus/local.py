"""``LocalBus``: the in-process, deterministic bus of the embedded dry-run and the unit tests.

A product feature, not a test double: a dry-run of a whole cluster runs its daemons as
``LocalBus`` sessions on one :class:`LocalNetwork` (one session per simulated host), with the
same key expressions, messages and schema checks as over zenoh.

Determinism: every operation completes before it returns. ``put`` calls the matching
subscribers, ``request`` the matching queryables, ``declare_token``/``Token.close`` the
matching watchers, synchronously in the caller's thread and in declaration order (the
order in which subscriptions, queryables, watchers and tokens were declared across the
whole network). Entities declared while a delivery is running do not see that delivery.
Each message is still encoded and decoded on every hop, so a dry-run rejects what a real
cluster would reject.

Thread safety: the network's tables are guarded by a lock; callbacks run outside it, in
the thread that called ``put``/``request``/..., so they may use the bus themselves.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .base import (
    DEFAULT_TIMEOUT,
    Bus,
    Handler,
    Queryable,
    Reply,
    SampleCallback,
    Subscription,
    Token,
    TokenCallback,
)
from .keys import check_key_expr, intersects

log = logging.getLogger("drd.bus")


@dataclass(slots=True)
class _Entry:
    owner: LocalBus
    key_expr: str
    callback: Any
    live: bool = True


class LocalNetwork:
    """The medium several LocalBus sessions share: one per simulated cluster."""

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._seq = itertools.count()
        self._names = itertools.count(1)
        # insertion-ordered: iteration order is declaration order, which makes delivery deterministic
        self._subs: dict[int, _Entry] = {}
        self._queryables: dict[int, _Entry] = {}
        self._tokens: dict[int, _Entry] = {}
        self._watchers: dict[int, _Entry] = {}

    def session(self, name: str = "") -> LocalBus:
        """A new session on this network (one per simulated host or process)."""
        return LocalBus(self, name)

    def _next_name(self) -> str:
        return f"local{next(self._names)}"

    def _add(self, table: dict[int, _Entry], entry: _Entry) -> int:
        with self._lock:
            seq = next(self._seq)
            table[seq] = entry
            return seq

    def _remove(self, table: dict[int, _Entry], seq: int) -> _Entry | None:
        with self._lock:
            entry = table.pop(seq, None)
            if entry is not None:
                entry.live = False
            return entry

    def _closer(self, table: dict[int, _Entry], seq: int) -> Callable[[], None]:
        def close() -> None:
            self._remove(table, seq)

        return close

    def _match(self, table: dict[int, _Entry], key: str) -> list[_Entry]:
        with self._lock:
            return [e for e in table.values() if intersects(e.key_expr, key)]

    def _owned(self, table: dict[int, _Entry], owner: LocalBus) -> list[int]:
        with self._lock:
            return [seq for seq, e in table.items() if e.owner is owner]

    def _token_changed(self, key: str, alive: bool) -> None:
        for watcher in self._match(self._watchers, key):
            if watcher.live:
                watcher.owner._on_token(watcher.callback, key, alive)


class LocalBus(Bus):
    """A session on a :class:`LocalNetwork` (a private one if none is given)."""

    def __init__(self, network: LocalNetwork | None = None, name: str = "") -> None:
        self.network = network if network is not None else LocalNetwork()
        super().__init__(name or self.network._next_name())

    def put_raw(self, key: str, data: bytes) -> None:
        self._check_open()
        check_key_expr(key)
        for sub in self.network._match(self.network._subs, key):
            if sub.live:
                sub.owner._on_sample(sub.callback, key, bytes(data))

    def subscribe(self, key_expr: str, callback: SampleCallback) -> Subscription:
        self._check_open()
        check_key_expr(key_expr)
        net = self.network
        seq = net._add(net._subs, _Entry(self, key_expr, callback))
        return Subscription(key_expr, net._closer(net._subs, seq))

    def serve(self, key_expr: str, handler: Handler) -> Queryable:
        self._check_open()
        check_key_expr(key_expr)
        net = self.network
        seq = net._add(net._queryables, _Entry(self, key_expr, handler))
        return Queryable(key_expr, net._closer(net._queryables, seq))

    def request_raw(self, key: str, data: bytes | None, timeout: float = DEFAULT_TIMEOUT) -> list[Reply]:
        """Ask each matching queryable in turn; an answer produced after the deadline is dropped,
        and queryables not yet asked by then are skipped, as a zenoh querier would drop them."""
        self._check_open()
        check_key_expr(key)
        if timeout <= 0:
            raise ValueError(f"timeout must be positive, not {timeout!r}")
        deadline = time.monotonic() + timeout
        replies: list[Reply] = []
        for queryable in self.network._match(self.network._queryables, key):
            if time.monotonic() > deadline:
                break
            if not queryable.live:
                continue
            answer = queryable.owner._answer(queryable.callback, key, queryable.key_expr, data)
            if answer is None:
                continue
            if time.monotonic() > deadline:
                log.debug("bus %s: late reply from %r dropped", self.name, queryable.key_expr)
                continue
            replies.append(self._received_reply(key if answer.is_error else answer.key, answer.data, answer.is_error))
        return replies

    def declare_token(self, key: str) -> Token:
        self._check_open()
        check_key_expr(key, concrete=True)
        net = self.network
        seq = net._add(net._tokens, _Entry(self, key, None))
        net._token_changed(key, True)
        return Token(key, lambda: self._drop_token(seq))

    def _drop_token(self, seq: int) -> None:
        entry = self.network._remove(self.network._tokens, seq)
        if entry is not None:
            self.network._token_changed(entry.key_expr, False)

    def watch_tokens(self, key_expr: str, on_change: TokenCallback, history: bool = True) -> Subscription:
        self._check_open()
        check_key_expr(key_expr)
        net = self.network
        entry = _Entry(self, key_expr, on_change)
        with net._lock:
            existing = [t.key_expr for t in net._tokens.values() if intersects(key_expr, t.key_expr)]
            seq = net._add(net._watchers, entry)
        if history:
            for key in existing:
                if entry.live:
                    self._on_token(on_change, key, True)
        return Subscription(key_expr, net._closer(net._watchers, seq))

    def alive(self, key_expr: str, timeout: float = 1.0) -> list[str]:
        self._check_open()
        check_key_expr(key_expr)
        return sorted({t.key_expr for t in self.network._match(self.network._tokens, key_expr)})

    def close(self) -> None:
        """Drop this session's subscriptions, queryables and watchers, then its tokens
        (other sessions' watchers see them gone, in declaration order)."""
        if self._closed:
            return
        self._closed = True
        net = self.network
        with net._lock:
            for table in (net._subs, net._queryables, net._watchers):
                for seq in net._owned(table, self):
                    net._remove(table, seq)
            tokens = net._owned(net._tokens, self)
        for seq in tokens:
            self._drop_token(seq)

    def __repr__(self) -> str:
        return f"LocalBus({self.name!r}{', closed' if self._closed else ''})"
