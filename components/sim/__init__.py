"""The `sim` drivers: one module per RC type, each implementing its `drd.hw.interfaces` protocol on a
`drd.sim.Simulation`. Imported lazily by `drd.hw.drivers.load_driver`, one module at a time, so this
package imports no driver module itself; only the shared `SimDriver` base lives here."""

from __future__ import annotations

import math
from collections.abc import Callable
from types import TracebackType

from drd.hosts import Device
from drd.hw.interfaces import Fence, HardwareError
from drd.sim import SimError, Simulation


class _SimErrors:
    """The context manager of `SimDriver.sim_errors`: one per driver, reused by every call (a `contextmanager`
    generator would cost more than most of the simulator's readings)."""

    __slots__ = ("device_id",)

    def __init__(self, device_id: str) -> None:
        self.device_id = device_id

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None) -> None:
        if isinstance(e, SimError):
            raise HardwareError(f"{self.device_id}: {e}") from e


class SimDriver:
    """Base of every sim driver: the device, the robot it belongs to, the simulator and the epoch fence."""

    #: Methods and attributes whose value is a function of the simulated world at one instant (its `version`):
    #: no side effect, noise seeded per instant. The cluster's Creator reads them ahead of a component's step
    #: (`drd.cluster.creator`), which then costs no round trip to the component's process.
    READINGS: frozenset[str] = frozenset()
    #: Commands (`drd.runtime.ownership`): setpoints hold until the next one and are multiplexed per control
    #: cycle; actions run at once and return a result; `STOP` brings the device to a safe stop. Each goes through
    #: the device's gate, which lets only the current grant's holder through.
    SETPOINTS: tuple[str, ...] = ()
    ACTIONS: tuple[str, ...] = ()
    STOP: str | None = None

    def __init__(self, device: Device, robot_id: str, sim: Simulation) -> None:
        self.device, self.robot_id, self.sim = device, robot_id, sim
        self.fence = Fence(f"{device.id} ({robot_id})")
        self._sim_errors = _SimErrors(device.id)

    def option(self, key: str, default: float, check: Callable[[float], bool] = lambda x: x > 0) -> float:
        """A numeric device option (hosts.yaml `options:`), or `default`; a bad value names device and key."""
        value = self.device.options.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
                or not check(float(value)):
            raise HardwareError(f"{self.device.id}: option {key} has a bad value {value!r}")
        return float(value)

    def sim_errors(self) -> _SimErrors:
        """Turn the simulator's `SimError` into the interfaces' `HardwareError`, naming the device (`with`)."""
        return self._sim_errors

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.device.id!r}, robot={self.robot_id!r})"
