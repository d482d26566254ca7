"""Cluster benchmark: a real N-daemon cluster on loopback: start time, `missionctl status`, idle memory and CPU.

Run `python bench/cluster.py [--daemons 10] [--routers R] [--repeat 10] [--idle 30] [--json] [--profile]` (never by
pytest). It writes a hosts file in a temporary folder (1 controller and N-1 Ranger hosts, each with a Ranger's
five simulated devices, every endpoint a free tcp/127.0.0.1 port; with `--routers R`, 2 by default from 20
daemons, the controller and the first R-1 Rangers are also zenoh routers and every other daemon is their client),
starts every daemon at once (the routers first) as its own `python -m drd.cli.drd start` process, and measures:

- start: seconds from the first `drd start` until the controller sees all N hosts up;
- `missionctl status --json --config FILE`, N runs (median and p90): a subprocess, as a user runs it (wall time,
  output read and checked: every host up, no error; an incomplete answer is counted), beside its floors
  `python -c pass` and `python -c "import drd.cli.missionctl"`; in this process, already imported:
  `ClusterClient.connect`, `client.status()`, `close`, each request status makes, and reading the hosts file;
- how many client daemons hold a link to each router;
- idle, once the worker pools kept warm at start have gone (`--settle`): each daemon's CPU (with its children)
  over `--idle` seconds, then its PSS, USS and RSS, by role; and the same of N `python -m drd.bus.peer`
  processes started the same way (the peer: an interpreter with a zenoh session, a token and a queryable).

Goals (issue #15): `status` < 0.5 s (median); an idle daemon with its workers <= 60 MB PSS; all up <= 30 s.
Every process started is stopped in a `finally` (SIGTERM to its process group, then SIGKILL, bounded), also on
Ctrl-C, SIGTERM or an error.
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import functools
import io
import json
import os
import pstats
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the tests' helpers import each other
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ... imported as `tests.*`

from drd.cluster.workers import KEEP_WARM  # noqa: E402
from drd.daemon.client import ClusterClient  # noqa: E402
from tests.cluster_support import DRD, RANGER, ROOT  # noqa: E402
from tests.net_support import free_ports  # noqa: E402

GOAL = 0.5  # seconds, median of `missionctl status` (issue #15: of 50 daemons; it was 1 s of 10)
IDLE_GOAL_MB = 60.0  # PSS of an idle daemon with its workers (issue #15)
IDLE_GOAL_CPU = 1.0  # % of one core, an idle daemon with its workers (issue #15)
START_GOAL = 30.0  # seconds for every daemon to be up (issue #15: 50 daemons)
LEASE = 3.0  # seconds, as in the repository's hosts.yaml
START_TIMEOUT = 30.0  # seconds, plus 5 s per daemon: a 2-core machine imports them all at once
STOP_TIMEOUT = 10.0  # seconds for every daemon to go after SIGTERM, before SIGKILL


def missionctl_cmd() -> list[str]:
    """The `missionctl` console script installed beside this interpreter (what a user types), else
    the same entry point through `python -c` (never a pyenv shim, whose bash start-up is not ours)."""
    script = Path(sys.executable).parent / "missionctl"
    if script.is_file() and os.access(script, os.X_OK):
        return [str(script)]
    return [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]


def fleet_yaml(cluster: str, names: Sequence[str], ports: Sequence[int], routers: Sequence[str]) -> str:
    """A hosts file: the first name is the controller, the others workers with a Ranger each (cameras of 640 to
    8,000 px, so each host differs), the hosts named in `routers` also with the role `router`."""
    lines = ["cluster:", f"  name: {cluster}", "  security: {mode: none}", f"  lease: {int(LEASE * 1000)}ms",
             "hosts:"]
    for i, (name, port) in enumerate(zip(names, ports, strict=True)):
        roles = ["controller" if i == 0 else "worker", *(["router"] if name in routers else [])]
        lines += [f"  {name}:", f"    endpoint: tcp/127.0.0.1:{port}", f"    roles: [{', '.join(roles)}]"]
        if i:
            lines.append(RANGER.format(name=name, resolution=480 + 160 * (1 + (i - 1) % 47)).rstrip())
    return "\n".join(lines) + "\n"


class Cluster:
    """N `drd start` processes of ours, each the leader of its own process group (so a Ctrl-C in the
    terminal reaches only this script, whose `finally` stops them in order). With `routers` > 0, the
    controller and the first `routers` - 1 Rangers also have the role `router`: every other daemon is a
    zenoh client of those, not a peer of all (docs/daemon.md, topologies)."""

    def __init__(self, folder: Path, n: int, routers: int = 0) -> None:
        self.folder = folder
        self.names = ["controller"] + [f"ranger{i}" for i in range(1, n)]
        self.routers = self.names[:routers]
        self.ports = free_ports(n)
        self.name = f"bench{os.getpid()}_{self.ports[0]}"
        self.hosts_file = folder / "hosts.yaml"
        self.hosts_file.write_text(fleet_yaml(self.name, self.names, self.ports, self.routers))
        self.endpoints = [f"tcp/127.0.0.1:{p}" for name, p in zip(self.names, self.ports, strict=True)
                          if not self.routers or name in self.routers]  # where missionctl connects
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.started = 0.0  # perf_counter of the first `drd start`

    def role(self, name: str) -> str:
        """The daemon's roles as one label: controller+router, worker+router, worker (or controller)."""
        base = "controller" if name == "controller" else "worker"
        return f"{base}+router" if name in self.routers else base

    def start_all(self) -> None:
        """Every daemon at once, the routers first (a client of the routers waits for one to answer)."""
        self.started = time.perf_counter()
        for name in sorted(self.names, key=lambda n: n not in self.routers):
            cmd = [*DRD, "start", "--host", name, "--config", str(self.hosts_file),
                   "--run-dir", str(self.folder / "run")]
            with (self.folder / f"{name}.log").open("ab") as log:
                self.procs[name] = subprocess.Popen(cmd, cwd=ROOT, stdin=subprocess.DEVNULL, stdout=log,
                                                    stderr=log, start_new_session=True)

    def log(self, name: str) -> str:
        path = self.folder / f"{name}.log"
        return path.read_text(errors="replace")[-2000:] if path.exists() else ""

    def wait_up(self, timeout: float) -> float:
        """Seconds from the first `drd start` until the controller sees every host up; exits with the logs if
        it does not in time."""
        deadline = time.monotonic() + timeout
        client: ClusterClient | None = None
        up: set[str] = set()
        try:
            while True:
                for name, proc in self.procs.items():
                    if proc.poll() is not None:
                        raise SystemExit(f"drd {name} exited with {proc.returncode}:\n{self.log(name)}")
                try:
                    if client is None:
                        client = ClusterClient.connect(self.endpoints, cluster=self.name, timeout=2.0,
                                                       prefer=self.names)
                    hosts = client.hosts()
                    if hosts.answered_by == "controller":
                        up = {h.name for h in hosts.hosts if h.state == "up"}
                        if up >= set(self.names):
                            return time.perf_counter() - self.started
                except Exception:  # noqa: BLE001 - not up yet: the daemons are still importing
                    pass
                if time.monotonic() > deadline:
                    missing = sorted(set(self.names) - up)
                    raise SystemExit(f"timed out after {timeout:g} s: hosts not up: {', '.join(missing)}")
                time.sleep(0.2)
        finally:
            if client is not None:
                client.close()

    def stop_all(self) -> list[str]:
        """SIGTERM every process group still alive, wait (bounded), SIGKILL what is left; the names killed."""
        def signal_group(proc: subprocess.Popen[bytes], sig: int) -> None:
            if proc.poll() is None:  # not reaped: its pid (and group id) is still ours
                try:
                    os.killpg(proc.pid, sig)
                except ProcessLookupError:
                    pass

        for proc in self.procs.values():
            signal_group(proc, signal.SIGTERM)
        deadline = time.monotonic() + STOP_TIMEOUT
        killed = []
        for name, proc in self.procs.items():
            try:
                proc.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                signal_group(proc, signal.SIGKILL)
                proc.wait(timeout=5)
                killed.append(name)
        return killed


