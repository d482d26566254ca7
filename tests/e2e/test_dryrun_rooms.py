"""A dry-run refuses a mission naming a room its world lacks, before anything runs (users audit 9, D6; the check
itself is tests/unit/test_unknown_rooms.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.unit.test_unknown_rooms import MISSION

ROOT = Path(__file__).resolve().parents[2]


def test_a_dry_run_refuses_it_before_anything_runs(tmp_path: Path) -> None:
    (tmp_path / "corral.mission").write_text(MISSION.replace('"hallway_nope"', '"n7"'))
    done = subprocess.run([sys.executable, "-c", "from drd.cli.missionctl import main; main()", "dry-run",
                           "corral.mission", "--config", str(ROOT / "hosts.yaml")], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2 and done.stdout == "", done.stderr
    assert "corral.mission:3:39: error: no room named n7 in world corridor" in done.stderr
    assert "did you mean n1?" in done.stderr and "^^^^" in done.stderr
