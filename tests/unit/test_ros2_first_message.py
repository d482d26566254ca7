"""A `ros2` reading waits for a topic's first message only until `max_age` after the driver subscribed (ROS 2 audit
12, D4: each battery reading waited 2 s again for a topic nobody published, inside a control step whose deadline is
1 s, and the healthy host was reported as not answering)."""

from __future__ import annotations

import threading
from types import SimpleNamespace
from typing import Any

import pytest

from components.ros2 import Latest
from drd.hw.interfaces import HardwareError


class Waits(threading.Condition):
    """A condition that records how long each `wait_for` was allowed to block (and never blocks)."""

    def __init__(self) -> None:
        super().__init__()
        self.timeouts: list[float | None] = []

    def wait_for(self, predicate: Any, timeout: float | None = None) -> Any:
        self.timeouts.append(timeout)
        return predicate()


def test_the_first_message_is_waited_for_once_until_max_age_after_subscribing() -> None:
    clock = [10.0]
    driver = SimpleNamespace(describe=lambda: "base.drive", opts=SimpleNamespace(endpoint="tcp/127.0.0.1:7447"),
                             link=SimpleNamespace(now=lambda: clock[0],
                                                  source=lambda endpoint: f"the robot's router at {endpoint}"))
    latest = Latest(driver, "battery", "/base/battery_state", 2.0)  # type: ignore[arg-type]
    waits = latest.arrived = Waits()
    clock[0] = 10.5
    with pytest.raises(HardwareError, match="no message on /base/battery_state"):
        latest.get()
    assert waits.timeouts == [pytest.approx(1.5)]  # what is left of the 2 s since it subscribed
    clock[0] = 12.5
    for _ in range(3):
        with pytest.raises(HardwareError, match="no message on /base/battery_state"):
            latest.get()
    assert len(waits.timeouts) == 1  # later readings answer at once
