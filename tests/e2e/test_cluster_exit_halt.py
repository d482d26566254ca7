"""A mission that ends with its robot's setpoint still in force: on a cluster the robot was stopped (its host
halts the device as the component is unbound), but the `halted` record came back with the host's reply after the
mission's `finished`, and the executive dropped it (a trace ends with `finished`): from the trace alone the robot
looked left moving (safety audit 7, D4). Now a mission's end carries its gate operations to their hosts first,
and the trace of `missionctl run --trace` shows the halt before `finished`, as a dry-run's does."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cluster_support import MISSIONCTL, DaemonCluster, corridor_hosts, eventually, running, running_cluster, user_kit

KIT = '''from drd.runtime.component import Component, Status


class Coast(Component):
    """Drives for a while and ends without stopping: the runtime must stop the robot."""

    def step(self, now):
        if now >= 2.0:
            return Status.SUCCESS
        self.device("drive").set_velocity(0.3, 0.0)
        return Status.RUNNING


class Onward(Component):
    """Drives on and on."""

    def step(self, now):
        self.device("drive").set_velocity(0.2, 0.0)
        return Status.RUNNING
'''
MANIFEST = """name: Coast
kind: behavior
description: Drives and ends without stopping.
entry_point: coastkit:Coast
needs:
  drive: {type: Drive, of: [Ranger], description: the base.}
interfaces: [Drive]
"""
MISSION = "mission CoastAway {\n    needs r: Ranger\n    Coast\n}\n"


def test_the_halt_at_a_missions_end_is_in_its_cluster_trace_before_finished(tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    user_kit(tmp_path, monkeypatch, "coastkit", KIT, {"Coast": MANIFEST})
    (tmp_path / "coast.mission").write_text(MISSION)
    with running_cluster(tmp_path, ["controller", "ranger1"]) as c:
        c.hosts_file.write_text(corridor_hosts(c))
        c.start_all()
        c.wait_ready()
        c.wait_up()
        trace = tmp_path / "t.jsonl"
        r = c.missionctl("run", str(tmp_path / "coast.mission"), "--config", str(c.hosts_file), "--trace",
                         str(trace), "--speed", "4", timeout=120)
        assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-2000:])
    records = [json.loads(line) for line in trace.read_text().splitlines() if line.strip()]
    kinds = [x["kind"] for x in records]
    assert kinds[-1] == "finished", kinds[-5:]
    moving = [x for x in records if x["kind"] == "command" and x["accepted"]]
    assert moving and moving[-1]["method"] == "set_velocity", moving[-3:]  # it never stopped the robot itself
    halts = [x for x in records if x["kind"] == "halted" and x["device"] == moving[-1]["device"]]
    assert halts, kinds[-8:]
    assert records.index(halts[-1]) > records.index(moving[-1]), "the halt comes after the last command"


FOREVER = "mission DriveOn {\n    needs r: Ranger\n    Onward\n}\n"


def test_the_robots_host_lost_mid_motion_leaves_a_halt_in_the_trace(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """Safety audit 8, D6: kill -9 of the robot's host while a behavior drives: the robot was stopped, but the trace
    ended with its last `set_velocity` (the gates that record halts were on the host gone, and the mission's last
    stops could not reach it). Now the trace says the drive was stopped, or could not be reached, before `finished`."""
    user_kit(tmp_path, monkeypatch, "coastkit", KIT, {"Onward": MANIFEST.replace("Coast", "Onward")})
    (tmp_path / "drive.mission").write_text(FOREVER)
    with running_cluster(tmp_path, ["controller", "ranger1"]) as c:
        c.hosts_file.write_text(corridor_hosts(c, simulator_on_controller=True))  # the world outlives ranger1
        c.start_all()
        c.wait_ready()
        c.wait_up()
        trace = tmp_path / "t.jsonl"
        with running([*MISSIONCTL, "run", str(tmp_path / "drive.mission"), "--config", str(c.hosts_file),
                      "--trace", str(trace)]) as run:
            eventually(lambda: running_for(c, 1.0), "the robot to move", 60, explain=lambda: c.tails())
            c.procs["ranger1"].kill()
            c.procs["ranger1"].wait(timeout=10)
            out, err = run.communicate(timeout=90)
            assert run.returncode == 1, (out[-2000:], err[-2000:])
    records = [json.loads(line) for line in trace.read_text().splitlines() if line.strip()]
    moving = [x for x in records if x["kind"] == "command" and x["accepted"]]
    halts = [x for x in records if x["kind"] == "halted" and x["device"] == moving[-1]["device"]]
    assert halts and records.index(halts[-1]) > records.index(moving[-1]), [x["kind"] for x in records[-8:]]
    assert records[-1]["kind"] == "finished" and records[-1]["outcome"] == "failure", records[-1]


def running_for(c: DaemonCluster, seconds: float) -> bool:
    """Whether a mission has run `seconds` of its time (its status, from the controller)."""
    got = c.missionctl("status", "--config", str(c.hosts_file), "--json", timeout=30)
    missions = json.loads(got.stdout)["missions"] if got.returncode == 0 else []
    return any(m["outcome"] is None and float(m.get("time") or 0) >= seconds for m in missions)
