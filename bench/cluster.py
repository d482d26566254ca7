"""Cluster benchmark: `missionctl status` of a real N-daemon cluster on loopback, end to end.

Run `python bench/cluster.py [--daemons 10] [--repeat 10] [--json] [--profile]` (never by pytest). It
writes a hosts file in a temporary folder (1 controller and N-1 workers, each worker with a Ranger's
five simulated devices, every endpoint a free tcp/127.0.0.1 port), starts every daemon as its own
`python -m drd.cli.drd start` process, waits (bounded) until the controller sees all N hosts up, then
times, with `time.perf_counter`, N runs (median and p90) of:

- `missionctl status --json --config FILE`: a subprocess, as a user runs it (wall time, output read
  and checked: every host up);
- floors of that subprocess: `python -c pass` (interpreter start-up) and `python -c "import
  drd.cli.missionctl"` (start-up and every import missionctl does before it talks to a daemon);
- in this process, already imported: `ClusterClient.connect`, `client.status()` (the call
  `missionctl status` makes) and `close`, and each request status makes on its own.

Goal: `missionctl status` of a 10-daemon cluster < 1 s (median). Every daemon started is stopped in a
`finally` (SIGTERM to its process group, then SIGKILL, bounded), also on Ctrl-C, SIGTERM or an error.
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

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drd.daemon.client import ClusterClient  # noqa: E402
from tests.cluster_support import DRD, ROOT, free_ports, hosts_yaml  # noqa: E402

GOAL = 1.0  # seconds, median of `missionctl status`
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


class Cluster:
    """N `drd start` processes of ours, each the leader of its own process group (so a Ctrl-C in the
    terminal reaches only this script, whose `finally` stops them in order)."""

    def __init__(self, folder: Path, n: int) -> None:
        self.folder = folder
        self.names = ["controller"] + [f"ranger{i}" for i in range(1, n)]
        self.ports = free_ports(n)
        self.name = f"bench{os.getpid()}_{self.ports[0]}"
        self.hosts_file = folder / "hosts.yaml"
        self.hosts_file.write_text(hosts_yaml(self.name, self.names, self.ports, lease=LEASE))
        self.endpoints = [f"tcp/127.0.0.1:{p}" for p in self.ports]
        self.procs: dict[str, subprocess.Popen[bytes]] = {}

    def start_all(self) -> None:
        for name in self.names:
            cmd = [*DRD, "start", "--host", name, "--config", str(self.hosts_file),
                   "--run-dir", str(self.folder / "run")]
            with (self.folder / f"{name}.log").open("ab") as log:
                self.procs[name] = subprocess.Popen(cmd, cwd=ROOT, stdin=subprocess.DEVNULL, stdout=log,
                                                    stderr=log, start_new_session=True)

    def log(self, name: str) -> str:
        path = self.folder / f"{name}.log"
        return path.read_text(errors="replace")[-2000:] if path.exists() else ""

    def wait_up(self, timeout: float) -> float:
        """Seconds until the controller sees every host up; exits with the logs if it does not in time."""
        start = time.perf_counter()
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
                            return time.perf_counter() - start
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
    status_cmd = [*missionctl_cmd(), "status", "--json", "--config", str(cluster.hosts_file)]

    def all_up(stdout: str) -> None:
        data = json.loads(stdout)
        up = {h["name"] for h in data["hosts"] if h["state"] == "up"}
        if up != set(cluster.names) or data["errors"] or data["answered_by"] != "controller":
            raise SystemExit(f"status is not the whole cluster: up={sorted(up)} errors={data['errors']}")

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

    from rich.console import Console

    from drd.cli.common import print_json

    phases: dict[str, list[float]] = {k: [] for k in ("connect", "status()", "close", "connect+status+close",
                                                      "print_json (rich, to a pipe)",
                                                      "print_json (missionctl's, to a pipe)")}
    calls: dict[str, list[float]] = {k: [] for k in ("daemons()", "hosts()", "components()", "daemon_status()",
                                                      "resources()", "missions()")}
    for i in range(repeat + 1):  # the first round is a warm-up
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
        if i:
            for k, v in (("connect", t1 - t0), ("status()", t2 - t1), ("close", t4 - t3),
                         ("connect+status+close", (t1 - t0) + (t2 - t1) + (t4 - t3))):
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
    return {"subprocess": {k: stats(v) for k, v in wall.items()},
            "in_process": {k: stats(v) for k, v in phases.items()},
            "requests": {k: stats(v) for k, v in calls.items()}}


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
    console.print(f"Python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load {load}; "
                  f"{result['daemons']} daemons (1 controller + {result['daemons'] - 1} workers) up in "
                  f"{result['startup_s']:.1f} s; {result['repeat']} runs each")
    for title, key in (("as a user runs it (subprocess wall time)", "subprocess"),
                       ("in this process, imports done (ClusterClient)", "in_process"),
                       ("each request of status(), on a connected client", "requests")):
        table = Table(title=title, title_justify="left")
        for col in ("what", "median ms", "p90 ms", "min ms", "max ms"):
            table.add_column(col, justify="left" if col == "what" else "right")
        for what, s in result[key].items():
            table.add_row(what, *(f"{s[k] * 1000:.1f}" for k in ("median", "p90", "min", "max")))
        console.print(table)
    median = result["subprocess"]["missionctl status --json"]["median"]
    verdict = "[bold green]PASS[/]" if result["pass"] else "[bold red]MISS[/]"
    console.print(f"goal: missionctl status of a {result['daemons']}-daemon cluster < {GOAL:g} s (median): "
                  f"{median:.3f} s  {verdict}")
    if result.get("stopped_by_sigkill"):
        console.print(f"[yellow]needed SIGKILL: {', '.join(result['stopped_by_sigkill'])}[/]")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--daemons", type=int, default=10, help="daemons: 1 controller and N-1 workers")
    parser.add_argument("--repeat", type=int, default=10, help="timed runs of each measurement")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument("--profile", action="store_true", help="also cProfile one in-process status")
    args = parser.parse_args()
    if args.daemons < 1 or args.repeat < 1:
        parser.error("--daemons and --repeat must be at least 1")

    def on_signal(signum: int, _frame: object) -> None:
        raise KeyboardInterrupt(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, on_signal)  # SIGTERM/SIGHUP unwind through the finally, like Ctrl-C
    signal.signal(signal.SIGHUP, on_signal)
    with tempfile.TemporaryDirectory(prefix="drd-bench-") as tmp:
        cluster = Cluster(Path(tmp), args.daemons)
        killed: list[str] = []
        try:
            cluster.start_all()
            startup = cluster.wait_up(START_TIMEOUT + 5.0 * args.daemons)
            result = measure(cluster, args.repeat)
            prof = profile(cluster) if args.profile else None
        finally:
            signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not skip the stop
            try:
                killed = cluster.stop_all()
            finally:
                signal.signal(signal.SIGINT, signal.default_int_handler)
    result.update(daemons=args.daemons, repeat=args.repeat, startup_s=startup, goal_s=GOAL,
                  stopped_by_sigkill=killed,
                  **{"pass": result["subprocess"]["missionctl status --json"]["median"] < GOAL})
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
