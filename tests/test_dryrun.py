"""The embedded dry-run: real executive, manager, drivers and simulator in one process."""

from __future__ import annotations

import io
import json

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
