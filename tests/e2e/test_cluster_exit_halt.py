"""A mission that ends with its robot's setpoint still in force: on a cluster the robot was stopped (its host
halts the device as the component is unbound), but the `halted` record came back with the host's reply after the
mission's `finished`, and the executive dropped it (a trace ends with `finished`): from the trace alone the robot
looked left moving (safety audit 7, D4). Now a mission's end carries its gate operations to their hosts first,
and the trace of `missionctl run --trace` shows the halt before `finished`, as a dry-run's does."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cluster_support import corridor_hosts, running_cluster, user_kit

KIT = '''from drd.runtime.component import Component, Status


class Coast(Component):
    """Drives for a while and ends without stopping: the runtime must stop the robot."""

    def step(self, now):
        if now >= 2.0:
            return Status.SUCCESS
        self.device("drive").set_velocity(0.3, 0.0)
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
