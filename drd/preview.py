"""What a mission would get at start on a cluster, without running it (`missionctl plan --config hosts.yaml`).

As `nomad plan` does for a job: the mission is entered on an executive over the hosts file's team, exactly as a
run starts it, and read back at that instant, before any control cycle (so no component steps and no robot
moves). The preview says which robot and device each need gets, which host would run each component (the host
of its devices, else the Load Balancer's policy over idle hosts), who waits and behind whom, and what cannot
hold: a need nothing in the hosts file satisfies, a binding or a `var` that fails at entry.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from drd.explain import Explainer
from drd.hosts import Cluster, Role
from drd.placement import Placed, place, view_of, with_more
from drd.runtime import records as rec
from drd.runtime.resources import BindingError
from drd.sim.world import World
from dsl.catalog import Catalog, ComponentType, Kind
from dsl.statechart import State, Statechart


@dataclass
class Preview:
    """One mission at start: `holds` (path -> need -> unit), `components` (one row per component that would
    start), `waits` (as `Explainer.waiting`), `problems` (what cannot hold, each a sentence)."""

    mission: str
    cluster: str
    holds: list[dict[str, Any]] = field(default_factory=list)
    components: list[dict[str, Any]] = field(default_factory=list)
    waits: list[dict[str, Any]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"mission": self.mission, "cluster": self.cluster, "holds": self.holds,
                "components": self.components, "waits": self.waits, "problems": self.problems}


def preview(charts: Sequence[tuple[Statechart, int | None]], cluster: Cluster, world: World,
            catalog: Catalog) -> list[Preview]:
    """Enter each mission (with its priority, or its own) on one team and read what each got at start."""
    from drd.dryrun import team  # the dry-run's team: the same executive, resources and drivers

    _sim, executive = team(cluster, world, catalog)
    runs: list[tuple[Statechart, str, list[rec.Record]]] = []
    for n, (chart, priority) in enumerate(charts, 1):
        records: list[rec.Record] = []
        mid = executive.submit(chart, f"{chart.name}-{n}", listeners=[records.append],
                               priority=priority or chart.priority)
        runs.append((chart, mid, records))
    placer = _Placer(cluster)
    previews = [_at_start(chart, mid, [r for r in records if r.at <= 0.0], executive.missions[mid], catalog, placer)
                for chart, mid, records in runs]
    for interp in executive.missions.values():
        if not interp.finished:
            interp.stop("preview only")
    close = getattr(_sim, "close", None)
    if callable(close):  # a team of ROS 2 robots was served for the preview
        close()
    return previews


class _Placer:
    """Where each component would run: its devices' host, else the policy over idle worker hosts (counting the
    preview's own placements, so a second instance spreads as the daemon's would)."""

    def __init__(self, cluster: Cluster) -> None:
        self.cluster = cluster
        self.hosts_of = {r.id: r.host for r in cluster.resources()}
        self.workers = [h.name for h in cluster.hosts if Role.WORKER in h.roles] or None
        self.views = {h.name: view_of(h) for h in cluster.hosts}

    def host(self, component: ComponentType, devices: Mapping[str, str],
             params: Mapping[str, Any]) -> tuple[str | None, str]:
        """(host, why), or (None, why not)."""
        hosts = sorted({self.hosts_of.get(u, "") for u in devices.values()} - {""})
        if hosts:
            return ", ".join(hosts), "its devices are there"
        decision = place(component, list(self.views.values()), self.cluster.placement, params=params,
                         affinity=self.workers)
        if not isinstance(decision, Placed):
            return None, decision.reason
        self.views[decision.host] = with_more(self.views[decision.host], component.name)
        return decision.host, "placement: " + "; ".join(decision.reasons[:1])


def _at_start(chart: Statechart, mid: str, at_start: list[rec.Record], interp: Any, catalog: Catalog,
              placer: _Placer) -> Preview:
    """One mission's preview, from its records at t=0 (and its live nodes' parameters, for the placement)."""
    p = Preview(mid, placer.cluster.name)
    states = {r.path: chart.states[r.state] for r in at_start if isinstance(r, rec.Entered)}
    active = _active(at_start)
    grants = {path: g for path, g in Explainer(at_start).holds_now().items() if path in active}
    p.holds = [{"path": path, "resources": {k: v for k, v in g.items() if "." not in k}} for path, g in grants.items()]
    for path in active:
        state = states[path]
        component = catalog.get(state.component or "") if state.component else None
        if component is None or component.kind is not Kind.BEHAVIOR or any(
                q.startswith((path + "/", path + "[")) for q in active):
            continue
        devices = _devices(interp, path, state)
        if len(devices) < len(state.needs):
            continue  # it waits for its needs: it starts only once they are granted
        node = interp.find(path)
        names = {spec.name for spec in component.params}
        params = {k: v for k, v in (node.scope.items() if node is not None else ()) if k in names}
        host, why = placer.host(component, devices, params)
        if host is None:
            p.problems.append(f"{path}: {component.name} cannot be placed: {why}")
        p.components.append({"path": path, "component": component.name, "devices": devices, "host": host,
                             "why": why})
    p.waits = Explainer(at_start).waiting_now()
    p.problems += [f"{w['path']}: nothing in the hosts file can grant {', '.join(w['needs'])}"
                   for w in p.waits if not w["blocked_by"]]
    p.problems += [f"{r.path} would end at start: {r.outcome}: {r.reason}"
                   for r in at_start if isinstance(r, rec.Finished) and r.outcome != "success"]
    return p


def _active(records: Sequence[rec.Record]) -> list[str]:
    """The paths entered and not exited, in entry order."""
    active: dict[str, None] = {}
    for r in records:
        if isinstance(r, rec.Entered):
            active[r.path] = None
        elif isinstance(r, rec.Exited):
            active.pop(r.path, None)
    return list(active)


def _devices(interp: Any, path: str, state: State) -> dict[str, str]:
    """The unit each need of the leaf at `path` is bound to, resolved as the run binds it
    (`ResourceClient.resolve`: the whole binding chain, a part of a held robot); a need not held yet is left out."""
    node = interp.find(path)
    out: dict[str, str] = {}
    if node is None:
        return out
    for need in state.needs:
        try:
            _holder, unit, _robot, _part = interp.resources.resolve(node, need)
        except BindingError:
            continue
        out[need.name] = unit
    return out
