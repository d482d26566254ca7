"""The corridor mission on `hosts.ros2.yaml`: every device on `driver: ros2`, the dry-run serving the simulated world
as ROS 2 robots in its own process (drd.sim.ros2.LockstepSimulation), every command and reading an rmw_zenoh
message; it succeeds as the `sim` run does. Slow for a unit test (about 10 s each), bounded by the mission's end."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from drd.dryrun import Mission, run_many
from drd.hosts import load_hosts
from drd.sim import load_world
from drd.sim.ros2 import LockstepSimulation
from dsl import compile_text
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "missions" / "corridor_surveillance.mission"


def _chart(catalog: Catalog) -> Any:
    compiled = compile_text(MISSION.read_text(encoding="utf-8"), catalog, str(MISSION))
    assert compiled.ok and compiled.statechart is not None
    return compiled.statechart


def test_the_corridor_mission_succeeds_through_rmw_zenoh(catalog: Catalog) -> None:
    world = load_world(ROOT / "worlds" / "corridor.yaml")
    seen: list[LockstepSimulation] = []
    counts: dict[str, Counter[str]] = {}

    def progress(sim: Any, _executive: Any) -> None:
        if not seen:
            seen.append(sim)
        assert sim.link is not None and sim.served is not None
        counts.update(sent=Counter(sim.link.sent), received=Counter(sim.link.received),
                      commands=Counter(sim.served.received))

    ros2 = run_many([Mission(_chart(catalog))], load_hosts(ROOT / "hosts.ros2.yaml", catalog), world, catalog,
                    progress=progress, until=600.0)[0]
    assert isinstance(seen[0], LockstepSimulation) and seen[0].served is None  # served, then closed after the run
    assert ros2.outcome == "success", ros2.reason
    sim = run_many([Mission(_chart(catalog))], load_hosts(ROOT / "hosts.yaml", catalog), world, catalog)[0]
    assert sim.outcome == "success"
    assert [s["scout"] for s in ros2.scouts] == [s["scout"] for s in sim.scouts]  # six Scouts, in the same order
    assert len(ros2.doors) == len(sim.doors) and abs(ros2.sim_time - sim.sim_time) < 5.0
    sent, received, commands = counts["sent"], counts["received"], counts["commands"]

    def total(counter: Counter[str], topic: str) -> int:
        return sum(n for key, n in counter.items() if f"/{topic}/" in f"/{key}/")

    assert total(sent, "ranger1/cmd_vel") > 100 and total(sent, "scout1/cmd_vel") > 10  # commands went out...
    assert total(commands, "ranger1/cmd_vel") == total(sent, "ranger1/cmd_vel")  # ...and every one arrived
    assert total(sent, "ranger1/launcher/launch") == 6  # one launch request per Scout
    assert total(received, "ranger1/scan") > 1000 and total(received, "scout1/camera/image_raw") > 1000


def test_missionctl_dry_run_on_hosts_ros2_yaml(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-c", "from drd.cli.missionctl import main; main()", "dry-run",
                           str(MISSION), "--config", str(ROOT / "hosts.ros2.yaml"), "--json"],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout)
    report = report[0] if isinstance(report, list) else report
    assert report["outcome"] == "success" and len(report["scouts"]) == 6


def test_a_real_robots_frames_in_the_hosts_file_are_the_dry_runs_too(catalog: Catalog, tmp_path: Path) -> None:
    """ROS 2 audit 17, D3: a real robot's hosts file naming its frames (as docs/ros2.md advises) could not be
    dry-run: the served simulator stamped `ranger1/odom`..., the drivers dropped every message, and the error asked
    whether the real robot's router was up. The served robots now publish in the frames the hosts file names."""
    import yaml

    data = yaml.safe_load((ROOT / "hosts.ros2.yaml").read_text(encoding="utf-8"))
    devices = data["hosts"]["ranger1"]["devices"]
    frames = {"drive": {"odom_frame": "k7_odom", "base_frame": "k7_base"}, "ranges": {"scan_frame": "k7_lidar"},
              "camera": {"camera_frame": "k7_cam"}}
    for name, given in frames.items():
        devices[name].setdefault("driver_options", {}).update(given)
    hosts = tmp_path / "hosts.yaml"
    hosts.write_text(yaml.safe_dump(data), encoding="utf-8")
    text = "mission Forward {\n    needs ranger: Ranger\n    FollowCorridor(speed: 0.4)\n" \
           "    FollowCorridor -> done after 5s\n}\n"
    compiled = compile_text(text, catalog, "forward.mission")
    assert compiled.ok and compiled.statechart is not None
    [report] = run_many([Mission(compiled.statechart)], load_hosts(hosts, catalog),
                        load_world(ROOT / "worlds" / "corridor.yaml"), catalog, until=20.0)
    assert report.outcome == "success", report.reason
    assert report.tracks["ranger1"][-1][1] > 1.5  # it drove on the scans and odometry it read in those frames
