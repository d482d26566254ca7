"""The simulator served as ROS 2 robots (drd.sim.ros2, `drd sim --ros2`), seen by zenoh-ros2-sdk, an independent
rmw_zenoh client: its subscriber gets the Ranger's LaserScan with the configured beams, its Twist moves the
simulated Ranger, its topic listing shows the served topics with their types; and the CLI as a real process."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drd.bus.ros2 import Ros2Session, topic_key
from drd.hosts import Cluster, load_hosts
from drd.hw.ros2 import BATTERY, DETECTIONS, LASER_SCAN, ODOMETRY, TWIST, message_types, yaw_of
from drd.sim.ros2 import IMAGE_WIDTH, TF, ServedRobots
from dsl.catalog import Catalog
from tests.ros2_support import eventually, free_port, msg_definitions, ros2_sdk, served_team

ROOT = Path(__file__).resolve().parents[2]
SDK_TYPES = (TWIST, LASER_SCAN, ODOMETRY, DETECTIONS, "sensor_msgs/msg/Image", BATTERY, TF)


@pytest.fixture
def cluster(catalog: Catalog) -> Cluster:
    return load_hosts(ROOT / "hosts.yaml", catalog)


@pytest.fixture
def served(cluster: Cluster) -> Iterator[tuple[ServedRobots, int]]:
    """The corridor team served in real time (x4) on a free loopback port, on a thread of this process."""
    with served_team(cluster, 4.0) as team:
        yield team


@pytest.fixture
def sdk(tmp_path: Path) -> Iterator[Any]:
    with ros2_sdk(message_types(), SDK_TYPES, tmp_path / "msgs") as module:
        yield module


def test_the_sdk_receives_the_rangers_scan_with_its_beams(served: tuple[ServedRobots, int], sdk: Any) -> None:
    _robots, port = served
    got: list[Any] = []
    sub = sdk.ROS2Subscriber(topic="/ranger1/scan", msg_type=LASER_SCAN, callback=got.append, domain_id=0,
                             router_port=port)
    try:
        eventually(lambda: got, "a LaserScan on /ranger1/scan")
        scan = got[-1]
        assert len(scan.ranges) == 181  # hosts.yaml: beams 181, max_range 8
        assert scan.range_max == pytest.approx(8.0) and scan.header.frame_id == "ranger1/laser"
        assert scan.angle_min == pytest.approx(-math.pi / 2) and scan.angle_max == pytest.approx(math.pi / 2)
        finite = np.asarray(scan.ranges)[np.isfinite(scan.ranges)]
        assert len(finite) > 90 and (finite < 8.0).all()  # the corridor's walls; +inf where nothing is hit
    finally:
        sub.close()


def test_the_battery_state_has_a_voltage(served: tuple[ServedRobots, int], sdk: Any) -> None:
    """sensor_msgs/BatteryState says `voltage` is mandatory (only the other measurements may be NaN)."""
    _robots, port = served
    got: list[Any] = []
    sub = sdk.ROS2Subscriber(topic="/ranger1/battery_state", msg_type=BATTERY, callback=got.append, domain_id=0,
                             router_port=port)
    try:
        eventually(lambda: got, "a BatteryState on /ranger1/battery_state")
        state = got[-1]
        assert math.isfinite(state.voltage) and state.voltage == pytest.approx(14.4)  # a 4S Li-ion pack, nominal
        assert state.percentage == pytest.approx(1.0) and state.power_supply_technology == 2  # LION
        assert math.isnan(state.temperature) and state.header.frame_id == "ranger1/base_link"
    finally:
        sub.close()


def test_tf_relates_the_frames_the_topics_are_stamped_in(served: tuple[ServedRobots, int], sdk: Any) -> None:
    """rviz and Nav2 place a scan through tf (REP 105): /tf has odom -> base_link per robot, where its odometry
    says; /tf_static (transient local: a late listener gets it) has base_link -> laser and camera."""
    from zenoh_ros2_sdk.qos import QosDurability, QosProfile

    _robots, port = served
    moving: list[Any] = []
    fixed: list[Any] = []
    odom: list[Any] = []
    subs = [sdk.ROS2Subscriber(topic="/tf", msg_type=TF, callback=moving.append, domain_id=0, router_port=port),
            sdk.ROS2Subscriber(topic="/tf_static", msg_type=TF, callback=fixed.append, domain_id=0, router_port=port,
                               qos=QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=1)),
            sdk.ROS2Subscriber(topic="/ranger1/odom", msg_type=ODOMETRY, callback=odom.append, domain_id=0,
                               router_port=port)]
    try:
        eventually(lambda: moving and fixed and odom, "/tf, /tf_static (published before we joined) and odometry")
        static = {(t.header.frame_id, t.child_frame_id) for t in fixed[-1].transforms}
        assert {("ranger1/base_link", "ranger1/laser"), ("ranger1/base_link", "ranger1/camera"),
                ("scout1/base_link", "scout1/camera")} <= static  # a Scout's camera on the Scout
        assert ("scout1/base_link", "scout1/laser") not in static  # a Scout has no laser
        frames = {t.child_frame_id: t for t in moving[-1].transforms}
        base = frames["ranger1/base_link"]
        assert base.header.frame_id == "ranger1/odom" and "scout1/base_link" in frames
        assert (base.transform.translation.x, base.transform.translation.y) == pytest.approx((0.0, 0.0), abs=1e-6)
        assert base.transform.rotation.w == pytest.approx(1.0)  # it has not moved: where its odometry says
        stamp = base.header.stamp
        assert 0 <= stamp.nanosec < 1_000_000_000 and stamp.sec >= 0
    finally:
        for sub in subs:
            sub.close()


def test_a_twist_from_the_sdk_moves_the_simulated_ranger(served: tuple[ServedRobots, int], sdk: Any) -> None:
    robots, port = served
    odom: list[Any] = []
    lock = threading.Lock()

    def on_odom(msg: Any) -> None:
        with lock:
            odom.append(msg)

    sub = sdk.ROS2Subscriber(topic="/ranger1/odom", msg_type=ODOMETRY, callback=on_odom, domain_id=0,
                             router_port=port)
    pub = sdk.ROS2Publisher(topic="/ranger1/cmd_vel", msg_type=TWIST, domain_id=0, router_port=port)
    try:
        eventually(lambda: odom, "odometry on /ranger1/odom")
        with lock:
            first = odom[-1]
        assert (first.pose.pose.position.x, first.pose.pose.position.y) == pytest.approx((0.0, 0.0), abs=1e-6)
        assert first.header.frame_id == "ranger1/odom" and first.child_frame_id == "ranger1/base_link"
        vector = pub.session_mgr.store.types["geometry_msgs/msg/Vector3"]

        def moved() -> bool:
            pub.publish(linear=vector(x=0.4, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0))
            with lock:
                return bool(odom[-1].pose.pose.position.x > 0.3)

        eventually(moved, "the Ranger to drive 0.3 m forward", timeout=10)
        with lock:
            last = odom[-1]
        assert last.twist.twist.linear.x == pytest.approx(0.4)  # what the wheels execute
        assert abs(yaw_of(last.pose.pose.orientation)) < 0.1
        assert robots.sim.pose("ranger1").x > 1.3  # ground truth: it started at x = 1
    finally:
        pub.close()
        sub.close()



def test_a_base_whose_cmd_vel_goes_quiet_stops_as_a_real_one_would(served: tuple[ServedRobots, int],
                                                                    sdk: Any) -> None:
    """docs/ros2.md: the last line is the robot's own cmd_vel timeout. The served base kept its last Twist forever,
    so a client that died mid-drive (or sent one Twist) drove it into the wall; it stops after 0.5 s of sim time."""
    robots, port = served
    pub = sdk.ROS2Publisher(topic="/ranger1/cmd_vel", msg_type=TWIST, domain_id=0, router_port=port)
    vector = pub.session_mgr.store.types["geometry_msgs/msg/Vector3"]
    try:
        pub.publish(linear=vector(x=0.4, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0))
        eventually(lambda: robots.sim.command("ranger1") == (0.4, 0.0) or robots.timeouts, "the Twist to drive it")
        eventually(lambda: robots.sim.command("ranger1") == (0.0, 0.0), "the base to stop on its own", timeout=10)
        assert robots.timeouts == 1 and "ranger1" not in robots.commanded
        stopped = robots.sim.pose("ranger1")
        time.sleep(0.3)  # 1.2 s of sim time: it stays where it stopped
        assert robots.sim.pose("ranger1").x == pytest.approx(stopped.x, abs=1e-9)
    finally:
        pub.close()


def test_a_non_finite_twist_is_refused_and_the_world_goes_on(served: tuple[ServedRobots, int], sdk: Any) -> None:
    """Clients audit D1: one Twist with NaN (or inf) in it made the pose NaN and `drd sim --ros2` exit 70 (a cluster
    mission failed, "the simulator stopped answering"). It is refused and logged; the next good Twist drives."""
    robots, port = served
    pub = sdk.ROS2Publisher(topic="/ranger1/cmd_vel", msg_type=TWIST, domain_id=0, router_port=port)
    vector = pub.session_mgr.store.types["geometry_msgs/msg/Vector3"]
    start = robots.sim.pose("ranger1")
    try:
        for bad in (math.nan, math.inf, -math.inf):
            pub.publish(linear=vector(x=bad, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=bad))
        time.sleep(0.5)  # the world steps on meanwhile
        pose = robots.sim.pose("ranger1")
        assert all(math.isfinite(v) for v in (pose.x, pose.y, pose.heading)), pose
        assert (pose.x, pose.y) == pytest.approx((start.x, start.y), abs=1e-6), "a refused Twist moves nothing"

        def moved() -> bool:
            pub.publish(linear=vector(x=0.4, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0))
            return bool(robots.sim.pose("ranger1").x > start.x + 0.3)

        eventually(moved, "the Ranger to drive on a good Twist", timeout=10)
    finally:
        pub.close()

def test_the_sdk_lists_the_served_topics_with_their_types(served: tuple[ServedRobots, int], sdk: Any) -> None:
    _robots, port = served
    wanted = {"/ranger1/cmd_vel": [TWIST], "/ranger1/odom": [ODOMETRY], "/ranger1/scan": [LASER_SCAN],
              "/ranger1/camera/image_raw": ["sensor_msgs/msg/Image"], "/ranger1/camera/detections": [DETECTIONS],
              "/ranger1/battery_state": ["sensor_msgs/msg/BatteryState"],
              "/ranger1/launcher/magazine": ["std_msgs/msg/String"], "/scout1/cmd_vel": [TWIST],
              "/scout1/foot/jump": ["std_msgs/msg/String"], "/scout1/radio/link/ranger1": ["std_msgs/msg/Bool"],
              "/clock": ["rosgraph_msgs/msg/Clock"]}
    listed: dict[str, list[str]] = {}

    def shown() -> bool:
        listed.update(dict(sdk.get_topic_names_and_types(domain_id=0, router_port=port, timeout=0.5)))
        return all(listed.get(t) == types for t, types in wanted.items())

    eventually(shown, f"the SDK to list {wanted} (it lists {listed})")
    info = sdk.get_topic_info("/ranger1/scan", domain_id=0, router_port=port, verbose=True)
    assert info.publisher_count == 1 and info.publishers[0].node_name == "drd_sim"
    assert info.publishers[0].qos == "2::,5:,:,:,,"  # SensorDataQoS, as laser drivers publish


def test_the_sdk_computes_the_vision_msgs_hashes_drd_registers(served: tuple[ServedRobots, int], sdk: Any) -> None:
    """vision_msgs is not in rosbags: drd registers its Jazzy .msg text; the SDK hashes the same text its own way."""
    _robots, port = served
    types = message_types()
    defs = msg_definitions(types, [DETECTIONS])
    assert set(defs) >= {DETECTIONS, "vision_msgs/msg/Detection2D", "vision_msgs/msg/BoundingBox2D"}
    sub = sdk.ROS2Subscriber(topic="/ranger1/camera/detections", msg_type=DETECTIONS, callback=lambda m: None,
                             domain_id=0, router_port=port)
    try:
        assert sub.keyexpr == topic_key(0, "/ranger1/camera/detections", DETECTIONS, types.type_hash(DETECTIONS))
    finally:
        sub.close()


def test_the_camera_is_served_as_an_image_and_detections(served: tuple[ServedRobots, int], sdk: Any) -> None:
    _robots, port = served
    images: list[Any] = []
    found: list[Any] = []
    subs = [sdk.ROS2Subscriber(topic="/ranger1/camera/image_raw", msg_type="sensor_msgs/msg/Image",
                               callback=images.append, domain_id=0, router_port=port),
            sdk.ROS2Subscriber(topic="/ranger1/camera/detections", msg_type=DETECTIONS, callback=found.append,
                               domain_id=0, router_port=port)]
    try:
        eventually(lambda: images and found, "an image and a detection array")
        image = images[-1]
        assert (image.width, image.height, image.encoding) == (IMAGE_WIDTH, 1, "32FC1")
        pixels = np.frombuffer(bytes(image.data), dtype="<f4")
        assert len(pixels) == IMAGE_WIDTH and ((pixels >= 0) & (pixels <= 1)).all()
        assert found[-1].header.frame_id == "ranger1/camera"
    finally:
        for sub in subs:
            sub.close()


# ---------------------------------------------------------------- the command line, as a real process

DRD = [sys.executable, "-c", "from drd.cli.drd import main; main()"]


def _first_line(proc: subprocess.Popen[str], timeout: float) -> str:
    """The process's first line of stdout, waited for at most `timeout` s (a reader thread: no blocking forever)."""
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.append(proc.stdout.readline() if proc.stdout else ""),
                              daemon=True)
    reader.start()
    reader.join(timeout)
    if not lines or not lines[0]:
        proc.kill()
        _out, err = proc.communicate(timeout=5)
        pytest.fail(f"drd sim printed nothing within {timeout:g} s; stderr: {err[-2000:]}")
    return lines[0]


