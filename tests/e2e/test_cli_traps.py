"""CLI traps a newcomer met (issue #12), each through the real command or its rendering: dry-run from any
directory, one name per concept (`--config`/`--hosts`, `--json` with JSON errors, `--version`), what
`drd components` shows, `run`'s progress and `status` at 80 columns, `stop` without an id, Ctrl-C on a
dry-run. No timing assertions: the waits below are bounded, never measured."""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import typer
from rich.console import Console  # noqa: TID251 - rendering what the commands print, at a chosen width

from drd.cli import cluster, common

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
DRD = [sys.executable, "-m", "drd.cli.drd"]
CORRIDOR = ROOT / "missions" / "corridor_surveillance.mission"
SHORT = "mission Short {\n    Wait(duration: 1s)\n}\n"


def missionctl(*args: str, cwd: Path = ROOT, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          check=False)


def drd(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*DRD, *args], cwd=cwd, capture_output=True, text=True, timeout=60, check=False)


def json_error(stderr: str) -> dict[str, Any]:
    """The one JSON error a command wrote on stderr under --json (every stderr line is JSON then)."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert lines, "no error written"
    errors = [json.loads(line) for line in lines]
    assert all(isinstance(e, dict) for e in errors), stderr
    last: dict[str, Any] = errors[-1]
    return last


# --- 1. dry-run from any directory --------------------------------------------------------------------


def test_the_readme_first_command_still_runs_the_corridor_from_the_repository_root() -> None:
    r = missionctl("dry-run", "missions/corridor_surveillance.mission")
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.startswith("mission CorridorSurveillance  success")
    assert "Traceback" not in r.stderr


def test_dry_run_from_another_directory_with_absolute_paths(tmp_path: Path) -> None:
    mission = tmp_path / "short.mission"
    mission.write_text(SHORT)
    r = missionctl("dry-run", str(mission), "--config", str(ROOT / "hosts.yaml"), "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["outcome"] == "success"
    # the alias, and a world named by the hosts file found beside it (two_rangers), not in the cwd
    r = missionctl("dry-run", str(mission), "--hosts", str(ROOT / "hosts.two_rangers.yaml"), "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    # --world by name from anywhere: beside the hosts file, else drd's own worlds
    r = missionctl("dry-run", str(mission), "-c", str(ROOT / "hosts.yaml"), "--world", "corridor", cwd=tmp_path)
    assert r.returncode == 0, r.stderr


def test_dry_run_with_the_defaults_elsewhere_says_where_it_looked(tmp_path: Path) -> None:
    mission = tmp_path / "short.mission"
    mission.write_text(SHORT)
    r = missionctl("dry-run", str(mission), cwd=tmp_path)
    assert r.returncode == 2, r.stdout + r.stderr
    assert f"hosts.yaml: no such file (looked at {tmp_path / 'hosts.yaml'})" in r.stderr
    assert str(ROOT / "hosts.yaml") in r.stderr, "the hint names drd's own hosts file"
    assert "Traceback" not in r.stderr
    # a hosts file copied here names the world `corridor`: no worlds/ here, so drd's own is used
    shutil.copy(ROOT / "hosts.yaml", tmp_path / "hosts.yaml")
    r = missionctl("dry-run", "short.mission", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("mission Short  success")


def test_a_missing_world_lists_every_path_tried(tmp_path: Path) -> None:
    r = missionctl("dry-run", str(CORRIDOR), "--world", "nowhere", cwd=tmp_path)
    assert r.returncode == 2
    assert "hosts.yaml: no such file" in r.stderr  # the hosts file first: it is read before the world
    r = missionctl("dry-run", str(CORRIDOR), "-c", str(ROOT / "hosts.yaml"), "--world", "nowhere", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    for path in (tmp_path / "worlds" / "nowhere.yaml", ROOT / "worlds" / "nowhere.yaml"):
        assert str(path) in r.stderr, r.stderr
    r = missionctl("dry-run", str(CORRIDOR), "-c", str(ROOT / "hosts.yaml"), "--world", "nowhere", "--json",
                   cwd=tmp_path)
    error = json_error(r.stderr)
    assert error["code"] == 2 and str(tmp_path / "worlds" / "nowhere.yaml") in error["looked"]


# --- 2. one name per concept ------------------------------------------------------------------------------

HOSTS_FILE_COMMANDS = [["missionctl", c] for c in ("dry-run", "check-trace", "hosts", "status", "components",
                                                    "resources", "query", "run", "stop", "tune")] + [["drd", "start"]]
PRINTING_COMMANDS = [["missionctl", c] for c in ("validate", "plan", "dry-run", "check-trace", "hosts", "status",
                                                  "components", "resources", "query", "run", "stop", "tune")] + [
    ["drd", c] for c in ("components", "version", "start", "stop", "status")]


def _help(command: list[str]) -> str:
    tool = MISSIONCTL if command[0] == "missionctl" else DRD
    r = subprocess.run([*tool, *command[1:], "--help"], cwd=ROOT, capture_output=True, text=True, timeout=60,
                       check=False, env={**os.environ, "COLUMNS": "200"})
    assert r.returncode == 0, r.stderr
    return r.stdout


@pytest.mark.parametrize("command", HOSTS_FILE_COMMANDS, ids=" ".join)
def test_the_hosts_file_is_config_everywhere_with_hosts_as_alias(command: list[str]) -> None:
    text = _help(command)
    assert re.search(r"--config\b", text) and re.search(r"--hosts\b", text) and re.search(r"-c\b", text), text


@pytest.mark.parametrize("command", PRINTING_COMMANDS, ids=" ".join)
def test_every_command_that_prints_has_json(command: list[str]) -> None:
    assert re.search(r"--json\b", _help(command))


def test_plan_json_is_format_json() -> None:
    a, b = missionctl("plan", str(CORRIDOR), "--json"), missionctl("plan", str(CORRIDOR), "--format", "json")
    assert a.returncode == b.returncode == 0
    assert json.loads(a.stdout) == json.loads(b.stdout)


@pytest.mark.parametrize("args", [
    ("dry-run", "nope.mission", "--json"),
    ("dry-run", str(CORRIDOR), "--speed", "0", "--json"),
    ("dry-run", str(CORRIDOR), "--json", "--config", "nowhere.yaml"),
    ("plan", "hosts.yaml", "--json"),
    ("run", "README.md", "--json"),
    ("status", "--json", "--config", "nowhere.yaml"),
    ("stop", "--json", "--config", "nowhere.yaml"),
    ("validate", "--json", "--frobnicate"),
], ids=lambda a: " ".join(a[:2]))
def test_errors_under_json_are_json_on_stderr(args: tuple[str, ...]) -> None:
    r = missionctl(*args)
    assert r.returncode == 2, r.stdout + r.stderr
    assert r.stdout == ""
    error = json_error(r.stderr)
    assert error["code"] == 2 and isinstance(error["error"], str) and error["error"]
    assert "Traceback" not in r.stderr


def test_an_invalid_mission_under_json_gives_its_diagnostics(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mission"
    bad.write_text("mission M {\n    DetectDor\n}\n")
    r = missionctl("dry-run", str(bad), "--json")
    assert r.returncode == 2 and r.stdout == ""
    error = json_error(r.stderr)
    assert error["diagnostics"][0]["message"] == "unknown behavior DetectDor"
    assert error["diagnostics"][0]["line"] == 2


def test_drd_errors_under_json_are_json_too(tmp_path: Path) -> None:
    r = drd("start", "--host", "ranger1", "--config", str(tmp_path / "none.yaml"), "--json")
    assert r.returncode == 2 and json_error(r.stderr)["code"] == 2


def test_version_on_both_tools_from_the_installed_distribution() -> None:
    from importlib.metadata import version

    for tool, name in ((MISSIONCTL, "missionctl"), (DRD, "drd")):
        r = subprocess.run([*tool, "--version", "--json"], cwd=ROOT, capture_output=True, text=True, timeout=60,
                           check=False)
        assert r.returncode == 0 and json.loads(r.stdout) == {"program": name, "version": version("drd")}
    assert drd("version").stdout.strip() == f"drd {version('drd')}"


def test_an_internal_error_is_one_line_and_exit_70() -> None:
    code = ("import sys; from drd.cli.common import run_app\n"
            "def app(**kwargs): raise RuntimeError('boom')\n"
            "sys.argv = ['x']\nrun_app(app, 'x')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False,
                       env={k: v for k, v in os.environ.items() if k != "DRD_DEBUG"})
    assert r.returncode == 70, r.stderr
    assert "internal error: RuntimeError: boom" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-c", code.replace("['x']", "['x', '--json']")], capture_output=True,
                       text=True, timeout=60, check=False)
    assert r.returncode == 70 and json_error(r.stderr)["code"] == 70


# --- 3. a file that is not a mission, on run too ---------------------------------------------------------


@pytest.mark.parametrize(("name", "text", "says"), [
    ("hosts.yaml", None, "hosts.yaml is a YAML file, not a mission"),
    ("notes.md", "# notes\n", "notes.md is a Markdown file, not a mission"),
    ("empty.mission", "# nothing here\n", "declares no mission"),
])
def test_run_refuses_a_file_that_is_no_mission_before_asking_the_cluster(tmp_path: Path, name: str,
                                                                          text: str | None, says: str) -> None:
    target = ROOT / name if text is None else tmp_path / name
    if text is not None:
        target.write_text(text)
    r = missionctl("run", str(target), "--config", str(tmp_path / "no-cluster.yaml"))
    assert r.returncode == 2, r.stdout + r.stderr
    assert says in r.stderr and "no such file" not in r.stderr, "refused before looking for a cluster"


# --- 4. drd components -------------------------------------------------------------------------------------


def test_drd_components_shows_inputs_outputs_events_and_durations() -> None:
    r = drd("components", "--kind", "behavior")
    assert r.returncode == 0, r.stderr
    text = r.stdout
    for word in ("params", "needs", "outputs", "events"):
        assert re.search(rf"\b{word}\b", text), word
    assert "duration: duration = 10s" in text or "duration: duration = 60s" in text
    assert not re.search(r"duration = \d+\.\d", text), "durations as the language writes them, not seconds"
    data = {c["name"]: c for c in json.loads(drd("components", "--json").stdout)}
    assert {"inputs", "outputs", "events"} <= set(data["Watch"])
    assert any(e["name"] == "MotionDetected" for e in data["Watch"]["events"])
    assert any(o["name"] == "waited" for o in data["Wait"]["outputs"])
    inputs = {i["name"]: i["type"] for c in data.values() for i in c["inputs"]}
    if inputs:  # declared data flow: components with inputs show them (`door: Door`)
        assert "inputs" in text or "inputs" in drd("components").stdout


# --- 5. run's progress and status at 80 columns ----------------------------------------------------------


class _Sub:
    def close(self) -> None:
        pass


class _Bus:
    def __init__(self, client: _FakeClient) -> None:
        self.client = client

    def subscribe(self, key: str, callback: Any) -> _Sub:
        return _Sub()

    def call(self, key: str, payload: Any, timeout: float = 0.0) -> Any:
        from drd.executive_messages import MissionStatus

        self.client.calls.append(payload)
        self.client.running = [m for m in self.client.running if m != payload.mission]
        return MissionStatus(0.0, [{"id": payload.mission, "outcome": "stopped", "reason": "stopped by operator"}])


class _Keys:
    executive = "drd/test/executive"


class _FakeClient:
    """What `missionctl run` and `stop` use of a cluster: no record ever comes, the executive's clock moves."""

    cluster = "test"

    def __init__(self, running: list[str], polls_until_done: int = 10**9) -> None:
        self.running = list(running)
        self.polls = 0
        self.polls_until_done = polls_until_done
        self.calls: list[Any] = []
        self.bus = _Bus(self)
        self.keys = _Keys()

    def missions(self, mission: str = "", **_options: Any) -> list[dict[str, Any]]:
        self.polls += 1
        done = self.polls >= self.polls_until_done
        return [{"id": m, "outcome": "success" if done else None, "reason": "", "time": 100.0 + 2.5 * self.polls}
                for m in self.running if not mission or m == mission]


