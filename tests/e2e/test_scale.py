"""Issue #15, 1,000 robots: the generated building (`missionctl world generate`) and the corridor mission on it,
unchanged, the wings in parallel; the pieces that were made to scale keep their answers."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from drd.hosts import load_hosts, parse_hosts
from drd.sim.building import Building, BuildingError, hosts, world
from drd.sim.world import check_hosts, load_world, parse_world
from dsl.catalog import Catalog
from tests.conftest import ROOT


def missionctl(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["missionctl", *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False)


def test_five_wings_generated_then_dry_run_each_ranger_launches_a_scout(tmp_path: Path, catalog: Catalog) -> None:
    out = tmp_path / "building"
    r = missionctl("world", "generate", "--wings", "5", "--scouts", "19", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    said = json.loads(r.stdout)
    assert (said["robots"], said["rangers"], said["scouts"]) == (100, 5, 95)
    cluster = load_hosts(out / "hosts.yaml", catalog)
    sim_world = load_world(out / "worlds" / "building_5x19.yaml")
    assert check_hosts(sim_world, cluster) == []

    r = missionctl("dry-run", str(ROOT / "missions" / "corridor_surveillance.mission"), "--hosts",
                   str(out / "hosts.yaml"), "--until", "60", "--json")
    assert r.returncode == 1, r.stderr  # stopped at --until, with its report
    report = json.loads(r.stdout)
    assert report["outcome"] == "stopped"
    carrier = {robot.id: robot.carrier for robot in cluster.robots if robot.carrier}
    launched_by = {carrier[s["scout"]] for s in report["scouts"]}
    assert launched_by == {f"ranger{w}" for w in range(1, 6)}  # every wing's Ranger, in the same minute
    assert not report["degraded"] and not report["failure_chain"]
    # each Ranger took its own wing's doors only
    for door in report["doors"]:
        wing = round(-door["y"] / Building(5, 19).pitch)
        assert 0 <= wing < 5


def test_generate_refuses_bad_counts_and_keeps_existing_files(tmp_path: Path) -> None:
    r = missionctl("world", "generate", "--wings", "0", "--scouts", "100", "--out", str(tmp_path), "--json")
    assert r.returncode == 2
    assert json.loads(r.stderr)["error"] == "--wings 0: expected 1 to 500; --scouts 100: expected 1 to 99"
    assert not any(tmp_path.iterdir())
    assert missionctl("world", "generate", "--wings", "1", "--scouts", "2", "--out", str(tmp_path)).returncode == 0
    r = missionctl("world", "generate", "--wings", "1", "--scouts", "2", "--out", str(tmp_path))
    assert r.returncode == 2 and "exists" in r.stderr and "--force" in r.stderr
    assert missionctl("world", "generate", "--wings", "1", "--scouts", "2", "--out", str(tmp_path),
                      "--force").returncode == 0


@pytest.mark.parametrize(("wings", "scouts"), [(1, 1), (1, 2), (3, 19), (2, 20), (50, 19)])
def test_building_data_loads_and_matches(wings: int, scouts: int, catalog: Catalog) -> None:
    b = Building(wings, scouts)
    w = parse_world(world(b), "gen")
    c = parse_hosts(hosts(b), "gen", catalog)
    assert check_hosts(w, c) == []
    assert len(w.rangers) == wings and len(w.scout_ids) == wings * scouts
    assert sum(d.state.value == "open" for d in w.doors) == wings * scouts  # one open door per Scout
    assert {r.carrier for r in c.robots if r.type == "Scout"} == {f"ranger{i}" for i in range(1, wings + 1)}


def test_building_counts_are_checked() -> None:
    for wings, scouts in [(0, 1), (1, 0), (501, 1), (1, 100)]:
        with pytest.raises(BuildingError):
            Building(wings, scouts)


def test_the_light_index_answers_as_scanning_every_room_and_corner() -> None:
    """The index is now built room by room; each point must get the light a scan of everything gives."""
    import math

    w = parse_world(world(Building(3, 5)), "gen")
    light = w.light
    w2 = parse_world(world(Building(3, 5)), "gen2")
    object.__setattr__(w2, "_light_cells", {})  # no cell: every point looks at everything
    for i in range(-400, 400, 7):
        for j in range(-500, 150, 3):
            x, y = i / 10 + 0.013, j / 10 + 0.007
            assert math.isclose(light(x, y), w2.light(x, y)), (x, y)
