"""A `restored` record's times (records audit 18, #5): `since` is rounded to the microsecond as `at` is (it read
50.00000000000044), and a dry-run's `paused` is the sim seconds of the outage it models, kill to restart
(docs/trace.md: wall time on a cluster, whose world waits for its controller; sim time in a dry-run)."""

from __future__ import annotations

import io
import json

from drd import inject
from drd.dryrun import run
from drd.hosts import load_hosts
from drd.sim.world import load_world
from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import ROOT


def test_a_restores_since_and_paused_are_rounded_sim_seconds_in_a_dry_run(catalog: Catalog) -> None:
    chart = compile_file(ROOT / "missions" / "corridor_surveillance.mission", catalog).statechart
    assert chart is not None
    cluster, world = load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" / "corridor.yaml")
    known = {"hosts": {h.name for h in cluster.hosts}, "robots": {r.id for r in cluster.robots},
             "doors": {d.id for d in world.doors}}
    trace = io.StringIO()
    run(chart, cluster, world, catalog, until=120.0, trace=trace,
        injections=inject.parse_all(["kill controller at 50s", "restart controller at 58s"], **known))
    [restored] = [r for line in trace.getvalue().splitlines() if (r := json.loads(line))["kind"] == "restored"]
    assert (restored["at"], restored["since"], restored["paused"]) == (58.0, 50.0, 8.0), restored
