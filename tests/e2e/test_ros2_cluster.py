"""`hosts.ros2.yaml` on a real 2-daemon cluster (controller, ranger1) on loopback: the simulator host (ranger1,
`simulator: {ros2: true, listen: ...}`) serves the world the controller runs as ROS 2 robots on its own zenoh router,
and every device of ranger1, on `driver: ros2`, reaches it over rmw_zenoh as it would reach real robots. The corridor
mission succeeds and zenoh-ros2-sdk, an independent client of that router, sees the served topics and drd's; then,
the controller killed while the Ranger drives, the robot side (the SDK listening to `/ranger1/cmd_vel`) receives a
zero Twist within 0.5 s. About two minutes (the mission runs at 2x real time). Every process is ours and killed by
pid (`tests/cluster_support.py`). The hosts file's refusals of a bad `simulator:` are checked first, without
processes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cluster_support import MISSIONCTL, ROOT, DaemonCluster, eventually, free_ports, serving_cluster

from drd.hosts import HostsError, Serving, parse_hosts
from drd.hw.ros2 import LASER_SCAN, TWIST, message_types
from dsl.catalog import Catalog
from tests.ros2_support import ros2_sdk

NAMES = ["controller", "ranger1"]
MISSION = "missions/corridor_surveillance.mission"
#: The cluster runs at 2x real time: the served world is stepped by the controller, but the drivers see it as a
#: robot, through the network (a reading up to a step old, a command landing at the next step); at 5x a control
#: cycle is 20 ms and that latency made AlignRanger overshoot now and then on a loaded 2-core machine.
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
    text = text.replace("listen: tcp/127.0.0.1:7500,", f"listen: tcp/127.0.0.1:{port},")
    return text.replace("endpoint: tcp/127.0.0.1:7500, domain_id: 0,",
                        f"endpoint: tcp/127.0.0.1:{port}, domain_id: 0, watchdog: {WATCHDOG},")


# -- the hosts file (no processes) ------------------------------------------------------------------------------


def _ros2_file(serving: str, roles: str = "[worker, simulator]") -> Any:
    import yaml

    text = (ROOT / "hosts.ros2.yaml").read_text(encoding="utf-8")
    text = text.replace("simulator: {ros2: true, listen: tcp/127.0.0.1:7500, domain_id: 0}", serving)
    return yaml.safe_load(text.replace("roles: [worker, simulator]", f"roles: {roles}"))


def test_the_simulator_host_serves_ros2_as_hosts_yaml_says(catalog: Catalog) -> None:
    cluster = parse_hosts(_ros2_file("simulator: {ros2: true, listen: tcp/0.0.0.0:7600, domain_id: 7}"),
                          "hosts.ros2.yaml", catalog)
    assert cluster.host("ranger1").serving == Serving(True, "tcp/0.0.0.0:7600", 7)
    assert cluster.controller.serving == Serving()  # not a simulator: serves nothing


@pytest.mark.parametrize(("serving", "roles", "problem"), [
    ("simulator: {ros2: true, listen: tcp/127.0.0.1:7500}", "[worker]",
     "hosts.ranger1.simulator: only the host with the role simulator serves the world: add simulator to its roles"),
    ("simulator: {ros2: yes please, listen: tcp/127.0.0.1:7500}", "[worker, simulator]",
     "hosts.ranger1.simulator.ros2: expected true or false, got"),
    ("simulator: {ros2: true}", "[worker, simulator]", "hosts.ranger1.simulator: ros2: true needs listen"),
    ("simulator: {ros2: true, listen: 7500}", "[worker, simulator]",
     "hosts.ranger1.simulator.listen: expected a non-empty string, got int 7500"),
    ("simulator: {ros2: true, listen: localhost}", "[worker, simulator]",
     "hosts.ranger1.simulator.listen: expected tcp/HOST:PORT or udp/HOST:PORT"),
    ("simulator: {ros2: true, listen: tcp/127.0.0.1:7500, domain_id: 300}", "[worker, simulator]",
     "hosts.ranger1.simulator.domain_id:"),
    ("simulator: {ros2: true, listen: tcp/127.0.0.1:7500, domian_id: 3}", "[worker, simulator]",
     "hosts.ranger1.simulator.domian_id: unknown key (did you mean domain_id?)"),
    ("simulator: {ros2: true, listen: tcp/127.0.0.1:7447}", "[worker, simulator]",
     "hosts.ranger1.simulator.listen: tcp/127.0.0.1:7447 is the endpoint of host controller's daemon"),
])
def test_a_bad_simulator_entry_is_refused_naming_file_and_key(catalog: Catalog, serving: str, roles: str,
                                                              problem: str) -> None:
    with pytest.raises(HostsError) as err:
        parse_hosts(_ros2_file(serving, roles), "hosts.ros2.yaml", catalog)
    messages = [str(p) for p in err.value.problems]
    assert any(m.startswith("hosts.ros2.yaml") and problem in m for m in messages), messages


# -- a cluster ---------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cluster(robots_port: int, tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    """The daemons of hosts.ros2.yaml; ranger1, the simulator host, listens on `robots_port` as the robots' router."""
    with serving_cluster(tmp_path_factory.mktemp("ros2_cluster"), NAMES, lambda c: ros2_hosts(c, robots_port)) as c:
        yield c


