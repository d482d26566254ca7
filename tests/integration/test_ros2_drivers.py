"""The `ros2` drivers (components/ros2): a fake robot written with zenoh-ros2-sdk (an independent rmw_zenoh client:
it publishes scans and odometry and obeys cmd_vel) driven by drd's `Ros2Drive`, the safety stops seen on the robot
side, stale data refused; then every driver against the simulator served as ROS 2 robots (drd.sim.ros2)."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from components.ros2.camera import Ros2Camera
from components.ros2.drive import Ros2Drive
from components.ros2.jump import Ros2Jump
from components.ros2.launcher import Ros2Launcher
from components.ros2.radio_channel import Ros2RadioChannel
from components.ros2.range_sensor import Ros2RangeSensor
from drd.bus.ros2 import MessageTypes, Ros2Session
from drd.hosts import Device, load_hosts
from drd.hw.commands import spec_of
from drd.hw.drivers import DriverError, check_driver_classes, load_driver
from drd.hw.interfaces import Camera, Drive, HardwareError, Jump, Launcher, RadioChannel, RangeSensor, StaleCommand
from drd.hw.ros2 import LASER_SCAN, ODOMETRY, TWIST, Ros2Link, message_types, quaternion
from drd.runtime.ownership import DeviceGate
from drd.sim.ros2 import ServedRobots
from dsl.catalog import Catalog
from tests.ros2_support import FAST_OPEN, eventually, free_port, ros2_sdk, served_team

ROOT = Path(__file__).resolve().parents[2]


def device(kind: str, name: str, options: dict[str, object] | None = None, **driver_options: object) -> Device:
    return Device(f"robot.{name}", "robot", kind, "ros2", options or {}, driver_options=driver_options)


@pytest.fixture
def router() -> Iterator[int]:
    """The robot's zenoh router (rmw_zenohd's part), on a free loopback port."""
    port = free_port()
    session = Ros2Session.listen(f"tcp/127.0.0.1:{port}", options=FAST_OPEN, types=message_types())
    try:
        yield port
    finally:
        session.close()


@pytest.fixture
def link() -> Iterator[Ros2Link]:
    """A host's link of its own (not the process's default one), closed after."""
    link = Ros2Link()
    try:
        yield link
    finally:
        link.close()


class FakeRobot:
    """A differential robot written with zenoh-ros2-sdk only: it integrates the last cmd_vel into its odometry and
    publishes odometry and a 90-beam scan at 20 Hz, until told to fall silent."""

    def __init__(self, sdk: Any, port: int, name: str = "bot") -> None:
        common = {"domain_id": 0, "router_port": port}
        self.twists: list[tuple[float, Any]] = []  # (time.monotonic(), Twist) as received
        self.lock = threading.Lock()
        self.cmd = sdk.ROS2Subscriber(topic=f"/{name}/cmd_vel", msg_type=TWIST, callback=self._on_twist, **common)
        self.odom = sdk.ROS2Publisher(topic=f"/{name}/odom", msg_type=ODOMETRY, **common)
        self.scan = sdk.ROS2Publisher(topic=f"/{name}/scan", msg_type=LASER_SCAN, **common)
        self.make = MessageTypes(self.odom.session_mgr.store).make  # nested messages of the SDK's own classes
        self.pose = [0.0, 0.0, 0.0]
        self.v = self.omega = 0.0
        self.silent = threading.Event()
        self.faulted = threading.Event()  # NaN in the scan's geometry and the odometry's pose (ROS 2 audit 12)
        self.blind = threading.Event()  # scans with no beams (ROS 2 audit 17), or fewer than the angles say
        self.nan = threading.Event()  # scans whose every beam is NaN (REP 117: invalid)
        self.beams = 0
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _on_twist(self, msg: Any) -> None:
        with self.lock:
            self.twists.append((time.monotonic(), msg))
            self.v, self.omega = msg.linear.x, msg.angular.z

    def _run(self) -> None:
        period = 0.05
        while not self.stopped.wait(period):
            with self.lock:
                x, y, a = self.pose
                self.pose = [x + self.v * period * math.cos(a), y + self.v * period * math.sin(a),
                             a + self.omega * period]
                x, y, a = self.pose
            if self.silent.is_set():
                continue
            bad = self.faulted.is_set()
            if bad:
                x = math.nan
            odom = self.make(ODOMETRY, header={"frame_id": "odom"}, child_frame_id="base_link",
                             pose={"pose": {"position": {"x": x, "y": y}, "orientation": quaternion(a)}})
            self.odom.publish(header=odom.header, child_frame_id=odom.child_frame_id, pose=odom.pose, twist=odom.twist)
            ranges = np.full(90, 2.0, dtype=np.float32)
            ranges[:10] = np.inf
            if self.blind.is_set():
                ranges = ranges[:self.beams]
            if self.nan.is_set():
                ranges[:] = np.nan
            self.scan.publish(header=odom.header, angle_min=-math.pi / 2, angle_max=math.pi / 2,
                              angle_increment=math.nan if bad else math.pi / 89, time_increment=0.0,
                              scan_time=period, range_min=0.1, range_max=4.0, ranges=ranges,
                              intensities=np.zeros(0, dtype=np.float32))

    def last_twist(self) -> tuple[float, Any] | None:
        with self.lock:
            return self.twists[-1] if self.twists else None

    def close(self) -> None:
        self.stopped.set()
        self.thread.join(timeout=2)
        for entity in (self.cmd, self.odom, self.scan):
            entity.close()


@pytest.fixture
def robot(router: int, tmp_path: Path) -> Iterator[FakeRobot]:
    with ros2_sdk(message_types(), (TWIST, ODOMETRY, LASER_SCAN), tmp_path / "msgs") as sdk:
        bot = FakeRobot(sdk, router)
        try:
            yield bot
        finally:
            bot.close()


def drive_of(port: int, link: Ros2Link, **options: object) -> Ros2Drive:
    return Ros2Drive(device("Drive", "drive", {"max_speed": 0.5}, endpoint=f"tcp/127.0.0.1:{port}", **options),
                     "bot", link)


def test_ros2_drive_drives_a_robot_written_with_the_sdk(robot: FakeRobot, router: int, link: Ros2Link) -> None:
    drive = drive_of(router, link, origin=[1.0, 2.0, 90])
    ranges = Ros2RangeSensor(device("RangeSensor", "ranges", endpoint=f"tcp/127.0.0.1:{router}"), "bot", link)
    try:
        assert isinstance(drive, Drive) and isinstance(ranges, RangeSensor)
        eventually(lambda: _reads(drive.odometry), "the robot's odometry")
        x0, y0, heading0 = drive.odometry()
        assert (x0, y0, heading0) == pytest.approx((1.0, 2.0, math.pi / 2), abs=0.05)  # origin ∘ odom
        assert drive.origin() == pytest.approx((1.0, 2.0, math.pi / 2))
        deadline = time.monotonic() + 10
        while drive.odometry()[1] < y0 + 0.3:  # as a behavior does: a command every control cycle
            assert time.monotonic() < deadline, "the robot did not move"
            drive.set_velocity(2.0, 0.0)  # clamped to max_speed, 0.5
            time.sleep(0.1)
        last = robot.last_twist()
        assert last is not None and last[1].linear.x == pytest.approx(0.5) and last[1].angular.z == 0.0
        x1, _y1, _ = drive.odometry()
        assert x1 == pytest.approx(1.0, abs=0.05)  # the robot's x is the map's y (origin heading 90 degrees)
        scan = ranges.scan()
        assert len(scan.ranges) == 90 and scan.max_range == 4.0 and scan.ranges[0] == 4.0  # +inf: nothing hit
        assert scan.ranges[50] == pytest.approx(2.0) and scan.angle(89) == pytest.approx(math.pi / 2)
        assert ranges.scan() is ranges.scan() or True  # the same object until a new scan comes
        drive.stop()
        eventually(lambda: (t := robot.last_twist()) is not None and t[1].linear.x == 0.0, "the stop")
    finally:
        drive.close()
        ranges.close()


def _refusal(reading: Any) -> str:
    """Why `reading` fails now ("" when it reads)."""
    try:
        reading()
        return ""
    except HardwareError as e:
        return str(e)


def _reads(reading: Any) -> bool:
    try:
        reading()
        return True
    except HardwareError:
        return False


def _zero_after(robot: FakeRobot, since: float, within: float) -> float:
    """How long after `since` the robot side received a zero Twist (fails after `within` s)."""
    deadline = since + within + 1.0
    while time.monotonic() < deadline:
        with robot.lock:
            zeros = [t for t, m in robot.twists if t >= since and m.linear.x == 0.0 and m.angular.z == 0.0]
        if zeros:
            return zeros[0] - since
        time.sleep(0.005)
    pytest.fail(f"no zero Twist on the robot side within {within + 1.0:g} s")


def test_the_watchdog_stops_the_robot_when_commands_stop(robot: FakeRobot, router: int, link: Ros2Link) -> None:
    drive = drive_of(router, link, watchdog=0.3)
    try:
        eventually(lambda: _reads(drive.odometry), "the robot's odometry")
        drive.set_velocity(0.3, 0.1)
        eventually(lambda: (t := robot.last_twist()) is not None and t[1].linear.x == pytest.approx(0.3), "a Twist")
        sent = time.monotonic()
        after = _zero_after(robot, sent, 0.5)
        assert 0.2 <= after <= 0.5, after  # the watchdog (0.3 s), not sooner, and within half a second
        assert drive.watchdog_stops == 1
        time.sleep(0.5)
        with robot.lock:
            assert sum(1 for t, _ in robot.twists if t > sent) == 1  # one zero Twist per silence
    finally:
        drive.close()


def test_stop_close_and_a_fenced_out_command_each_send_a_zero_twist(robot: FakeRobot, router: int,
                                                                    link: Ros2Link) -> None:
    drive = drive_of(router, link)
    try:
        for act in ("stop", "fence", "close"):
            drive.set_velocity(0.2, 0.0, epoch=5)
            eventually(lambda: (t := robot.last_twist()) is not None and t[1].linear.x == pytest.approx(0.2),
                       "a Twist")
            since = time.monotonic()
            if act == "stop":
                drive.stop(epoch=5)
            elif act == "fence":
                with pytest.raises(StaleCommand):
                    drive.set_velocity(0.4, 0.0, epoch=4)  # a revoked grant's command: refused, and the base stops
            else:
                drive.close()
            assert _zero_after(robot, since, 0.5) <= 0.5
    finally:
        drive.close()


def test_a_revoked_grant_stops_the_robot_through_the_gate(robot: FakeRobot, router: int, link: Ros2Link) -> None:
    """The ownership gate in front of the Drive (drd.runtime.ownership): the holder's grant ends, the gate halts the
    device (its declared STOP, `stop`), and the robot side sees a zero Twist."""
    drive = drive_of(router, link)
    gate = DeviceGate("robot.drive", drive, spec_of(drive), lambda _mission, _record: None)
    try:
        gate.grant("M/Follow", 7, 0.0, exclusive=True)
        gate.execute(drive, "M/Follow", 7, "set_velocity", (0.3, 0.0), {}, 0.0)
        eventually(lambda: (t := robot.last_twist()) is not None and t[1].linear.x == pytest.approx(0.3), "a Twist")
        since = time.monotonic()
        gate.clear("M/Follow", 0.1, "revoked")
        assert _zero_after(robot, since, 0.5) <= 0.5
    finally:
        drive.close()


def test_the_rate_limit_holds_commands_back_but_sends_the_latest(robot: FakeRobot, router: int,
                                                                 link: Ros2Link) -> None:
    drive = drive_of(router, link, max_rate=10)
    try:
        start = time.monotonic()
        for k in range(50):  # 50 commands in a burst
            drive.set_velocity(0.01 * (k + 1), 0.0)
        eventually(lambda: (t := robot.last_twist()) is not None and t[1].linear.x == pytest.approx(0.5),
                   "the latest command, sent when the interval ended")
        with robot.lock:
            assert len([t for t, _ in robot.twists if t >= start]) <= 3  # the first, the latest (10 a second)
    finally:
        drive.close()


def test_stale_or_missing_data_raise(robot: FakeRobot, router: int, link: Ros2Link) -> None:
    drive = drive_of(router, link, max_age=0.3)
    elsewhere = Ros2RangeSensor(device("RangeSensor", "ranges", endpoint=f"tcp/127.0.0.1:{router}",
                                       topics={"scan": "/nobody/scan"}, max_age=0.2), "bot", link)
    try:
        eventually(lambda: _reads(drive.odometry), "the robot's odometry")
        robot.silent.set()
        time.sleep(0.5)
        with pytest.raises(HardwareError, match=r"stale: older than 0.3 s"):
            drive.odometry()
        with pytest.raises(HardwareError, match=r"no message on /nobody/scan"):
            elsewhere.scan()
        with pytest.raises(HardwareError, match="battery"):  # nobody publishes it: the static battery stands
            drive.battery()
    finally:
        drive.close()
        elsewhere.close()


def test_nan_geometry_or_pose_is_a_faulted_sensor_not_a_reading(robot: FakeRobot, router: int,
                                                                link: Ros2Link) -> None:
    """ROS 2 audit 12: a scan with a NaN angle_increment was read (a wall 0.3 m ahead unseen, the robot drove through
    it) and a NaN pose passed a geofence; both now fail the reading, as a stale one does, so the behavior stops."""
    drive = drive_of(router, link)
    ranges = Ros2RangeSensor(device("RangeSensor", "ranges", endpoint=f"tcp/127.0.0.1:{router}"), "bot", link)
    try:
        eventually(lambda: _reads(drive.odometry) and _reads(ranges.scan), "the robot's odometry and scan")
        assert math.isfinite(ranges.scan().angle_step)
        robot.faulted.set()
        eventually(lambda: not _reads(drive.odometry) and not _reads(ranges.scan), "the faulted readings refused")
        with pytest.raises(HardwareError, match="does not know where it is"):
            drive.odometry()
        with pytest.raises(HardwareError, match="scan geometry is not usable"):
            ranges.scan()
    finally:
        drive.close()
        ranges.close()


def test_a_scan_without_its_beams_is_a_faulted_laser_not_free_space(robot: FakeRobot, router: int,
                                                                    link: Ros2Link) -> None:
    """ROS 2 audit 17, D2: a laser publishing well-formed scans with no ranges (lost data, still heartbeating) was
    read as nothing in sight, and FollowCorridor drove the robot 2 m through a wall. A scan with fewer than half
    the beams its angles say fails the reading, as a stale one does; 89 of 90 (a driver's rounding) is read."""
    ranges = Ros2RangeSensor(device("RangeSensor", "ranges", endpoint=f"tcp/127.0.0.1:{router}"), "bot", link)
    try:
        eventually(lambda: _reads(ranges.scan), "the robot's scan")
        for beams in (0, 30):
            robot.beams = beams
            robot.blind.set()
            said = f"the laser gives {beams} beams where its scan's angles say 90"
            eventually(lambda said=said: said in _refusal(ranges.scan), f"a scan of {beams} beams refused")
        robot.beams = 89
        eventually(lambda: _reads(ranges.scan), "a scan one beam short read")
        assert len(ranges.scan().ranges) == 89
    finally:
        ranges.close()


def test_a_scan_of_nan_beams_is_a_faulted_laser_named_as_every_other_fault(robot: FakeRobot, router: int,
                                                                          link: Ros2Link) -> None:
    """ROS 2 audit 22, #3: the refusal of a scan with every beam NaN did not say which laser (with several robots,
    which one failed?), where every other fault of a laser names it."""
    ranges = Ros2RangeSensor(device("RangeSensor", "ranges", endpoint=f"tcp/127.0.0.1:{router}"), "bot", link)
    try:
        eventually(lambda: _reads(ranges.scan), "the robot's scan")
        robot.nan.set()
        eventually(lambda: "90 of 90 beams are NaN" in _refusal(ranges.scan), "the scan refused")
        assert _refusal(ranges.scan).startswith(ranges.describe() + ": the laser gives no valid reading")
    finally:
        robot.nan.clear()
        ranges.close()


def test_a_scan_of_absurd_size_is_a_faulted_laser(robot: FakeRobot, router: int, link: Ros2Link,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """ROS 2 audit 18, #3: 1,000,000-beam scans (4 MB, 5 a second) were converted and shipped every cycle, the
    host's control loop fell behind and the mission failed blaming the host. A scan of more than MAX_BEAMS fails the
    reading, naming the laser (here the limit is lowered under the fake robot's 90 beams)."""
    from components.ros2 import range_sensor

    ranges = Ros2RangeSensor(device("RangeSensor", "ranges", endpoint=f"tcp/127.0.0.1:{router}"), "bot", link)
    try:
        eventually(lambda: _reads(ranges.scan), "the robot's scan")
        monkeypatch.setattr(range_sensor, "MAX_BEAMS", 60)
        eventually(lambda: "the laser gives 90 beams, more than 60" in _refusal(ranges.scan), "the scan refused")
    finally:
        ranges.close()


def test_zeros_on_a_loss_go_out_through_the_standby_session_else_one_of_their_own(robot: FakeRobot,
                                                                                    router: int) -> None:
    """ROS 2 audit 17, D4: the controller opened a session to the robot's router only once a host was lost (0.15 to
    0.21 s before the first zero). Its standby session, linked to the router, carries the zeros; closed (or its
    router gone), a stop opens a session of its own, as before."""
    from drd.hw.safestop import DriveStop, StandbyLinks, send_zeros

    endpoint = f"tcp/127.0.0.1:{router}"
    stops = [DriveStop("h", "bot", "drive", endpoint, 0, "bot", "cmd_vel")]
    standby = StandbyLinks()
    try:
        standby.link.session(endpoint)
        eventually(lambda: standby.link.connected(endpoint), "the standby session linked to the router")
        before = len(robot.twists)
        assert send_zeros(stops, "a test", standby=standby, gap=0.05) == []
        assert sum(standby.link.sent.values()) == 3  # through the standby session
        eventually(lambda: len(robot.twists) >= before + 3, "three zeros at the robot")
    finally:
        standby.close()
    assert not standby.link.connected(endpoint)
    before = len(robot.twists)
    assert send_zeros(stops, "a test", standby=standby, gap=0.05) == []  # a session of its own
    assert sum(standby.link.sent.values()) == 3
    eventually(lambda: len(robot.twists) >= before + 3, "three zeros more at the robot")
    last = robot.last_twist()
    assert last is not None and last[1].linear.x == 0.0 and last[1].angular.z == 0.0


def test_messages_in_another_frame_are_dropped(robot: FakeRobot, router: int, link: Ros2Link) -> None:
    """The fake robot's odometry is in `odom` / `base_link`: a Drive told to expect other frames takes none of it."""
    right = drive_of(router, link, odom_frame="odom", base_frame="base_link")
    wrong = drive_of(router, link, odom_frame="odom", base_frame="bot/base_footprint", max_age=0.3)
    try:
        eventually(lambda: _reads(right.odometry), "odometry in the frames expected")
        # the frames it came in, not the router's address (ROS 2 audit 17, D3: the router was up)
        with pytest.raises(HardwareError, match=r"no message on /bot/odom in frame 'odom' \(child 'bot/base_footprint'"
                                                r"\) within 0.3 s: \d+ came in frame 'odom' \(child 'base_link'\)"):
            wrong.odometry()
    finally:
        right.close()
        wrong.close()


def test_options_are_checked_before_anything_runs(catalog: Catalog, tmp_path: Path) -> None:
    bad = device("Drive", "drive", endpoint="tcp/127.0.0.1:1", watchdg=0.5, max_age=-1, origin=[1, 2])
    with pytest.raises(DriverError, match=r"driver_options.watchdg: unknown option"):
        load_driver(bad, "bot", {})
    hosts = (ROOT / "hosts.ros2.yaml").read_text(encoding="utf-8")
    hosts = hosts.replace("7500, domain_id: 0, origin", "7500, domain_id: 0, topik: {}, origin")  # drivers.ros2
    (tmp_path / "hosts.yaml").write_text(hosts, encoding="utf-8")
    problems = check_driver_classes(load_hosts(tmp_path / "hosts.yaml", catalog), "ranger1", catalog)
    assert problems and all("driver_options.topik: unknown option" in p for p in problems)
    assert problems[0].startswith(f"{tmp_path / 'hosts.yaml'}: hosts.ranger1.devices.drive.driver_options")


# ---------------------------------------------------------------- every driver against the served simulator


@pytest.fixture
def served(catalog: Catalog) -> Iterator[tuple[ServedRobots, int]]:
    with served_team(load_hosts(ROOT / "hosts.yaml", catalog), 2.0) as team:
        yield team


def test_every_ros2_driver_works_the_served_simulator(served: tuple[ServedRobots, int], link: Ros2Link) -> None:
    robots, port = served
    at = {"endpoint": f"tcp/127.0.0.1:{port}", "origin": [1.0, 0.0, 0.0], "max_age": 1.0}
    drive = Ros2Drive(device("Drive", "drive", {"max_speed": 0.8}, **at), "ranger1", link)
    laser = Ros2RangeSensor(device("RangeSensor", "ranges", {"beams": 181}, **at), "ranger1", link)
    camera = Ros2Camera(device("Camera", "camera", {"fov": 60.0}, **at), "ranger1", link)
    launcher = Ros2Launcher(device("Launcher", "launcher", {"max_range": 6.0}, **at), "ranger1", link)
    foot = Ros2Jump(device("Jump", "foot", **at), "scout1", link)
    radio = Ros2RadioChannel(device("RadioChannel", "radio", peer="ranger1", **at), "scout1", link)
    drivers: list[Any] = [drive, laser, camera, launcher, foot, radio]
    try:
        for d, kind in zip(drivers, (Drive, RangeSensor, Camera, Launcher, Jump, RadioChannel), strict=True):
            assert isinstance(d, kind)
        eventually(lambda: _reads(drive.odometry) and _reads(launcher.loaded), "the served robot's state")
        assert drive.odometry() == pytest.approx((1.0, 0.0, 0.0), abs=0.05)  # the world's start pose, via origin
        assert drive.battery() == pytest.approx(1.0)
        assert len(laser.scan().ranges) == 181 and laser.scan().max_range == 8.0
        lights = camera.brightness(16)
        assert len(lights) == 16 and all(0.0 <= v <= 1.0 for v in lights) and len(camera.brightness(4)) == 4
        assert isinstance(camera.detections(), list)
        assert launcher.loaded() == ("scout1", "scout2", "scout3", "scout4", "scout5", "scout6")
        assert radio.link_ok() is True  # a Scout in its Ranger's magazine
        with pytest.raises(HardwareError, match="magazine"):
            foot.jump(0.3)  # the served simulator refuses: a Scout in the magazine cannot hop
        landing = launcher.launch("scout1", 0.0, 3.0)
        assert (landing.x, landing.y) == pytest.approx((4.0, 0.0), abs=0.1) and landing.duration > 0
        eventually(lambda: launcher.loaded()[0] == "scout2", "the magazine without scout1")
        with pytest.raises(HardwareError, match="not in ranger1's magazine"):
            launcher.launch("scout1", 0.0, 3.0)
        start = drive.odometry()[0]
        deadline = time.monotonic() + 10
        while drive.odometry()[0] < start + 0.3:
            assert time.monotonic() < deadline, "the served Ranger did not move"
            drive.set_velocity(0.5, 0.0)
            time.sleep(0.05)
        drive.stop()
        assert robots.sim.pose("ranger1").x > 1.2
        eventually(lambda: robots.sim.state("scout1").value == "floor", "scout1 to land", timeout=10)
        foot.jump(0.2)  # on the floor now: the hop is accepted
    finally:
        for d in drivers:
            d.close()
