"""Placement past hosts that refuse a movable component (fleet audit defect 2), on real daemons on loopback.

`Nap` is `Wait`'s manifest renamed. The controller and `z` have it; `a1` and `a2` have a `Nap` whose parameter is
named `length` (they announce Nap, and their Creators refuse a start with `duration`); `b` has no Nap at all. With
placement by instances alone every worker scores 0 and ties go to the smaller name, so a1, a2 and b all come
before z: three tries used to end on them and fail the state. Now b is filtered (it does not offer Nap), a1 and
a2 refuse with their Creators' words, kept in the decision, and the instance lands on z.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cluster_support import DaemonCluster, eventually, instances_only_hosts, running_cluster

NAMES = ["controller", "a1", "a2", "b", "z"]
NAP = """name: Nap
kind: behavior
description: Wait renamed, for the placement tests.
entry_point: components.behaviors.wait:Wait
process: container
params:
  duration:
    type: duration
    default: 10s
    min: 0s
    max: 24h
    description: How long to wait.
movable: true
outputs:
  waited:
    fields: {seconds: float, pid: int, steps: int}
    description: The mission time waited so far.
"""
MISSION = "mission OneNap {\n    Nap(duration: 60s)\n}\n"


def folder(root: Path, name: str, manifest: str) -> Path:
    (root / name / "Nap").mkdir(parents=True)
    (root / name / "Nap" / "manifest.yaml").write_text(manifest)
    return root / name


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    root = tmp_path_factory.mktemp("refusing_hosts")
    good = folder(root, "good", NAP)
    odd = folder(root, "odd", NAP.replace("  duration:\n", "  length:\n"))
    extra = {"controller": good, "z": good, "a1": odd, "a2": odd}
    with running_cluster(root, NAMES) as c:
        c.hosts_file.write_text(instances_only_hosts(c))
        for name in NAMES:
            c.start(name, extra=["-C", str(extra[name])] if name in extra else [])
        c.wait_ready()
        c.wait_up()
        yield c


def placement_of(c: DaemonCluster, mid: str) -> dict[str, Any] | None:
    r = c.missionctl("status", "--config", str(c.hosts_file), "--json", timeout=30)
    assert r.returncode == 0, r.stderr[-2000:]
    mission = next((m for m in json.loads(r.stdout)["missions"] if m["id"] == mid), None)
    placed = mission["placements"] if mission else []
    return placed[-1] if placed else None


def test_the_instance_lands_on_the_capable_host_past_refusing_ones_and_the_refusals_are_explained(
        cluster: DaemonCluster, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    mission = tmp_path / "onenap.mission"
    mission.write_text(MISSION)
    monkeypatch.setenv("DRD_COMPONENTS", str(cluster.folder / "good"))  # missionctl checks the mission locally
    r = cluster.missionctl("run", str(mission), "--config", str(cluster.hosts_file), "--detach", timeout=60)
    assert r.returncode == 0, (r.stdout, r.stderr, cluster.tails("controller"))
    mid = r.stdout.strip()
    try:
        eventually(lambda: placement_of(cluster, mid) is not None, "the Nap to be placed", 30)
        entry = placement_of(cluster, mid)
        assert entry is not None and (entry["instance"], entry["host"]) == ("OneNap/Nap", "z"), \
            (entry, cluster.tails("controller"))
        filtered = entry["decision"]["filtered"]
        refusal = "Nap has no parameter 'duration' (declared: length)"
        assert set(filtered) == {"controller", "a1", "a2", "b"}, filtered
        assert filtered["b"] == ["does not offer Nap (its daemon has no manifest of it, or cannot import its module)"]
        assert filtered["controller"] == ["no worker role"]
        for host in ("a1", "a2"):
            [why] = filtered[host]
            assert why.startswith("excluded (its start there failed: ") and refusal in why, why
        log = cluster.log("controller")
        assert "placement: a1 refused Nap: " in log and "placement: a2 refused Nap: " in log, log[-3000:]
        assert "placement: Nap on b" not in log, "b, which does not offer Nap, is never tried"
    finally:
        cluster.missionctl("stop", mid, "--config", str(cluster.hosts_file), timeout=60)