def _capture(monkeypatch: pytest.MonkeyPatch, module: Any, width: int = 80) -> io.StringIO:
    buf = io.StringIO()
    monkeypatch.setattr(module, "err", Console(file=buf, width=width, highlight=False))
    return buf


def test_run_progress_shows_the_sim_time_every_interval_even_without_records(monkeypatch: pytest.MonkeyPatch
                                                                             ) -> None:
    buf = _capture(monkeypatch, cluster)
    monkeypatch.setattr(cluster._RecordWatch, "every", 0.05)
    watch = cluster._RecordWatch(_FakeClient(["M-1"], polls_until_done=6), None)  # type: ignore[arg-type]
    result = watch.follow("M-1", 60.0, base=100.0)
    assert result.outcome == "success"
    times = [float(t) for t in re.findall(r"sim +([0-9.]+) s", buf.getvalue())]
    assert len(times) >= 3, buf.getvalue()
    assert times == sorted(times) and times[-1] > times[0] > 0, "the time moves though no record came"


class _BusyClient(_FakeClient):
    """An executive that refuses its first polls as busy (its loop held the lock: a large mission starting)."""

    def missions(self, mission: str = "", **options: Any) -> list[dict[str, Any]]:
        from drd.bus import RemoteError

        if self.polls < 3:
            self.polls += 1
            raise RemoteError("drd/test/executive/status", "the controller is busy (...); try again")
        return super().missions(mission, **options)


