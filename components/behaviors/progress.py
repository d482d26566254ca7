"""Whether a driving behavior is getting anywhere: nav2's progress checker (a distance within a time allowance),
on one number the behavior says is "how far it has got" (the distance from where it started, minus the distance to
its goal). Why: a wall follower or a homing behavior that meets something it cannot get past turns, backs off and
tries again for ever, and a mission without a bound of its own ran to its time limit (worlds audit 13)."""

from __future__ import annotations

import math

#: Metres a behavior must gain beyond its best within STUCK seconds of running.
PROGRESS, STUCK = 0.5, 30.0


def allowance(speed: float) -> float:
    """STUCK seconds, or the time three PROGRESS steps take at a slow `speed` (m/s) if longer; never at speed 0 (a
    robot told not to move makes no progress to miss). Reverify audit 14, D2: at 0.016 m/s, within the manifest's
    range, an empty corridor failed at 30 s."""
    return math.inf if speed <= 0 else max(STUCK, 3 * PROGRESS / speed)


class Progress:
    """The best a behavior has got so far, and since when. `reset` when it is resumed: the time it was suspended is
    not time it failed to move."""

    def __init__(self, step: float = PROGRESS, allowance: float = STUCK) -> None:
        self.step, self.allowance = step, allowance
        self.best: tuple[float, float] | None = None  # (since, value)

    def reset(self) -> None:
        self.best = None

    def stalled(self, now: float, got: float) -> bool:
        """Whether `got` (how far it has got, metres: larger is better) has not grown `step` beyond its best for
        `allowance` seconds."""
        if self.best is None or got >= self.best[1] + self.step:
            self.best = (now, got if self.best is None else max(got, self.best[1]))
            return False
        return now - self.best[0] >= self.allowance

    def says(self, how: str = "farther") -> str:
        """The reason a stalled behavior gives (`how`: which way it should have got, "farther", "nearer home")."""
        return f"no progress: got no more than {self.step:g} m {how} in {self.allowance:g} s"
