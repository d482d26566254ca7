"""Drivers declare what they are (issue #14): their readings and their commands. A driver that declares nothing,
a reading it lacks, or a member of its device's interface it does not declare, is refused when it is loaded; a
behavior's device handle reaches the declared names only, so an undeclared method (a command whose author forgot
`epoch`) cannot bypass the gate."""

from __future__ import annotations

from typing import Any

import pytest

from drd.hw.commands import DriverDeclarationError, conforms, declared, spec_of
from drd.hw.interfaces import INTERFACES
from drd.runtime.ownership import Binding, BoundDevice


class Wheels:
    READINGS = frozenset({"odometry", "origin", "max_speed"})
    SETPOINTS = ("set_velocity", "stop")
    STOP = "stop"

    def __init__(self) -> None:
        self.max_speed = 1.0
        self.moved: list[tuple[float, float]] = []

    def odometry(self) -> tuple[float, float, float]:
        return (0.0, 0.0, 0.0)

    def origin(self) -> tuple[float, float, float]:
        return (0.0, 0.0, 0.0)

    def set_velocity(self, v: float, omega: float, epoch: int | None = None) -> None:
        self.moved.append((v, omega))

    def stop(self, epoch: int | None = None) -> None:
        self.moved.append((0.0, 0.0))

    def turbo(self, v: float) -> None:  # undeclared, and no epoch: once a "reading" that drove the robot
        self.moved.append((v, 0.0))


def test_a_driver_that_declares_nothing_is_refused() -> None:
    class Silent:
        def odometry(self) -> tuple[float, float, float]:
            return (0.0, 0.0, 0.0)

    with pytest.raises(DriverDeclarationError, match="declares nothing"):
        declared(Silent)


def test_a_reading_the_driver_lacks_is_refused_on_the_built_driver() -> None:
    class Promises(Wheels):
        READINGS = frozenset({"odometry", "origin", "max_speed", "battery"})

    declared(Promises)  # `battery` could be set when built: the class alone cannot tell
    with pytest.raises(DriverDeclarationError, match="READINGS names battery, which it does not have"):
        spec_of(Promises())


def test_a_reading_that_takes_an_epoch_is_a_command_in_disguise() -> None:
    class Confused(Wheels):
        READINGS = frozenset({"odometry", "origin", "max_speed", "stop"})
        SETPOINTS = ("set_velocity",)
        STOP = None

    with pytest.raises(DriverDeclarationError, match="stop take an epoch"):
        declared(Confused)


def test_an_interface_member_left_undeclared_is_named() -> None:
    class Forgetful(Wheels):
        READINGS = frozenset({"odometry", "max_speed"})

    assert conforms(Wheels, INTERFACES["Drive"]) == []
    assert conforms(Forgetful, INTERFACES["Drive"]) == [
        "origin of the Drive interface: declare it in READINGS, SETPOINTS or ACTIONS"]


def handle(driver: Any) -> BoundDevice:
    binding = Binding("drive", "ranger1.drive", "M/Follow", 1)
    binding.driver = driver
    return BoundDevice(binding, "M/Follow", None, (0, 0), None, lambda: 0.0)


def test_a_behavior_reaches_declared_names_only() -> None:
    wheels = Wheels()
    device = handle(wheels)
    assert device.odometry() == (0.0, 0.0, 0.0) and device.max_speed == 1.0
    with pytest.raises(AttributeError, match="turbo is neither a reading nor a command its driver declares"):
        device.turbo(3.0)
    with pytest.raises(AttributeError):
        device.moved  # noqa: B018 - an attribute of the driver's own, not declared
    assert wheels.moved == []  # the undeclared method never ran


class Thrower:
    READINGS = frozenset({"loaded"})
    ACTIONS = ("launch",)
    MOVES = {"launch": "scout_id"}

    def loaded(self) -> tuple[str, ...]:
        return ("s1", "s2")

    def launch(self, scout_id: str, heading: float, distance: float, epoch: int | None = None) -> str:
        return scout_id


def test_an_action_that_moves_another_robot_names_its_argument() -> None:
    assert declared(Thrower).moves == {"launch": (0, "scout_id")}
    for moves, problem in (({"loaded": "x"}, "MOVES names 'loaded', which is not one of its ACTIONS"),
                           ({"launch": "scout"}, "MOVES names argument 'scout' of launch, which it does not take")):
        bad = type("BadThrower", (Thrower,), {"MOVES": moves})
        with pytest.raises(DriverDeclarationError, match=problem):
            declared(bad)


@pytest.mark.parametrize(("args", "kwargs"), [(("s2", 0.0, 1.0), {}), ((), {"scout_id": "s2", "heading": 0.0,
                                                                              "distance": 1.0})])
def test_the_gate_admits_such_an_action_only_from_a_holder_of_that_robot(args: tuple[Any, ...],
                                                                         kwargs: dict[str, Any]) -> None:
    from drd.runtime.ownership import DeviceGate

    gate = DeviceGate("r.launcher", Thrower(), declared(Thrower), lambda mission, record: None)
    gate.grant("M/Throw", 1, 0.0, exclusive=True)
    assert gate.admit("M/Throw", 1, "launch", args, kwargs, 0.0, holds=lambda robot: robot == "s1") == (
        "it does not hold s2, which launch moves")
    assert gate.admit("M/Throw", 1, "launch", args, kwargs, 0.0) == "it does not hold s2, which launch moves"
    assert gate.admit("M/Throw", 1, "launch", args, kwargs, 0.0, holds=lambda robot: robot == "s2") == ""
