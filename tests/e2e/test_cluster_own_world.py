"""A cluster on a world of the user's own (worlds/NAME.yaml beside the hosts file, where `missionctl world generate`
writes one and where a dry-run finds it): every daemon starts on it and a mission runs there. It used to be looked
for under drd's own worlds/ only, so `drd start` refused it (`cluster.world: no world ...`). Every process is ours
and killed by pid (`tests/cluster_support.py`)."""

from __future__ import annotations

import json
from pathlib import Path

from cluster_support import ROOT, DaemonCluster, corridor_hosts, serving_cluster
from mcap.reader import make_reader

NAMES = ["controller", "ranger1"]


def test_daemons_start_and_run_a_mission_on_a_world_beside_their_hosts_file(tmp_path: Path) -> None:
    (tmp_path / "worlds").mkdir()
    corridor = (ROOT / "worlds" / "corridor.yaml").read_text()
    (tmp_path / "worlds" / "annex_hall.yaml").write_text(corridor.replace("name: corridor", "name: annex_hall", 1))
    assert not (ROOT / "worlds" / "annex_hall.yaml").exists()  # the daemons run from ROOT: only ours has it

    def hosts(cluster: DaemonCluster) -> str:
        text = corridor_hosts(cluster)
        assert "  world: corridor " in text
        return text.replace("  world: corridor ", "  world: annex_hall ", 1)

    with serving_cluster(tmp_path, NAMES, hosts) as cluster:  # every daemon ready and up, the simulator too
        mission = ROOT / "missions" / "corridor_surveillance.mission"
        recording = tmp_path / "run.mcap"
        run = cluster.missionctl("run", str(mission), "--config", str(cluster.hosts_file), "--speed", "20",
                                 "--json", "--record", str(recording), timeout=120)
        assert run.returncode == 0, cluster.tails(*NAMES) + run.stderr
        assert "(world annex_hall," in run.stderr
        report = json.loads(run.stdout)
        assert report["outcome"] == "success" and len(report["scouts"]) == 6, report
    with recording.open("rb") as f:  # the client found it too: the recording carries it, for a replay to draw
        attached = {a.name: a.data for a in make_reader(f).iter_attachments()}
    assert attached["world.yaml"] == (tmp_path / "worlds" / "annex_hall.yaml").read_bytes()
