"""The time components see starts with each world on a cluster, as in a dry-run (users audit 22, #2): the
executive's clock goes on across worlds (the manager's times must never go back), and components saw it, so a
second run of the same mission started its component at 1.1 s, a third at 2.2 s, and a guard on a time an event
carried took the other branch after a few runs. Real daemons on loopback, every process ours and killed by pid."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cluster_support import corridor_hosts, running_cluster, user_kit

KIT = '''from drd.runtime.component import Component, Status


class Stamp(Component):
    """Says the time it starts at and the time of each step, and ends once a second of the world's time passed."""

    def start(self):
        self.ctx.log(f"start at {self.ctx.now():.1f}")

    def step(self, now):
        self.ctx.log(f"step at {now:.1f}")
        return Status.SUCCESS if now >= 1.0 else Status.RUNNING
'''
MANIFEST = """name: Stamp
kind: behavior
description: Says the times it sees.
entry_point: stampkit:Stamp
"""
MISSION = "mission StampIt {\n    Stamp\n}\n"


def test_each_run_in_a_new_world_sees_the_worlds_time_from_zero(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    user_kit(tmp_path, monkeypatch, "stampkit", KIT, {"Stamp": MANIFEST})
    (tmp_path / "stamp.mission").write_text(MISSION)
    seen: list[list[str]] = []
    with running_cluster(tmp_path, ["controller", "ranger1"]) as c:
        c.hosts_file.write_text(corridor_hosts(c))
        c.start_all()
        c.wait_ready()
        c.wait_up()
        for _ in range(2):  # one after the other: each opens a new world
            r = c.missionctl("run", str(tmp_path / "stamp.mission"), "--config", str(c.hosts_file), "--json",
                             "--speed", "4", timeout=120)
            assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-2000:])
            seen.append([line["text"] for line in json.loads(r.stdout)["logs"]])
    dry = c.missionctl("dry-run", str(tmp_path / "stamp.mission"), "--config", str(c.hosts_file), "--json",
                       timeout=120)
    assert dry.returncode == 0, dry.stderr[-2000:]
    predicted = [line["text"] for line in json.loads(dry.stdout)["logs"]]
    assert seen[0][0] == "start at 0.0" and seen[0][1] == "step at 0.1", seen[0]
    assert seen[1] == seen[0] == predicted, (seen, predicted)
