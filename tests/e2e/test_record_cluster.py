"""`missionctl run --record` on a real 3-daemon cluster (issue #13): besides the records, what the client sees of the
cluster (hosts up or down, their load reports, where each instance runs) and the robots' poses, which the client
asks the simulator for; read back with the `mcap` reader. Every process is ours and killed by pid."""

from __future__ import annotations

import json
import socket
import subprocess
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import orjson
import pytest
from cluster_support import MISSIONCTL, DaemonCluster, serving_cluster
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from test_cluster_run import NAMES, corridor_hosts


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("record_cluster"), NAMES, corridor_hosts) as c:
        yield c


def messages(path: Path) -> list[tuple[str, int, Any]]:
    factory, decoders, out = DecoderFactory(), {}, []
    with path.open("rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(log_time_order=False):
            if channel.message_encoding == "json":
                out.append((channel.topic, message.log_time, orjson.loads(message.data)))
            elif schema is not None:
                decoder = decoders.setdefault(schema.id, factory.decoder_for(channel.message_encoding, schema))
                out.append((channel.topic, message.log_time, decoder(message.data)))
    return out


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def test_a_cluster_run_records_hosts_loads_placements_and_poses(cluster: DaemonCluster, tmp_path: Path) -> None:
    port = free_port()  # and serves them live (tests/e2e/test_record_live.py has a viewer)
    run = cluster.missionctl("run", "missions/corridor_surveillance.mission", "--config", str(cluster.hosts_file),
                             "--speed", "5", "--until", "20", "--record", str(tmp_path / "run.mcap"), "--json",
                             "--trace", str(tmp_path / "run.jsonl"),
                             "--foxglove", f"127.0.0.1:{port}", timeout=120)
    assert run.returncode == 1, run.stderr[-2000:]  # stopped at --until
    assert f"live view on ws://127.0.0.1:{port}" in run.stderr
    report = json.loads(run.stdout)
    got = messages(tmp_path / "run.mcap")
    counts = Counter(topic for topic, *_ in got)
    hosts = [m for topic, _t, m in got if topic == "/drd/hosts"]
    assert hosts and {h["name"]: h["state"] for h in hosts[-1]["hosts"]} == dict.fromkeys(NAMES, "up")
    loads = [m for topic, _t, m in got if topic == "/drd/hosts/load"]
    assert {m["host"] for m in loads} == set(NAMES) and all(0 <= m["cpu"] for m in loads)
    placed = {(i["name"], i["host"]) for topic, _t, m in got if topic == "/drd/placements" for i in m["instances"]}
    assert any(name.endswith("FollowCorridor") and host == "ranger1" for name, host in placed), placed
    assert counts["/drd/records"] >= len(report["timeline"]) > 0
    # the world, as this installation has it, then scout1's camera view when its camera is first read (the
    # simulator host's `view` reading)
    assert counts["/drd/active"] > 0 and counts["/drd/world"] == 2
    track = [(t, tf.translation.x) for topic, t, m in got if topic == "/drd/tf" for tf in m.transforms
             if tf.child_frame_id == "ranger1" and tf.parent_frame_id == "world"]
    assert len(track) > 5 and track[-1][1] > track[0][1] + 2  # it drove east along the corridor
    assert all(0 <= t <= (report["sim_time"] + 1) * 1e9 for t, _x in track)  # the mission's time
    carried = {tf.child_frame_id for topic, _t, m in got if topic == "/drd/tf" for tf in m.transforms
               if tf.parent_frame_id == "ranger1"}
    assert carried == {f"scout{i}" for i in range(1, 7)}  # every Scout in its magazine at first
    # what the sensors read, from the simulator's host (`drd/<cluster>/world`), as a dry-run records them
    scans = [(t, m) for topic, t, m in got if topic == "/drd/scan/ranger1"]
    assert len(scans) > 20 and all(len(m.ranges) == 181 for _t, m in scans)
    assert all(0 <= t <= (report["sim_time"] + 1) * 1e9 for t, _m in scans)  # the mission's time
    assert [t for t, _m in scans] == sorted(t for t, _m in scans)
    flights = [m for topic, _t, m in got if topic == "/drd/flights"]
    launched = {report_scout["scout"] for report_scout in report["scouts"]} if report.get("scouts") else set()
    assert {m["robot"] for m in flights if m["kind"] != "landing"} >= launched and flights, report.get("scouts")
    assert counts["/drd/light"] > 20, counts  # the Scout's dark-corner search (no camera reads in the first 20 s)
    # where each Scout ended, as a dry-run's report says it, from the last pose recorded
    ends = {s["scout"]: (s["x"], s["y"]) for s in report["scouts"]}
    assert ends and all(isinstance(v, float) for xy in ends.values() for v in xy), report["scouts"]
    last = {tf.child_frame_id: (tf.translation.x, tf.translation.y) for topic, _t, m in got if topic == "/drd/tf"
            for tf in m.transforms if tf.parent_frame_id == "world"}
    assert all(abs(x - last[s][0]) < 0.01 and abs(y - last[s][1]) < 0.01 for s, (x, y) in ends.items()), ends
    runs = [m for topic, _t, m in got if topic == "/drd/runs"]
    assert [s["scout"] for s in runs[0]["scouts"] if "x" in s] == list(ends)
    replay = subprocess.run([*MISSIONCTL, "replay", str(tmp_path / "run.mcap"), "--json", "--trace",
                             str(tmp_path / "replay.jsonl")], cwd=tmp_path, capture_output=True, text=True,
                            timeout=60, check=False)
    assert replay.returncode == 1 and json.loads(replay.stdout) == report, replay.stderr[-2000:]
    seqs_of_records(tmp_path, got)


def seqs_of_records(tmp_path: Path, got: list[tuple[str, int, Any]]) -> None:
    """The recorded records carry `seq` as the run's trace lines do, so a replayed trace merges with another
    (`check-trace --together`, which refuses records without it)."""
    traced = {r["seq"]: r for r in map(json.loads, (tmp_path / "run.jsonl").read_text().splitlines())}
    recorded = [m for topic, _t, m in got if topic == "/drd/records"]
    assert recorded and all(m["seq"] in traced and traced[m["seq"]]["kind"] == m["kind"] for m in recorded)
    replayed = [json.loads(line) for line in (tmp_path / "replay.jsonl").read_text().splitlines()]
    assert [r["seq"] for r in replayed] == [m["seq"] for m in recorded]
    (tmp_path / "other.jsonl").write_text((tmp_path / "replay.jsonl").read_text())
    together = subprocess.run([*MISSIONCTL, "check-trace", "--together", str(tmp_path / "replay.jsonl"),
                               str(tmp_path / "other.jsonl"), "--json"], cwd=tmp_path, capture_output=True,
                              text=True, timeout=60, check=False)
    assert "without seq" not in together.stderr and together.returncode in (0, 1), together.stderr[-2000:]


def test_a_recording_ends_with_its_mission_though_the_world_runs_on(cluster: DaemonCluster, tmp_path: Path) -> None:
    """Records audit 26, D5: a mission sharing the world with another kept recording that world's poses and readings
    for seconds after its own `finished` (the observer runs until the report is done)."""
    config = str(cluster.hosts_file)
    other = cluster.missionctl("run", "missions/corridor_surveillance.mission", "--config", config, "--speed", "10",
                               "--until", "150", "--priority", "2", "--detach")
    assert other.returncode == 0, other.stderr[-2000:]
    try:
        run = cluster.missionctl("run", "missions/shared_camera.mission", "--config", config, "--priority", "1",
                                 "--record", str(tmp_path / "b.mcap"), "--json", timeout=180)
        assert run.returncode in (0, 1), run.stderr[-2000:]
        got = messages(tmp_path / "b.mcap")
        [end] = [t for topic, t, _m in got if topic == "/drd/runs"]
        assert end == round(json.loads(run.stdout)["sim_time"] * 1e9)
        late = Counter(topic for topic, t, _m in got if t > end)
        assert not late, late  # the other mission's world went on: none of it is this mission's
    finally:
        cluster.missionctl("stop", "--all", "--config", config)
