"""The watched robots' telemetry never holds a Creator's reply (found with ROS 2 robots: a driver waiting for its
first message held every gate update past the controller's 1 s): `BackgroundRead` gives this cycle's reading when
it comes within the wait, else the last one."""

from __future__ import annotations

import threading

from drd.cluster.guard import BackgroundRead


def test_a_quick_read_is_fresh_every_time() -> None:
    count = iter(range(100))
    reads = BackgroundRead(lambda: next(count))
    assert [reads.get(5.0) for _ in range(3)] == [0, 1, 2]


def test_a_read_that_waits_gives_the_last_result_and_lands_later() -> None:
    release = threading.Event()
    values = iter(["first", "slow", "third"])

    def read() -> str:
        value = next(values)
        if value == "slow":
            release.wait(10)
        return value

    reads = BackgroundRead(read)
    assert reads.get(5.0) == "first"
    assert reads.get(0.05) == "first"  # the second read waits on its driver: the reply does not
    assert reads.get(0.05) == "first"  # still running: not started twice
    release.set()
    assert reads.get(5.0) in ("slow", "third")  # the slow one landed, or it and the next one


def test_a_read_that_raises_leaves_the_last_result() -> None:
    calls = [0]

    def read() -> int:
        calls[0] += 1
        if calls[0] == 2:
            raise RuntimeError("no message yet")
        return calls[0]

    reads = BackgroundRead(read)
    assert reads.get(5.0) == 1
    assert reads.get(5.0) == 1
    assert reads.get(5.0) == 3
