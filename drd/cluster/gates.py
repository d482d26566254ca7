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

import threading
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from drd.bus import Message, message
from drd.runtime import records as rec


@message("drd.gate.update", 1)
class GateUpdate(Message):
    """Gate operations for one host, in order: `["grant", device, holder, epoch, at]`,
    `["clear", device, holder, at, reason]`, `["unbind", device, issuer, at, reason]` (holders and issuers are
    mission-qualified paths)."""

    ops: list[list[Any]]
    world: str = ""  # the world the devices' drivers run in, and its reset count (as `ComponentCall`)
    generation: int = 0


@message("drd.gate.update-reply", 1)
class GateUpdateReply(Message):
    """The records the gates made while applying the update (halts), as `wire_record` dicts."""

    records: list[dict[str, Any]]


class RemoteGates:
    """`drd.runtime.ownership.Gates` for devices on other hosts: operations queued per host (see the module)."""

    def __init__(self, device_hosts: Mapping[str, str]) -> None:
        self.device_hosts = dict(device_hosts)
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
        if host is None:  # an aggregate, or a device no host serves: nothing to tell
            return
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


def wire_record(mission: str, record: rec.Record) -> dict[str, Any]:
    """A gate's record as a reply carries it."""
    return {"mission": mission, **record.to_dict()}


_KINDS: dict[str, type[rec.Record]] = {"command": rec.Command, "halted": rec.Halted}


def from_wire(data: Mapping[str, Any]) -> tuple[str, rec.Record] | None:
    """(mission, record) of a `wire_record` dict, or None if it is not a gate's record (never trusted further)."""
    kind = _KINDS.get(str(data.get("kind")))
    mission = data.get("mission")
    if kind is None or not isinstance(mission, str):
        return None
    fields = {k: v for k, v in data.items() if k not in ("kind", "mission")}
    try:
        return mission, kind(**fields)
    except TypeError:
        return None


def deliver(records: Iterable[Mapping[str, Any]] | None, sink: Callable[[str, rec.Record], None]) -> None:
    """Hand each gate record of a reply to the mission it concerns."""
    for data in records or ():
        found = from_wire(data) if isinstance(data, Mapping) else None
        if found is not None:
            sink(*found)
