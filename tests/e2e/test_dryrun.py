"""The embedded dry-run: real executive, manager, drivers and simulator in one process."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

from drd.dryrun import run
from drd.hosts import load_hosts
from drd.sim.world import load_world
from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import ROOT, shared_examples
from tests.runtime_support import Timed


def test_shared_camera_dry_run_shows_fig8_in_report_and_trace(catalog: Catalog) -> None:
    chart = compile_file(shared_examples() / "shared_camera.mission", catalog).statechart
    assert chart is not None
    trace = io.StringIO()
    report = run(chart, load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" / "corridor.yaml"),
                 catalog, registry={"Observe": Timed}, trace=trace)
    assert report.outcome == "success", report.reason
    holders = [h["path"].rsplit("/", 1)[-1] for h in report.holds()]
    assert holders[:4] == ["first", "second", "first", "second"] and holders[-1] == "third"
    assert all(h["resources"] == {"cam": "ranger1.camera"} for h in report.holds())
    lines = [json.loads(x) for x in trace.getvalue().splitlines()]
    assert [x["path"] for x in lines if x["kind"] == "granted"][:2] == ["SharedCamera/first", "SharedCamera/second"]
    assert report.sim_time > 36 and report.real_time_factor > 1
    assert json.loads(json.dumps(report.to_dict()))["outcome"] == "success"


def test_same_seed_same_run(catalog: Catalog) -> None:
    chart = compile_file(shared_examples() / "shared_camera.mission", catalog).statechart
    assert chart is not None
    cluster, world = load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" / "corridor.yaml")
    runs = [run(chart, cluster, world, catalog, registry={"Observe": Timed}, seed=7) for _ in range(2)]
    assert [r.to_dict()["timeline"] for r in runs][0] == runs[1].to_dict()["timeline"]


def test_corridor_dry_run_from_the_command_line() -> None:
    """The main job: every open door found (never a closed one), a Scout launched through each."""
    import subprocess

    r = subprocess.run(["missionctl", "dry-run", str(ROOT / "missions" / "corridor_surveillance.mission"),
                        "--json", "--until", "900"], cwd=ROOT, capture_output=True, text=True, timeout=300,
                       check=False)
    report = json.loads(r.stdout)
    assert r.returncode == (0 if report["outcome"] == "success" else 1)
    world = load_world(ROOT / "worlds" / "corridor.yaml")
    open_doors = sorted(((d.a[0] + d.b[0]) / 2, (d.a[1] + d.b[1]) / 2) for d in world.doors if d.state.value == "open")
    found = sorted((round(d["x"]), round(d["y"])) for d in report["doors"])
    assert found == [(round(x), round(y)) for x, y in open_doors]
    assert sorted(s["scout"] for s in report["scouts"]) == [f"scout{i}" for i in range(1, 7)]
    assert_every_open_room_watched(report, world)


def assert_every_open_room_watched(report: dict[str, Any], world: Any) -> None:
    """Every instance succeeded, one Scout ended in each room behind an open door, and intruders were seen."""
    instances = [t for t in report["timeline"] if t["path"].count("/") == 1 and t["path"].endswith("]")]
    assert len(instances) == 6 and all(t["status"] == "success" for t in instances), instances
    open_rooms = sorted(d.room for d in world.doors if d.state.value == "open")
    rooms = sorted(next(r.id for r in world.rooms if r.contains(s["x"], s["y"])) for s in report["scouts"])
    assert rooms == open_rooms
    assert report["detections"]  # intruder1 walks through n3 and n4, which get Scouts


def dry_run_cli(mission: Path, *args: str) -> dict[str, Any]:
    import subprocess

    r = subprocess.run(["missionctl", "dry-run", str(mission), "--json", *args], cwd=ROOT, capture_output=True,
                       text=True, timeout=300, check=False)
    report: dict[str, Any] = json.loads(r.stdout)
    assert r.returncode == (0 if report["outcome"] == "success" else 1), r.stderr
    return report


def test_two_rangers_watch_every_open_room_sooner_than_one() -> None:
    """The example's promise: with more Rangers the instances proceed in parallel, with no change to the file."""
    mission = ROOT / "missions" / "corridor_surveillance.mission"
    one = dry_run_cli(mission)
    two = dry_run_cli(mission, "--world", "two_rangers", "--hosts", "hosts.two_rangers.yaml")
    assert one["outcome"] == two["outcome"] == "success"
    assert_every_open_room_watched(two, load_world(ROOT / "worlds" / "two_rangers.yaml"))
    assert two["sim_time"] < one["sim_time"] - 20
    assert {h["resources"]["ranger"] for h in two["holds"] if "ranger" in h["resources"]} == {"ranger1", "ranger2"}


