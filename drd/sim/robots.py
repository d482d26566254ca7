"""The simulator's robots: their public records (`Pose`, `Flight`, `RobotState`) and mutable bodies.

A `RobotBody` is the simulator's private state for one robot; it lives here with its wheel
odometry so `drd.sim.physics` stays about stepping the world and answering commands.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from enum import StrEnum

import pymunk

from drd.sim.geometry import Point


class RobotState(StrEnum):
    MAGAZINE = "magazine"
    """Riding in its Ranger's magazine: not in the space, at its Ranger's pose."""
    FLYING = "flying"
    """Launched or jumping: not in the space until it lands."""
    FLOOR = "floor"
    """A body in the space: it drives, collides and is seen."""
    LOST = "lost"
    """Gone (destroyed, out of battery, injected loss): every command and sensor fails."""


class SimError(Exception):
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
    last: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the true pose at the end of the previous step
    flight: Flight | None = None
    magazine: list[str] = field(default_factory=list)
    trail: list[tuple[float, float, float]] = field(default_factory=list)

    def drive(self, body: pymunk.Body, gravity: tuple[float, float], damping: float, dt: float) -> None:
        """pymunk's velocity callback: the wheels set the velocity after positions are integrated and contacts
        found, and before they are solved, so a robot pushing at a wall is held at its surface."""
        a = body.angle
        body.velocity = (self.v * math.cos(a), self.v * math.sin(a))
        body.angular_velocity = self.omega

    def integrate_odometry(self, rng: random.Random, sigma: float) -> None:
        """Integrate the wheels' view of the motion since the last step: forward distance and turn, with noise."""
        x, y, a = self.body.position.x, self.body.position.y, self.body.angle
        lx, ly, la = self.last
        self.last = (x, y, a)
        ds = (x - lx) * math.cos(la) + (y - ly) * math.sin(la)  # wheels do not feel sideways pushes
        da = a - la
        if ds == 0.0 and da == 0.0:
            return
        if sigma:
            ds *= 1 + rng.gauss(0.0, sigma)
            da += rng.gauss(0.0, sigma * (abs(da) + abs(ds)))
        ox, oy, oa = self.odom
        mid = oa + da / 2
        self.odom = (ox + ds * math.cos(mid), oy + ds * math.sin(mid), oa + da)
