"""Drivers seen through a grant: every command carries the grant's fencing epoch.

The Resource Controller Manager gives each grant of a unit a strictly larger epoch; a driver
refuses commands with an older one (`drd.hw.StaleCommand`). A component never handles epochs:
the runtime hands it its devices wrapped here.
"""

from __future__ import annotations

import functools
import inspect
from typing import Any


class Fenced:
    """`driver` with `epoch=` filled in on every method that takes one."""

    __slots__ = ("_driver", "_epoch")

    def __init__(self, driver: Any, epoch: int | None):
        self._driver = driver
        self._epoch = epoch

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._driver, name)
        if self._epoch is not None and callable(value) and _takes_epoch(value):
            return functools.partial(value, epoch=self._epoch)
        return value

    def __repr__(self) -> str:
        return f"Fenced({self._driver!r}, epoch={self._epoch})"


@functools.cache
def _signature_has_epoch(func: Any) -> bool:
    try:
        return "epoch" in inspect.signature(func).parameters
    except (TypeError, ValueError):
        return False


def _takes_epoch(method: Any) -> bool:
    return _signature_has_epoch(getattr(method, "__func__", method))
