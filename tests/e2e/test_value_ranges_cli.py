"""Values checked where they are written (issue #18), through the real commands: a parameter outside its manifest's
range and a hosts.yaml number outside its declared range each exit 2 with the located message, no traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.conftest import ROOT

MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
FAST = "mission Fast {\n    needs ranger: Ranger\n    FollowCorridor(speed: 50)\n}\n"


def missionctl(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], cwd=cwd, capture_output=True, text=True, timeout=120, check=False)


def test_validate_refuses_a_constant_argument_outside_its_range_with_its_location(tmp_path: Path) -> None:
    mission = tmp_path / "fast.mission"
    mission.write_text(FAST, encoding="utf-8")
    for command in ("validate", "dry-run"):
        r = missionctl(command, str(mission))
        out = r.stdout + r.stderr
        assert r.returncode == 2, out
        assert (f"{mission.as_posix()}:3:27: error: speed 50 is out of range: 0..2 m/s (FollowCorridor's manifest, "
                "components/FollowCorridor/manifest.yaml)") in out
        assert "hint: give speed a value within 0..2 m/s" in out and "Traceback" not in out


def test_dry_run_refuses_hosts_values_outside_their_ranges_with_file_line_and_key(tmp_path: Path) -> None:
    text = (ROOT / "hosts.yaml").read_text(encoding="utf-8")
    for old, new in (("lease: 3s", "lease: 0s"), ("capacity: 10", "capacity: 0"), ("cores: 2", "cores: .nan"),
                     ("battery: 1.0, magazine: 6", "battery: 3, magazine: 6"), ("slice: 60s", "slice: -1s")):
        text = text.replace(old, new, 1)
    (tmp_path / "hosts.yaml").write_text(text, encoding="utf-8")
    r = missionctl("dry-run", str(ROOT / "missions" / "corridor_surveillance.mission"), "--hosts", "hosts.yaml",
                   cwd=tmp_path)
    out = r.stdout + r.stderr
    assert r.returncode == 2, out
    for line in ("hosts.yaml:7: cluster.lease: 0s is out of range: 100ms..10min",
                 "hosts.yaml:15: hosts.controller.cores: expected an integer (1..4096 cores), got float nan",
                 "hosts.yaml:31: hosts.ranger1.devices.radio.capacity: 0 is out of range: 1..1000000",
                 "hosts.yaml:26: hosts.ranger1.devices.drive.slice: expected a duration such as 3s or 500ms",
                 "hosts.yaml:55: hosts.ranger1.robots.ranger1.properties.battery: 3 is out of range: 0..1"):
        assert line in out, out
    assert "Traceback" not in out and "sim time" not in out  # nothing ran


def test_an_evaluated_argument_outside_its_range_fails_the_run_saying_why(tmp_path: Path) -> None:
    """`--param` keeps working; the value it gives reaches the range check when the state is entered."""
    mission = tmp_path / "tuned.mission"
    mission.write_text("mission Tuned {\n    var s: float = 0.1\n    needs ranger: Ranger\n"
                       "    FollowCorridor(speed: s * 10)\n}\n", encoding="utf-8")
    r = missionctl("dry-run", str(mission), "--param", "s=5", "--until", "5")
    out = r.stdout + r.stderr
    assert r.returncode == 1, out
    assert "FollowCorridor: speed 50 is out of range: 0..2 m/s (FollowCorridor's manifest)" in out
    assert "Traceback" not in out
