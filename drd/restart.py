"""The dry-run's controller, which `--inject 'kill controller at T'` and `'restart controller at T2'` replace as
on a cluster (issue #16).

Killed, it says nothing more (a dead process records nothing), the hosts stop every robot (the gates lose their
holders, as a Creator does when the controller's token vanishes), and its missions wait. Started again, it is a
new executive over the same world, with the resources the manager would know then (not those of hosts killed
or not joined yet, nor lost robots); it puts back the Static Dependency Database's changes and resumes each
unfinished mission from its journal, i.e. its state at the end of the last control cycle before the kill
(`drd.runtime.snapshot`), as `drd start` does on a cluster. Killed with no restart to come, its missions stop
there, saying so: that is what an operator sees who does not start the controller again.

With several controller hosts and a replicated store (`cluster.store: {etcd: ...}`), as on such a cluster: the first
controller acts, the others are standbys. Killed, the acting one is replaced by the first standby still alive once
the election's lease ran out (`drd.cluster.election.election_ttl`, the lease the dead one can no longer renew), which
resumes the missions from the replicated journal as a restart does; a standby's death changes nothing else; a
controller started again is a standby while another acts, and acts (once the dead one's lease ran out) when none
does.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Sequence
from contextlib import AbstractContextManager
from typing import Any

from drd.executive import Executive
from drd.runtime import records as rec
from drd.runtime.interpreter import stop_together
from drd.runtime.snapshot import NodeImage, capture, property_changes
from dsl.statechart import Statechart

Listener = Callable[[rec.Record], None]


class ControllerLife:
    """The executive of a dry-run and what restarting it needs. `make(gone)` builds an executive without the
    resources whose ids are in `gone`."""

    def __init__(self, executive: Executive, make: Callable[[Collection[str]], Executive],
                 resources: Iterable[Any], gone: Collection[str] = (), *, controllers: Sequence[str] = (),
                 election: float = 0.0, grace: float = 0.0, down: Iterable[str] = ()) -> None:
        """`controllers`: the controller hosts, the acting one first (several: a replicated store elects);
        `election`: the election's lease, seconds (0: one controller, no election); `grace`: how long a controller
        started again waits for the hosts with devices that are `down` before it resumes (`drd start`'s two leases
        and 5 s, `drd.daemon.missions.MissionRunner._resume`)."""
        self.executive: Executive | None = executive
        self.acting = controllers[0] if controllers else ""
        self.standbys = list(controllers[1:])  # alive standby controllers, in the order they would win
        self.election = election
        self.standbys_later = set(controllers) if election else set()  # hosts whose restart resumes (an election)
        self.takeover: tuple[float, str] | None = None  # (when, by whom) a standby takes the dead one's place
        self.make = make
        self.resources = list(resources)
        self.gone: set[str] = set(gone)  # resource ids the manager does not know now (killed, lost, not joined)
        self.submitted: dict[str, tuple[Statechart, list[Listener], int]] = {}
        self.interpreters: dict[str, Any] = {}  # every mission's latest interpreter
        self._saved: dict[str, NodeImage] = {}
        self._properties: dict[str, dict[str, Any]] = {}
        self._died_at = 0.0
        self._numbered = 0  # the dead executive's last record number or highest epoch (`Executive.highest_number`)
        self.grace = grace
        self.down: set[str] = set(down)  # hosts with devices down now (killed, or not joined yet)
        self.resuming: tuple[float, str] | None = None  # (until when, which controller) waits for `down` to resume

    def together(self) -> AbstractContextManager[None]:
        """Missions submitted in this block start as one: their requests are granted by priority, not by which was
        submitted first (`drd.runtime.broker.ResourceBroker.together`)."""
        assert self.executive is not None
        return self.executive.together()

    def submit(self, chart: Statechart, mid: str, listeners: list[Listener], priority: int) -> None:
        assert self.executive is not None
        self.submitted[mid] = (chart, listeners, priority)
        self.executive.submit(chart, mid, listeners=listeners, priority=priority)
        self.interpreters[mid] = self.executive.missions[mid]

    def kill(self, now: float, host: str, restarting: bool) -> str:
        """A controller's daemon dies now: a standby's changes nothing; the acting one's missions wait for a standby's
        takeover, or a restart (or stop, with none to come)."""
        if host in self.standbys:
            self.standbys.remove(host)
            return f"a standby controller is gone; {self.acting if self.executive is not None else 'none'} acts"
        if self.takeover is not None and self.takeover[1] == host:  # the standby about to win: the next one will
            self.takeover = (self.takeover[0], self.standbys.pop(0)) if self.standbys else None
            return "the standby about to take over is gone" + (f"; {self.takeover[1]} will" if self.takeover else "")
        if self.election and host != self.acting:
            return "nothing happens: it is not running"
        executive = self.executive
        if executive is None:
            return "nothing happens: the controller is already down"
        if self.standbys:  # its election lease runs out, then the first standby left wins
            self.takeover = (now + self.election, self.standbys.pop(0))
            restarting = True
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
        orphan = getattr(executive.gates, "orphan_all", None)
        if orphan is not None:  # the hosts stop every robot, and record it (`halted`), as a cluster's Creators do
            orphan(now, f"controller {host} lost (killed)")
        executive.abandon()  # a dead process says nothing more
        self._numbered = executive.highest_number()  # what the next controller numbers and grants above
        self.executive, self._died_at = None, now
        if self.takeover is not None:
            return (f"every robot stopped; {len(self._saved)} mission(s) wait for standby {self.takeover[1]}, which"
                    f" takes over once the election's lease of {self.election:g} s runs out")
        return f"every robot stopped; {len(self._saved)} mission(s) wait for the controller"

    def tick(self, now: float) -> str | None:
        """A standby's takeover, when its time came, or a restarted controller's resume once the hosts it waits for
        are back (or its grace ran out): what happened (None: nothing)."""
        if self.resuming is not None and (not self.down or now >= self.resuming[0] - 1e-9):
            _until, host = self.resuming
            self.resuming = None
            without = f" without {', '.join(sorted(self.down))} (still down)" if self.down else ""
            return f"{host} resumed{without}: " + self._resume(now, host)
        if self.takeover is None or now < self.takeover[0] - 1e-9:
            return None
        _when, host = self.takeover
        self.takeover = None
        return f"standby controller {host} elected: " + self._resume(now, host)

    def restart(self, now: float, host: str = "") -> str:
        """A controller starts again: a standby while another acts (or is about to), else it resumes the missions
        it journaled (with an election, once the dead one's lease ran out: they resume at the next `tick` then)."""
        if self.executive is not None or self.takeover is not None:
            if not self.election:
                return "nothing happens: the controller is running"
            self.standbys.append(host)
            acting = self.acting if self.executive is not None else self.takeover[1] if self.takeover else ""
            return f"a standby controller again ({acting} acts)"
        if self.election and now < self._died_at + self.election - 1e-9:  # the dead one's key lingers until then
            self.takeover = (self._died_at + self.election, host or self.acting)
            return f"campaigns: elected once the lost controller's lease runs out, at {self.takeover[0]:g} s"
        if self.down and self.grace > 0:  # as `drd start` does: the hosts with devices first (cluster audit 20, #3)
            self.resuming = (now + self.grace, host)
            return (f"waits for {', '.join(sorted(self.down))} (down) to resume the missions, until"
                    f" {now + self.grace:g} s at most")
        return self._resume(now, host)

    def _resume(self, now: float, host: str) -> str:
        """This controller acts: a new executive resumes the journaled missions."""
        self.acting = host or self.acting
        executive = self.executive = self.make(self.gone)
        executive.continue_records(self._numbered)  # as a journal's numbering, with no gap: nothing went unsaved
        for rid, values in self._properties.items():
            for key, value in values.items():
                if executive.pool.view(rid) is not None:
                    executive.pool.set_property(rid, key, value, now)
        with executive.together():  # by priority, not by who is entered first (safety audit 7, D2)
            for mid, image in self._saved.items():
                chart, listeners, priority = self.submitted[mid]
                executive.submit(chart, mid, listeners=listeners, priority=priority, resume=image,
                                 since=self._died_at, paused=now - self._died_at)
                self.interpreters[mid] = executive.missions[mid]
        resumed, self._saved = len(self._saved), {}
        return f"{resumed} mission(s) resumed from the journal after {now - self._died_at:g} s"

    def finished(self) -> bool:
        return all(interp.finished for interp in self.interpreters.values())

    def end(self, why: str) -> None:
        """The run ends now: the missions still running stop (those waiting for a controller that never came
        back stop silently: no controller records their end)."""
        reason = why if self.executive is not None else f"{why}; the controller was down"
        stop_together(self.interpreters.values(), reason)  # as one stop: none is granted what another gives back
        if self.executive is not None:
            self.executive.close()
