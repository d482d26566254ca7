"""`missionctl migrate`, the controller's side: move a running movable component to another host (issue #15).

The controller serves `drd/<cluster>/missions/migrate` (an operator's key: `drd.daemon.acl`). A `Migrate`
names an instance (`<mission>/<path>`, or its path when one mission runs it) and a host. With the missions'
lock held (no control cycle runs meanwhile, so the behavior misses no step), the instance's proxy
(`drd.cluster.remote.RemoteComponent.migrate`) stops it where it runs as `moved` (its fresh snapshot comes
back and nothing of it stays there), then sets it up on the new host, restores that snapshot and starts it.
Its state in the mission neither fails nor restarts: the statechart never sees the move.

Refused, with the reason, before anything moves (`refusal`, pure): an unknown instance, one that is not
running, a component whose manifest does not say `movable: true` or that is bound to devices, a host that
is not in the hosts file, is down, or may not run components (the Load Balancer's hosts: the `worker` ones,
every host when none has that role). What the component needs besides devices is what any host of the
cluster runs (the standard catalog); a host that cannot start it refuses, and the instance goes on where it
was.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from typing import Any

from drd.bus import Bus, Message, Query, Reply, message
from drd.bus.keys import is_concrete
from drd.cluster.remote import ComponentError, RemoteComponent
from drd.errors import MissionInputError
from drd.hosts import Cluster, Role

log = logging.getLogger("drd.daemon.migrate")


def migrate_key(cluster: str) -> str:
    return f"drd/{cluster}/missions/migrate"


@message("drd.component.migrate", 1)
class Migrate(Message):
    """Move `instance` (`<mission>/<path>`, or a path) to `host`."""

    instance: str
    host: str


@message("drd.component.migrated", 1)
class Migrated(Message):
    """What moved: the instance, its component, from and to which host, and the state it took along (`[state]`;
    `[None]`: its component keeps no state, it was started afresh and told so)."""

    mission: str
    path: str
    component: str
    source: str
    host: str
    state: list[Any]


class MigrateError(MissionInputError):
    """A refused migration: the reason, for the operator (exit 2)."""


def find(instances: Iterable[tuple[str, str, Any]], name: str) -> tuple[str, str, Any]:
    """The (mission, path, component) `name` designates among the running `instances`: `<mission>/<path>`, or a
    path that one mission runs. MigrateError naming the running instances otherwise."""
    found = list(instances)
    exact = [i for i in found if f"{i[0]}/{i[1]}" == name]
    by_path = [i for i in found if i[1] == name]
    if exact:
        return exact[0]
    if len(by_path) == 1:
        return by_path[0]
    if len(by_path) > 1:
        named = ", ".join(f"{m}/{p}" for m, p, _ in by_path)
        raise MigrateError(f"{name} runs in several missions: name one ({named})")
    known = ", ".join(sorted(f"{m}/{p}" for m, p, _ in found)[:12]) or "none"
    raise MigrateError(f"no running instance {name} (running: {known})")


def refusal(cluster: Cluster, movable: bool, component: str, source: str | None, host: str,
            down: Callable[[str], bool]) -> str:
    """Why moving an instance of `component` (declared movable or not, running on `source`, None if it runs
    nowhere else than in the controller or is bound to devices) to `host` is refused, or "" (pure)."""
    names = [h.name for h in cluster.hosts]
    if not movable:
        return f"{component} cannot move: its manifest does not say `movable: true`"
    if source is None:
        return f"{component} runs where its devices are, not on a host the Load Balancer picks: it cannot move"
    if host not in names:
        return f"unknown host {host!r} (hosts: {', '.join(names)})"
    workers = [h.name for h in cluster.hosts if Role.WORKER in h.roles]
    if workers and host not in workers:
        return f"{host} does not run components (the worker hosts: {', '.join(workers)})"
    if down(host):
        return f"host {host} is down"
    if host == source:
        return f"{component} already runs on {host}"
    return ""


class Migrations:
    """Serves `Migrate` on the controller for the missions of `runner` (`drd.daemon.missions.MissionRunner`)."""

    def __init__(self, bus: Bus, runner: Any) -> None:
        self.runner = runner
        self._queryable = bus.serve(migrate_key(runner.cluster.name), self._serve)

    def close(self) -> None:
        self._queryable.close()

    def _serve(self, query: Query) -> Message | Reply:
        if not is_concrete(query.key):  # a change of state is asked by this exact key (drd.daemon.acl)
            return query.error(f"ask {query.queryable} by its exact key")
        if not isinstance(query.payload, Migrate):
            return query.error("expected a drd.component.migrate")
        try:
            return self.migrate(query.payload)
        except (MigrateError, ComponentError) as e:
            return query.error(str(e))

    def instances(self) -> list[tuple[str, str, Any]]:
        """(mission, path, component) of every running leaf of the controller's missions (the lock held)."""
        out = []
        for mid, interp in self.runner.controller.executive.missions.items():
            if interp.finished:
                continue
            out += [(mid, node.path, comp) for node, comp in interp.host.active()]
        return out

    def migrate(self, req: Migrate) -> Migrated:
        runner = self.runner
        with runner.lock:  # no control cycle meanwhile: the instance misses no step
            mission, path, comp = find(self.instances(), req.instance)
            name = getattr(comp, "name", type(comp).__name__)
            ct = runner.catalog.get(name)
            remote = isinstance(comp, RemoteComponent) and comp.movable and comp.host is not None
            source = comp.host if remote else None
            why = refusal(runner.cluster, bool(ct is not None and ct.movable), name, source, req.host,
                          runner.host_down)
            if why:
                raise MigrateError(f"{mission}/{path}: {why}")
            assert isinstance(comp, RemoteComponent) and source is not None
            try:
                state = comp.migrate(req.host)
            finally:  # moved, or started there and its own code raised (it is there, failed): status says where
                if comp.host == req.host:
                    runner.placements.moved(mission, path, req.host, source)
        log.info("mission %s: %s (%s) moved from %s to %s with its state %s", mission, path, name, source,
                 req.host, state[0] if state else None)
        return Migrated(mission, path, name, source, req.host, list(state))