def test_the_corridor_mission_succeeds_on_the_clusters_served_robots(cluster: DaemonCluster, robots_port: int,
                                                                    tmp_path: Path) -> None:
    done = subprocess.run([*MISSIONCTL, "run", MISSION, "--config", str(cluster.hosts_file), "--speed", SPEED,
                           "--until", "400", "--json"], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 0, (done.stdout[-1000:], done.stderr[-2000:], cluster.log("ranger1")[-3000:])
    report = json.loads(done.stdout)
    assert report["outcome"] == "success" and len(report["scouts"]) == 6 and report["doors"], (  # which room, when
        report["outcome"], report["reason"], report["doors"], report["scouts"], cluster.tails("controller"))
    # an independent rmw_zenoh client of the cluster's router sees the served robots and drd's drivers on it
    with ros2_sdk(message_types(), [TWIST, LASER_SCAN], tmp_path / "msgs") as sdk:
        listed: dict[str, list[str]] = {}

        def shown() -> bool:
            listed.update(dict(sdk.get_topic_names_and_types(domain_id=0, router_port=robots_port, timeout=0.5)))
            return listed.get("/ranger1/scan") == [LASER_SCAN] and listed.get("/ranger1/cmd_vel") == [TWIST]

        eventually(shown, f"the SDK to list the served topics (it lists {sorted(listed)})")
        scan = sdk.get_topic_info("/ranger1/scan", domain_id=0, router_port=robots_port, verbose=True)
        assert {e.node_name for e in scan.publishers} == {"drd_sim"}  # the simulator host publishes it
        assert {e.node_name for e in scan.subscribers} == {"drd"}  # ranger1's ros2 RangeSensor reads it


def test_a_geofenced_mission_on_the_served_robots_ends_at_its_fence(cluster: DaemonCluster, tmp_path: Path) -> None:
    """A constraint from the first instant: the host's guard read the Ranger's battery on the command's thread and
    waited 2 s for the robot's first battery state, holding the Creator, so the world it serves did not step and the
    behavior's scans went stale (`HardwareError ... /ranger1/scan is 2.01 s old`); now the fence ends it."""
    (tmp_path / "fenced.mission").write_text("mission Fenced {\n    needs ranger: Ranger\n"
                                             "    constraint fence: distance(ranger, point(1, 0)) <= 3\n"
                                             "    FollowCorridor(speed: 0.5)\n}\n")
    done = subprocess.run([*MISSIONCTL, "run", str(tmp_path / "fenced.mission"), "--config", str(cluster.hosts_file),
                           "--speed", SPEED, "--until", "60", "--json"], cwd=ROOT, capture_output=True, text=True,
                          timeout=300, check=False)
    report = json.loads(done.stdout)
    assert done.returncode == 1 and report["reason"].startswith("constraint fence violated"), (
        report["reason"], cluster.log("ranger1")[-3000:])


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


def test_the_simulator_host_stops_cleanly_after_its_missions(cluster: DaemonCluster) -> None:
    """Its drivers' ROS 2 subscriptions are closed with them: nothing keeps the stopped daemon's process alive
    (it had to be killed: `drd stop` waited 10 s for zenoh's callback threads)."""
    r = cluster.drd("stop", "--host", "ranger1", "--run-dir", str(cluster.run_dir), "--json")
    assert r.returncode == 0, r.stderr
    [row] = [d for d in json.loads(r.stdout)["daemons"] if d["host"] == "ranger1"]
    assert row["outcome"] == "stopped", row
    assert "still running" not in cluster.log("ranger1")  # no thread was left to give up on
