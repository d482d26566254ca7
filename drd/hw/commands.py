"""What a driver says it is: which of its methods command the hardware, and how to stop it safely.

A driver class declares its commands as class attributes: `SETPOINTS` (a value that holds until the next one:
`set_velocity`, `stop`; multiplexed per control cycle between the behaviors sharing the device), `ACTIONS` (done
at once, with a result: `launch`, `jump`) and `STOP`, the setpoint that brings the device to a safe stop (called
with `epoch=None` when the behavior that set it in motion loses its authority). Everything else is a reading
and goes straight to the driver. Whether a method commands is declared, never guessed: a public method that takes
an `epoch` (the mark of a command) but is not declared is refused when the driver is loaded, so no command can
slip past the gate (`drd.runtime.ownership`).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any

from drd.errors import ComponentFailure

__all__ = ["DriverDeclarationError", "DriverSpec", "declared", "spec_of"]


class DriverDeclarationError(ComponentFailure, TypeError):
    """A driver class declares commands it does not have, or has commands it does not declare."""


@dataclass(frozen=True, slots=True)
class DriverSpec:
    """A driver's declared setpoints, actions and safe stop."""

    setpoints: frozenset[str] = frozenset()
    actions: frozenset[str] = frozenset()
    stop: str | None = None

    @property
    def commands(self) -> frozenset[str]:
        return self.setpoints | self.actions


_SPECS: dict[type, DriverSpec] = {}


def spec_of(driver: object) -> DriverSpec:
    """The declared commands of `driver`'s class, checked once per class.

    Raises:
        DriverDeclarationError: a declared command is missing or not callable, `STOP` is not a declared command,
            or a public method takes an `epoch` without being declared.
    """
    return declared(type(driver))


def declared(cls: type) -> DriverSpec:
    """`spec_of` for a driver class (checked before any driver is built: `drd start` refuses a bad one)."""
    found = _SPECS.get(cls)
    if found is None:
        found = _SPECS[cls] = _declared(cls)
    return found


def _declared(cls: type) -> DriverSpec:
    setpoints = frozenset(getattr(cls, "SETPOINTS", ()))
    actions = frozenset(getattr(cls, "ACTIONS", ()))
    stop = getattr(cls, "STOP", None)
    problems = [f"{m} is declared but is not a method" for m in sorted(setpoints | actions)
                if not callable(getattr(cls, m, None))]
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
    if problems:
        raise DriverDeclarationError(f"driver {cls.__module__}.{cls.__qualname__}: {'; '.join(problems)}")
    return DriverSpec(setpoints, actions, stop)


def _takes_epoch(method: Any) -> bool:
    try:
        return "epoch" in inspect.signature(method).parameters
    except (TypeError, ValueError):
        return False
