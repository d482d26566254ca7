"""The request path's own pieces (issue #14): the queriers a ZenohBus keeps, and the values built per request.

`ZenohBus.request_raw` asks through a zenoh Querier declared once per (key, timeout) and kept, at most
`MAX_QUERIERS` of them (the oldest goes first); `Query`, `Reply` and `Sample` are msgspec Structs, built
about six times faster than the frozen dataclasses they were, and still frozen, compared, hashed and shown
alike. The zenoh tests skip when eclipse-zenoh cannot be imported.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import pytest

from drd.bus import BusClosed, BusError, Ping, Pong, Query, Reply, Sample
from tests.net_support import eventually as wait
from tests.net_support import free_port

if TYPE_CHECKING:
    from drd.bus.zenoh_bus import ZenohBus

try:
    import zenoh  # noqa: F401

    ZENOH_ERROR = ""
except ImportError as exc:  # pragma: no cover - depends on the machine
    ZENOH_ERROR = f"eclipse-zenoh cannot be imported ({exc}): pip install eclipse-zenoh"

FAST_OPEN = {"scouting/delay": 50}
WAIT = 5.0


def eventually(predicate: Callable[[], object], what: str, timeout: float = WAIT) -> None:
    """`net_support.eventually`, waiting `WAIT` by default."""
    wait(predicate, what, timeout, poll=0.01)




@pytest.fixture
def peers() -> Iterator[tuple[ZenohBus, ZenohBus]]:
    """A server and a client session, connected; the server answers a Ping on `q/<name>` with Pong(nonce, key)."""
    if ZENOH_ERROR:
        pytest.skip(ZENOH_ERROR)
    from drd.bus.zenoh_bus import ZenohBus

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    server = ZenohBus(listen=[endpoint], options=FAST_OPEN, name="server")
    client = ZenohBus(connect=[endpoint], options=FAST_OPEN, name="client")
    try:
        server.serve("q/*", lambda query: Pong(query.payload.nonce if isinstance(query.payload, Ping) else 0,
                                               query.key))
        eventually(lambda: client.request("q/probe", Ping(0), timeout=0.5), "the server's queryable")
        yield server, client
    finally:
        client.close()
        server.close()


def test_a_querier_is_declared_once_per_key_and_timeout_and_the_oldest_goes_past_the_bound(
        peers: tuple[ZenohBus, ZenohBus], monkeypatch: pytest.MonkeyPatch) -> None:
    from drd.bus import zenoh_bus

    _, client = peers
    monkeypatch.setattr(zenoh_bus, "MAX_QUERIERS", 3)
    assert client.call("q/a", Ping(1), timeout=1.0) == Pong(1, "q/a")
    first = client._queriers[("q/a", 1.0)]
    assert client.call("q/a", Ping(2), timeout=1.0) == Pong(2, "q/a")
    assert client._queriers[("q/a", 1.0)] is first  # kept, not declared again
    assert client.call("q/a", Ping(3), timeout=2.0) == Pong(3, "q/a")  # another timeout: another querier
    for n, name in enumerate("bcd"):
        assert client.call(f"q/{name}", Ping(n), timeout=1.0) == Pong(n, f"q/{name}")
    assert list(client._queriers) == [("q/b", 1.0), ("q/c", 1.0), ("q/d", 1.0)]
    assert client.call("q/a", Ping(4), timeout=1.0) == Pong(4, "q/a")  # dropped, declared again
    assert list(client._queriers) == [("q/c", 1.0), ("q/d", 1.0), ("q/a", 1.0)]


def test_a_request_goes_on_when_its_querier_is_dropped_meanwhile(
        peers: tuple[ZenohBus, ZenohBus], monkeypatch: pytest.MonkeyPatch) -> None:
    from drd.bus import zenoh_bus

    server, client = peers
    monkeypatch.setattr(zenoh_bus, "MAX_QUERIERS", 1)
    started, release = threading.Event(), threading.Event()

    def slow(query: Query) -> Pong:
        if query.payload == Ping(7):
            started.set()
            release.wait(WAIT)
        return Pong(7, "slow")

    server.serve("slow", slow)
    eventually(lambda: client.request("slow", Ping(0), timeout=0.5), "the slow queryable")
    answers: list[object] = []
    asking = threading.Thread(target=lambda: answers.append(client.call("slow", Ping(7), timeout=WAIT)))
    asking.start()
    assert started.wait(WAIT)
    assert client.call("q/other", Ping(1), timeout=1.0) == Pong(1, "q/other")  # drops the querier of "slow"
    assert ("slow", WAIT) not in client._queriers
    release.set()
    asking.join(WAIT)
    assert answers == [Pong(7, "slow")]


def test_closing_undeclares_the_queriers_and_ends_a_request_in_flight(peers: tuple[ZenohBus, ZenohBus]) -> None:
    server, client = peers
    release = threading.Event()
    server.serve("hold", lambda query: Pong(1, "late") if query.payload == Ping(0) or release.wait(WAIT) else None)
    eventually(lambda: client.request("hold", Ping(0), timeout=0.5), "the holding queryable")
    outcome: list[object] = []

    def ask() -> None:
        try:
            outcome.append(client.request("hold", Ping(1), timeout=WAIT))
        except BusError as exc:  # the request's querier undeclared under it
            outcome.append(exc)

    asking = threading.Thread(target=ask)
    asking.start()
    eventually(lambda: ("hold", WAIT) in client._queriers, "the request's querier")
    start = time.monotonic()
    client.close()
    asking.join(WAIT)
    release.set()
    assert not asking.is_alive() and time.monotonic() - start < WAIT / 2
    assert outcome == [[]] or isinstance(outcome[0], BusError)
    assert client._queriers == {}
    with pytest.raises(BusClosed):
        client.request("q/a", Ping(1), timeout=1.0)


def test_the_values_built_per_request_stay_frozen_compared_hashed_and_shown_alike() -> None:
    query = Query("a/b", Ping(1), "a/*")
    assert query == Query("a/b", Ping(1), "a/*") and query != Query("a/b", None, "a/*")
    assert repr(query) == "Query(key='a/b', payload=Ping(nonce=1, sent_at=0.0), queryable='a/*')"
    assert query.reply(Pong(1), "a/b") == Reply(Pong(1), "a/b") and query.error("no") == Reply(error="no")
    reply = Reply(key="a/b", error="refused")
    assert not reply.ok and Reply(Pong(1)).ok and reply.payload is None
    same = Reply(key="a/b", error="refused")
    assert hash(reply) == hash(same) and len({reply, same}) == 1
    sample = Sample("a/b", Ping(2))
    for value, field in ((query, "key"), (reply, "error"), (sample, "payload")):
        with pytest.raises(AttributeError):
            setattr(value, field, None)
