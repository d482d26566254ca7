"""An emit its manifest refuses says the component's own line on a cluster as in a dry-run (users audit 21, #3): a
worker's events are replayed on the controller and checked there, far from the component's code, and the reason
named drd's `emits.py` instead. Real daemons on loopback (controller, ranger1) and a user's own component."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from cluster_support import MISSIONCTL, ROOT, corridor_hosts, running_cluster, user_kit

KIT = '''from drd.runtime.component import Component, Status


class Liar(Component):
    """Counts boxes, and says so with the wrong type."""

    def step(self, now):
        self.ctx.emit("Tally", boxes=True)
        return Status.SUCCESS
'''
MANIFEST = """name: Liar
kind: behavior
description: Emits a Tally whose boxes is not an int.
entry_point: liarkit:Liar
events:
  Tally:
    fields: {boxes: int}
    description: how many boxes it counted.
"""
MISSION = "mission Counting {\n    Liar\n}\n"
SAYS = "Liar emits Tally with boxes=True (bool) where its manifest declares boxes: int (at "
LINE = "liarkit.py:8, in step)"


def test_a_refused_emit_names_the_components_line_on_a_cluster_as_in_a_dry_run(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    user_kit(tmp_path, monkeypatch, "liarkit", KIT, {"Liar": MANIFEST})
    (tmp_path / "count.mission").write_text(MISSION)
    dry = subprocess.run([*MISSIONCTL, "dry-run", str(tmp_path / "count.mission"), "--json"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120, check=False)
    predicted = json.loads(dry.stdout)
    assert SAYS in predicted["reason"] and predicted["reason"].endswith(LINE), predicted["reason"]
    with running_cluster(tmp_path, ["controller", "ranger1"]) as c:
        c.hosts_file.write_text(corridor_hosts(c))
        c.start_all()
        c.wait_ready()
        c.wait_up()
        r = c.missionctl("run", str(tmp_path / "count.mission"), "--config", str(c.hosts_file), "--json",
                         timeout=120)
    assert r.returncode == 1, (r.stdout[-2000:], r.stderr[-2000:])
    reason = json.loads(r.stdout)["reason"]
    assert SAYS in reason and reason.endswith(LINE) and "emits.py" not in reason, reason
