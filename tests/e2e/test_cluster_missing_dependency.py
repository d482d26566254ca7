"""A component whose module needs a library only some hosts have (a vendor SDK on the robot's computer): the other
hosts start anyway, say once that they will not run it, and do not offer it, so placement puts it where the
library is. A mistake in the manifest itself (tests/e2e/test_drd_start_fast_path.py) is still refused at start.

`Sweep` is `Wait` behind a module that imports `sweep_vendor_sdk`, which only `zulu`'s environment has. With
placement by instances alone ties go to the smaller name, so `alpha` would be tried first if it offered Sweep.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from cluster_support import instances_only_hosts, running_cluster

from tests.conftest import ROOT

NAMES = ["controller", "alpha", "zulu"]
SWEEP = """name: Sweep
kind: behavior
description: Wait behind a vendor library.
entry_point: sweep_mod:Sweep
process: container
params:
  duration:
    type: duration
    default: 1s
    min: 0s
    max: 1h
    description: How long to sweep.
"""
MISSION = "mission Sweeping {\n    Sweep(duration: 1s)\n}\n"
WARNING = ("alpha will not run Sweep: its module sweep_mod needs sweep_vendor_sdk, which is not installed here "
           "({manifest})")


def test_a_host_without_a_components_library_starts_and_the_component_runs_where_the_library_is(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "comp" / "Sweep").mkdir(parents=True)
    manifest = tmp_path / "comp" / "Sweep" / "manifest.yaml"
    manifest.write_text(SWEEP)
    (tmp_path / "code").mkdir()
    (tmp_path / "code" / "sweep_mod.py").write_text(
        "import sweep_vendor_sdk  # noqa: F401\n\nfrom components.behaviors.wait import Wait as Sweep  # noqa: F401\n")
    (tmp_path / "vendor").mkdir()
    (tmp_path / "vendor" / "sweep_vendor_sdk.py").write_text("VERSION = 1\n")
    mission = tmp_path / "sweeping.mission"
    mission.write_text(MISSION)
    without = os.pathsep.join([str(tmp_path / "code"), str(ROOT)])
    env = {**os.environ, "DRD_COMPONENTS": str(tmp_path / "comp")}
    with running_cluster(tmp_path, NAMES) as c:
        c.hosts_file.write_text(instances_only_hosts(c))
        for name in NAMES:
            library = [str(tmp_path / "vendor")] if name == "zulu" else []
            c.start(name, env={**env, "PYTHONPATH": os.pathsep.join([*library, without])})
        c.wait_ready()
        c.wait_up()
        assert WARNING.format(manifest=manifest) in c.log("alpha"), c.log("alpha")[-2000:]
        assert "will not run" not in c.log("zulu"), c.log("zulu")[-2000:]
        r = c.missionctl("components", "--config", str(c.hosts_file), "--json", timeout=30)
        assert r.returncode == 0, r.stderr[-2000:]
        offered = json.loads(r.stdout)["types"]
        assert "zulu" in offered["Sweep"] and "alpha" not in offered["Sweep"], offered["Sweep"]
        assert "alpha" in offered["Wait"], offered["Wait"]  # what alpha can import, it offers
        monkeypatch.setenv("DRD_COMPONENTS", str(tmp_path / "comp"))  # missionctl checks the mission locally
        run = c.missionctl("run", str(mission), "--config", str(c.hosts_file), "--json", timeout=90)
        assert run.returncode == 0, (run.stdout[-2000:], run.stderr[-2000:], c.tails("controller", "alpha"))
        assert json.loads(run.stdout)["outcome"] == "success"
        status = c.missionctl("status", "--config", str(c.hosts_file), "--json", timeout=30)
        [placed] = json.loads(status.stdout)["missions"][0]["placements"]
        assert (placed["instance"], placed["host"]) == ("Sweeping/Sweep", "zulu"), placed
        assert placed["decision"]["filtered"]["alpha"] == [
            "does not offer Sweep (its daemon has no manifest of it, or cannot import its module)"], placed
