"""A robot left driving by a dead host (safety audit 1): kill -9 of the daemon hosting a robot's `ros2` Drive in the
middle of a motion leaves nothing in that process to stop the robot (its watchdog died with it). The controller,
which marks the host down, sends the robot a zero Twist itself; and the host's daemon, started again, sends one
before it serves missions. Said by the robot's side: tests/fake_ros2_robot.py (no drd code) logs every Twist it
receives. 2 daemons (controller, ranger1: no simulator) and the robot, each a process of ours killed by pid; about
25 s."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from pathlib import Path

import pytest
from cluster_support import MISSIONCTL, DaemonCluster, eventually, running, serving_cluster
from test_ros2_real_robots import NAMES, real_hosts, robot, twists

pytest.importorskip("zenoh_ros2_sdk", reason="zenoh-ros2-sdk is not installed (pip install -e '.[test]')")

__all__ = ["robot"]  # the fake robot's fixture, shared with test_ros2_real_robots

LONG = """mission Long {
    needs ranger: Ranger
    FollowCorridor(speed: 0.4)
    FollowCorridor -> done after 60s
}
"""
ZERO = {"v": 0.0, "w": 0.0}


@pytest.fixture
def cluster(robot: tuple[int, Path], tmp_path: Path) -> Iterator[DaemonCluster]:
    folder = tmp_path / "cluster"
    folder.mkdir()
    with serving_cluster(folder, NAMES, lambda c: real_hosts(c, robot[0])) as c:
        yield c


def test_a_killed_host_robot_is_stopped_by_the_controller_then_by_its_restart(
        cluster: DaemonCluster, robot: tuple[int, Path], tmp_path: Path) -> None:
    cmd_log = robot[1]
    mission = tmp_path / "long.mission"
    mission.write_text(LONG, encoding="utf-8")
    before = len(twists(cmd_log))
    with running([*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), "--json"]) as run:
        eventually(lambda: len([t for t in twists(cmd_log)[before:] if t["v"] > 0.3]) >= 5, "the robot driven",
                   timeout=30)
        cluster.procs["ranger1"].send_signal(signal.SIGKILL)
        cluster.procs["ranger1"].wait(timeout=10)
        killed = len(twists(cmd_log))
        # the robot's side: a zero Twist after the last moving one, though its driver's process is gone
        eventually(lambda: twists(cmd_log)[-1] == ZERO and len(twists(cmd_log)) > killed, "a zero Twist after the"
                   f" kill\n{cluster.tails('controller', chars=2000)}", timeout=20)
        out, err = run.communicate(timeout=60)
    assert run.returncode != 0, (out[-1000:], err[-2000:])  # the mission failed: its robot's host is down
    got = twists(cmd_log)[before:]
    moving = max(i for i, t in enumerate(got) if t["v"] > 0.3)
    stopped = got.index(ZERO, moving)
    assert all(t == ZERO for t in got[stopped:]), got[stopped:]  # nothing moves it again
    said = "zero Twist (3 times) to ranger1.drive (ranger1) /ranger1/cmd_vel"
    eventually(lambda: said in cluster.log("controller"), "the controller's zero Twists all sent")
    assert "host ranger1 down" in cluster.log("controller"), cluster.tails()

    # the host's daemon again: a zero before it serves missions, whoever was driving the robot before
    restart, logged = len(twists(cmd_log)), len(cluster.log("ranger1"))
    cluster.start("ranger1")
    # the robot's side: zeros from the restarted daemon, nothing else (the controller's were all sent before)
    eventually(lambda: len(twists(cmd_log)) > restart, f"a zero Twist from the restarted ranger1\n"
               f"{cluster.tails('ranger1')}", timeout=30)
    got = twists(cmd_log)[restart:]
    assert got and all(t == ZERO for t in got), got
    eventually(lambda: "host ranger1 starting" in cluster.log("ranger1")[logged:], "the restarted ranger1's log")
    assert "drd ranger1 started" not in cluster.log("ranger1")[logged:].split("host ranger1 starting")[0]  # before


def test_a_frozen_host_robot_is_stopped_by_the_controller_during_the_freeze(
        cluster: DaemonCluster, robot: tuple[int, Path], tmp_path: Path) -> None:
    """SIGSTOP of the robot's host: its watchdog is frozen with it. The zero comes from the controller once the lease
    lapses, while the host is still stopped; kept frozen until its resources leave the manager (its grants freed),
    then SIGCONT: the host commands nothing that moves the robot again (its fence)."""
    cmd_log = robot[1]
    mission = tmp_path / "long.mission"
    mission.write_text(LONG, encoding="utf-8")
    before = len(twists(cmd_log))
    ranger1 = cluster.procs["ranger1"]
    with running([*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), "--json"]) as run:
        eventually(lambda: len([t for t in twists(cmd_log)[before:] if t["v"] > 0.3]) >= 5, "the robot driven",
                   timeout=30)
        ranger1.send_signal(signal.SIGSTOP)
        try:
            frozen = len(twists(cmd_log))
            eventually(lambda: twists(cmd_log)[-1] == ZERO and len(twists(cmd_log)) > frozen, "a zero Twist during"
                       f" the freeze\n{cluster.tails('controller', chars=2000)}", timeout=20)
            assert ranger1.poll() is None  # still frozen: the zero is not its own
            # frozen until its grants are gone (a freeze shorter than that is survived: the mission drives on)
            eventually(lambda: "host ranger1 resources-removed" in cluster.log("controller"), "ranger1's resources"
                       " to leave the manager")
        finally:
            ranger1.send_signal(signal.SIGCONT)
        out, err = run.communicate(timeout=60)
    assert run.returncode != 0, (out[-1000:], err[-2000:])
    # fewer than 3 when the host reports again before the last (it stops its robot itself then)
    eventually(lambda: "host ranger1 down" in cluster.log("controller") and "times) to ranger1.drive"
               in cluster.log("controller"), "the controller's zero Twists sent")
    got = twists(cmd_log)[before:]
    moving = max(i for i, t in enumerate(got) if t["v"] > 0.3)
    assert got.index(ZERO, moving) < len(got) and all(t == ZERO for t in got[got.index(ZERO, moving):]), got[moving:]
