"""A cluster of real robots, with no simulator host, runs missions (audit D1): 2 daemons (controller, ranger1)
whose hosts file gives no host the role simulator, and ranger1's devices all on `driver: ros2`, pointing at an
independent ROS 2 robot (tests/fake_ros2_robot.py, a process of its own written with zenoh-ros2-sdk only, its own
zenoh router on a free port). `missionctl run` drives it in real time, in no simulated world; the robot itself
says what it received: Twists that move it, then a final zero one. A speed other than real time and a named world
are refused, and `drd start` refuses a `sim` device when no host is a simulator. `run --record` keeps the robot's
poses and scans as its drivers read them, read back with the `mcap` library's own reader. About 40 s. Every process
is ours and killed by pid."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cluster_support import MISSIONCTL, ROOT, DaemonCluster, eventually, free_ports, serving_cluster

from drd.hw.ros2 import BATTERY, DETECTIONS, IMAGE, LASER_SCAN, ODOMETRY, STRING, TWIST, message_types
from tests.ros2_support import write_msg_files

pytest.importorskip("zenoh_ros2_sdk", reason="zenoh-ros2-sdk is not installed (pip install -e '.[test]')")

NAMES = ["controller", "ranger1"]
PROBE = """mission Probe {
    needs ranger: Ranger
    FollowCorridor(speed: 0.3)
    FollowCorridor -> done after 4s
}
"""


def real_hosts(cluster: DaemonCluster, robot_port: int, drive: str = "ros2") -> str:
    """No host is a simulator; every device of ranger1 is driven through the robot's own router."""
    controller, ranger1 = cluster.ports
    return f"""cluster:
  name: {cluster.name}
  security: {{mode: none}}
  lease: 1000ms
hosts:
  controller:
    endpoint: tcp/127.0.0.1:{controller}
    roles: [controller]
  ranger1:
    endpoint: tcp/127.0.0.1:{ranger1}
    roles: [worker]
    drivers:
      ros2: {{endpoint: tcp/127.0.0.1:{robot_port}, domain_id: 0, origin: [1.0, 0.0, 0.0]}}
    devices:
      drive: {{type: Drive, driver: {drive}, options: {{max_speed: 0.8}}}}
      ranges: {{type: RangeSensor, driver: ros2, options: {{beams: 181, max_range: 8.0}}}}
      camera: {{type: Camera, driver: ros2, options: {{resolution: 640, fov: 60.0}}}}
      launcher: {{type: Launcher, driver: ros2, options: {{max_range: 6.0}}}}
    robots:
      ranger1:
        type: Ranger
        parts: {{drive: drive, ranges: ranges, camera: camera, launcher: launcher}}
        properties: {{battery: 1.0, magazine: 0}}
"""


@pytest.fixture(scope="module")
def robot(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[int, Path]]:
    """The fake robot's process (its router's port, the file of the Twists it received); killed by pid after."""
    folder = tmp_path_factory.mktemp("fake_robot")
    msgs = write_msg_files(message_types(), [TWIST, ODOMETRY, LASER_SCAN, IMAGE, DETECTIONS, BATTERY, STRING],
                           folder / "msgs")
    port, cmd_log = free_ports(1)[0], folder / "cmd_vel.jsonl"
    cmd_log.touch()
    out = folder / "robot.out"
    with out.open("wb") as sink:  # its odometry pose beside the Twists' log (`pose_of`)
        proc = subprocess.Popen([sys.executable, str(ROOT / "tests" / "fake_ros2_robot.py"), str(port), str(msgs),
                                 str(cmd_log), str(folder / "pose.json")], cwd=folder, stdout=sink,
                                stderr=subprocess.STDOUT)
    try:
        eventually(lambda: b"serving" in out.read_bytes() or proc.poll() is not None, "the fake robot to serve")
        assert proc.poll() is None, out.read_text(errors="replace")
        yield port, cmd_log
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


@pytest.fixture(scope="module")
def cluster(robot: tuple[int, Path], tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("real_robots"), NAMES, lambda c: real_hosts(c, robot[0])) as c:
        yield c


def twists(cmd_log: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in cmd_log.read_text(encoding="utf-8").splitlines() if line.strip()]


def run(cluster: DaemonCluster, mission: Path, *options: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), *options],
                          cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)


def test_a_mission_drives_the_real_robot_then_stops_it(cluster: DaemonCluster, robot: tuple[int, Path],
                                                       tmp_path: Path) -> None:
    mission = tmp_path / "probe.mission"
    mission.write_text(PROBE, encoding="utf-8")
    done = run(cluster, mission, "--until", "30", "--json")
    assert done.returncode == 0, (done.stdout[-1000:], done.stderr[-2000:], cluster.tails())
    report = json.loads(done.stdout)
    assert report["outcome"] == "success", report
    assert "started on the cluster (world none (real robots), 1x real time" in done.stderr, done.stderr[-2000:]
    # the robot's side: it was driven forward, and the last Twist it got stops it (the mission's end)
    eventually(lambda: twists(robot[1]) and twists(robot[1])[-1] == {"v": 0.0, "w": 0.0}, "a final zero Twist")
    got = twists(robot[1])
    moving = [t for t in got if t["v"] > 0.1]
    assert len(moving) >= 10, got[-20:]  # about 4 s of commands at 10 Hz
    assert got.index(moving[-1]) < len(got) - 1 and got[-1] == {"v": 0.0, "w": 0.0}
    # no simulation step went to any host: nobody serves one, and the controller says the loop ran in real time
    assert "did not step" not in cluster.log("controller") and "serves no simulation" not in cluster.log("ranger1")


