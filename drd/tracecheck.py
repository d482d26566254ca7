"""The ownership invariant, checked from a trace alone (the records of `docs/trace.md`, as dicts).

What a run promises, whatever happened in it: a device obeys only the behavior subtree holding its current
grant, at that grant's epoch; an exclusive unit has one holder at a time; every hold ends by the end of a
finished mission. `check` reads `granted` (units and epochs), `revoked`/`released`/`exited` (ends of holds) and
`command` records, in order, per mission (`mission` field, when a trace holds several), and lists every breach.
Pure: the caller reads the file (`missionctl check-trace` does).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True, slots=True)
class Breach:
    """One violation of the invariant, at a record of the trace."""

    at: float
    kind: str  # "non-holder command", "double hold", "held at the end"
    detail: str


@dataclass
class OwnershipReport:
    records: int = 0
    commands: int = 0
    accepted: int = 0
    refused: int = 0
    grants: int = 0
    breaches: list[Breach] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.breaches

    def summary(self) -> str:
        return (f"ownership: {self.accepted} accepted commands of {self.commands} ({self.refused} refused),"
                f" {self.grants} grants; {len(self.breaches)} breaches")


def under(path: str, holder: str) -> bool:
    """Whether `path` is `holder` or lies in its subtree."""
    return path == holder or path.startswith(holder + "/")


def check(records: Iterable[Mapping[str, Any]], sharable: Collection[str] = ()) -> OwnershipReport:
    """Check a trace's records in order; `sharable`: unit ids that several holders may hold at once."""
    report = OwnershipReport()
    holders: dict[tuple[str, str], dict[str, int]] = {}  # (mission, unit) -> {holder path: epoch}
    finished: set[str] = set()
    for r in records:
        report.records += 1
        kind, mission, path = r.get("kind"), str(r.get("mission", "")), str(r.get("path", ""))
        at = float(r.get("at", 0.0) or 0.0)
        if kind == "granted":
            report.grants += 1
            for unit, epoch in dict(r.get("epochs") or {}).items():
                held = holders.setdefault((mission, unit), {})
                others = [h for h in held if h != path]
                shared_by_missions = [(m, u) for (m, u), hs in holders.items() if u == unit and m != mission and hs]
                if unit not in sharable and (others or shared_by_missions):
                    who = others or [f"{m}: {', '.join(holders[(m, u)])}" for m, u in shared_by_missions]
                    report.breaches.append(Breach(at, "double hold", f"{unit} granted to {path} while held by "
                                                  f"{', '.join(who)}"))
                held[path] = int(epoch)
        elif kind in ("revoked", "released"):
            for unit in r.get("resources") or ():
                holders.get((mission, str(unit)), {}).pop(path, None)
        elif kind == "exited":
            for (m, _), held in holders.items():
                if m == mission:
                    held.pop(path, None)
        elif kind == "finished":
            finished.add(mission)
            left = [(u, h) for (m, u), held in holders.items() if m == mission for h in held]
            for unit, holder in left:
                report.breaches.append(Breach(at, "held at the end", f"{holder} still holds {unit}"))
        elif kind == "command":
            report.commands += 1
            if not r.get("accepted"):
                report.refused += 1
                continue
            report.accepted += 1
            unit, epoch = str(r.get("device")), r.get("epoch")
            held = holders.get((mission, unit), {})
            if not any(under(path, h) and e == epoch for h, e in held.items()):
                have = ", ".join(f"{h} at epoch {e}" for h, e in held.items()) or "nobody"
                report.breaches.append(Breach(at, "non-holder command", f"{path} commanded {unit}."
                                              f"{r.get('method')} at epoch {epoch}; holders: {have}"))
    return report