def test_drd_sim_ros2_serves_until_sigterm(tmp_path: Path) -> None:
    port = free_port()
    proc = subprocess.Popen([*DRD, "sim", "--world", "corridor", "--config", str(ROOT / "hosts.yaml"), "--ros2",
                             "--listen", f"tcp/127.0.0.1:{port}", "--speed", "2", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                            env={**os.environ, "DRD_DEBUG": "1"})
    try:
        serving = json.loads(_first_line(proc, 60))
        assert serving["event"] == "serving" and serving["endpoint"] == f"tcp/127.0.0.1:{port}"
        assert ["/ranger1/scan", LASER_SCAN] in serving["robots"]["ranger1"]
        got: list[Any] = []
        with ros2_sdk(message_types(), SDK_TYPES, tmp_path / "msgs") as sdk:
            sub = sdk.ROS2Subscriber(topic="/ranger1/scan", msg_type=LASER_SCAN, callback=got.append,
                                     domain_id=0, router_port=port)
            try:
                eventually(lambda: got and got[-1].header.stamp.nanosec + got[-1].header.stamp.sec > 0,
                           "the served process's scans, sim time running")
            finally:
                sub.close()
        assert len(got[-1].ranges) == 181
        os.kill(proc.pid, signal.SIGTERM)
        out, err = proc.communicate(timeout=15)
        assert proc.returncode == 0, err
        stopped = json.loads(out.strip().splitlines()[-1])
        assert stopped["event"] == "stopped" and stopped["sim_time"] > 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=5)


