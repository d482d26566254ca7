"""`Bus.call_reaching`: a call that reached nothing (no route now: a router lost) is asked again until its timeout
or until its callee is down; a callee that got the call and did not answer in time is not asked twice."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from drd.bus import BusTimeout, Ping, Pong, Query
from drd.bus.local import LocalBus


def test_a_call_that_reached_nothing_is_answered_once_the_callee_is_back() -> None:
    bus = LocalBus()
    served: list[Any] = []
    threading.Timer(0.2, lambda: served.append(bus.serve("t/x", lambda q: Pong(7, "back")))).start()
    assert bus.call_reaching("t/x", Ping(7), timeout=5.0) == Pong(7, "back")
    assert served, "answered by the queryable declared 0.2 s after the call"


def test_it_stops_asking_once_the_callee_is_down() -> None:
    bus, asked = LocalBus(), []

    def down() -> bool:
        asked.append(1)
        return len(asked) >= 3
    with pytest.raises(BusTimeout) as err:
        bus.call_reaching("t/x", Ping(1), timeout=5.0, gone=down)
    assert len(asked) == 3 and err.value.unreached, "the third answer of gone() ends it"


def test_after_its_timeout_it_says_how_often_it_asked() -> None:
    with pytest.raises(BusTimeout, match=r"nothing answered there for 0.3 s \(asked \d+ times: no route to it\)"):
        LocalBus().call_reaching("t/x", Ping(1), timeout=0.3)


def test_a_callee_that_took_the_call_and_was_too_slow_is_not_asked_again() -> None:
    """The query reached it and ran out of time (not `unreached`): asking again could run it twice."""
    bus, calls = LocalBus(), []

    def slow(query: Query) -> Pong:
        calls.append(1)
        threading.Event().wait(0.3)
        return Pong(1, "late")
    bus.serve("t/x", slow)
    with pytest.raises(BusTimeout) as err:
        bus.call_reaching("t/x", Ping(1), timeout=0.2)
    assert calls == [1] and not err.value.unreached