def test_run_says_nothing_of_a_controller_gone_while_it_answers_busy(monkeypatch: pytest.MonkeyPatch) -> None:
    """`Wait(duration: 1s)[1000]` on a cluster: the first cycle's placements hold the executive's lock, its status is
    refused as busy for a moment, and the client said the controller did not answer (as if it had died)."""
    buf = _capture(monkeypatch, cluster)
    monkeypatch.setattr(cluster._RecordWatch, "every", 0.05)
    watch = cluster._RecordWatch(_BusyClient(["M-1"], polls_until_done=6), None)  # type: ignore[arg-type]
    result = watch.follow("M-1", 60.0, base=100.0)
    assert result.outcome == "success"
    assert "does not answer" not in buf.getvalue() and "is back" not in buf.getvalue(), buf.getvalue()


def _status_data() -> dict[str, Any]:
    mid = "CorridorSurveillance-6179574"
    root = "CorridorSurveillance"

    def node(path: str, kind: str, children: list[dict[str, Any]], **resources: str) -> dict[str, Any]:
        return {"path": path, "kind": kind, "phase": "active", "resources": resources, "children": children}

    rs = f"{root}/RoomSurveillance"
    tree = node(root, "compound", [node(rs, "multi", [
        node(f"{rs}[0]", "compound", [node(f"{rs}[0]/HideInCorner", "compound", [
            node(f"{rs}[0]/HideInCorner/LocateDarkCornerWithAVeryLongNameIndeed", "leaf", [])])], scout="scout1"),
        node(f"{rs}[1]", "compound", [node(f"{rs}[1]/FindNewDoor", "parallel", [
            node(f"{rs}[1]/FindNewDoor/FollowCorridor", "leaf", []),
            node(f"{rs}[1]/FindNewDoor/DetectDoor", "leaf", [])])], ranger="ranger1", scout="scout2")])])

    def unit(uid: str, kind: str, holders: list[str], queue: tuple[str, ...] = (), load: float = 1.0,
             capacity: float = 1.0) -> dict[str, Any]:
        return {"id": uid, "type": kind, "host": "ranger1", "sharable": capacity > 1, "capacity": capacity,
                "load": load, "epoch": 3, "holders": holders, "queue": list(queue), "properties": {}}

    h0, h1, h2 = (f"{mid}/{rs}[{i}]" for i in range(3))
    return {
        "cluster": "corridor", "answered_by": "controller", "at": 1000.0,
        "hosts": [{"name": n, "state": "up", "since": 990.0, "reason": "joined", "endpoint": "tcp/127.0.0.1:1",
                   "roles": ["controller"] if n == "controller" else ["worker"], "cpu": 12.0, "memory": 3.0,
                   "load1": 0.2, "instances": 3, "report_age": 0.1, "devices": [], "robots": [], "pid": 1}
                  for n in ("controller", "ranger1")],
        "instances": [{"name": f"{rs}[1]/FindNewDoor/FollowCorridor", "component": "FollowCorridor",
                       "host": "ranger1", "state": "running", "key": "k", "pid": 42, "mission": mid}],
        "services": [],
        "resources": {
            "units": [unit("ranger1.drive", "Drive", [h1], (h2,)), unit("ranger1.camera", "Camera", ["other-1/x"]),
                      unit("ranger1.scout1.wheels", "Drive", [h0]),
                      unit("ranger1.radio", "RadioChannel", [h0, h1], load=2.0, capacity=10.0)],
            "robots": [{"id": "ranger1", "type": "Ranger", "host": "ranger1",
                        "parts": {"drive": "ranger1.drive", "camera": "ranger1.camera"}, "holders": [h1]},
                       {"id": "scout1", "type": "Scout", "host": "ranger1",
                        "parts": {"wheels": "ranger1.scout1.wheels", "radio": "ranger1.radio"}, "holders": [h0]},
                       {"id": "scout2", "type": "Scout", "host": "ranger1", "parts": {"radio": "ranger1.radio"},
                        "holders": []}],
            "queue": [{"holder": h2, "priority": 1, "mission": mid, "needs": {"ranger": "Ranger"}}],
            "removing": {}},
        "missions": [{"id": mid, "mission": mid, "outcome": None, "reason": "", "time": 61.1, "tree": tree}],
        "daemon": None, "errors": {},
        "events": [{"at": 995.0, "kind": "up", "host": "ranger1", "detail": "joined"}],
    }


