"""The simulator's robots: their public records (`Pose`, `Flight`, `RobotState`) and mutable bodies.

A `RobotBody` is the simulator's private state for one robot; it lives here with its wheel
odometry so `drd.sim.physics` stays about stepping the world and answering commands.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import pymunk

from drd.errors import HardwareFailure
from drd.sim.geometry import Point


def _chipmunk() -> Any:
    """pymunk's cffi library when it has the body accessors the hot paths use, else None (the public API)."""
    try:
        from pymunk._chipmunk_cffi import lib
    except ImportError:
        return None
    names = ("cpBodyGetPosition", "cpBodyGetAngle", "cpBodySetVelocity", "cpBodySetAngularVelocity",
             "cpBodySetPosition")
    return lib if all(hasattr(lib, n) for n in names) and hasattr(pymunk.Body(), "_body") else None


#: pymunk's attribute setters go through a Python `__setattr__` and a property each, which costs three times
#: chipmunk's own setter; the sub-step loop (every robot's wheels, every intruder) calls chipmunk directly.
_CP = _chipmunk()


def placement(body: pymunk.Body) -> tuple[float, float, float]:
    """`(*body.position, body.angle)`, lean."""
    if _CP is None:
        x, y = body.position
        return x, y, body.angle
    cp = body._body
    p = _CP.cpBodyGetPosition(cp)
    return p.x, p.y, _CP.cpBodyGetAngle(cp)


def set_velocity(body: pymunk.Body, vx: float, vy: float) -> None:
    """`body.velocity = (vx, vy)`, lean."""
    if _CP is None:
        body.velocity = (vx, vy)
    else:
        _CP.cpBodySetVelocity(body._body, (vx, vy))


def set_position(body: pymunk.Body, x: float, y: float) -> None:
    """`body.position = (x, y)`, lean."""
    if _CP is None:
        body.position = (x, y)
    else:
        _CP.cpBodySetPosition(body._body, (x, y))


class RobotState(StrEnum):
    MAGAZINE = "magazine"
    """Riding in its Ranger's magazine: not in the space, at its Ranger's pose."""
    FLYING = "flying"
    """Launched or jumping: not in the space until it lands."""
    FLOOR = "floor"
    """A body in the space: it drives, collides and is seen."""
    LOST = "lost"
    """Gone (destroyed, dead, an injected loss: `Simulation.lose`): every command and sensor fails. A battery the
    world's model runs flat does not lose the robot: like a real one's low-voltage cut-off, it stops the actuators
    and leaves the robot on the floor, reporting (`Simulation.battery` reads 0), so a mission sees an empty robot,
    not a vanished one."""


class SimError(HardwareFailure):
    """A command the simulated hardware cannot carry out (a lost robot, a Scout not in a magazine...)."""


@dataclass(frozen=True, slots=True)
class Pose:
    x: float
    y: float
    heading: float


@dataclass(frozen=True, slots=True)
class Flight:
    """A launch or a jump: from `start` to `end` between `t0` and `t1`; `blocked` if a wall stopped it short."""

    robot: str
    kind: str
    start: Point
    end: Point
    t0: float
    t1: float
    heading: float
    blocked: bool


@dataclass
class RobotBody:
    """Mutable state of one robot; `group` keeps its own shape out of its own ray casts."""

    id: str
    kind: str  # "ranger" | "scout"
    body: pymunk.Body
    shape: pymunk.Circle
    group: int
    max_speed: float
    wheel_base: float
    state: RobotState
    carrier: str | None = None
    v: float = 0.0
    omega: float = 0.0
    odom: tuple[float, float, float] = (0.0, 0.0, 0.0)
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)  # where its odometry began (the world's start pose)
    charge: float = 1.0  # battery, 0 (empty: wheels, foot and launcher stop) .. 1 (full)
    last: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the true pose at the end of the previous step
    flight: Flight | None = None
    magazine: list[str] = field(default_factory=list)
    trail: list[tuple[float, float, float]] = field(default_factory=list)
    _still: bool | None = field(default=None, init=False, repr=False, compare=False)

    def wheels_changed(self) -> None:
        """Give chipmunk the velocity update that fits the command (call after changing `v` or `omega`): `drive`
        while the wheels turn; while they stand still, chipmunk's own update, which in a space without damping
        sets the velocity to zero every step, as `drive` would, without a call into Python per body per step
        (a watching Scout stands still for most of a mission)."""
        still = self.v == 0.0 and self.omega == 0.0
        if still is not self._still:
            self.body.velocity_func = pymunk.Body.update_velocity if still else self.drive
            self._still = still

    def drive(self, body: pymunk.Body, gravity: tuple[float, float], damping: float, dt: float) -> None:
        """pymunk's velocity callback: the wheels set the velocity after positions are integrated and contacts
        found, and before they are solved, so a robot pushing at a wall is held at its surface."""
        if _CP is None:
            a = body.angle
            body.velocity = (self.v * math.cos(a), self.v * math.sin(a))
            body.angular_velocity = self.omega
            return
        cp = body._body  # every robot, every sub-step: chipmunk's setters directly (see `set_velocity`)
        a = _CP.cpBodyGetAngle(cp)
        _CP.cpBodySetVelocity(cp, (self.v * math.cos(a), self.v * math.sin(a)))
        _CP.cpBodySetAngularVelocity(cp, self.omega)

    def integrate_odometry(self, x: float, y: float, a: float, rngs: Callable[[str, str], random.Random],
                           sigma: float) -> None:
        """Integrate the wheels' view of the motion since the last step (the body is now at `x, y`, heading `a`):
        forward distance and turn, with noise from `rngs(robot id, "odometry")`, asked only when it moved."""
        lx, ly, la = self.last
        if x == lx and y == ly and a == la:
            return
        self.last = (x, y, a)
        ds = (x - lx) * math.cos(la) + (y - ly) * math.sin(la)  # wheels do not feel sideways pushes
        da = a - la
        if ds == 0.0 and da == 0.0:
            return
        if sigma:
            rng = rngs(self.id, "odometry")
            ds *= 1 + rng.gauss(0.0, sigma)
            da += rng.gauss(0.0, sigma * (abs(da) + abs(ds)))
        ox, oy, oa = self.odom
        mid = oa + da / 2
        self.odom = (ox + ds * math.cos(mid), oy + ds * math.sin(mid), oa + da)
