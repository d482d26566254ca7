"""What a driver says it is: which of its methods command the hardware, and how to stop it safely.

A driver class declares its commands as class attributes: `SETPOINTS` (a value that holds until the next one:
`set_velocity`, `stop`; multiplexed per control cycle between the behaviors sharing the device), `ACTIONS` (done
at once, with a result: `launch`, `jump`) and `STOP`, the setpoint that brings the device to a safe stop (called
with `epoch=None` when the behavior that set it in motion loses its authority). Everything else is a reading
and goes straight to the driver. Whether a method commands is declared, never guessed: a public method that takes
an `epoch` (the mark of a command) but is not declared is refused when the driver is loaded, so no command can
slip past the gate (`drd.runtime.ownership`).

An action that moves another robot (a launcher's `launch(scout_id, ...)` throws a Scout) names the argument
that says which, in `MOVES` (`{"launch": "scout_id"}`): the gate then admits it only from a behavior that holds
that robot too, not only the device it calls.

Readings are declared too (`READINGS`: the methods and attributes a behavior may read), and a behavior reaches
nothing else of a driver: its device handle forwards declared names only. A driver that declares nothing, a
reading it does not have, or an interface member (`drd.hw.interfaces`: what its device type promises behaviors)
it declares neither as a reading nor as a command, is refused when it is loaded.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from typing import Any

from drd.errors import ComponentFailure

__all__ = ["DriverDeclarationError", "DriverSpec", "conforms", "declared", "spec_of"]


class DriverDeclarationError(ComponentFailure, TypeError):
    """A driver class declares commands it does not have, or has commands it does not declare."""


@dataclass(frozen=True, slots=True)
class DriverSpec:
    """A driver's declared readings, setpoints, actions and safe stop."""

    setpoints: frozenset[str] = frozenset()
    actions: frozenset[str] = frozenset()
    stop: str | None = None
    readings: frozenset[str] = frozenset()
    #: action -> (position, name) of its argument naming the robot it moves (`MOVES`)
    moves: dict[str, tuple[int, str]] = field(default_factory=dict)
    #: Everything a behavior may use of the driver (read on every access through a device handle: computed once).
    names: frozenset[str] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", self.readings | self.setpoints | self.actions)

    @property
    def commands(self) -> frozenset[str]:
        return self.setpoints | self.actions


_SPECS: dict[type, DriverSpec] = {}


def spec_of(driver: object) -> DriverSpec:
    """The declarations of `driver`'s class, checked once per class, and its readings on the driver itself (an
    attribute such as `max_speed` may be set when it is built).

    Raises:
        DriverDeclarationError: as `declared`, or a declared reading the built driver does not have.
    """
    spec = declared(type(driver))
    missing = sorted(r for r in spec.readings if not hasattr(driver, r))
    if missing:
        cls = type(driver)
        raise DriverDeclarationError(f"driver {cls.__module__}.{cls.__qualname__}: READINGS names "
                                     f"{', '.join(missing)}, which it does not have")
    return spec


def conforms(cls: type, interface: type) -> list[str]:
    """What of `interface` (a protocol of `drd.hw.interfaces`) the driver class declares neither as a reading nor
    as a command: a behavior written against the interface would find it missing."""
    spec = declared(cls)
    members = {n for n in getattr(interface, "__annotations__", {}) if not n.startswith("_")}
    members |= {n for n, v in vars(interface).items() if callable(v) and not n.startswith("_")}
    missing = sorted(members - spec.names)
    return [f"{', '.join(missing)} of the {interface.__name__} interface: declare "
            f"{'it' if len(missing) == 1 else 'them'} in READINGS, SETPOINTS or ACTIONS"] if missing else []


def declared(cls: type) -> DriverSpec:
    """`spec_of` for a driver class (checked before any driver is built: `drd start` refuses a bad one)."""
    found = _SPECS.get(cls)
    if found is None:
        found = _SPECS[cls] = _declared(cls)
    return found


def _declared(cls: type) -> DriverSpec:
    setpoints = frozenset(getattr(cls, "SETPOINTS", ()))
    actions = frozenset(getattr(cls, "ACTIONS", ()))
    readings = frozenset(getattr(cls, "READINGS", ()))
    stop = getattr(cls, "STOP", None)
    problems = [f"{m} is declared but is not a method" for m in sorted(setpoints | actions)
                if not callable(getattr(cls, m, None))]
    if not (setpoints or actions or readings):
        problems.append("it declares nothing: list what behaviors may read in READINGS and its commands in "
                        "SETPOINTS or ACTIONS")
    if readings & (setpoints | actions):
        problems.append(f"{', '.join(sorted(readings & (setpoints | actions)))} declared both a reading and a command")
    readings_taking_epoch = sorted(r for r in readings if callable(getattr(cls, r, None))
                                   and _takes_epoch(getattr(cls, r)))
    if readings_taking_epoch:
        problems.append(f"{', '.join(readings_taking_epoch)} take an epoch (a command) but are declared READINGS")
    if setpoints & actions:
        problems.append(f"{', '.join(sorted(setpoints & actions))} declared both in SETPOINTS and in ACTIONS")
    if stop is not None and stop not in setpoints:
        problems.append(f"STOP names {stop!r}, which is not one of its SETPOINTS")
    for attr in dir(cls):
        if attr.startswith("_") or attr in setpoints or attr in actions:
            continue
        method = getattr(cls, attr, None)
        if callable(method) and _takes_epoch(method):
            problems.append(f"{attr} takes an epoch (a command) but is in neither SETPOINTS nor ACTIONS")
    moves = _moves(cls, actions, problems)
    if problems:
        raise DriverDeclarationError(f"driver {cls.__module__}.{cls.__qualname__}: {'; '.join(problems)}")
    return DriverSpec(setpoints, actions, stop, readings, moves)


def _moves(cls: type, actions: frozenset[str], problems: list[str]) -> dict[str, tuple[int, str]]:
    """`MOVES`, checked: each an action of `cls` with a parameter of that name; its position among the arguments
    a caller passes (after `self`)."""
    out: dict[str, tuple[int, str]] = {}
    for action, argument in dict(getattr(cls, "MOVES", {})).items():
        if action not in actions:
            problems.append(f"MOVES names {action!r}, which is not one of its ACTIONS")
            continue
        try:
            names = list(inspect.signature(getattr(cls, action)).parameters)[1:]
        except (TypeError, ValueError):
            names = []
        if argument not in names:
            problems.append(f"MOVES names argument {argument!r} of {action}, which it does not take")
            continue
        out[action] = (names.index(argument), argument)
    return out


def _takes_epoch(method: Any) -> bool:
    try:
        return "epoch" in inspect.signature(method).parameters
    except (TypeError, ValueError):
        return False