class Peers:
    """The peer of the start and idle figures: `python -m drd.bus.peer` processes (an interpreter, a zenoh session
    connected to the cluster's entry points, one liveliness token and one queryable: what any Python process on
    this bus costs, before drd's own work), started all at once as the daemons were."""

    def __init__(self, folder: Path, cluster: Cluster, n: int) -> None:
        self.folder = folder / "peers"
        self.folder.mkdir()
        key = f"drd-bench/{cluster.name}/peer"  # not a host of the cluster: its daemons never see them
        self.cmds = [[sys.executable, "-m", "drd.bus.peer", "--host", f"peer{i}",
                      *(a for e in cluster.endpoints for a in ("--connect", e)),
                      "--token", f"{key}{i}", "--serve", f"{key}{i}/ping"] for i in range(n)]
        self.procs: list[subprocess.Popen[bytes]] = []

    def start(self, timeout: float) -> float:
        """Seconds from the first start until every peer has printed `ready`."""
        began = time.perf_counter()
        for i, cmd in enumerate(self.cmds):
            with (self.folder / f"peer{i}.out").open("wb") as fh:
                self.procs.append(subprocess.Popen(cmd, cwd=ROOT, stdin=subprocess.DEVNULL, stdout=fh,
                                                   stderr=subprocess.STDOUT, start_new_session=True,
                                                   env=CHILD_ENV))
        waiting = set(range(len(self.procs)))
        deadline = time.monotonic() + timeout
        while waiting:
            waiting = {i for i in waiting if b"ready" not in (self.folder / f"peer{i}.out").read_bytes()}
            if any(self.procs[i].poll() is not None for i in waiting):
                raise SystemExit(f"a peer exited: {(self.folder / f'peer{min(waiting)}.out').read_text()[-2000:]}")
            if time.monotonic() > deadline:
                raise SystemExit(f"timed out after {timeout:g} s: {len(waiting)} peers not ready")
            time.sleep(0.05)
        return time.perf_counter() - began

    def stop(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in self.procs:
            try:
                proc.wait(timeout=STOP_TIMEOUT)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=5)


