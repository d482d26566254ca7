"""Drivers seen through a grant: fenced by epoch, and multiplexed between behaviors.

The Resource Controller Manager gives each grant of a unit a strictly larger epoch; a driver
refuses commands with an older one (`drd.hw.StaleCommand`). A component never handles epochs:
the runtime hands it its devices wrapped here.

A command is a driver method that takes an `epoch`. When several active behaviors set one
actuator (FollowCorridor and AvoidObstacles both drive the Ranger), the reference says that in
each control cycle the command of the highest priority wins and, among equals, the behavior
declared last (a later layer subsumes an earlier one). With an `Arbiter`, commands are proposed
during the cycle and only the winner per driver is executed at its end. Only setpoint commands
(those returning None: `set_velocity`, `stop`) are multiplexed; an action with a result (a
launch) runs at once, and queries (scans, odometry, detections) always go straight through.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(slots=True)
class Proposal:
    rank: tuple[int, int]  # (-priority, declaration order): the larger wins
    call: Callable[[], Any]
    owner: Any  # who proposed it (the runtime's node), for error reports


class Arbiter:
    """Collects the commands of one control cycle; `flush` runs the winner per driver."""

    def __init__(self) -> None:
        # The best proposal so far per driver (by id). Public so that the runtime can skip calling
        # `flush` in the usual cycle that commanded nothing: a dict test instead of two calls.
        self.best: dict[int, Proposal] = {}

    def propose(self, driver: Any, proposal: Proposal) -> None:
        best = self.best.get(id(driver))
        if best is None or proposal.rank >= best.rank:
            self.best[id(driver)] = proposal

    def flush(self, on_error: Callable[[Any, Exception], None]) -> int:
        """Execute the winning commands; returns how many ran."""
        if not self.best:
            return 0
        winners, self.best = list(self.best.values()), {}
        for p in winners:
            try:
                p.call()
            except Exception as e:  # a driver refusing a command fails its proposer, not the cycle
                on_error(p.owner, e)
        return len(winners)


class Fenced:
    """`driver` with `epoch=` filled in on commands, which go through `arbiter` when there is one.

    `epoch` may be a callable: a behavior suspended and resumed gets a new grant, and so a new epoch.
    """

    __slots__ = ("_driver", "_epoch", "_arbiter", "_rank", "_owner")

    def __init__(self, driver: Any, epoch: int | None | Callable[[], int | None], arbiter: Arbiter | None = None,
                 rank: tuple[int, int] = (0, 0), owner: Any = None):
        self._driver = driver
        self._epoch = epoch
        self._arbiter = arbiter
        self._rank = rank
        self._owner = owner

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._driver, name)
        if not (callable(value) and _takes_epoch(value)):
            return value
        epoch = self._epoch() if callable(self._epoch) else self._epoch  # the grant's current epoch
        command = functools.partial(value, epoch=epoch) if epoch is not None else value
        if self._arbiter is None or not _returns_nothing(value):
            return command  # an action with a result (a launch) runs at once, still fenced
        arbiter, driver, rank, owner = self._arbiter, self._driver, self._rank, self._owner

        def propose(*args: Any, **kwargs: Any) -> None:
            arbiter.propose(driver, Proposal(rank, functools.partial(command, *args, **kwargs), owner))
        return propose

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


@functools.cache
def _signature_returns_nothing(func: Any) -> bool:
    try:
        return inspect.signature(func).return_annotation in (None, "None")
    except (TypeError, ValueError):
        return False


def is_command(method: Any) -> bool:
    """A setpoint command: fenced by an epoch and returning nothing (`Fenced` multiplexes those per cycle)."""
    return callable(method) and _takes_epoch(method) and _returns_nothing(method)


def _returns_nothing(method: Any) -> bool:
    """Setpoint commands (`set_velocity`, `stop`) return None: those are multiplexed per cycle."""
    return _signature_returns_nothing(getattr(method, "__func__", method))
