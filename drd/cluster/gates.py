"""The gates of devices on other hosts, from the controller's side, and the records they send back.

On a cluster a device's gate (`drd.runtime.ownership.DeviceGate`) lives in the Creator of the device's host,
next to its driver. The controller's interpreters tell `RemoteGates` each grant, each end of one and each
unbinding, as they tell in-process gates in a dry-run; `RemoteGates` queues them per host. They go out before
anything else that host is asked (a lifecycle call or a step batch carries them, `take`), and at the end of
every control cycle to the hosts nobody called (`flush`, a `GateUpdate`): a device whose holder lost it stops
in the cycle it lost it. What the gates record there (commands, halts) comes back with the replies, as plain
dicts, and goes to the mission it concerns (`records`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from drd.bus import Message, message
from drd.rcm.constraints import Measure
from drd.runtime import records as rec
from drd.runtime.constraints import Breach

log = logging.getLogger("drd.cluster.gates")

#: (host, robot -> live values) of a `telemetry` record.
Seen = Callable[[str, Mapping[str, Any]], None]


@message("drd.gate.update", 2)
class GateUpdate(Message):
    """Gate operations for one host, in order: `["grant", device, holder, epoch, at]`,
    `["clear", device, holder, at, reason]`, `["unbind", device, issuer, at, reason]` (holders and issuers are
    mission-qualified paths), and the constraints' (`guard`, `unguard`, `seen`, `watch`: `drd.cluster.guard`)."""

    ops: list[list[Any]]
    world: str = ""  # the world the devices' drivers run in, and its reset count (as `ComponentCall`)
    generation: int = 0
    term: float = 0.0  # the controller's (as `ComponentCall`)


@message("drd.gate.update-reply", 1)
class GateUpdateReply(Message):
    """The records the gates made while applying the update (halts, breaches, telemetry), as dicts."""

    records: list[dict[str, Any]]


class RemoteGates:
    """`drd.runtime.ownership.Gates` for devices on other hosts: operations queued per host (see the module)."""

    def __init__(self, device_hosts: Mapping[str, str], deliver: Callable[[], None] | None = None) -> None:
        """`deliver`: carries the queued operations now and records their replies (the controller's mission
        runner: `settle`)."""
        self.device_hosts = dict(device_hosts)
        self.seen: Seen | None = None  # where robots' live values in the replies go (`drd.cluster.telemetry`)
        self.deliver = deliver
        self._pending: dict[str, list[list[Any]]] = {}
        self._lock = threading.Lock()  # the mission loops of several missions share it

    def grant(self, device: str, holder: str, epoch: int, at: float) -> None:
        self._add(device, ["grant", device, holder, epoch, at])

    def clear(self, device: str, holder: str, at: float, reason: str) -> None:
        self._add(device, ["clear", device, holder, at, reason])

    def unbind(self, device: str, issuer: str, at: float, reason: str) -> None:
        self._add(device, ["unbind", device, issuer, at, reason])

    def _add(self, device: str, op: list[Any]) -> None:
        host = self.device_hosts.get(device)
        if host is not None:  # else an aggregate, or a device no host serves: nothing to tell
            self.send(host, op)

    def send(self, host: str, op: list[Any]) -> None:
        """Queue an operation for `host` (in order with its gates' operations)."""
        with self._lock:
            self._pending.setdefault(host, []).append(op)

    def take(self, host: str) -> list[list[Any]] | None:
        """The operations queued for `host`, now on their way (None when there are none)."""
        with self._lock:
            return self._pending.pop(host, None)

    def hosts(self) -> list[str]:
        """The hosts with operations waiting."""
        with self._lock:
            return sorted(self._pending)

    def settle(self) -> None:
        """Carry the queued operations now, their records back before whatever the caller records next: a mission
        ending halts the setpoints its components left in force, and those `halted` records must come before its
        `finished`, as in a dry-run (safety audit 7, D4: the executive dropped them, after `finished`)."""
        if self.deliver is not None and self.hosts():
            self.deliver()


def wire_record(mission: str, record: rec.Record) -> dict[str, Any]:
    """A gate's record as a reply carries it."""
    return {"mission": mission, **record.to_dict()}


_KINDS: dict[str, type[rec.Record]] = {"command": rec.Command, "halted": rec.Halted}


def from_wire(data: Mapping[str, Any]) -> tuple[str, rec.Record | Breach] | None:
    """(mission, record) of a `wire_record` dict or a guard's `breach`, or None if it is neither (never trusted
    further)."""
    mission = data.get("mission")
    if not isinstance(mission, str):
        return None
    if data.get("kind") == "breach":
        breach = breach_of(data)
        return (mission, breach) if breach is not None else None
    kind = _KINDS.get(str(data.get("kind")))
    if kind is None:
        return None
    fields = {k: v for k, v in data.items() if k not in ("kind", "mission")}
    try:
        return mission, kind(**fields)
    except TypeError:
        return None


def breach_of(data: Mapping[str, Any]) -> Breach | None:
    """A `breach` record's `Breach` (`drd.cluster.guard`), or None if malformed."""
    try:
        m = Measure(bool(data["holds"]), float(data["margin"]), float(data["value"]), float(data["limit"]),
                    str(data.get("measured") or "compare"))
        return Breach(str(data["holder"]), str(data["name"]), m)
    except (KeyError, TypeError, ValueError):
        return None


def deliver(records: Iterable[Mapping[str, Any]] | None, sink: Callable[[str, rec.Record | Breach], None],
            seen: Seen | None = None) -> None:
    """Hand each gate record of a reply to the mission it concerns, and robots' live values to `seen`."""
    for data in records or ():
        if not isinstance(data, Mapping):
            continue
        if data.get("kind") == "telemetry":
            host, robots = data.get("host"), data.get("robots")
            if seen is not None and isinstance(host, str) and isinstance(robots, Mapping):
                seen(host, robots)
            continue
        found = from_wire(data)
        if found is not None:
            sink(*found)


def take_pending(bus: Any, cluster: str, hosts: Iterable[str], update: GateUpdate, patience: float,
                 down: Callable[[str], bool] = lambda h: False) -> list[dict[str, Any]]:
    """What each of `hosts` recorded and has not sent yet (the halts it made when it lost its controller), asked
    now with an empty `update` rather than left for its next reply to a controller: those records must reach the
    trace before anything a resuming or waking controller does with the mission (docs/trace.md, causal order).
    A host that does not answer at once (links a freeze dropped are being made again) is asked again for up to
    `patience` seconds; a host still silent then, or refusing the term, keeps its records for its next reply."""
    got: list[dict[str, Any]] = []
    for host in hosts:
        deadline = time.monotonic() + patience
        while not down(host):
            try:
                reply = bus.call(f"drd/{cluster}/host/{host}/creator", update, timeout=max(0.1, min(1.0, patience)))
            except Exception as e:  # no answer yet: ask again until the patience runs out
                if time.monotonic() >= deadline:
                    log.warning("%s's pending records were not taken (%s): they come with its next reply", host, e)
                    break
                time.sleep(0.1)
                continue
            if isinstance(reply, GateUpdateReply):
                got += [r for r in reply.records or () if isinstance(r, dict)]
            break
    return got
