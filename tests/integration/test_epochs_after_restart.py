"""A controller killed and started again in a dry-run grants above every epoch the dead one gave (safety audit 25,
D1): its manager started at 0, so the resumed mission's grants reused epochs 1, 2... of the units, and a grant of
the new controller looked, in the trace and at a gate, like one of the old one's. Checked from the trace only:
every unit's epochs over the `granted` records strictly increase, across the restart."""

from __future__ import annotations

import io
import json

from drd import inject
from drd.dryrun import run
from drd.hosts import load_hosts
from drd.sim.world import load_world
from dsl import compile_text
from dsl.catalog import Catalog
from tests.conftest import ROOT

TURNS = """mission Turns {
    parallel all {
        Turn as left priority 2
        Turn as right priority 2
    }
}
behavior Turn {
    needs ranger: Ranger for 2s
    FollowCorridor(speed: 0.4)
    FollowCorridor -> done after 6s
}
"""


def test_a_restarted_controller_never_grants_an_epoch_the_dead_one_gave(catalog: Catalog) -> None:
    chart = compile_text(TURNS, catalog, "turns.mission").statechart
    assert chart is not None
    cluster, world = load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" / "corridor.yaml")
    known = {"hosts": {h.name for h in cluster.hosts}, "robots": {r.id for r in cluster.robots},
             "doors": {d.id for d in world.doors}}
    trace = io.StringIO()
    run(chart, cluster, world, catalog, until=12.0, trace=trace,
        injections=inject.parse_all(["kill controller at 3s", "restart controller at 5s"], **known))
    records = [json.loads(line) for line in trace.getvalue().splitlines()]
    assert any(r["kind"] == "restored" for r in records)  # the restart happened and resumed the mission
    last: dict[str, int] = {}
    grants_after = 0
    for r in records:
        if r["kind"] != "granted":
            continue
        grants_after += r["at"] >= 5.0
        for unit, epoch in r["epochs"].items():
            assert epoch > last.get(unit, 0), (r, last)
            last[unit] = epoch
    assert grants_after >= 2  # the resumed holder and the next slice's were checked too
