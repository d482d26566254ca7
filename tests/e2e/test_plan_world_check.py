"""`missionctl plan --config` says that the world and the hosts file disagree as `dry-run` says it (reverify audit 7,
D-b): it built the missing robot's drivers first and reported their failure (`device ... could not be built ...
no robot 'bb8' in world depot`), where the dry-run names the world file, its key and what to write there."""

from __future__ import annotations

import subprocess
import sys

from tests.conftest import ROOT

MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
SAID = "rangers: no Ranger 'ranger2', which hosts.two_rangers.yaml configures"


def test_plan_and_dry_run_name_a_robot_the_world_lacks_alike() -> None:
    said = []
    for command in ("plan", "dry-run"):
        r = subprocess.run([*MISSIONCTL, command, "missions/corridor_surveillance.mission", "--config",
                            "hosts.two_rangers.yaml", "--world", "corridor"], cwd=ROOT, capture_output=True,
                           text=True, timeout=120, check=False)
        assert r.returncode == 2 and SAID in r.stderr, (command, r.stdout[-1500:], r.stderr[-1500:])
        assert "could not be built" not in r.stderr, r.stderr
        said.append(sorted(line for line in r.stderr.splitlines() if line.startswith("error:")))
    assert said[0] == said[1]