def test_sweep_example_maps_sweeps_and_comes_home() -> None:
    """Calibrate and MapCorridor in any order, then SweepCorridor (back along the corridor), then ReturnToStart."""
    report = dry_run_cli(shared_examples() / "sweep.mission")
    assert report["outcome"] == "success", report["reason"]
    ended = {t["path"]: t for t in report["timeline"]}
    assert ended["Sweep/MapCorridor"]["status"] == ended["Sweep/Calibrate"]["status"] == "success"
    assert ended["Sweep/SweepCorridor"]["entered"] >= max(ended["Sweep/MapCorridor"]["exited"],
                                                         ended["Sweep/Calibrate"]["exited"])
    assert ended["Sweep/ReturnToStart"]["status"] == "success"  # home, not the `after 5min` escape


def test_shared_camera_from_the_command_line_alternates_with_the_real_observe() -> None:
    """Fig. 8 end to end: the standard Observe counts camera time only, so each 12 s observation takes three
    slices; the report's holds alternate first/second, then third gets the camera after both are done."""
    import subprocess

    r = subprocess.run(["missionctl", "dry-run", str(shared_examples() / "shared_camera.mission"), "--json"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 0, r.stderr
    report = json.loads(r.stdout)
    holds = [(h["path"].rsplit("/", 1)[-1], h["ended"]) for h in report["holds"]]
    assert holds == [("first", "revoked"), ("second", "revoked"), ("first", "revoked"), ("second", "revoked"),
                     ("first", "exited"), ("second", "exited"), ("third", "exited")]
    done = {h["path"].rsplit("/", 1)[-1]: h["to"] for h in report["holds"] if h["ended"] == "exited"}
    third_from = next(h["from"] for h in report["holds"] if h["path"].endswith("third"))
    assert third_from >= max(done["first"], done["second"]) and 35.0 < report["sim_time"] < 38.0
    waits = {w["path"].rsplit("/", 1)[-1]: w for w in report["waits"]}
    assert waits["third"]["from"] == 0.0 and waits["third"]["to"] == third_from


def test_live_progress_shows_time_active_behaviors_holds_and_waiters(catalog: Catalog) -> None:
    from drd.cli.report import progress_view

    chart = compile_file(ROOT / "missions" / "corridor_surveillance.mission", catalog).statechart
    assert chart is not None
    lines: list[str] = []
    run(chart, load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" / "corridor.yaml"), catalog,
        until=12, progress=lambda sim, ex: lines.append(progress_view(sim, ex).plain), progress_every=10)
    first, later = lines[0], lines[1]
    assert first.startswith("sim     0.1 s") and "FollowCorridor" in first and "DetectDoor" in first
    assert "holds 1" in first and "waiting 5" in first  # the counts; examples only while the line has room
    assert "FollowCorridor" in later


def test_a_run_that_cannot_keep_the_pace_asked_says_so() -> None:
    """No machine runs a million times real time: the report says the pace was not kept, and by whom."""
    import subprocess

    mission = str(ROOT / "missions" / "corridor_surveillance.mission")
    lines = {}
    for speed in ("1000000", None):
        args = ["--speed", speed] if speed else []
        r = subprocess.run(["missionctl", "dry-run", mission, "--until", "3", *args], cwd=ROOT, capture_output=True,
                           text=True, timeout=300, check=False)
        lines[speed] = next(line for line in r.stdout.splitlines() if line.startswith("sim time"))
    assert lines["1000000"].endswith("x real time (1e+06x asked: the machine could not keep up)"), lines
    assert lines[None].endswith("x real time"), lines
    report = dry_run_cli(ROOT / "missions" / "corridor_surveillance.mission", "--until", "3", "--speed", "1000000")
    assert report["speed"] == 1_000_000
