"""What a host needs before it starts, checked whole: the refusal comes before any process, pidfile or bus session
exists, naming the file and the key, instead of a failure at the first mission (issue #18).

`drd start` checks its host: the driver classes its devices name, the entry point of every component manifest
(any behavior may be placed on any worker), and, on the controller and the simulator's host, the world the cluster
names; a cluster with no simulator host runs real robots in no world, so none of its devices may be on `sim`.
A component whose module imports a library this host lacks is not a mistake in its manifest: the host starts and
does not offer it (`StartCheck.unavailable`), so placement puts it on a host that has the library.
`missionctl dry-run` runs every host in its own process, so it checks them all.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from drd import entrypoints
from drd.entrypoints import EntryPointError, MissingDependency
from drd.hosts import Cluster, Role
from drd.hw.drivers import SIM, check_driver_classes
from dsl.catalog import Catalog


@dataclass(frozen=True)
class StartCheck:
    """What keeps a host from starting (`problems`, each naming its file and key), and the component types it
    starts without (`unavailable`: type -> why, a library their module imports that is not installed here)."""

    problems: list[str] = field(default_factory=list)
    unavailable: dict[str, str] = field(default_factory=dict)

    def warnings(self, host: str) -> list[str]:
        """One line per unavailable type, for the operator starting `host`."""
        return [f"{host} will not run {name}: {why}" for name, why in sorted(self.unavailable.items())]


def entry_point_check(catalog: Catalog, names: Iterable[str] | None = None, *, hosting: bool = False) -> StartCheck:
    """Every manifest entry point (or those of the components `names`) imported, each problem naming the manifest:
    a module or class that is not there, or a module that fails to import. With `hosting` (a daemon, which need
    not run every component), a module whose dependency is not installed makes its type unavailable instead."""
    check = StartCheck()
    wanted = set(names) if names is not None else None
    for ct in sorted(catalog.components.values(), key=lambda c: c.name):
        if ct.entry_point is None or (wanted is not None and ct.name not in wanted):
            continue
        try:
            entrypoints.load(ct.entry_point)
        except MissingDependency as e:
            if not hosting:
                check.problems.append(f"{ct.source}: entry_point: {e}")
            else:
                check.unavailable[ct.name] = (f"its module {entrypoints.split(ct.entry_point)[0]} needs "
                                              f"{e.dependency}, which is not installed here ({ct.source})")
        except EntryPointError as e:
            check.problems.append(f"{ct.source}: entry_point: {e}")
    return check


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


def start_check(cluster: Cluster, host: str, catalog: Catalog) -> StartCheck:
    """What keeps `host` from starting (no problems when nothing does), and what it starts without. With no
    simulator host the missions run on the real robots, in no world: no world is loaded. A device left on a `sim`
    driver then is refused when a mission is run (`sim_driver_problems`, said by `missionctl run`), not here: such
    daemons serve all but missions."""
    components = entry_point_check(catalog, hosting=True)
    problems = check_driver_classes(cluster, host, catalog) + components.problems
    roles = cluster.host(host).roles
    simulated = any(Role.SIMULATOR in h.roles for h in cluster.hosts)
    if simulated and (Role.CONTROLLER in roles or Role.SIMULATOR in roles):  # they make the world a mission runs in
        problems += world_problems(cluster)
    return StartCheck(problems, components.unavailable)


def dry_run_problems(cluster: Cluster, catalog: Catalog, components: Iterable[str]) -> list[str]:
    """What keeps a dry-run of missions using `components` from starting: every host's drivers (they all run in its
    process) and those components' entry points."""
    problems = [p for h in cluster.hosts for p in check_driver_classes(cluster, h.name, catalog)]
    return problems + entry_point_check(catalog, components).problems
