"""The controller's placement decisions, kept for `missionctl status`, and the devices near an instance.

`MissionRunner.place` asks the policy (`drd.placement.place`) for each movable instance; what it decided
(the `Decision` record: hosts filtered and why, hosts scored with their parts, the winner) is kept here, the
last one per instance path and mission, at most `KEPT_PER_MISSION` instances per mission, and forgotten when the
executive forgets the mission. The executive's status adds them to each mission (`placements`).

`near_devices` finds the instance being placed in its mission's live tree and counts, by host, the devices its
mission state uses: those granted to its ancestors and to the states under its parent (its siblings and their
descendants). That is what device affinity scores (docs/placement.md). No I/O: it reads the live tree.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Collection, Iterable, Mapping
from typing import Any

from drd.placement import Decision

#: Instances of one mission whose last decision is kept (the most recently placed).
KEPT_PER_MISSION = 100
#: Scored hosts, and filtered hosts, a decision shows in a status reply at most (the log has the rest).
SHOWN_HOSTS = 5


class PlacementLog:
    """The last placement decision of each instance of each mission the executive still knows."""

    def __init__(self, known: Callable[[], Collection[str]]) -> None:
        """`known`: the missions the executive still knows (the others' decisions are dropped)."""
        self.known = known
        self._lock = threading.Lock()
        self._by_mission: dict[str, OrderedDict[str, tuple[str, Decision]]] = {}
        self._moved: dict[tuple[str, str], tuple[str, str]] = {}  # (mission, instance) -> (host, from) of a migrate

    def note(self, mission: str, instance: str, decision: Decision) -> None:
        """The policy decided where `instance` (its path, or the component's name when unknown) goes: `placed`
        the first time, `re-placed` after (its host was lost, or a start there failed)."""
        known = set(self.known())
        with self._lock:
            for mid in [m for m in self._by_mission if m not in known and m != mission]:
                del self._by_mission[mid]
            kept = self._by_mission.setdefault(mission, OrderedDict())
            how = "re-placed" if kept.pop(instance, None) is not None else "placed"
            kept[instance] = (how, decision)
            self._moved.pop((mission, instance), None)
            while len(kept) > KEPT_PER_MISSION:
                kept.popitem(last=False)

    def moved(self, mission: str, instance: str, host: str, source: str) -> None:
        """`missionctl migrate` moved `instance` from `source` to `host`: its entry says so (its last decision, the
        policy's, is kept for what it weighed), until the policy places it again (placement audit 24, #5: status
        went on saying the host it had left)."""
        with self._lock:
            if instance in self._by_mission.get(mission, {}):
                self._moved[(mission, instance)] = (host, source)

    def of(self, mission: str) -> list[dict[str, Any]]:
        """The mission's decisions, oldest placement first, as plain JSON (`status_entry`)."""
        with self._lock:
            kept = list(self._by_mission.get(mission, {}).items())
            moved = {i: self._moved[(mission, i)] for i, _ in kept if (mission, i) in self._moved}
        out = [status_entry(instance, how, d) for instance, (how, d) in kept]
        for entry in out:
            if entry["instance"] in moved:
                host, source = moved[entry["instance"]]
                entry.update(host=host, how="migrated", summary=f"{host} (moved from {source} by missionctl migrate)")
        return out

    def extras(self, mission: str) -> dict[str, Any]:
        """What the executive's status adds to the mission: `placements`, when it placed anything."""
        entries = self.of(mission)
        return {"placements": entries} if entries else {}


def status_entry(instance: str, how: str, decision: Decision, shown: int = SHOWN_HOSTS) -> dict[str, Any]:
    """One instance's decision in a status reply: `instance`, `host`, `how`, `summary` (one line) and `decision`
    (the record, with at most `shown` scored and `shown` filtered hosts; `left_out` counts the others)."""
    record = decision.as_dict()
    filtered = list(record["filtered"].items())
    left = {"scored": max(0, len(record["scored"]) - shown), "filtered": max(0, len(filtered) - shown)}
    record["scored"], record["filtered"] = record["scored"][:shown], dict(filtered[:shown])
    if any(left.values()):
        record["left_out"] = left
    return {"instance": instance, "host": decision.winner, "how": how, "summary": decision.summary(),
            "decision": record}


def near_devices(root: Any, component: str, hosts_of: Mapping[str, str]) -> tuple[str | None, dict[str, int]]:
    """The path of the instance of `component` being placed under `root` (the mission's live tree: its leaf
    whose movable component has no host yet), and its nearby devices counted by host (`hosts_of`: resource id ->
    host). (None, {}) when no such leaf is found."""
    leaf = next((n for n in _live(root) if _being_placed(n, component)), None)
    if leaf is None:
        return None, {}
    around: list[Any] = list(leaf.ancestors())
    if leaf.parent is not None:
        around += [n for n in leaf.parent.subtree() if n is not leaf.parent]
    counts: dict[str, int] = {}
    for rid in sorted(_resources(around)):
        host = hosts_of.get(rid)
        if host:
            counts[host] = counts.get(host, 0) + 1
    return str(leaf.path), counts


def _live(root: Any) -> Iterable[Any]:
    return root.subtree() if root is not None else ()


def _being_placed(node: Any, component: str) -> bool:
    """A leaf of `component` whose movable proxy is between placements (its host unset: `RemoteComponent._place`
    clears it before asking the policy)."""
    comp = node.component
    return (getattr(node.state, "component", None) == component and comp is not None
            and getattr(comp, "movable", False) and getattr(comp, "host", "") is None)


def _resources(nodes: Iterable[Any]) -> set[str]:
    """The resources (robots and units) granted to `nodes`, each once."""
    out: set[str] = set()
    for n in nodes:
        out.update(str(v) for v in (n.grant or {}).values())
        out.update(str(u) for u in n.units)
    return out
