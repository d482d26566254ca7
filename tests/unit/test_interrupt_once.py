"""`missionctl run`'s Ctrl-C handling (`drd.cli.cluster._interrupt_once`), with real signals to this process: the
first interrupt raises, its second delivery within the window is ignored, and once the stop is over nothing raises
(CI saw the client die of SIGINT, exit -2, on a second delivery held through the stop's call on a busy machine)."""

from __future__ import annotations

import ctypes
import signal
import threading
import time
from collections.abc import Iterator

import pytest

from drd.cli import cluster


@pytest.fixture(autouse=True)
def python_sigint() -> Iterator[None]:
    previous = signal.getsignal(signal.SIGINT)
    yield
    signal.signal(signal.SIGINT, previous)


def test_the_first_interrupt_raises_and_its_second_delivery_is_ignored() -> None:
    with cluster._interrupt_once() as taken:
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGINT)  # within SAME_INTERRUPT: the same Ctrl-C
    assert len(taken) == 1


def test_an_interrupt_after_the_stop_is_over_is_ignored(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(cluster, "SAME_INTERRUPT", 0.0)  # a late delivery: past the window
    with cluster._interrupt_once() as taken:
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt):  # during the stop: gives up waiting for the report
            signal.raise_signal(signal.SIGINT)
    signal.raise_signal(signal.SIGINT)  # the handler stays, and raises nothing now: the process is ending
    assert len(taken) == 2


def test_without_an_interrupt_the_previous_handler_comes_back() -> None:
    before = signal.getsignal(signal.SIGINT)
    with cluster._interrupt_once():
        assert signal.getsignal(signal.SIGINT) is not before
    assert signal.getsignal(signal.SIGINT) is before


def test_a_second_delivery_whose_handler_runs_late_is_still_the_same_ctrl_c() -> None:
    """The stop's call blocks the main thread (a C call, here libc's usleep) while the second delivery comes, 0.1 s
    after the first, to another thread: its handler runs only after the call, 2 s on. What counts is when it came."""
    libc = ctypes.CDLL(None)
    with cluster._interrupt_once() as taken:
        sent = threading.Event()

        def deliver_twice() -> None:
            signal.pthread_kill(threading.get_ident(), signal.SIGINT)  # to this thread: the main one is not woken
            sent.set()
            time.sleep(0.1)
            signal.pthread_kill(threading.get_ident(), signal.SIGINT)

        sender = threading.Thread(target=deliver_twice)
        with pytest.raises(KeyboardInterrupt):
            sender.start()
            while True:  # back in the interpreter every millisecond: the first's handler runs at once
                time.sleep(0.001)
        sender_done = sent.wait(5.0)
        try:
            libc.usleep(2_000_000)  # the stop's call: the second's handler waits for it to return
            time.sleep(0.01)  # back in the interpreter: the second's handler has run
        except KeyboardInterrupt:
            pytest.fail("the second delivery of one Ctrl-C, handled 2 s after the first, was taken for another")
        sender.join()
    assert sender_done and len(taken) == 1


def test_a_ctrl_c_pressed_again_later_still_raises() -> None:
    """The window is from when the first came: a press a window later is the operator's second."""
    with cluster._interrupt_once() as taken:
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
        time.sleep(cluster.SAME_INTERRUPT + 0.1)
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
    assert len(taken) == 2 and taken[1] - taken[0] >= cluster.SAME_INTERRUPT
