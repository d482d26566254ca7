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


@message("drd.mission.command", 2)
class MissionCommand(Message):
    """An operator's command: `status`, `stop` (a mission, or all with mission ""), `emit`, or `records` (of a
    mission, numbered after `after`: what a client missed while its controller was away, `MissionRecords`)."""

    op: str
    mission: str = ""
    event: str = ""
    fields: dict[str, Any] | None = None
    after: int = 0


@message("drd.mission.records", 1)
class MissionRecords(Message):
    """A running mission's latest records (at most `drd.executive.KEPT_RECORDS`), in order."""

    records: list[MissionRecord]


@message("drd.mission.status", 1)
class MissionStatus(Message):
    """Every mission the executive knows, with its outcome and active state tree."""

    time: float
    missions: list[dict[str, Any]]
