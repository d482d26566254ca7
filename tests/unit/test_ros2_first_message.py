"""A `ros2` reading waits for a topic's first message only until `max_age` after the driver subscribed (ROS 2 audit
12, D4: each battery reading waited 2 s again for a topic nobody published, inside a control step whose deadline is
1 s, and the healthy host was reported as not answering)."""

from __future__ import annotations

import math
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


def test_a_battery_percentage_on_another_scale_is_not_known() -> None:
    """ROS 2 audit 18, #4: a robot reporting 30.0 (30 %, a driver on 0..100) read as a full battery, so a battery
    floor of 0.5 never held; NaN was already not known. Rounding just past 0..1 is the charge, clamped."""
    from components.ros2.drive import charge

    assert charge(0.3, "d") == 0.3 and charge(1.004, "d") == 1.0 and charge(-0.002, "d") == 0.0
    for bad in (30.0, 1.5, -0.2, math.nan, math.inf):
        with pytest.raises(HardwareError, match="not know its charge|outside 0..1"):
            charge(bad, "d")
