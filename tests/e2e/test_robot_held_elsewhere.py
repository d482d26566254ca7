"""A behavior may hold a whole robot served by another host than its devices (new-user audit 8, D2): it holds it
to move it with an action that `MOVES` it, or to keep it still, and never calls a device of it. On a cluster such
a state failed with `its devices are on several hosts`, where a dry-run ran it; the Creator also refused a binding
to a robot that is not its own host's. Here a behavior drives ranger1 (on host ranger1) while holding ranger2 (on
host ranger2) as a whole: it runs where ranger1's devices are, and ranger2 stays held, unmoved."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cluster_support import running_cluster, two_rangers_hosts, user_kit

KIT = '''from drd.runtime.component import Component, Status


class Shepherd(Component):
    """Drives its own Ranger a little while holding another as a whole (which it never calls)."""

    def step(self, now):
        if now >= 1.5:
            self.device("drive").stop()
            return Status.SUCCESS
        self.device("drive").set_velocity(0.2, 0.0)
        return Status.RUNNING
'''
MANIFEST = """name: Shepherd
kind: behavior
description: Drives one Ranger, holding another.
entry_point: shepherdkit:Shepherd
needs:
  drive: {type: Drive, of: [Ranger], description: its own base.}
  flock: {type: Ranger, description: a Ranger held as a whole.}
interfaces: [Drive]
"""
MISSION = """mission Herding {
    needs drive: Drive where drive.id == "ranger1.drive"
    needs flock: Ranger where flock.id == "ranger2"
    Shepherd
}
"""


def test_a_behavior_holding_a_robot_of_another_host_runs_where_its_devices_are(tmp_path: Path,
                                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    user_kit(tmp_path, monkeypatch, "shepherdkit", KIT, {"Shepherd": MANIFEST})
    (tmp_path / "herd.mission").write_text(MISSION)
    with running_cluster(tmp_path, ["controller", "ranger1", "ranger2"]) as c:
        c.hosts_file.write_text(two_rangers_hosts(c, "{mode: none}"))
        c.start_all()
        c.wait_ready()
        c.wait_up()
        trace = tmp_path / "t.jsonl"
        r = c.missionctl("run", str(tmp_path / "herd.mission"), "--config", str(c.hosts_file), "--trace",
                         str(trace), "--json", timeout=120)
        report = json.loads(r.stdout) if r.stdout.strip().startswith("{") else {}
        assert r.returncode == 0 and report.get("outcome") == "success", (r.stdout[-2000:], r.stderr[-2000:])
    records = [json.loads(line) for line in trace.read_text().splitlines() if line.strip()]
    moved = {x["device"] for x in records if x["kind"] == "command" and x["accepted"]}
    assert moved == {"ranger1.drive"}, moved