def tree(pid: int) -> list[psutil.Process]:
    """A process and all its descendants (a daemon's workers and fork server), those still alive."""
    try:
        root = psutil.Process(pid)
        return [root, *root.children(recursive=True)]
    except psutil.NoSuchProcess:
        return []


def cpu_seconds(pid: int) -> dict[int, float]:
    """CPU seconds (user + system) of each process of the tree, by pid."""
    out = {}
    for proc in tree(pid):
        with contextlib.suppress(psutil.NoSuchProcess):
            t = proc.cpu_times()
            out[proc.pid] = t.user + t.system
    return out


def memory_mb(pid: int) -> dict[str, float]:
    """PSS, USS and RSS of the tree in MB (PSS: shared pages split among their users; USS: pages only it has;
    RSS: every page it maps, what it would hold alone on a machine, summed over processes that share some), and
    how many processes it holds."""
    pss = uss = rss = 0
    procs = tree(pid)
    for proc in procs:
        with contextlib.suppress(psutil.NoSuchProcess):
            info = proc.memory_full_info()
            pss, uss, rss = pss + info.pss, uss + info.uss, rss + info.rss
    return {"pss_mb": pss / 2**20, "uss_mb": uss / 2**20, "rss_mb": rss / 2**20, "processes": len(procs)}


def idle(pids: dict[str, int], seconds: float) -> dict[str, dict[str, float]]:
    """Each tree's CPU share of one core over `seconds` of idling (new children count from 0), then its memory."""
    before = {name: cpu_seconds(pid) for name, pid in pids.items()}
    t0 = time.perf_counter()
    time.sleep(seconds)
    after = {name: cpu_seconds(pid) for name, pid in pids.items()}
    wall = time.perf_counter() - t0
    return {name: {"cpu_percent": 100 * sum(v - before[name].get(p, 0.0) for p, v in after[name].items()) / wall,
                   **memory_mb(pid)} for name, pid in pids.items()}


def router_links(cluster: Cluster) -> dict[str, int]:
    """How many of the other daemons hold a TCP link to each router, as the operating system sees them (a zenoh
    client keeps one link, to the first router of its list that answered)."""
    ports = {p: n for n, p in zip(cluster.names, cluster.ports, strict=True) if n in cluster.routers}
    links = dict.fromkeys(cluster.routers, 0)
    for name, proc in cluster.procs.items():
        if name in cluster.routers:
            continue
        with contextlib.suppress(psutil.NoSuchProcess):
            for router in {ports[c.raddr.port] for c in psutil.Process(proc.pid).net_connections(kind="tcp")
                           if c.raddr and c.status == psutil.CONN_ESTABLISHED and c.raddr.port in ports}:
                links[router] += 1
    return links


