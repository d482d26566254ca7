"""Real `drd start` processes on loopback for the daemon tests: a hosts file on free ports, started
daemons, a client, bounded waits, and a teardown that kills every process it started by pid.

    with running_cluster(tmp_path, ["controller", "ranger1", "ranger2"]) as c:
        c.start_all()
        c.wait_up()
        c.client().hosts()
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from drd.daemon.client import ClusterClient
from tests.net_support import eventually, free_ports

ROOT = Path(__file__).resolve().parents[1]
DRD = [sys.executable, "-m", "drd.cli.drd"]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
LEASE = 1.0  # seconds: short, so the SIGSTOP test is short
LOAD_PERIOD = 0.2
START_TIMEOUT = 45.0  # a loaded 2-core machine imports three daemons at once






RANGER = """\
    devices:
      drive: {{type: Drive, driver: sim, options: {{max_speed: 0.8}}}}
      ranges: {{type: RangeSensor, driver: sim, options: {{beams: 181, max_range: 8.0}}}}
      camera: {{type: Camera, driver: sim, options: {{resolution: {resolution}, fov: 60.0}}}}
      launcher: {{type: Launcher, driver: sim, options: {{max_range: 6.0}}}}
      radio: {{type: RadioChannel, driver: sim, capacity: 10, options: {{range: 30.0}}}}
    robots:
      {name}:
        type: Ranger
        parts: {{drive: drive, ranges: ranges, camera: camera, launcher: launcher}}
        properties: {{battery: 1.0, magazine: 0}}
