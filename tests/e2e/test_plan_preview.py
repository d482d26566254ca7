"""`missionctl plan --config hosts.yaml` previews a run's start without running it (issue #12): each need's robot
and device, each component's host, who waits behind whom, what cannot hold. Checked through the real command,
and against what a dry-run of the same mission actually granted at its start."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
CORRIDOR = ROOT / "missions" / "corridor_surveillance.mission"


def missionctl(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False)


def preview(mission: Path, hosts: Path = ROOT / "hosts.yaml") -> tuple[int, dict[str, Any]]:
    done = missionctl("plan", str(mission), "--config", str(hosts), "--json")
    assert done.stdout, done.stderr
    return done.returncode, json.loads(done.stdout)["preview"]


def test_the_preview_grants_what_the_run_grants_at_its_start(tmp_path: Path) -> None:
    rc, p = preview(CORRIDOR)
    assert rc == 0 and p["problems"] == []
    trace = tmp_path / "run.jsonl"
    done = missionctl("dry-run", str(CORRIDOR), "--until", "0.1", "--trace", str(trace), "--json")
    assert done.returncode == 1, done.stderr  # stopped at --until
    granted = {}
    for line in trace.read_text(encoding="utf-8").splitlines():
        r = json.loads(line)
        if r["kind"] == "granted" and r["at"] == 0.0:
            granted[r["path"]] = {k: v for k, v in r["resources"].items() if "." not in k}
    assert granted, "the dry-run granted nothing at its start"
    assert {h["path"]: h["resources"] for h in p["holds"]} == granted
    # every component that starts runs where its devices are, and the devices are the holder's parts
    assert p["components"] and all(c["host"] == "ranger1" and c["devices"] for c in p["components"])
    assert {c["devices"]["drive"] for c in p["components"] if "drive" in c["devices"]} == {"ranger1.drive"}
    # the other room watchers wait behind the first, which holds the Ranger and a Scout
    first = next(iter(granted))
    assert len(p["waits"]) == 5
    assert all(w["blocked_by"][0] == {"path": first, "holds": granted[first]} for w in p["waits"])


def test_a_need_nothing_grants_cannot_hold_and_a_constraint_is_no_problem(tmp_path: Path) -> None:
    mission = tmp_path / "bad.mission"
    mission.write_text('mission Bad {\n    needs ranger: Ranger\n'
                       '    constraint fence: distance(ranger, point(1, 0)) <= 6\n'
                       '    needs cam: Camera where cam.id == "nosuch.camera"\n'
                       '    Observe(duration: 2s)\n}\n', encoding="utf-8")
    rc, p = preview(mission)
    assert rc == 1
    assert any("need cam can never be satisfied" in x for x in p["problems"]), p["problems"]
    assert not any("fence" in x for x in p["problems"]), "a cluster guards constraints as a dry-run does"
    text = missionctl("plan", str(mission), "--config", str(ROOT / "hosts.yaml"))
    assert text.returncode == 1 and "cannot hold: " in text.stdout and "nothing runs" in text.stdout


def test_movable_components_are_placed_by_the_policy_on_worker_hosts(tmp_path: Path) -> None:
    hosts = (ROOT / "hosts.yaml").read_text(encoding="utf-8").replace(
        "  ranger1:\n", "  pc1:\n    endpoint: tcp/127.0.0.1:7449\n    roles: [worker]\n\n  ranger1:\n", 1)
    (tmp_path / "hosts.yaml").write_text(hosts, encoding="utf-8")
    mission = tmp_path / "two.mission"
    mission.write_text("mission Two {\n    parallel all {\n        Wait(duration: 1s) as a\n"
                       "        Wait(duration: 1s) as b\n    }\n}\n", encoding="utf-8")
    rc, p = preview(mission, tmp_path / "hosts.yaml")
    assert rc == 0, p
    hosts_of = {c["path"]: c["host"] for c in p["components"]}
    # idle hosts tie on load; the second instance goes where there is none yet; never the controller
    assert hosts_of == {"Two/a": "pc1", "Two/b": "ranger1"}
    assert all(c["why"].startswith("placement: ") for c in p["components"])


def test_a_missing_hosts_file_says_where_it_looked(tmp_path: Path) -> None:
    done = missionctl("plan", str(CORRIDOR), "--config", str(tmp_path / "nope.yaml"))
    assert done.returncode == 2 and "nope.yaml" in done.stderr and "Traceback" not in done.stderr


def test_a_need_bound_through_two_behaviors_is_resolved_as_the_run_binds_it(tmp_path: Path) -> None:
    """The preview binds a leaf's needs with the runtime's own resolver (issue #14: one need-binding resolver): a
    Ranger re-declared by two nested behaviors reaches FollowCorridor's drive and ranges (one hop of the chain
    used to lose the component from the preview altogether)."""
    mission = tmp_path / "nested.mission"
    mission.write_text("mission Nested {\n    needs ranger: Ranger\n    Outer\n}\n\n"
                       "behavior Outer {\n    needs ranger: Ranger\n    Inner\n}\n\n"
                       "behavior Inner {\n    needs ranger: Ranger\n    FollowCorridor(speed: 0.3)\n}\n",
                       encoding="utf-8")
    rc, p = preview(mission)
    assert rc == 0 and p["problems"] == []
    assert p["components"] == [{"path": "Nested/Outer/Inner/FollowCorridor", "component": "FollowCorridor",
                                "devices": {"drive": "ranger1.drive", "ranges": "ranger1.ranges"},
                                "host": "ranger1", "why": "its devices are there"}]
