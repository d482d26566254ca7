"""`missionctl run`'s Ctrl-C handling (`drd.cli.cluster._interrupt_once`), with real signals to this process: the
first interrupt raises, its second delivery within the window is ignored, and once the stop is over nothing raises
(CI saw the client die of SIGINT, exit -2, on a second delivery held through the stop's call on a busy machine)."""

from __future__ import annotations

import signal
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