"""


def hosts_yaml(cluster: str, names: Sequence[str], ports: Sequence[int], *, lease: float = LEASE,
               security: str = "{mode: none}") -> str:
    """A hosts file: the first name is the controller, the others are workers with a Ranger each
    (cameras of resolution 640, 800, 960...)."""
    lines = ["cluster:", f"  name: {cluster}", f"  security: {security}", f"  lease: {int(lease * 1000)}ms",
             "hosts:"]
    for i, (name, port) in enumerate(zip(names, ports, strict=True)):
        lines += [f"  {name}:", f"    endpoint: tcp/127.0.0.1:{port}",
                  f"    roles: [{'controller' if i == 0 else 'worker'}]"]
        if i:
            lines.append(RANGER.format(name=name, resolution=480 + 160 * i).rstrip())
    return "\n".join(lines) + "\n"


class DaemonCluster:
    """Daemons of one hosts file, each a `drd start` process of ours; `close()` kills what is left."""

    def __init__(self, folder: Path, names: Sequence[str], *, lease: float = LEASE,
                 security: str = "{mode: none}") -> None:
        self.folder = folder
        self.names = list(names)
        self.ports = free_ports(len(names))
        self.name = f"t{os.getpid()}_{self.ports[0]}"
        self.hosts_file = folder / "hosts.yaml"
        self.hosts_file.write_text(hosts_yaml(self.name, names, self.ports, lease=lease, security=security))
        self.run_dir = folder / "run"
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.endpoints = [f"tcp/127.0.0.1:{p}" for p in self.ports]
        self._clients: list[ClusterClient] = []

    def start(self, name: str, *, hosts_file: Path | None = None, extra: Sequence[str] = (),
              env: dict[str, str] | None = None) -> subprocess.Popen[bytes]:
        """`drd start` for host `name`, logging to its file; `env` replaces the environment (a host with other
        libraries installed)."""
        log = (self.folder / f"{name}.log").open("ab")
        cmd = [*DRD, "start", "--host", name, "--config", str(hosts_file or self.hosts_file),
               "--run-dir", str(self.run_dir), "--load-period", str(LOAD_PERIOD), "--peer-grace", "1", *extra]
        with log:
            proc = subprocess.Popen(cmd, cwd=ROOT, stdin=subprocess.DEVNULL, stdout=log, stderr=log, env=env)
        self.procs[name] = proc
        return proc

    def start_all(self) -> None:
        for name in self.names:
            self.start(name)

    def pid(self, name: str) -> int:
        return self.procs[name].pid

    def log(self, name: str) -> str:
        path = self.folder / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def tails(self, *names: str, chars: int = 4000) -> str:
        """The end of each named daemon's log (all by default), for a failure message."""
        return "\n".join(f"--- {name}.log (last {chars} characters) ---\n{self.log(name)[-chars:]}"
                         for name in names or self.names)

    def pidfile(self, name: str) -> dict[str, object] | None:
        try:
            data: dict[str, object] = json.loads((self.run_dir / self.name / f"{name}.pid").read_text())
        except (OSError, ValueError):
            return None
        return data

    def wait_ready(self, names: Sequence[str] | None = None) -> None:
        """Every daemon has declared its services (its pidfile says `running`)."""
        for name in names or self.names:
            def ready(name: str = name) -> bool:
                proc = self.procs[name]
                if proc.poll() is not None:
                    pytest.fail(f"drd {name} exited with {proc.returncode}:\n{self.log(name)}")
                info = self.pidfile(name)
                return info is not None and info.get("state") == "running"

            eventually(ready, f"drd {name} to start", START_TIMEOUT, poll=0.05)

    def client(self, timeout: float = 2.0) -> ClusterClient:
        client = ClusterClient.connect(self.endpoints, cluster=self.name, timeout=timeout, prefer=self.names)
        self._clients.append(client)
        return client

    def states(self, client: ClusterClient) -> dict[str, str]:
        return {h.name: h.state for h in client.hosts().hosts}

    def wait_up(self, client: ClusterClient | None = None, names: Sequence[str] | None = None,
                timeout: float = 20.0) -> None:
        """The controller sees every named host up."""
        client = client or self.client()
        wanted = set(names or self.names)
        eventually(lambda: {h for h, s in self.states(client).items() if s == "up"} >= wanted,
                   f"hosts {sorted(wanted)} to be up", timeout, poll=0.05)

    def missionctl(self, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
        return subprocess.run([*MISSIONCTL, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                              check=False)

    def drd(self, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
        return subprocess.run([*DRD, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False)

    def close(self) -> None:
        for client in self._clients:
            client.close()
        for proc in self.procs.values():
            if proc.poll() is None:
                try:
                    os.kill(proc.pid, signal.SIGCONT)  # a SIGSTOPped process must not survive the test
                    os.kill(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            proc.wait(timeout=10)


@contextmanager
def running(cmd: Sequence[str]) -> Iterator[subprocess.Popen[str]]:
    """A command (`missionctl run ...`) running in the background; killed and reaped if still running after, and its
    pipes closed either way (left open by a test that failed before reading them, they were collected as an
    unclosed file later, in another test, which pytest then failed)."""
    proc = subprocess.Popen(list(cmd), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=10)
        for pipe in (proc.stdout, proc.stderr):
            if pipe is not None:
                pipe.close()


def succeeded(cluster: DaemonCluster, proc: subprocess.Popen[str], out: str, err: str) -> dict[str, object]:
    """The JSON report of a `missionctl run --json` that exited 0 with a successful mission (else fail, showing
    its output and the controller's log)."""
    assert proc.returncode == 0, (out[-2000:], err[-2000:], cluster.log("controller")[-3000:])
    report: dict[str, object] = json.loads(out)
    assert report["outcome"] == "success"
    return report


@contextmanager
def serving_cluster(folder: Path, names: Sequence[str],
                    hosts: Callable[[DaemonCluster], str]) -> Iterator[DaemonCluster]:
    """Daemons of the hosts file `hosts(cluster)` (written on the cluster's free ports), every one started, ready
    and seen up by the controller; all killed by pid afterwards."""
    with running_cluster(folder, names) as cluster:
        cluster.hosts_file.write_text(hosts(cluster))
        cluster.start_all()
        cluster.wait_ready()
        cluster.wait_up()
        yield cluster


@contextmanager
def running_cluster(folder: Path, names: Sequence[str], *, lease: float = LEASE,
                    security: str = "{mode: none}") -> Iterator[DaemonCluster]:
    cluster = DaemonCluster(folder, names, lease=lease, security=security)
    try:
        yield cluster
    finally:
        cluster.close()


def instances_only_hosts(c: DaemonCluster) -> str:
    """A hosts file of `c`'s names, the first the controller and the others bare workers, placed by instance count
    alone: every idle worker scores the same and ties go to the smaller name, so which host is tried is known."""
    lines = ["cluster:", f"  name: {c.name}", "  security: {mode: none}", "  lease: 1000ms",
             "  placement: {cpu: 0, memory: 0, instances: 1, affinity: 0}", "hosts:"]
    for i, (name, endpoint) in enumerate(zip(c.names, c.endpoints, strict=True)):
        lines += [f"  {name}:", f"    endpoint: {endpoint}", f"    roles: [{'worker' if i else 'controller'}]"]
    return "\n".join(lines) + "\n"


def corridor_hosts(cluster: DaemonCluster, *, simulator_on_controller: bool = False, lease: str = "1000ms") -> str:
    """The repository's hosts.yaml (controller; ranger1 with its Scouts and, unless moved to the controller, the
    simulator) on the cluster's free ports and name, with the test lease."""
    text = (ROOT / "hosts.yaml").read_text()
    if simulator_on_controller:
        text = text.replace("roles: [worker, simulator]", "roles: [worker]")
        text = text.replace("roles: [controller]", "roles: [controller, simulator]")
    ports = dict(zip(cluster.names, cluster.ports, strict=True))
    text = text.replace("name: corridor", f"name: {cluster.name}").replace("lease: 3s", f"lease: {lease}")
    text = text.replace("127.0.0.1:7447", f"127.0.0.1:{ports['controller']}")
    return text.replace("127.0.0.1:7448", f"127.0.0.1:{ports['ranger1']}")


def read_trace(path: Path) -> list[dict[str, Any]]:
    """A `--trace` file's records: its whole lines (one read while the client writes may end in half a record)."""
    return [json.loads(line) for line in path.read_text().splitlines(keepends=True)
            if line.strip() and line.endswith("\n")]


@contextmanager
def password_cluster(folder: Path, names: Sequence[str], security: str, users: dict[str, str],
                     hosts: Callable[[DaemonCluster], str], started: Sequence[str]) -> Iterator[DaemonCluster]:
    """A cluster of `hosts(cluster)` with the password file `users` (user -> password) beside it, the daemons
    `started` running and ready; all killed by pid afterwards."""
    (folder / "users").write_text("".join(f"{u}:{p}\n" for u, p in users.items()))
    with running_cluster(folder, names, security=security) as c:
        c.hosts_file.write_text(hosts(c))
        for name in started:
            c.start(name)
        c.wait_ready(started)
        yield c


def assert_spoofing_fails(cluster: DaemonCluster, rogue: Any, victim: str,
                          view: Callable[[], dict[str, dict[str, Any]]]) -> None:
    """`rogue` (a client session) fakes `victim`'s load twice as often as it reports, calls its Creator and asks
    the executive to stop every mission: neither call gets an answer (a worker's credentials may not stop
    missions either: security audit D3), and the hosts' `view()` (host -> its row) never shows the fake load."""
    from drd.bus import BusTimeout, LoadReport
    from drd.cluster.remote import ComponentCall
    from drd.executive_messages import MissionCommand

    stop = threading.Event()

    def fake_loads() -> None:
        while not stop.is_set():
            rogue.bus.put(f"drd/{cluster.name}/host/{victim}/load", LoadReport(victim, 99.5, 99.5, 9.5, 42,
                                                                                time.time()))
            time.sleep(0.1)

    thread = threading.Thread(target=fake_loads, daemon=True)
    thread.start()
    try:
        with pytest.raises(BusTimeout):  # only a controller calls a Creator: dropped where it arrives
            rogue.bus.call(f"drd/{cluster.name}/host/{victim}/creator", ComponentCall("retire", "Short-1", ""),
                           timeout=2.0)
        with pytest.raises(BusTimeout):  # an operator's (or the administrators') to ask: dropped where it arrives
            rogue.bus.call(f"drd/{cluster.name}/executive", MissionCommand("stop"), timeout=2.0)
        for _ in range(3):
            row = view()[victim]
            assert row["cpu"] != 99.5 and row["instances"] != 42, row
    finally:
        stop.set()
        thread.join(timeout=5)


@contextmanager
def corridor_run(cluster: DaemonCluster, trace: Path, speed: float = 20.0) -> Iterator[tuple[Any, str]]:
    """`missionctl run` of the corridor mission at `speed`, its records in `trace`, in the background: once the
    mission holds its first grant, the running process and the mission's id (the process is killed if still
    running afterwards)."""
    cmd = [*MISSIONCTL, "run", str(ROOT / "missions" / "corridor_surveillance.mission"), "--config",
           str(cluster.hosts_file), "--speed", f"{speed:g}", "--json", "--trace", str(trace)]
    with running(cmd) as run:
        eventually(lambda: trace.exists() and any(r["kind"] == "granted" for r in read_trace(trace)),
                   "the mission to run", 60, poll=0.1)
        yield run, str(read_trace(trace)[0]["mission"])


def two_rangers_hosts(cluster: DaemonCluster, security: str) -> str:
    """The repository's two-Ranger team (controller, ranger1, ranger2) on the cluster's first three ports, with
    `security`, the test lease and the simulator on the controller."""
    text = (ROOT / "hosts.two_rangers.yaml").read_text()
    text = text.replace("name: corridor_two_rangers", f"name: {cluster.name}").replace("lease: 3s", "lease: 1000ms")
    text = text.replace("security: {mode: none}", f"security: {security}")
    text = text.replace("roles: [worker, simulator]", "roles: [worker]").replace("roles: [controller]",
                                                                                  "roles: [controller, simulator]")
    for port, default in zip(cluster.ports, (7447, 7448, 7449), strict=False):
        text = text.replace(f"127.0.0.1:{default}", f"127.0.0.1:{port}")
    return text


def user_kit(folder: Path, monkeypatch: pytest.MonkeyPatch, module: str, code: str,
             manifests: dict[str, str]) -> None:
    """A user's own components in `folder`: the module `module.py` holding `code`, a manifest per component under
    `comps/<name>/`, and the environment that finds them (`DRD_COMPONENTS`, `PYTHONPATH`) for every process the
    test starts after this."""
    (folder / f"{module}.py").write_text(code)
    for name, manifest in manifests.items():
        (folder / "comps" / name).mkdir(parents=True)
        (folder / "comps" / name / "manifest.yaml").write_text(manifest)
    monkeypatch.setenv("DRD_COMPONENTS", str(folder / "comps"))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(folder), str(ROOT)]))
