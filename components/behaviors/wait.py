"""Wait: succeed after `duration` seconds of mission time, holding nothing.

The time counts from the first start. A Wait started again after its host was lost (a movable component
placed again elsewhere) only knows the time it is restarted at, so it waits its whole duration again: its
output `waited` {seconds, pid} says how long and in which process the last step ran.
"""

from __future__ import annotations

import os

from drd.runtime.component import Component, Status


class Wait(Component):
    def start(self) -> None:
        self.duration = float(self.ctx.params["duration"])
        self.began = self.ctx.now()

    def step(self, now: float) -> Status:
        waited = now - self.began
        self.ctx.outputs["waited"] = {"seconds": waited, "pid": os.getpid()}
        return Status.SUCCESS if waited >= self.duration - 1e-6 else Status.RUNNING
