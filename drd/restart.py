"""The dry-run's controller, which `--inject 'kill controller at T'` and `'restart controller at T2'` replace as
on a cluster (issue #16).

Killed, it says nothing more (a dead process records nothing), the hosts stop every robot (the gates lose their
holders, as a Creator does when the controller's token vanishes), and its missions wait. Started again, it is a
new executive over the same world, with the resources the manager would know then (not those of hosts killed
or not joined yet, nor lost robots); it puts back the Static Dependency Database's changes and resumes each
unfinished mission from its journal, i.e. its state at the end of the last control cycle before the kill
(`drd.runtime.snapshot`), as `drd start` does on a cluster. Killed with no restart to come, its missions stop
there, saying so: that is what an operator sees who does not start the controller again.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable
from typing import Any

from drd.executive import Executive
from drd.runtime import records as rec
from drd.runtime.snapshot import NodeImage, capture, property_changes
from dsl.statechart import Statechart

Listener = Callable[[rec.Record], None]


class ControllerLife:
    """The executive of a dry-run and what restarting it needs. `make(gone)` builds an executive without the
    resources whose ids are in `gone`."""

    def __init__(self, executive: Executive, make: Callable[[Collection[str]], Executive],
                 resources: Iterable[Any], gone: Collection[str] = ()) -> None:
        self.executive: Executive | None = executive
        self.make = make
        self.resources = list(resources)
        self.gone: set[str] = set(gone)  # resource ids the manager does not know now (killed, lost, not joined)
        self.submitted: dict[str, tuple[Statechart, list[Listener], int]] = {}
        self.interpreters: dict[str, Any] = {}  # every mission's latest interpreter
        self._saved: dict[str, NodeImage] = {}
        self._properties: dict[str, dict[str, Any]] = {}
        self._died_at = 0.0

    def submit(self, chart: Statechart, mid: str, listeners: list[Listener], priority: int) -> None:
        assert self.executive is not None
        self.submitted[mid] = (chart, listeners, priority)
        self.executive.submit(chart, mid, listeners=listeners, priority=priority)
        self.interpreters[mid] = self.executive.missions[mid]

    def kill(self, now: float, host: str, restarting: bool) -> str:
        """The controller's daemon dies now; its missions wait for a restart (or stop, with none to come)."""
        executive = self.executive
        if executive is None:
            return "nothing happens: the controller is already down"
        if not restarting:
            for interp in executive.missions.values():
                if not interp.finished:
                    interp.stop(f"the controller ({host}) was lost: every host stopped its robots; start it again"
                                " to resume the mission (`restart " + host + " at ...`)")
            return "every mission stopped, every robot with it"
        for mid, interp in executive.missions.items():
            if not interp.finished and interp.root is not None:
                self._saved[mid] = NodeImage.from_dict(capture(interp.root).to_dict())
        self._properties = property_changes(self.resources, executive.pool)
        executive.abandon()  # a dead process says nothing more
        orphan = getattr(executive.gates, "orphan_all", None)
        if orphan is not None:
            orphan(now, "controller lost")  # the hosts stop every robot
        self.executive, self._died_at = None, now
        return f"every robot stopped; {len(self._saved)} mission(s) wait for the controller"

    def restart(self, now: float) -> str:
        """The controller starts again and resumes the missions it journaled."""
        if self.executive is not None:
            return "nothing happens: the controller is running"
        executive = self.executive = self.make(self.gone)
        for rid, values in self._properties.items():
            for key, value in values.items():
                if executive.pool.view(rid) is not None:
                    executive.pool.set_property(rid, key, value, now)
        for mid, image in self._saved.items():
            chart, listeners, priority = self.submitted[mid]
            executive.submit(chart, mid, listeners=listeners, priority=priority, resume=image, since=self._died_at,
                             paused=now - self._died_at)
            self.interpreters[mid] = executive.missions[mid]
        resumed, self._saved = len(self._saved), {}
        return f"{resumed} mission(s) resumed from the journal after {now - self._died_at:g} s"

    def finished(self) -> bool:
        return all(interp.finished for interp in self.interpreters.values())

    def end(self, why: str) -> None:
        """The run ends now: the missions still running stop (those waiting for a controller that never came
        back stop silently: no controller records their end)."""
        for interp in self.interpreters.values():
            if not interp.finished:
                interp.stop(why if self.executive is not None else f"{why}; the controller was down")
        if self.executive is not None:
            self.executive.close()
