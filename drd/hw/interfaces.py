"""The hardware interfaces behaviors talk to: `Drive`, `RangeSensor`, `Camera`, `Launcher`, `Jump`, `RadioChannel`.

Behaviors see only these protocols, never a driver class or the simulator. Units are SI throughout:
metres, seconds, radians (counter-clockwise positive, 0 along the robot's heading), m/s and rad/s.

Fencing: every method that commands hardware takes an optional `epoch`, the epoch of the RCM grant
the caller holds. A driver remembers the highest epoch it has seen and refuses older ones with
`StaleCommand`, so a behavior whose grant was revoked cannot move a robot after its successor has.
`epoch=None` is an unfenced command (tests, tools).
"""

from __future__ import annotations

import bisect
import functools
import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from drd.errors import HardwareFailure

__all__ = [
    "INTERFACES", "Beams", "Camera", "DetectionLike", "Drive", "Fence", "HardwareError", "Jump", "Landing", "Launcher",
    "RadioChannel", "RangeSensor", "Scan", "StaleCommand",
]


class HardwareError(HardwareFailure):
    """The hardware cannot carry out a command (a lost robot, no such Scout in the magazine...)."""


class StaleCommand(HardwareError):
    """A command carried an epoch older than one the driver has already obeyed (a revoked grant)."""


class Fence:
    """The epoch fence every command-taking driver shares: remember the highest epoch, refuse older ones."""

    def __init__(self, what: str) -> None:
        self.what = what
        self.epoch: int | None = None

    def check(self, epoch: int | None) -> None:
        """Accept `epoch` (None: unfenced) or raise `StaleCommand` if it is older than the highest seen."""
        if epoch is None:
            return
        if self.epoch is not None and epoch < self.epoch:
            raise StaleCommand(f"{self.what}: command with epoch {epoch} refused, epoch {self.epoch} already seen")
        self.epoch = epoch


@dataclass(frozen=True, slots=True)
class Scan:
    """One laser scan: `ranges[i]` in metres along angle `angle_min + i * angle_step` (radians, relative to
    the heading, right to left). A beam that hit nothing reads exactly `max_range`."""

    ranges: tuple[float, ...]
    angle_min: float
    angle_step: float
    max_range: float

    def angle(self, i: int) -> float:
        """The bearing of beam `i` in radians, relative to the robot's heading."""
        return self.angle_min + i * self.angle_step

    def beams(self) -> Beams:
        """Every beam's bearing (exactly `angle(i)`), cosine and sine: computed once per laser, not per scan."""
        return _beams(len(self.ranges), self.angle_min, self.angle_step)


@dataclass(frozen=True, slots=True)
class Beams:
    """The directions of the beams of a scan, in the robot frame: what does not change from one scan to the next.

    `angles[i]` is `Scan.angle(i)`, and `cos[i]`, `sin[i]` its cosine and sine, so a beam's hit point is
    `(r * cos[i], r * sin[i])` with no trigonometry per scan.
    """

    angles: tuple[float, ...]
    cos: tuple[float, ...]
    sin: tuple[float, ...]

    def span(self, lo: float, hi: float) -> tuple[int, int]:
        """The beams `i0 <= i < i1` whose angle lies in `[lo, hi]` (a scan's angles increase, right to left)."""
        return bisect.bisect_left(self.angles, lo), bisect.bisect_right(self.angles, hi)


@functools.lru_cache(maxsize=32)
def _beams(n: int, angle_min: float, angle_step: float) -> Beams:
    angles = tuple(angle_min + i * angle_step for i in range(n))
    return Beams(angles, tuple(math.cos(a) for a in angles), tuple(math.sin(a) for a in angles))


@dataclass(frozen=True, slots=True)
class Landing:
    """Where a launched Scout should land, in the Ranger's odometry frame (m, m, rad), and the flight time (s)."""

    x: float
    y: float
    heading: float
    duration: float


class DetectionLike(Protocol):
    """A person in a camera's view."""

    @property
    def label(self) -> str:
        """Track label given by the detector."""
        ...

    @property
    def bearing(self) -> float:
        """Radians relative to the camera's heading, positive to the left."""
        ...

    @property
    def distance(self) -> float:
        """Metres from the camera."""
        ...

    @property
    def light(self) -> float:
        """Light level where the person stands, 0 (dark) to 1."""
        ...


@runtime_checkable
class Drive(Protocol):
    """A wheeled base."""

    max_speed: float
    """Top linear speed in m/s; faster commands are clamped."""

    def set_velocity(self, v: float, omega: float, epoch: int | None = None) -> None:
        """Drive at `v` m/s forward and `omega` rad/s counter-clockwise until the next command."""
        ...

    def stop(self, epoch: int | None = None) -> None:
        """Stop the wheels (v = omega = 0)."""
        ...

    def odometry(self) -> tuple[float, float, float]:
        """The pose the wheels believe in: x, y in metres, heading in radians (start pose plus noisy motion)."""
        ...

    def origin(self) -> tuple[float, float, float]:
        """Where the odometry began (the pose at power-on, or the simulation's start pose)."""
        ...


@runtime_checkable
class RangeSensor(Protocol):
    """A planar laser range finder."""

    def scan(self) -> Scan:
        """The latest scan (metres, radians)."""
        ...


@runtime_checkable
class Camera(Protocol):
    """A colour camera with a person detector and region brightness."""

    fov: float
    """Horizontal field of view in radians."""

    def detections(self) -> list[DetectionLike]:
        """People seen now: in the field of view, in line of sight, and in enough light."""
        ...

    def brightness(self, n_regions: int) -> list[float]:
        """Mean light (0..1) of `n_regions` vertical strips of the image, right to left."""
        ...


@runtime_checkable
class Launcher(Protocol):
    """The Ranger's Scout launcher."""

    max_range: float
    """Farthest launch in metres."""

    def launch(self, scout_id: str, heading: float, distance: float, epoch: int | None = None) -> Landing:
        """Throw Scout `scout_id` out of the magazine, `heading` radians from the Ranger's heading,
        `distance` metres (capped at `max_range`); returns where it should land."""
        ...

    def loaded(self) -> tuple[str, ...]:
        """The Scouts still in the magazine, in launch order."""
        ...


@runtime_checkable
class Jump(Protocol):
    """A Scout's spring foot."""

    def jump(self, dx: float, epoch: int | None = None) -> None:
        """Hop `dx` metres straight ahead (over low obstacles)."""
        ...


@runtime_checkable
class RadioChannel(Protocol):
    """The radio link between a Scout and its Ranger."""

    def link_ok(self, peer: str | None = None) -> bool:
        """Whether this robot can talk to `peer` now (default: a Scout's own Ranger)."""
        ...


#: RC type name (as in the manifests) -> interface.
INTERFACES: dict[str, type] = {
    "Drive": Drive, "RangeSensor": RangeSensor, "Camera": Camera, "Launcher": Launcher, "Jump": Jump,
    "RadioChannel": RadioChannel,
}