@pytest.mark.parametrize(("options", "said"), [
    (["--speed", "20"], "--speed 20: no host has the role simulator in hosts.yaml: missions run on the real robots,"
                        " in real time"),
    (["--world", "corridor"], "--world corridor: no host has the role simulator in hosts.yaml"),
])
def test_what_real_robots_cannot_do_is_refused(cluster: DaemonCluster, robot: tuple[int, Path], tmp_path: Path,
                                                options: list[str], said: str) -> None:
    mission = tmp_path / "probe.mission"
    mission.write_text(PROBE, encoding="utf-8")
    before = len(twists(robot[1]))
    done = run(cluster, mission, *options, "--json")
    assert done.returncode == 2, (done.stdout[-1000:], done.stderr[-2000:])
    assert said in json.loads(done.stderr.strip().splitlines()[-1])["error"], done.stderr
    assert not [t for t in twists(robot[1])[before:] if t["v"]]  # the robot was not driven


def test_a_sim_device_with_no_simulator_host_is_refused_when_a_mission_is_run(tmp_path: Path) -> None:
    """The daemons of such a file start (they serve status, placement, the trader), and `missionctl run` says which
    device keeps a mission from running, by file and key."""
    with serving_cluster(tmp_path, NAMES, lambda c: real_hosts(c, free_ports(1)[0], drive="sim")) as c:
        mission = tmp_path / "probe.mission"
        mission.write_text(PROBE, encoding="utf-8")
        done = run(c, mission, "--json")
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert (f"{c.hosts_file}: hosts.ranger1.devices.drive.driver: sim, but no host has the role simulator"
            in done.stderr), done.stderr


def pose_of(robot: tuple[int, Path]) -> dict[str, float]:
    """The fake robot's own odometry pose now (its odom frame: where it was switched on)."""
    found: dict[str, float] = json.loads((robot[1].parent / "pose.json").read_text(encoding="utf-8"))
    return found


Poses = list[tuple[float, float, float]]


def read_recording(path: Path) -> tuple[Poses, list[tuple[float, Any]], list[dict[str, Any]]]:
    """With mcap's own reader (no drd code): ranger1's poses on /drd/tf (time, x, y), its scans on
    /drd/scan/ranger1 (time, the LaserScan) and the records, each time in s of log time."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    poses, scans, records = [], [], []
    protobuf = DecoderFactory()
    with path.open("rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(
                topics=["/drd/tf", "/drd/scan/ranger1", "/drd/records"]):
            t = message.log_time / 1e9
            if channel.topic == "/drd/records":  # JSON
                records.append(json.loads(message.data))
                continue
            decode = protobuf.decoder_for(channel.message_encoding, schema)
            assert decode is not None, channel
            decoded = decode(message.data)
            if channel.topic == "/drd/tf":
                poses += [(t, f.translation.x, f.translation.y) for f in decoded.transforms
                          if f.child_frame_id == "ranger1" and f.parent_frame_id == "world"]
            else:
                scans.append((t, decoded))
    return poses, scans, records


def test_a_recording_of_real_robots_has_their_poses_and_scans(cluster: DaemonCluster, robot: tuple[int, Path],
                                                             tmp_path: Path) -> None:
    """No simulator to ask: the robot's host says what its drivers read. The poses are the robot's odometry in the
    mission's map (the driver's origin, 1 m ahead of the odom frame's), they move as the robot does, and the scans
    are the fake robot's corridor, each at the mission's time."""
    mission, out = tmp_path / "probe.mission", tmp_path / "run.mcap"
    mission.write_text(PROBE, encoding="utf-8")
    start = pose_of(robot)
    done = run(cluster, mission, "--until", "30", "--json", "--record", str(out))
    assert done.returncode == 0, (done.stdout[-1000:], done.stderr[-2000:], cluster.tails())
    eventually(lambda: twists(robot[1])[-1] == {"v": 0.0, "w": 0.0}, "a final zero Twist")
    end = pose_of(robot)
    assert end["x"] - start["x"] >= 0.5, (start, end)  # the robot itself went forward (4 s at 0.3 m/s)
    poses, scans, records = read_recording(out)
    finished = next(r["at"] for r in records if r["kind"] == "finished")
    assert len(poses) >= 5, poses
    assert all(0.0 <= t <= finished + 1.0 for t, _, _ in poses), (finished, poses)  # the mission's time
    assert poses[0][0] <= 2.0, poses[:3]  # from its start on
    # where the robot was, in the map: origin (1, 0, 0 degrees) composed with its odometry
    assert abs(poses[0][1] - (1.0 + start["x"])) <= 0.5, (poses[0], start)
    assert abs(poses[-1][1] - (1.0 + end["x"])) <= 0.2 and abs(poses[-1][2] - end["y"]) <= 0.2, (poses[-1], end)
    assert poses[-1][1] - poses[0][1] >= 0.5, poses  # it moved as the robot did
    # its laser, as the robot published it: 181 beams over the half-plane ahead, the walls 2.5 m apart either side,
    # nothing straight ahead (+inf, REP 117)
    assert len(scans) >= 5, len(scans)
    assert all(0.0 <= t <= finished + 1.0 for t, _ in scans), (finished, [t for t, _ in scans])
    for _t, scan in scans:
        assert len(scan.ranges) == 181 and scan.frame_id == "ranger1", scan
        assert abs(scan.start_angle + math.pi / 2) < 1e-6 and abs(scan.end_angle - math.pi / 2) < 1e-6, scan
        assert abs(scan.ranges[0] + scan.ranges[-1] - 2.5) <= 0.1, (scan.ranges[0], scan.ranges[-1])
        assert math.isinf(scan.ranges[90]), scan.ranges[90]
