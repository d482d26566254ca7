"""FollowCorridor: keep to the middle of the corridor from the side ranges, driving forward.

Also home of the small scan helpers the other Ranger behaviors share (wall fit, home pose),
all computed in the robot frame from a `Scan` and from odometry, never from ground truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from drd.hw.interfaces import Scan
from drd.runtime.component import Component, Status

#: Gains of the P controller: rad/s per metre off the centre line, and per radian of heading error.
K_LATERAL = 1.2
K_HEADING = 2.0
MAX_OMEGA = 1.0


def points(scan: Scan, lo: float, hi: float) -> list[tuple[float, float, float]]:
    """(angle, x, y) in the robot frame of the beams with angle in [lo, hi] that hit something."""
    out = []
    for i, r in enumerate(scan.ranges):
        a = scan.angle(i)
        if lo <= a <= hi and r < scan.max_range:
            out.append((a, r * math.cos(a), r * math.sin(a)))
    return out


@dataclass(frozen=True)
class Wall:
    """A corridor wall fitted in the robot frame: perpendicular distance and angle of the wall (rad, CCW)."""

    distance: float
    angle: float
    inliers: int


def fit_wall(scan: Scan, side: int, expect: float | None = None) -> Wall | None:
    """Fit the wall on one side (+1 left, -1 right) by least squares on the beams near it, robust to door gaps
    and end walls: start from a lateral distance abeam that enough beams agree on (the nearest one, or the one
    nearest `expect`, the last known distance), keep the points close to it."""
    lo, hi = (math.radians(20), math.radians(160)) if side > 0 else (math.radians(-160), math.radians(-20))
    pts = [(x, side * y) for _, x, y in points(scan, lo, hi) if side * y > 0.05]
    abeam = sorted(y for (x, y) in pts if abs(x) <= 2 * y)  # within about 60 degrees of the perpendicular
    support = [y for i, y in enumerate(abeam) if sum(1 for z in abeam[i:i + 8] if z - y < 0.08) >= 6]
    if not support:
        return None
    d0 = support[0] if expect is None else min(support, key=lambda y: abs(y - expect))
    m, c = 0.0, d0
    for gate in (0.25, 0.1):
        inl = [(x, y) for x, y in pts if abs(y - (m * x + c)) < gate]
        if len(inl) < 5:
            return None
        n = len(inl)
        mx = sum(x for x, _ in inl) / n
        my = sum(y for _, y in inl) / n
        sxx = sum((x - mx) ** 2 for x, _ in inl)
        if sxx < 1e-6:
            return None
        m = sum((x - mx) * (y - my) for x, y in inl) / sxx
        c = my - m * mx
    a = math.atan(m)
    return Wall(c * math.cos(a), side * a, len(inl))


def corridor(scan: Scan, expect: tuple[float | None, float | None] = (None, None),
             jump: float = 0.4) -> tuple[Wall | None, Wall | None]:
    """The left and right walls (either may be None where no wall is seen, or where the fit is more than `jump`
    metres from the expected distance: a room seen through a doorway, not the corridor wall)."""
    out = []
    for side, exp in ((1, expect[0]), (-1, expect[1])):
        w = fit_wall(scan, side, exp)
        out.append(None if w is None or (exp is not None and abs(w.distance - exp) > jump) else w)
    return out[0], out[1]


def wrap(a: float) -> float:
    """An angle in [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


def remember_home(comp: Component) -> None:
    """Record where this robot's mission started (its first odometry pose) in the shared data, if any, under
    `home[<drive resource>]`, so ReturnToStart can drive back there."""
    ctx = comp.ctx
    shared: Any = ctx.services.get("shared") if ctx else None
    if ctx is None or not isinstance(shared, dict) or "drive" not in ctx.devices:
        return
    homes = shared.setdefault("home", {})
    if isinstance(homes, dict):
        key = ctx.resources.get("drive", "drive")
        if key not in homes:
            x, y, _ = comp.device("drive").odometry()
            homes[key] = (x, y)


class FollowCorridor(Component):
    """Drive forward at `speed`, steering to the centre line and along the walls; RUNNING until stopped."""

    def start(self) -> None:
        self.width: float | None = None
        self.expect: tuple[float | None, float | None] = (None, None)
        remember_home(self)

    def step(self, now: float) -> Status:
        speed = float(self.ctx.params.get("speed", 0.4))
        left, right = corridor(self.device("ranges").scan(), self.expect)
        self.expect = (left.distance if left else self.expect[0], right.distance if right else self.expect[1])
        walls = [w for w in (left, right) if w is not None]
        heading = sum(w.angle for w in walls) / len(walls) if walls else 0.0  # the corridor's direction
        offset = 0.0  # how far left of the centre line the robot is
        if left and right:
            self.width = left.distance + right.distance
            offset = (right.distance - left.distance) / 2
        elif self.width and left:
            offset = self.width / 2 - left.distance
        elif self.width and right:
            offset = right.distance - self.width / 2
        omega = K_HEADING * heading - K_LATERAL * offset
        omega = max(-MAX_OMEGA, min(MAX_OMEGA, omega))
        self.device("drive").set_velocity(speed, omega)
        return Status.RUNNING

    def suspend(self) -> None:
        self.device("drive").stop()

    def terminate(self, status: Status) -> None:
        self.device("drive").stop()
