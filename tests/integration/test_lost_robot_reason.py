"""A behavior that loses its robot says which one (docs audit item 5): the `exited` record's reason, the
degraded summary name the robot (`lost scout2 (resource lost)`), not `lost its
resources`. Real executive, manager, drivers and simulator (the dry-run), with an injected loss."""

from __future__ import annotations

from drd import inject
from drd.dryrun import run
from drd.hosts import load_hosts
from drd.runtime import records as rec
from drd.sim.world import load_world
from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import ROOT


def test_a_lost_scout_is_named_in_the_failed_instances_reason(catalog: Catalog) -> None:
    chart = compile_file(ROOT / "missions" / "corridor_surveillance.mission", catalog).raise_for_errors()
    assert chart is not None
    cluster = load_hosts(ROOT / "hosts.yaml", catalog)
    world = load_world(ROOT / "worlds" / "corridor.yaml")
    loss = inject.parse("lose scout2 at 70s", hosts={h.name for h in cluster.hosts},
                        robots={r.id for r in cluster.robots}, doors={d.id for d in world.doors})
    report = run(chart, cluster, world, catalog, until=300.0, injections=[loss])
    failed = [r for r in report.records if isinstance(r, rec.Exited) and r.status == "failure"]
    assert [(r.path, r.reason) for r in failed] == [
        ("CorridorSurveillance/RoomSurveillance[1]", "lost scout2 (resource lost)")]
    assert report.outcome == "success"  # graceful degradation: the other instances went on
