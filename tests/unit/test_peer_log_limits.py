"""What peers send is logged at most 10 lines of a kind per 10 s, on every logger that reports it (clients audit: a
1 kHz publisher of malformed ROS 2 messages wrote a line per message; the limit was on `drd.bus` alone, and a
logger's filter never sees its children's records)."""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest

from drd.daemon import logs


class Kept(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


@pytest.fixture
def kept() -> Iterator[Kept]:
    handler = Kept()
    root = logging.getLogger()
    root.addHandler(handler)
    saved = {name: list(logging.getLogger(name).filters) for name in (*logs.PEER_LOGGERS, logs.PLACEMENT_LOGGER)}
    try:
        yield handler
    finally:
        root.removeHandler(handler)
        for name, filters in saved.items():
            logging.getLogger(name).filters[:] = filters


@pytest.mark.parametrize("name", ["drd.bus.ros2", "drd.sim.ros2", "drd.hw.ros2", "drd.ros2", "drd.bus"])
def test_a_flood_on_a_peer_logger_is_cut_to_ten_lines(kept: Kept, name: str) -> None:
    logs.install(*logs.PEER_LOGGERS)
    log = logging.getLogger(name)
    for i in range(100):
        log.warning("ros2 %s: a payload that is not a %s: %s", "/ranger1/odom", "nav_msgs/msg/Odometry", i)
    assert len([r for r in kept.records if r.name == name]) == 10


def test_the_controllers_placement_lines_are_cut_to_a_hundred_per_window(kept: Kept) -> None:
    """Reverify audit 7, D-c: a mission restarting a component 99 times an instant logged 1,200 placement lines a
    second. `drd start` limits them (loosely: a mission placing 50 components at once logs them all)."""
    logs.install_daemon_limits()
    log = logging.getLogger(logs.PLACEMENT_LOGGER)
    level = log.level
    log.setLevel(logging.INFO)  # as a daemon's log is
    try:
        for _ in range(1_000):
            log.info("placement: %s on %s (%s)", "Storm", "ranger1", "fewest instances")
    finally:
        log.setLevel(level)
    placed = [r for r in kept.records if r.name == logs.PLACEMENT_LOGGER]
    assert len(placed) == logs.PLACEMENT_BURST == 100
