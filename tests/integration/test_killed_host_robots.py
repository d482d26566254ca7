"""A killed worker host's robots stop where they are and stay in the world (records audit 18, #1): docs/dryrun.md's
`kill` row, against `lose`, which takes a robot out of it. They were lost: no more `/drd/tf`, the other Ranger's laser
saw nothing where one stood, the report marked its Scouts lost. Real dry-run, read back with the `mcap` reader."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from drd import inject
from drd.dryrun import _inject, run
from drd.hosts import Cluster, load_hosts
from drd.record import Recorder
from drd.runtime import records as rec
from drd.sim.physics import Simulation
from drd.sim.robots import RobotState
from drd.sim.world import World, load_world
from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import ROOT


def _team(catalog: Catalog) -> tuple[Cluster, World]:
    return load_hosts(ROOT / "hosts.two_rangers.yaml", catalog), load_world(ROOT / "worlds" / "two_rangers.yaml")


def _parse(text: str, cluster: Cluster, world: World) -> inject.Injection:
    return inject.parse(text, hosts={h.name for h in cluster.hosts}, robots={r.id for r in cluster.robots},
                        doors={d.id for d in world.doors})


def test_a_killed_hosts_robots_stay_in_the_recorded_world_stopped(tmp_path: Path, catalog: Catalog) -> None:
    cluster, world = _team(catalog)
    chart = compile_file(ROOT / "missions" / "corridor_surveillance.mission", catalog).statechart
    assert chart is not None
    path = tmp_path / "kill.mcap"
    report = run(chart, cluster, world, catalog, until=400.0, recorder=Recorder(path),
                 injections=[_parse("kill ranger2 at 30s", cluster, world)])
    mine = {r.id for r in cluster.host("ranger2").robots}
    after: dict[str, list[tuple[float, float]]] = {rid: [] for rid in mine}
    with path.open("rb") as fh:
        for _s, _c, m, o in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=["/drd/tf"]):
            for t in o.transforms:
                if t.child_frame_id in mine and m.log_time >= 31e9:
                    after[t.child_frame_id].append((t.translation.x, t.translation.y))
    end = report.sim_time
    assert end > 60.0
    for rid, poses in after.items():  # sent to the end (every second at least), and standing still
        assert len(poses) >= int(end - 31) - 1, (rid, len(poses))
        assert max(math.dist(p, poses[0]) for p in poses) < 0.01, rid
    assert not any(s.get("lost") for s in report.scouts), report.scouts
    halts = [r for r in report.records if isinstance(r, rec.Halted) and abs(r.at - 30.0) < 0.05]
    assert halts and all(not h.error for h in halts), halts  # the stops reached robots that are there


def test_a_killed_hosts_robot_stands_on_the_floor_and_a_restart_gives_it_back(catalog: Catalog) -> None:
    cluster, world = _team(catalog)
    sim = Simulation(world, seed=0)
    life = SimpleNamespace(executive=None, gone=set(), down=set())  # the controller's host lives on: no manager
    sim.set_velocity("ranger2", 0.3, 0.0)
    sim.step(0.5)
    _inject(_parse("kill ranger2 at 0.5s", cluster, world), sim, life, cluster)  # type: ignore[arg-type]
    before = sim.pose("ranger2")
    for _ in range(10):
        sim.step(0.1)
    assert sim.state("ranger2") is RobotState.FLOOR and sim.pose("ranger2") == before
    assert "ranger2" in life.gone
    _inject(_parse("restart ranger2 at 2s", cluster, world), sim, life, cluster)  # type: ignore[arg-type]
    assert "ranger2" not in life.gone
    sim.set_velocity("ranger2", 0.3, 0.0)  # its drivers drive it again (a lost robot refuses: "is lost")
    sim.step(0.5)
    assert sim.pose("ranger2").x != before.x
