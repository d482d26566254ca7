"""Wait: succeed after `duration` seconds of mission time, holding nothing.

The time counts from the first start, and goes on counting wherever the instance runs: its snapshot says when it
began (mission time, which a move, a lost host or a new controller does not change) and how many control
cycles it has stepped, so a Wait moved (`missionctl migrate`), placed again after its host was lost, or
entered again by a new controller ends at its original deadline. Restored with nothing (`restore(None)`: its
state was lost), it waits its whole duration again and logs so. Its output `waited` {seconds, pid, steps}
says how long it has waited, which process ran its last step (where it runs) and how many steps it made.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

from drd.runtime.component import Component, Status


class Wait(Component):
    restored: Mapping[str, Any] | None = None
    lost = False

    def restore(self, state: Mapping[str, Any] | None) -> None:
        self.restored, self.lost = state, state is None

    def start(self) -> None:
        self.duration = float(self.ctx.params["duration"])
        state, self.restored = self.restored, None
        if state is not None:
            self.began, self.steps = float(state["began"]), int(state["steps"])
            return
        self.began, self.steps = self.ctx.now(), 0
        if self.lost:
            self.lost = False
            self.ctx.log(f"Wait restarted: its state was lost, it waits {self.duration:g} s again")

    def step(self, now: float) -> Status:
        # to the microsecond, as records' times are: the clock adds 0.1 s a cycle, so 1 s read 0.9999999999999999
        # and a guard `[w.waited.seconds >= 1.0]` held on a cluster and not in a dry-run (users audit 25, D1)
        waited = round(now - self.began, 6)
        self.steps += 1
        self.ctx.outputs["waited"] = {"seconds": waited, "pid": os.getpid(), "steps": self.steps}
        return Status.SUCCESS if waited >= self.duration - 1e-6 else Status.RUNNING

    def snapshot(self) -> Mapping[str, Any] | None:
        return {"began": self.began, "steps": self.steps}