def test_drd_sim_refuses_what_it_cannot_do(tmp_path: Path) -> None:
    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([*DRD, "sim", "--config", str(ROOT / "hosts.yaml"), *args], capture_output=True,
                              text=True, timeout=60, cwd=tmp_path, check=False)

    no_protocol = run()
    assert no_protocol.returncode == 2 and "--ros2" in no_protocol.stderr
    assert run("--ros2", "--speed", "0").returncode == 2
    assert "no such file" in run("--ros2", "--world", "nowhere").stderr
    blocker = Ros2Session.listen(f"tcp/127.0.0.1:{(port := free_port())}")
    try:
        taken = run("--ros2", "--listen", f"tcp/127.0.0.1:{port}", "--json")
    finally:
        blocker.close()
    assert taken.returncode == 2 and json.loads(taken.stderr.strip().splitlines()[-1])["code"] == 2
    nowhere = run("--ros2", "--listen", "tcp/nowhere.invalid:7447")  # a host name that does not resolve
    assert nowhere.returncode == 2 and "does not resolve" in nowhere.stderr and "Traceback" not in nowhere.stderr
    assert ".rs:" not in taken.stderr  # zenoh's Rust source locations are not the user's business
    for bad in ("bogus", "tcp/127.0.0.1:99999", "tcp/127.0.0.1"):  # a bad option, said in one line (not drd's bug)
        refused = run("--ros2", "--listen", bad, "--json")
        error = json.loads(refused.stderr)
        assert refused.returncode == 2 and error["code"] == 2 and bad in error["error"], refused.stderr