def test_status_at_80_columns_puts_missions_first_cuts_paths_and_groups_resources_by_robot() -> None:
    buf = io.StringIO()
    Console(file=buf, width=80).print(cluster.status_view(_status_data(), 80))
    lines = buf.getvalue().splitlines()
    assert max(len(line) for line in lines) <= 80, "\n".join(lines)
    text = buf.getvalue()
    order = [text.index(s) for s in ("missions", "CorridorSurveillance-6179574", "hosts", "resources by robot",
                                     "instances", "recent events")]
    assert order == sorted(order), text
    tree = text[:text.index("hosts")]
    assert "RoomSurveillance[1]/FindNewDoor" in tree and "ranger1, scout2" in tree
    assert "…" in tree, "the long path is cut from the middle, not wrapped"
    resources = text[text.index("resources by robot"):text.index("instances")]
    robots = [resources.index(r) for r in ("ranger1 Ranger", "scout1 Scout", "scout2 Scout", "shared")]
    assert robots == sorted(robots), resources
    assert "  camera" in resources, "a part held apart from its robot is shown under it"
    assert "  drive" not in resources, "a part held with its robot is not repeated (status is compact)"
    assert "RoomSurveillance[2]" in resources, "who waits, below its mission"


def test_shorten_cuts_from_the_middle_and_keeps_the_leaf() -> None:
    path = "CorridorSurveillance/RoomSurveillance[2]/HideInCorner/Watch"
    assert common.shorten(path, 80) == path
    leaf = "RoomSurveillance[0]/FindNewDoor/FollowCorridor"
    assert common.shorten(leaf, 40) == "RoomSurveillance[0]/…/FollowCorridor"
    assert common.shorten(path, 16) == "CorridorS…/Watch"
    for width in range(4, 70):
        cut = common.shorten(path, width)
        assert len(cut) <= width and (cut == path or "…" in cut)