def by_role(per: dict[str, dict[str, float]], role: Callable[[str], str]) -> dict[str, dict[str, float]]:
    """Per-daemon figures grouped by role: the median of each figure, and how many daemons."""
    groups: dict[str, list[dict[str, float]]] = {}
    for name, figures in per.items():
        groups.setdefault(role(name), []).append(figures)
    return {r: {**{k: statistics.median(f[k] for f in fs) for k in fs[0]}, "max_pss_mb": max(f["pss_mb"] for f in fs),
                "daemons": len(fs)} for r, fs in groups.items()}


def percentile(samples: Sequence[float], q: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, max(0, round(q * (len(ordered) - 1))))]


def stats(samples: Sequence[float]) -> dict[str, float]:
    return {"median": statistics.median(samples), "p90": percentile(samples, 0.9), "min": min(samples),
            "max": max(samples), "runs": len(samples)}


#: Subprocesses import this checkout's drd, even through a console script installed for another checkout.
CHILD_ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)}


def timed_run(cmd: Sequence[str], check: Callable[[str], None] | None = None) -> float:
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=60, check=False, env=CHILD_ENV)
    elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} exited with {proc.returncode}:\n{proc.stderr[-2000:]}")
    if check is not None:
        check(proc.stdout)
    return elapsed


def measure(cluster: Cluster, repeat: int) -> dict[str, Any]:
    """`missionctl status` as a user runs it (subprocesses, beside their floors), then its parts in this process."""
    incomplete: list[str] = []  # runs timed whose answer was not the whole cluster (counted, and a MISS)
    wall = subprocess_walls(cluster, repeat, incomplete)
    phases, calls = in_process_phases(cluster, repeat)
    return {"status_incomplete": incomplete,
            "subprocess": {k: stats(v) for k, v in wall.items()},
            "in_process": {k: stats(v) for k, v in phases.items()},
            "requests": {k: stats(v) for k, v in calls.items()}}


def subprocess_walls(cluster: Cluster, repeat: int, incomplete: list[str]) -> dict[str, list[float]]:
    """Wall seconds of `missionctl status --json` and of its floors, `repeat` runs each; every status answer that
    is not the whole cluster up is added to `incomplete`."""
    status_cmd = [*missionctl_cmd(), "status", "--json", "--config", str(cluster.hosts_file)]

    def all_up(stdout: str) -> None:
        data = json.loads(stdout)
        up = {h["name"] for h in data["hosts"] if h["state"] == "up"}
        if up != set(cluster.names) or data["errors"] or data["answered_by"] != "controller":
            incomplete.append(f"not up: {sorted(set(cluster.names) - up)}; errors: {data['errors']}")

    commands: dict[str, tuple[list[str], Callable[[str], None] | None]] = {
        "python -c pass": ([sys.executable, "-c", "pass"], None),
        "python -c 'import drd.cli.missionctl'": ([sys.executable, "-c", "import drd.cli.missionctl"], None),
        "missionctl status --json": (status_cmd, all_up),
    }
    for cmd, check in commands.values():  # warm the page cache and the .pyc files
        timed_run(cmd, check)
    wall: dict[str, list[float]] = {label: [] for label in commands}
    for _ in range(repeat):  # interleaved, so a busy moment hits every command alike
        for label, (cmd, check) in commands.items():
            wall[label].append(timed_run(cmd, check))
    return wall


