"""`missionctl world generate` at fleet size (scale audit D5): each step said on stderr while it runs (never
under --json), and files written by libyaml's emitter that are the pure-Python SafeDumper's text, byte for byte."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import yaml

from drd.sim.building import Building, hosts, world
from tests.conftest import ROOT


def missionctl(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["missionctl", *args], cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)


def body(path: Path) -> str:
    """The file without its one comment line."""
    return path.read_text(encoding="utf-8").split("\n", 1)[1]


def pure(data: object) -> str:
    return yaml.dump(data, Dumper=yaml.SafeDumper, sort_keys=False, default_flow_style=None, width=120,
                     allow_unicode=True)


def test_a_large_building_says_its_steps_and_writes_what_the_pure_dumper_writes(tmp_path: Path) -> None:
    b = Building(21, 99)  # 2,100 robots: past the threshold of progress
    r = missionctl("world", "generate", "--wings", "21", "--scouts", "99", "--out", str(tmp_path / "a"))
    assert r.returncode == 0, r.stderr
    steps = [line.strip() for line in r.stderr.splitlines() if line.strip().startswith(b.name)]
    assert [s.split(": ", 1)[1].split(" ")[0] for s in steps] == ["checking", "checking", "writing", "writing"]
    assert "2100 doors" in steps[0] and "2100 robots" in steps[1]
    assert body(tmp_path / "a" / "worlds" / f"{b.name}.yaml") == pure(world(b))
    assert body(tmp_path / "a" / "hosts.yaml") == pure(hosts(b))

    r = missionctl("world", "generate", "--wings", "21", "--scouts", "99", "--out", str(tmp_path / "j"), "--json")
    assert r.returncode == 0 and r.stderr == ""
    assert json.loads(r.stdout)["robots"] == 2100


def test_a_small_building_says_only_what_it_wrote(tmp_path: Path) -> None:
    r = missionctl("world", "generate", "--wings", "2", "--scouts", "3", "--out", str(tmp_path))
    assert r.returncode == 0 and "building_2x3:" not in r.stderr and "wrote" in r.stderr


def test_a_building_too_large_for_the_loaders_is_refused_and_nothing_is_written(tmp_path: Path) -> None:
    """Scale audit 11, D1: 420 wings of 19 Scouts (in the documented range) wrote a 4.2 MiB hosts file, which
    `dry-run` and `plan` then refused (files are read up to 4 MiB); the generator said "run it"."""
    r = missionctl("world", "generate", "--wings", "420", "--out", str(tmp_path / "big"))
    assert r.returncode == 2, r.stderr[-2000:]
    assert "hosts.yaml would be 4.2 MiB, more than the 4 MiB every command reads" in r.stderr
    assert "at most about 403 wings of 19 Scouts" in r.stderr and "run it" not in r.stderr
    assert not (tmp_path / "big").exists()