# --- 6. stop without an id --------------------------------------------------------------------------------


def test_stop_without_an_id_refuses_to_guess_between_several_missions(monkeypatch: pytest.MonkeyPatch) -> None:
    buf = _capture(monkeypatch, common, width=200)
    client = _FakeClient(["A-1", "B-2"])
    with pytest.raises(typer.Exit) as stopped:
        cluster.stop_missions(client, "", False, 1.0)
    assert stopped.value.exit_code == 2
    assert "2 missions run (A-1, B-2)" in buf.getvalue() and "--all" in buf.getvalue()
    assert client.calls == [], "nothing was stopped"


def test_stop_without_an_id_stops_the_one_running_and_all_with_all() -> None:
    client = _FakeClient(["A-1"])
    stopped = cluster.stop_missions(client, "", False, 1.0)
    assert [c.mission for c in client.calls] == ["A-1"] and stopped[0]["outcome"] == "stopped"
    client = _FakeClient(["A-1", "B-2"])
    cluster.stop_missions(client, "", True, 1.0)
    assert [c.mission for c in client.calls] == ["A-1", "B-2"]
    client = _FakeClient([])
    assert cluster.stop_missions(client, "", False, 1.0) == [] and client.calls == []


# --- 7. Ctrl-C on dry-run ---------------------------------------------------------------------------------