def in_process_phases(cluster: Cluster, repeat: int) -> tuple[dict[str, list[float]], dict[str, list[float]]]:
    """Seconds of each part of a status in this process, imports done (connect, status, close, printing, reading
    the hosts file), and of each request status makes: `repeat` rounds after one warm-up round."""
    from rich.console import Console

    from drd.cli.common import print_json
    from drd.hosts import load_endpoints

    phases: dict[str, list[float]] = {k: [] for k in ("connect", "status()", "close", "connect+status+close",
                                                      "print_json (rich, to a pipe)",
                                                      "print_json (missionctl's, to a pipe)",
                                                      "load_endpoints (reading the hosts file)")}
    calls: dict[str, list[float]] = {k: [] for k in ("daemons()", "hosts()", "components()", "daemon_status()",
                                                      "resources()", "missions()")}
    for i in range(repeat + 1):  # the first round is a warm-up
        data, timings, one = connected_round(cluster)
        if i:
            for k, v in timings.items():
                phases[k].append(v)
            for k, v in one.items():
                calls[k].append(v)
            sink = Console(file=io.StringIO())  # as `missionctl status --json` printed, stdout not a terminal
            s = time.perf_counter()
            sink.print_json(json.dumps(data))
            phases["print_json (rich, to a pipe)"].append(time.perf_counter() - s)
            with contextlib.redirect_stdout(io.StringIO()):  # as it prints now: json.dumps when not a terminal
                s = time.perf_counter()
                print_json(data)
                phases["print_json (missionctl's, to a pipe)"].append(time.perf_counter() - s)
            s = time.perf_counter()  # what `missionctl status --config FILE` does before it connects
            load_endpoints(cluster.hosts_file)
            phases["load_endpoints (reading the hosts file)"].append(time.perf_counter() - s)
    return phases, calls


def connected_round(cluster: Cluster) -> tuple[Any, dict[str, float], dict[str, float]]:
    """One client's life: its status answer, the seconds of connect, status, close (and their sum), and of each
    request status makes, asked again one by one on the same connection."""
    t0 = time.perf_counter()
    client = ClusterClient.connect(cluster.endpoints, cluster=cluster.name, timeout=2.0, prefer=cluster.names)
    t1 = time.perf_counter()
    try:
        data = client.status(20)
        t2 = time.perf_counter()
        one: dict[str, float] = {}
        for label, fn in (("daemons()", client.daemons), ("hosts()", functools.partial(client.hosts, 20)),
                          ("components()", client.components),
                          ("daemon_status()", functools.partial(client.daemon_status, "controller")),
                          ("resources()", client.resources), ("missions()", client.missions)):
            s = time.perf_counter()
            fn()
            one[label] = time.perf_counter() - s
    finally:
        t3 = time.perf_counter()
        client.close()
        t4 = time.perf_counter()
    timings = {"connect": t1 - t0, "status()": t2 - t1, "close": t4 - t3,
               "connect+status+close": (t1 - t0) + (t2 - t1) + (t4 - t3)}
    return data, timings, one


def profile(cluster: Cluster) -> str:
    """Where the time of one `missionctl status` goes: import time per top-level package (`-X importtime`,
    own time summed), the top cumulative cProfile entries of the real command, and of the in-process call."""
    status_args = ["status", "--json", "--config", str(cluster.hosts_file)]
    entry = "from drd.cli.missionctl import main; main()"  # the console script's body
    proc = subprocess.run([sys.executable, "-X", "importtime", "-c", entry, *status_args],
                          cwd=ROOT, capture_output=True, text=True, timeout=60, check=False, env=CHILD_ENV)
    per_package: dict[str, int] = {}
    for line in proc.stderr.splitlines():
        if line.startswith("import time:") and "|" in line and "self [us]" not in line:
            own, _cumulative, module = line[len("import time:"):].split("|")
            top = module.strip().split(".")[0]
            per_package[top] = per_package.get(top, 0) + int(own)
    total = sum(per_package.values())
    lines = [f"imports of one `missionctl status`: {total / 1000:.0f} ms in all; by top-level package (own time):"]
    for top, us in sorted(per_package.items(), key=lambda kv: -kv[1])[:15]:
        lines.append(f"  {top:24} {us / 1000:8.1f} ms")
    with tempfile.NamedTemporaryFile(suffix=".prof") as out:
        run = (f"import sys, cProfile; sys.argv = ['missionctl', *{status_args!r}]; "
               f"cProfile.run({entry!r}, {out.name!r})")
        cmd = [sys.executable, "-c", run]
        subprocess.run(cmd, cwd=ROOT, capture_output=True, timeout=60, check=False, env=CHILD_ENV)
        buf = io.StringIO()
        pstats.Stats(out.name, stream=buf).sort_stats("cumulative").print_stats(30)
    lines += ["", "cProfile of one `missionctl status --json` subprocess (cumulative):", buf.getvalue()]
    prof = cProfile.Profile()
    prof.enable()
    with ClusterClient.connect(cluster.endpoints, cluster=cluster.name, timeout=2.0, prefer=cluster.names) as c:
        c.status(20)
    prof.disable()
    buf = io.StringIO()
    pstats.Stats(prof, stream=buf).sort_stats("cumulative").print_stats(15)
    lines += ["cProfile of one in-process connect + status + close (cumulative):", buf.getvalue()]
    return "\n".join(lines)


