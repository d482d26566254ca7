"""Where a command would take a robot: the motion model the gates use to refuse a command before it breaks a
constraint (a geofence, a radio range), rather than after.

A pose is (x, y, heading) in metres and radians. `predict` answers for the commands of the standard interfaces
that move a robot (`Drive.set_velocity`, `Drive.stop`, `Jump.jump`); for anything else it answers None (the
command does not move the robot, as far as anyone can tell ahead).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

Pose = tuple[float, float, float]


def predict(kind: str, method: str, args: Sequence[Any], kwargs: Mapping[str, Any], pose: Pose,
            horizon: float) -> Pose | None:
    """The pose `horizon` seconds after `method(*args, **kwargs)` on a device of RC type `kind`, from `pose`."""
    x, y, heading = pose
    if kind == "Drive" and method == "set_velocity":
        v = _number(args, kwargs, 0, "v")
        omega = _number(args, kwargs, 1, "omega")
        if v is None or omega is None:
            return None
        if abs(omega) < 1e-9:
            return x + v * horizon * math.cos(heading), y + v * horizon * math.sin(heading), heading
        # a unicycle's arc
        radius = v / omega
        turned = heading + omega * horizon
        return (x + radius * (math.sin(turned) - math.sin(heading)),
                y - radius * (math.cos(turned) - math.cos(heading)), turned)
    if kind == "Drive" and method == "stop":
        return pose
    if kind == "Launcher" and method == "launch":  # where the thrown robot lands (its pose, not the launcher's)
        turn, distance = _number(args, kwargs, 1, "heading"), _number(args, kwargs, 2, "distance")
        if turn is None or distance is None:
            return None
        return x + distance * math.cos(heading + turn), y + distance * math.sin(heading + turn), heading + turn
    if kind == "Jump" and method == "jump":
        dx = _number(args, kwargs, 0, "dx")
        if dx is None:
            return None
        return x + dx * math.cos(heading), y + dx * math.sin(heading), heading
    return None


def _number(args: Sequence[Any], kwargs: Mapping[str, Any], index: int, name: str) -> float | None:
    value = kwargs.get(name, args[index] if index < len(args) else None)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    return float(value)
