"""A Ranger that FollowCorridor drove up to a door's jamb turns out of it, and the corridor mission ends.

The large-fleet audit's D1: on the generated building of 20 wings x 5 Scouts (seed 0), AlignRanger had turned
ranger12 to a south door at a steep angle to the corridor (1 rad), and the next FindNewDoor's FollowCorridor drove
it to 0.87 m of the door's east jamb. Its wall fits found no corridor wall at that angle (a short one through the
doorway, parallel to its heading), so it had no heading to turn by: blocked short of the end, it stopped and waited
for the way to clear, for good, and the mission with it. The same pose in a fresh one-wing building does not get
stuck (the fit goes the other way), so this runs that building and seed: the real executive, drivers and simulator
(`drd.dryrun.run`), bounded by `until`.
"""

from __future__ import annotations

import io
import json

from drd.dryrun import run
from drd.hosts import parse_hosts
from drd.sim import building
from drd.sim.world import parse_world
from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import ROOT


def test_the_corridor_mission_ends_on_the_20x5_building_seed_0(catalog: Catalog) -> None:
    b = building.Building(wings=20, scouts=5)
    world = parse_world(building.world(b), "building_20x5.yaml")
    cluster = parse_hosts(building.hosts(b), "hosts.yaml", catalog)
    chart = compile_file(ROOT / "missions" / "corridor_surveillance.mission", catalog).statechart
    assert chart is not None
    trace = io.StringIO()
    report = run(chart, cluster, world, catalog, until=250.0, seed=0, trace=trace)
    # the previous code: `stopped` at the limit, RoomSurveillance[85]/FindNewDoor still running
    assert report.outcome == "success", report.reason
    assert len(report.to_dict()["scouts"]) == 100
    records = [json.loads(line) for line in trace.getvalue().splitlines()]
    turns = [r for r in records if r["kind"] == "log" and "more open side" in r["text"]]
    # it said why it turned, once, in RoomSurveillance[85]; since FollowCorridor keeps only walls along the
    # corridor's line (`along`, tests/integration/test_follow_corridor_walls.py) it no longer reaches that jamb
    assert [r["path"].split("/")[1] for r in turns] in ([], ["RoomSurveillance[85]"])
