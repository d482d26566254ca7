"""A lost robot leaves the recorded world (records audit 18, #2): `/drd/world` deletes its body and its camera's
view (Foxglove's SceneUpdate `deletions`), and `replay --at` after the loss no longer places it. Its body stayed,
drawn at its last pose, and `state_at` listed it. Read back with the `mcap` reader."""

from __future__ import annotations

from pathlib import Path

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from drd import inject
from drd.dryrun import run
from drd.hosts import load_hosts
from drd.record import Recorder, read, state_at
from drd.sim.world import load_world
from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import ROOT


def test_a_lost_robots_body_is_deleted_from_the_scene_and_the_replay(tmp_path: Path, catalog: Catalog) -> None:
    chart = compile_file(ROOT / "missions" / "corridor_surveillance.mission", catalog).statechart
    assert chart is not None
    cluster, world = load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" / "corridor.yaml")
    loss = inject.parse("lose scout2 at 70s", hosts={h.name for h in cluster.hosts},
                        robots={r.id for r in cluster.robots}, doors={d.id for d in world.doors})
    path = tmp_path / "lose.mcap"
    run(chart, cluster, world, catalog, until=300.0, recorder=Recorder(path), injections=[loss])
    deleted = []
    with path.open("rb") as fh:
        for _s, _c, m, o in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=["/drd/world"]):
            deleted += [(m.log_time / 1e9, d.id) for d in o.deletions]
    assert deleted == [(70.0, "body/scout2"), (70.0, "fov/scout2")], deleted
    recording = read(path)
    assert "scout2" in state_at(recording, 69.0)["robots"]
    assert "scout2" not in state_at(recording, 75.0)["robots"]
    assert recording.last_place("scout2") is not None  # the report still says where it was lost