def report(result: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    routers = f", through {result['routers']} routers" if result["routers"] else ", a full mesh"
    console.print(f"Python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load {load}; "
                  f"{result['daemons']} daemons (1 controller + {result['daemons'] - 1} workers{routers}) up in "
                  f"{result['startup_s']:.1f} s from the first `drd start`; {result['repeat']} runs each")
    for title, key in (("as a user runs it (subprocess wall time)", "subprocess"),
                       ("in this process, imports done (ClusterClient)", "in_process"),
                       ("each request of status(), on a connected client", "requests")):
        table = Table(title=title, title_justify="left")
        for col in ("what", "median ms", "p90 ms", "min ms", "max ms"):
            table.add_column(col, justify="left" if col == "what" else "right")
        for what, s in result[key].items():
            table.add_row(what, *(f"{s[k] * 1000:.1f}" for k in ("median", "p90", "min", "max")))
        console.print(table)
    if "idle" in result:
        report_idle(console, result)
    for goal in result["goals"]:
        verdict = "[bold green]PASS[/]" if goal["pass"] else "[bold red]MISS[/]"
        console.print(f"goal: {goal['what']}: {goal['measured']}  {verdict}")
    if result.get("stopped_by_sigkill"):
        console.print(f"[yellow]needed SIGKILL: {', '.join(result['stopped_by_sigkill'])}[/]")


def report_idle(console: Any, result: dict[str, Any]) -> None:
    from rich.table import Table

    idle_s, peer = result["idle_s"], result["peer"]
    table = Table(title=f"idle, per daemon with its children, over {idle_s:g} s (median by role); the peer: "
                        f"`python -m drd.bus.peer` x {peer['count']}, up in {peer['startup_s']:.1f} s",
                  title_justify="left")
    for col in ("role", "daemons", "processes", "PSS MB", "max PSS MB", "USS MB", "RSS MB", "CPU % of a core",
                "PSS / peer's"):
        table.add_column(col, justify="left" if col == "role" else "right")
    for role, f in [*result["idle"].items(), ("peer", peer["idle"])]:
        table.add_row(role, str(f["daemons"]), f"{f['processes']:g}", f"{f['pss_mb']:.1f}", f"{f['max_pss_mb']:.1f}",
                      f"{f['uss_mb']:.1f}", f"{f['rss_mb']:.1f}", f"{f['cpu_percent']:.2f}",
                      f"{f['pss_mb'] / peer['idle']['pss_mb']:.2f}x")
    console.print(table)
    if result["router_links"]:
        console.print("clients linked to each router: " + ", ".join(f"{r} {n}" for r, n in
                                                                    result["router_links"].items()))
    console.print(f"start: {result['daemons']} daemons {result['startup_s']:.1f} s, {peer['count']} peers "
                  f"{peer['startup_s']:.1f} s ({result['startup_s'] / peer['startup_s']:.2f}x the peer)")


def goals(result: dict[str, Any]) -> list[dict[str, Any]]:
    """Issue #15's goals with what this run measured: status < 0.5 s (median), every daemon idle <= 60 MB PSS
    with its workers (the largest counts) and <= 1 % of a core (the busiest role counts), all up <= 30 s."""
    status = result["subprocess"]["missionctl status --json"]["median"]
    out = [{"what": f"missionctl status of {result['daemons']} daemons < {GOAL:g} s (median)",
            "measured": f"{status:.3f} s" + (f", {len(result['status_incomplete'])} answers incomplete"
                                              if result["status_incomplete"] else ""),
            "pass": status < GOAL and not result["status_incomplete"]}]
    if "idle" in result:
        worst = max(f["max_pss_mb"] for f in result["idle"].values())
        out.append({"what": f"an idle daemon with its workers <= {IDLE_GOAL_MB:g} MB PSS (the largest)",
                    "measured": f"{worst:.1f} MB", "pass": worst <= IDLE_GOAL_MB})
        role, busiest = max(((r, f["cpu_percent"]) for r, f in result["idle"].items()), key=lambda rf: rf[1])
        out.append({"what": f"an idle daemon <= {IDLE_GOAL_CPU:g} % of a core (the busiest role's median)",
                    "measured": f"{busiest:.2f} % ({role})", "pass": busiest <= IDLE_GOAL_CPU})
    out.append({"what": f"{result['daemons']} daemons up in <= {START_GOAL:g} s",
                "measured": f"{result['startup_s']:.1f} s", "pass": result["startup_s"] <= START_GOAL})
    return out


def run(args: argparse.Namespace, tmp: Path) -> dict[str, Any]:
    """Start the cluster, measure, stop it (in a `finally`, also on Ctrl-C or SIGTERM)."""
    cluster = Cluster(tmp, args.daemons, args.routers)
    peers = Peers(tmp, cluster, args.daemons if args.idle else 0)
    result: dict[str, Any] = {}
    killed: list[str] = []
    try:
        cluster.start_all()
        startup = cluster.wait_up(START_TIMEOUT + 5.0 * args.daemons)
        up_at = time.monotonic()
        result = measure(cluster, args.repeat)
        result["router_links"] = router_links(cluster)
        if args.idle:
            time.sleep(max(0.0, up_at + args.settle - time.monotonic()))  # the workers kept warm at start go
            result["peer"] = {"count": args.daemons, "startup_s": peers.start(START_TIMEOUT + 5.0 * args.daemons)}
            every = {**{n: p.pid for n, p in cluster.procs.items()},
                     **{f"peer{i}": p.pid for i, p in enumerate(peers.procs)}}
            per = idle(every, args.idle)
            result["idle"] = by_role({n: f for n, f in per.items() if n in cluster.procs}, cluster.role)
            result["peer"]["idle"] = by_role({n: f for n, f in per.items() if n not in cluster.procs},
                                             lambda _: "peer")["peer"]
            result["idle_per_daemon"] = {n: f for n, f in per.items() if n in cluster.procs}
        if args.profile:
            result["profile"] = profile(cluster)
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not skip the stop
        try:
            peers.stop()
            killed = cluster.stop_all()
        finally:
            signal.signal(signal.SIGINT, signal.default_int_handler)
    result.update(daemons=args.daemons, routers=len(cluster.routers), repeat=args.repeat, startup_s=startup,
                  goal_s=GOAL, idle_s=args.idle, settle_s=args.settle, stopped_by_sigkill=killed)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--daemons", type=int, default=10, help="daemons: 1 controller and N-1 workers")
    parser.add_argument("--routers", type=int, default=None,
                        help="daemons that are also zenoh routers, the controller first (default: 2 from 20 "
                             "daemons, else 0: a full mesh)")
    parser.add_argument("--repeat", type=int, default=10, help="timed runs of each measurement")
    parser.add_argument("--idle", type=float, default=30.0,
                        help="seconds of idling over which CPU is measured, then memory (0: skip, and the peers)")
    parser.add_argument("--settle", type=float, default=KEEP_WARM + 5.0,
                        help="seconds after all are up before the idle measurement (the pools keep their workers "
                             f"{KEEP_WARM:g} s after a daemon starts)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument("--profile", action="store_true", help="also cProfile one in-process status")
    args = parser.parse_args()
    if args.routers is None:
        args.routers = 2 if args.daemons >= 20 else 0
    if args.daemons < 1 or args.repeat < 1 or args.idle < 0 or not 0 <= args.routers <= args.daemons:
        parser.error("--daemons and --repeat must be at least 1, --idle at least 0, --routers 0 to --daemons")

    def on_signal(signum: int, _frame: object) -> None:
        raise KeyboardInterrupt(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, on_signal)  # SIGTERM/SIGHUP unwind through the finally, like Ctrl-C
    signal.signal(signal.SIGHUP, on_signal)
    with tempfile.TemporaryDirectory(prefix="drd-bench-") as tmp:
        result = run(args, Path(tmp))
    prof = result.pop("profile", None)
    result["goals"] = goals(result)
    result["pass"] = all(g["pass"] for g in result["goals"])
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        report(result)
    if prof is not None:
        print(prof)


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt as e:
        sys.exit(f"interrupted ({e or 'SIGINT'}): every daemon started was stopped")
