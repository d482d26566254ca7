"""`hosts.ros2.yaml` on a real 2-daemon cluster (controller, ranger1) on loopback: the world served as ROS 2 robots
by a `drd sim --ros2` process, every device of ranger1 on `driver: ros2` reaching it over rmw_zenoh. The corridor
mission succeeds; then, the controller killed while the Ranger drives, the robot side (zenoh-ros2-sdk listening to
`/ranger1/cmd_vel`) receives a zero Twist within 0.5 s, from ranger1's own watchdog. About two minutes (the mission
runs at 2x real time: a robot is not stepped by the cluster). Every process is ours and killed by pid
(`tests/cluster_support.py`)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cluster_support import MISSIONCTL, ROOT, DaemonCluster, eventually, free_ports, serving_cluster

from drd.hw.ros2 import TWIST, message_types
from tests.ros2_support import ros2_sdk

NAMES = ["controller", "ranger1"]
MISSION = "missions/corridor_surveillance.mission"
#: The served world and the cluster both run at 2x real time, each on its own clock, as a robot and a cluster do: at
#: 5x a control cycle is 20 ms and the loop's latency (data up to a publication old, commands landing between
#: steps) made AlignRanger overshoot now and then on a loaded 2-core machine (a later door then looked like a wall).
SPEED = "2"
WATCHDOG = 0.3


@pytest.fixture(scope="module")
def robots_port() -> int:
    return free_ports(1)[0]


def ros2_hosts(cluster: DaemonCluster, port: int) -> str:
    text = (ROOT / "hosts.ros2.yaml").read_text(encoding="utf-8")
    controller, ranger1 = cluster.ports
    text = text.replace("name: corridor", f"name: {cluster.name}").replace("lease: 3s", "lease: 1000ms")
    text = text.replace("127.0.0.1:7447", f"127.0.0.1:{controller}").replace("127.0.0.1:7448", f"127.0.0.1:{ranger1}")
    return text.replace("endpoint: tcp/127.0.0.1:7500, domain_id: 0,",
                        f"endpoint: tcp/127.0.0.1:{port}, domain_id: 0, watchdog: {WATCHDOG},")


@pytest.fixture(scope="module")
def served(robots_port: int, tmp_path_factory: pytest.TempPathFactory) -> Iterator[subprocess.Popen[str]]:
    """`drd sim --ros2` serving the corridor world, as the robots' router, for the whole module."""
    folder = tmp_path_factory.mktemp("ros2_served")
    log = (folder / "sim.log").open("w")
    proc = subprocess.Popen([sys.executable, "-m", "drd.cli.drd", "sim", "--world", "corridor", "--config",
                             str(ROOT / "hosts.ros2.yaml"), "--ros2", "--listen", f"tcp/127.0.0.1:{robots_port}",
                             "--speed", SPEED, "--json"], cwd=ROOT, stdout=log, stderr=log, text=True)
    try:
        eventually(lambda: (folder / "sim.log").read_text().startswith('{"event": "serving"') or proc.poll(),
                   "drd sim to serve", timeout=60)
        assert proc.poll() is None, (folder / "sim.log").read_text()
        yield proc
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)
        log.close()


@pytest.fixture(scope="module")
def cluster(served: subprocess.Popen[str], robots_port: int,
            tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("ros2_cluster"), NAMES, lambda c: ros2_hosts(c, robots_port)) as c:
        yield c


def test_the_corridor_mission_succeeds_on_ros2_robots(cluster: DaemonCluster) -> None:
    done = subprocess.run([*MISSIONCTL, "run", MISSION, "--config", str(cluster.hosts_file), "--speed", SPEED,
                           "--until", "400", "--json"], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 0, (done.stdout[-1000:], done.stderr[-2000:], cluster.log("ranger1")[-3000:])
    report = json.loads(done.stdout)
    assert report["outcome"] == "success" and len(report["scouts"]) == 6 and report["doors"]


def test_the_robot_gets_a_zero_twist_when_the_controller_dies(cluster: DaemonCluster, robots_port: int,
                                                             tmp_path: Path) -> None:
    """Last in this module: it kills the controller. The Ranger drives at the start of a mission (FindNewDoor);
    with the controller gone nobody commands, and ranger1's watchdog stops the base on its own."""
    twists: list[tuple[float, Any]] = []
    lock = threading.Lock()

    def on_twist(msg: Any) -> None:
        with lock:
            twists.append((time.monotonic(), msg))

    with ros2_sdk(message_types(), [TWIST], tmp_path / "msgs") as sdk:
        sub = sdk.ROS2Subscriber(topic="/ranger1/cmd_vel", msg_type=TWIST, callback=on_twist, domain_id=0,
                                 router_port=robots_port)
        run = subprocess.Popen([*MISSIONCTL, "run", MISSION, "--config", str(cluster.hosts_file), "--speed", SPEED,
                                "--json"], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            def driving() -> bool:
                with lock:
                    return any(m.linear.x > 0.1 for _, m in twists[-3:])

            eventually(driving, "the Ranger to drive", timeout=60)
            killed = time.monotonic()
            os.kill(cluster.pid("controller"), signal.SIGKILL)

            def zero() -> float | None:
                with lock:
                    return next((t for t, m in twists if t > killed and m.linear.x == 0.0 and m.angular.z == 0.0),
                                None)

            eventually(lambda: zero() is not None, "a zero Twist on /ranger1/cmd_vel", timeout=5)
            stopped = zero()
            assert stopped is not None and stopped - killed <= 0.5, stopped - killed if stopped else None
            # who sent it: the watchdog (no command for its period) or the gates stopping every device when the
            # controller's token vanished (`Creator.controller_lost`), whichever came first
            eventually(lambda: "zero Twist (watchdog)" in cluster.log("ranger1")
                       or "every device stopped" in cluster.log("ranger1"), "ranger1 to say why it stopped", 5)
        finally:
            sub.close()
            if run.poll() is None:
                run.kill()
            run.wait(timeout=10)