@pytest.mark.parametrize("as_json", [True, False], ids=["json", "text"])
def test_ctrl_c_on_a_dry_run_prints_the_report_of_what_ran_and_exits_1(tmp_path: Path, as_json: bool) -> None:
    mission = tmp_path / "long.mission"
    mission.write_text("mission Long {\n    Wait(duration: 1h)\n}\n")
    trace = tmp_path / "long.jsonl"
    cmd = [*MISSIONCTL, "dry-run", str(mission), "--speed", "1", "--trace", str(trace), *(["--json"] * as_json)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 90
        while not (trace.exists() and trace.stat().st_size > 0):  # the run has begun: the trace flushed its start
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the dry-run never started"
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=10)
    assert proc.returncode == 1, err
    assert "Ctrl-C" in err and "Traceback" not in err
    if as_json:
        report = json.loads(out)
        assert (report["outcome"], report["reason"]) == ("stopped", "stopped by operator")
        assert report["timeline"][0]["path"] == "Long"
        assert [a["path"] for a in report["still_active"]] == ["Long/Wait"]
    else:
        assert out.startswith("mission Long  stopped  stopped by operator")
        assert "still active when it stopped: 1" in out and "Wait  running since 0.0 s" in out


def test_a_missing_brace_names_the_block_never_closed_at_the_command_line(tmp_path: Path) -> None:
    (tmp_path / "open.mission").write_text("mission Patrol {\n    parallel all {\n        Observe\n"
                                           "    Calibrate\n}\n\nbehavior Later {\n    Observe\n}\n",
                                           encoding="utf-8")
    done = missionctl("validate", "open.mission", cwd=tmp_path)
    assert done.returncode == 2
    assert "open.mission:2:18: error: syntax: this `{` of `parallel all` is never closed" in done.stdout + done.stderr
    assert "    2 |     parallel all {" in done.stdout + done.stderr
    assert "before line 4" in done.stdout + done.stderr
    assert "reserved word" not in done.stdout + done.stderr


def test_a_priority_of_more_than_18_digits_is_refused_as_in_a_mission() -> None:
    """Users audit 9, D10: `--priority 99999999999999999999` ran (the report carried it), while `priority N` in the
    file and `--param` refuse a number of more than 18 digits."""
    r = missionctl("dry-run", "missions/corridor_surveillance.mission", "--priority", "99999999999999999999")
    assert r.returncode == 2 and "--priority" in r.stderr and "999999999999999999" in r.stderr, r.stderr
    assert r.stdout == ""


def test_replay_of_a_folder_says_it_is_a_folder(tmp_path: Path) -> None:
    """Reverify audit 14, D6: `replay BAG_FOLDER` (what `--ros2-bag` writes) said "no such file" of a folder that
    exists."""
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "bag.mcap").write_bytes(b"")
    done = missionctl("replay", str(tmp_path / "bag"), cwd=tmp_path)
    assert done.returncode == 2
    assert f"{tmp_path / 'bag'} is a folder, not a recording (it holds bag.mcap" in done.stderr, done.stderr
