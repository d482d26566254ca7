"""The Mission Executive's messages on the bus (`drd.executive`), in a module of their own: a client such as
`missionctl status` registers them without importing the executive, its manager and its interpreter (a fifth
of a second)."""

from __future__ import annotations

from typing import Any

from drd.bus import Message, message


@message("drd.mission.record", 2)
class MissionRecord(Message):
    """One runtime record (entry, exit, transition, grant, event...) of one mission. `seq` numbers the records
    of every mission of one controller in the order they happened (so the traces of missions that ran together
    merge in causal order)."""

    mission: str
    kind: str
    at: float
    path: str
    data: dict[str, Any]
    seq: int = 0


@message("drd.mission.command", 3)
class MissionCommand(Message):
    """An operator's command: `status`, `stop` (a mission, or all with mission ""), `emit`, or `records` (of a
    mission, numbered after `after`: what a client missed while its controller was away, `MissionRecords`).

    Replies come in pages (issue #16: no reply outgrows the transport): `status` answers the missions after the
    cursor `after` (the `next` of the page before; 0: from the first), at most `count` of them (0: the
    executive's page size) and at most half a bus message of them; `records` the same for a mission's records,
    numbered after `after`. A client asks again with `after=next` until `next` is 0."""

    op: str
    mission: str = ""
    event: str = ""
    fields: dict[str, Any] | None = None
    after: int = 0
    count: int = 0


@message("drd.mission.records", 2)
class MissionRecords(Message):
    """A page of a running mission's latest records (of at most `drd.executive.KEPT_RECORDS`), in order; `next`:
    the `after` to ask the next page with (0: this is the last)."""

    records: list[MissionRecord]
    next: int = 0


@message("drd.mission.status", 2)
class MissionStatus(Message):
    """A page of the missions the executive knows, in the order they started, each with its outcome and active
    state tree (and on a cluster `placements`: the controller's last placement decision of each movable
    instance, `drd.daemon.placements.status_entry`); `next`: the `after` to ask the next page with (0: this is
    the last)."""

    time: float
    missions: list[dict[str, Any]]
    next: int = 0
