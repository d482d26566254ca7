"""What a host needs before it starts, checked whole: the refusal comes before any process, pidfile or bus session
exists, naming the file and the key, instead of a failure at the first mission (issue #18).

`drd start` checks its host: the driver classes its devices name, the entry point of every component manifest
(any behavior may be placed on any worker), and, on the controller and the simulator's host, the world the cluster
names; a cluster with no simulator host runs real robots in no world, so none of its devices may be on `sim`.
`missionctl dry-run` runs every host in its own process, so it checks them all.
"""

from __future__ import annotations

from collections.abc import Iterable

from drd import entrypoints
from drd.entrypoints import EntryPointError
from drd.hosts import Cluster, Role
from drd.hw.drivers import SIM, check_driver_classes
from dsl.catalog import Catalog


def entry_point_problems(catalog: Catalog, names: Iterable[str] | None = None) -> list[str]:
    """Every manifest entry point (or those of the components `names`) imported, each problem naming the manifest:
    a module or class that is not there, or a module that fails to import."""
    problems = []
    wanted = set(names) if names is not None else None
    for ct in sorted(catalog.components.values(), key=lambda c: c.name):
        if ct.entry_point is None or (wanted is not None and ct.name not in wanted):
            continue
        try:
            entrypoints.load(ct.entry_point)
        except EntryPointError as e:
            problems.append(f"{ct.source}: entry_point: {e}")
    return problems


def world_problems(cluster: Cluster) -> list[str]:
    """The world `cluster.world` names, found under worlds/ and loaded (its own problems name its file)."""
    from drd.sim import WorldError, load_world
    from drd.sim.service import world_dirs, world_file

    try:
        load_world(world_file(cluster.world, world_dirs(cluster)))
    except ValueError as e:
        return [f"{cluster.source}: cluster.world: {e}"]
    except WorldError as e:
        return [str(p) for p in e.problems]
    return []


def sim_driver_problems(cluster: Cluster) -> list[str]:
    """With no simulator host, every device on a `sim` driver (it would have no world to read): each named by its
    file and key. Empty when a host has the role simulator."""
    if any(Role.SIMULATOR in h.roles for h in cluster.hosts):
        return []
    return [f"{cluster.source}: hosts.{h.name}.devices.{d.id.removeprefix(h.name + '.')}.driver: sim, but no host has"
            " the role simulator: drive it with a real driver (ros2, docs/ros2.md), or give one host the role"
            " simulator" for h in cluster.hosts for d in h.devices if d.driver == SIM]


def start_problems(cluster: Cluster, host: str, catalog: Catalog) -> list[str]:
    """What keeps `host` from starting (empty when nothing does). With no simulator host the missions run on the
    real robots, in no world: no world is loaded. A device left on a `sim` driver then is refused when a mission is
    run (`sim_driver_problems`, said by `missionctl run`), not here: such daemons serve all but missions."""
    problems = check_driver_classes(cluster, host, catalog) + entry_point_problems(catalog)
    roles = cluster.host(host).roles
    simulated = any(Role.SIMULATOR in h.roles for h in cluster.hosts)
    if simulated and (Role.CONTROLLER in roles or Role.SIMULATOR in roles):  # they make the world a mission runs in
        problems += world_problems(cluster)
    return problems


def dry_run_problems(cluster: Cluster, catalog: Catalog, components: Iterable[str]) -> list[str]:
    """What keeps a dry-run of missions using `components` from starting: every host's drivers (they all run in its
    process) and those components' entry points."""
    problems = [p for h in cluster.hosts for p in check_driver_classes(cluster, h.name, catalog)]
    return problems + entry_point_problems(catalog, components)
