"""`drd`: the Distributed Robotics Daemon's command line (one daemon per host).

`drd start --host NAME` runs this host's daemon (in the foreground, logging to stderr, or with
`--detach`); `drd stop` stops daemons by their pidfiles; `drd status` lists those of this machine.
See docs/daemon.md.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any, NoReturn

import typer
from rich.table import Table
from rich.text import Text

from drd.cli.common import (
    OK,
    catalog,
    duration_text,
    end_now,
    err,
    fail,
    fail_all,
    out,
    print_json,
    run_app,
    version_option,
)
from drd.cli.common import version as installed_version
from drd.cli.options import MAX_WAIT, ComponentsOption
from drd.signals import set_soon
from dsl.catalog import Kind

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from drd.daemon.security import Transport
    from drd.hosts import Cluster
    from drd.preflight import StartCheck
    from dsl.catalog import Catalog, ComponentType, ParamSpec, RecordSpec

app = typer.Typer(help="The Distributed Robotics Daemon: one per host.", no_args_is_help=True,
                  add_completion=False, rich_markup_mode=None)
version_option(app, "drd")


@app.command()
def components(
    kind: Kind = typer.Option(None, "--kind", "-k", help="Only this kind: behavior, rc, arc or data.",
                              show_default=False),
    as_json: bool = typer.Option(False, "--json", help="Print the catalog as JSON."),
    extra: list[Path] = ComponentsOption,
) -> int:
    """List the component types this host knows from its manifests: parameters, needs, inputs, outputs, events."""
    cat = catalog(extra)
    types = sorted((t for t in cat.components.values() if kind is None or t.kind is kind),
                   key=lambda t: (t.kind.value, t.name))
    if as_json:
        print_json([_component_dict(t) for t in types])
        return OK
    table = Table(title="Component types", title_justify="left")
    table.add_column("name", no_wrap=True)
    table.add_column("kind", no_wrap=True)
    table.add_column("interface")
    for t in types:
        table.add_row(t.name, t.kind.value, Text("\n").join(_interface(t)) or Text("—", style="dim"))
    out.print(table)
    return OK


def _component_dict(t: ComponentType) -> dict[str, object]:
    """A component type as `drd components --json` gives it (durations in seconds, as manifests mean them)."""
    def records(specs: Sequence[RecordSpec]) -> list[dict[str, object]]:
        return [{"name": r.name, "type": r.type, "fields": dict(r.fields)} for r in specs]

    return {
        "name": t.name, "kind": t.kind.value, "description": t.description, "source": t.source,
        "params": [{"name": p.name, "type": p.type, "default": p.default, "required": p.required} for p in t.params],
        "needs": [{"name": n.name, "type": n.type, "of": list(n.of)} for n in t.needs],
        "inputs": [{"name": i.name, "type": i.type, "optional": i.optional} for i in getattr(t, "inputs", ())],
        "outputs": records(t.outputs), "events": records(t.events),
        "parts": dict(t.parts), "fields": dict(t.fields),
    }


def _interface(t: ComponentType) -> list[Text]:
    """One line per kind of thing a component type declares, the way a mission writes it (`duration = 10s`)."""
    def default(p: ParamSpec) -> str:
        if p.required:
            return ""
        value = duration_text(float(p.default)) if p.type == "duration" and isinstance(p.default, int | float) \
            else p.default
        return f" = {value}"

    def fields(r: RecordSpec) -> str:
        return ", ".join(f"{k}: {v}" for k, v in r.fields.items())

    def output(r: RecordSpec) -> str:  # `door: Door`, or a record of fields: `waited: {seconds: float}`
        return f"{r.name}: {r.type}" if r.type not in ("record", "event") else f"{r.name}: {{{fields(r)}}}"

    def event(r: RecordSpec) -> str:  # as a mission emits it: `MotionDetected(area: float)`
        return f"{r.name}({fields(r)})"

    rows = [
        ("params", [f"{p.name}: {p.type}{default(p)}" for p in t.params]),
        ("needs", [f"{n.name}: {n.type}" + (f" of [{', '.join(n.of)}]" if n.of else "") for n in t.needs]),
        ("inputs", [f"{i.name}: {i.type}" + (" (optional)" if i.optional else "") for i in getattr(t, "inputs", ())]),
        ("outputs", [output(o) for o in t.outputs]),
        ("events", [event(e) for e in t.events]),
        ("parts", [f"{k}: {v}" for k, v in t.parts.items()]),
        ("fields", [f"{k}: {v}" for k, v in t.fields.items()]),
    ]
    return [Text.assemble((f"{what} ", "dim"), ", ".join(items)) for what, items in rows if items]


@app.command()
def version(as_json: bool = typer.Option(False, "--json", help="Print as JSON.")) -> int:
    """Print drd's version (also `drd --version`)."""
    if as_json:
        print_json({"program": "drd", "version": installed_version()})
    else:
        out.print(f"drd {installed_version()}")
    return OK


RunDirOption = typer.Option(None, "--run-dir", show_default=False,
                            help="Where pidfiles live (default: $DRD_RUN_DIR, else ~/.drd/run).")
READY_TIMEOUT = 30.0  # how long `drd start --detach` waits for the daemon to declare its services


def _security_hint(cluster: Any) -> str:
    """What to do about a refused transport: the configured security's requirement, or the open cluster's limits."""
    from drd.hosts import SecurityMode

    if cluster.security.mode is not SecurityMode.NONE:
        return "security is configured, so drd will not start without it"
    return "see docs/security.md: an open cluster is for this machine, or a network said to be open"


@app.command()
def start(
    host: str = typer.Option(..., "--host", help="This host's name in the hosts file.", show_default=False),
    config: Path = typer.Option(Path("hosts.yaml"), "--config", "-c", "--hosts",
                                help="The cluster's hosts file (`--hosts` is an alias)."),
    detach: bool = typer.Option(False, "--detach", "-d", help="Run in the background; log to --log-file."),
    log_file: Path = typer.Option(None, "--log-file", show_default=False,
                                  help="Log here instead of stderr (default with --detach: RUN_DIR/HOST.log);"
                                  " it rolls over at 10 MB, keeping 3 old files."),
    run_dir_opt: Path = RunDirOption,
    load_period: float = typer.Option(1.0, "--load-period", min=0.01, max=MAX_WAIT,
                                      help="Seconds between load reports (at most a third of the lease is used)."),
    peer_grace: float = typer.Option(3.0, "--peer-grace", min=0.0, max=MAX_WAIT,
                                     help="Seconds to wait for the peers before naming the unreachable ones."),
    log_level: str = typer.Option("info", "--log-level", help="debug, info, warning or error."),
    as_json: bool = typer.Option(False, "--json", help="With --detach: print the started daemon as JSON."),
    extra: list[Path] = ComponentsOption,
) -> int:
    """Start this host's daemon: join the cluster, report load, serve the Component Database (and, on
    the controller, the Resource Controller Manager and the Mission Executive). Stops on SIGTERM/SIGINT.
    First, a zero Twist to each `ros2` Drive of this host's robots (one a crashed daemon left driving stops);
    the controller sends one to a lost host's robots (docs/ros2.md "Safety")."""
    from drd.daemon import runfiles
    from drd.daemon.security import SecurityError, transport

    level = getattr(logging, log_level.upper(), None)
    if not isinstance(level, int):
        fail(f"--log-level {log_level}: expected debug, info, warning or error")
    cat = catalog(extra)
    cluster = _load_cluster(config, cat)
    try:
        cluster.host(host)
    except KeyError:
        fail(f"no host {host!r} in {config} (hosts: {', '.join(h.name for h in cluster.hosts)})")
    check = _preflight(cluster, host, cat)  # before any process or pidfile: a typo fails here
    if check.problems:
        fail_all(check.problems, hint="see docs/drivers.md (drivers), docs/components.md (manifests), docs/worlds.md")
    try:
        tr = transport(cluster, daemon=True, host=host)
    except SecurityError as e:
        fail_all(e.problems, hint=_security_hint(cluster))
    rd = runfiles.run_dir(run_dir_opt)
    try:
        runfiles.prepare(rd, cluster.name)
    except OSError as e:
        fail(f"run directory {rd}: cannot write there ({e.strerror or e})",
             hint="give a folder this user can write with --run-dir or $DRD_RUN_DIR")
    running = runfiles.read(runfiles.path_of(rd, cluster.name, host))
    if running is not None and running.running():
        fail(f"drd for host {host} is already running (pid {running.pid})", hint=f"drd stop --host {host}")
    if detach:
        for line in check.warnings(host):  # the daemon logs them too, in its log file
            err.print(f"warning: {line}", style="yellow", markup=False, highlight=False)
        return _detach(host, cluster.name, config, rd, log_file or rd / cluster.name / f"{host}.log", load_period,
                       peer_grace, log_level, extra, as_json)
    _configure_logging(host, log_file, level)
    for line in check.warnings(host):
        logging.getLogger("drd.daemon").warning("%s", line)
    return _serve(cluster, host, cat, tr, rd, config, log_file, load_period, peer_grace, check.unavailable)


def _preflight(cluster: Cluster, host: str, cat: Catalog) -> StartCheck:
    """What keeps `host` from starting, and what it starts without (`drd.preflight.start_check`), found in a forked
    child while this process is still single-threaded. The check imports every manifest's entry point: in the daemon,
    those modules (the behaviors, numpy with them) would stay for its whole life, about 9 MB it never uses (its
    workers import them from the fork server). Checked in this process where a fork is not known to be safe (no
    /proc/self/task to count threads), or when the child gives no answer (an exception there is then raised here,
    as before)."""
    from drd.preflight import StartCheck, start_check

    tasks = Path("/proc/self/task")
    if not hasattr(os, "fork") or not tasks.is_dir() or len(list(tasks.iterdir())) != 1:
        return start_check(cluster, host, cat)
    read, write = os.pipe()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:  # the child: check, answer, and end without the interpreter's shutdown (the parent's to do)
        code = 1
        try:
            os.close(read)
            with os.fdopen(write, "w", encoding="utf-8") as answer:
                json.dump(dataclasses.asdict(start_check(cluster, host, cat)), answer)
            code = 0
        finally:
            os._exit(code)
    os.close(write)
    with os.fdopen(read, encoding="utf-8") as answer:
        text = answer.read()
    _, status = os.waitpid(pid, 0)
    try:
        found: dict[str, Any] = json.loads(text) if os.waitstatus_to_exitcode(status) == 0 else {}
        return StartCheck([str(p) for p in found["problems"]],
                          {str(k): str(v) for k, v in found["unavailable"].items()})
    except (ValueError, TypeError, KeyError, AttributeError):  # no answer, or not the one asked for
        return start_check(cluster, host, cat)


def _load_cluster(config: Path, cat: Catalog) -> Cluster:
    from drd.hosts import HostsError, load_hosts

    try:
        return load_hosts(config, cat)
    except HostsError as e:
        fail_all(e.problems)


def _serve(cluster: Cluster, host: str, cat: Catalog, tr: Transport, rd: Path, config: Path, log_file: Path | None,
           load_period: float, peer_grace: float, unavailable: dict[str, str]) -> int:
    from drd.bus import BusError
    from drd.daemon import runfiles
    from drd.daemon.daemon import Daemon, DaemonConfig

    journal = rd / cluster.name / "journal.sqlite"  # the controller's missions, resumed after a crash
    daemon = Daemon(DaemonConfig(cluster, host, cat, tr, load_period=load_period, peer_grace=peer_grace,
                                 journal=journal, unavailable=unavailable))
    try:
        info = runfiles.claim(rd, host, cluster.name, str(config.absolute()), str(log_file or ""), daemon.roles)
    except runfiles.AlreadyRunning as e:
        fail(str(e), hint=f"drd stop --host {host}")
    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        logging.getLogger("drd.daemon").info("received %s, stopping", name)
        daemon.stop_reason = name
        set_soon(stop)

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    try:
        from drd.bus.zenoh_bus import zenoh_logs_from_env

        zenoh_logs_from_env()
        daemon.run(stop, ready=lambda: runfiles.mark(rd, info, "running"))
    except BusError as e:
        endpoint = tr.endpoints.get(host, cluster.host(host).endpoint)
        in_use = "already in use" in str(e).lower()
        fail(f"drd {host} cannot join the bus on {endpoint}: {e}",
             hint="is another process listening on that port?" if in_use else
             "check the endpoint in hosts.yaml and, with security, its files")
    finally:
        runfiles.release(rd, info)
    if daemon.stop_reason.startswith("conflict"):  # met another drd of this host name, which started first
        try:
            fail(f"drd {host} stopped: {daemon.stop_reason.removeprefix('conflict: ')}",
                 hint="host names are unique in a cluster: stop one of them, or start this one as another host")
        except typer.Exit as e:  # said; the process ends as a stopped daemon does (review)
            _exit_stopped(e.exit_code)
    _exit_stopped(OK)


#: Seconds a stopped daemon waits for the threads still running (a library's callback threads) before it exits.
LINGER = 2.0


def _exit_stopped(code: int) -> NoReturn:
    """End a stopped daemon (everything it ran is closed, its run file released) without the interpreter's
    shutdown: a library's thread still running would be waited for forever (zenoh's callback threads of a session
    nobody closed), or, a daemon thread in native code, torn down mid-call, and the process would abort after its
    `stopped` line ("FATAL: exception not rethrown", exit 134: ROS 2 audit 17, D5). Non-daemon threads get
    `LINGER` seconds to end first."""
    deadline = time.monotonic() + LINGER
    for t in threading.enumerate():
        if t is not threading.main_thread() and not t.daemon:
            t.join(max(0.0, deadline - time.monotonic()))
    left = [t.name for t in threading.enumerate() if t is not threading.main_thread() and not t.daemon
            and t.is_alive()]
    if left:
        logging.getLogger("drd.daemon").warning("exiting with %d thread(s) still running: %s", len(left),
                                                ", ".join(sorted(left)[:5]))
    end_now(code)


def _configure_logging(host: str, log_file: Path | None, level: int) -> None:
    """This process's logging: one handler, and rate limits on what peers can make us log."""
    from drd.daemon import logs

    logs.install_daemon_limits()
    handler: logging.Handler
    if log_file is not None:
        log_file.parent.mkdir(parents=True, exist_ok=True)
        handler = logs.RotatingLog(log_file)  # bounded, and reopened after an external logrotate
    else:
        handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logs.OneLine(f"%(asctime)s {host} %(levelname)s %(name)s: %(message)s"))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)


def _detach(host: str, cluster: str, config: Path, rd: Path, log_file: Path, load_period: float, peer_grace: float,
            log_level: str, extra: list[Path], as_json: bool = False) -> int:
    """Start the daemon as a new session in the background and wait until it serves (bounded)."""
    from drd.daemon import runfiles

    log_file = log_file.absolute()
    log_file.parent.mkdir(parents=True, exist_ok=True)
    # -P: not the working directory first on the import path, as `python -m` puts it (a foreground `drd start` has
    # it nowhere): a user's package there shadowed their PYTHONPATH (reverify audit 7, D-e); drd itself is found
    # where this process found it
    args = [sys.executable, "-P", "-m", "drd.cli.drd", "start", "--host", host, "--config", str(config.absolute()),
            "--run-dir", str(rd.absolute()), "--log-file", str(log_file), "--load-period", str(load_period),
            "--peer-grace", str(peer_grace), "--log-level", log_level]
    for folder in extra or ():
        args += ["--components", str(Path(folder).absolute())]
    here = str(Path(__file__).resolve().parents[2])  # the folder holding the drd package
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (os.environ.get("PYTHONPATH", ""), here) if p)}
    with log_file.open("ab") as fh:
        proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=fh, stderr=fh, start_new_session=True, env=env)
    deadline = time.monotonic() + READY_TIMEOUT
    while time.monotonic() < deadline:
        info = runfiles.read(runfiles.path_of(rd, cluster, host))
        if info is not None and info.pid == proc.pid and info.state == "running":
            if as_json:
                print_json({"host": host, "pid": proc.pid, "log": str(log_file), "state": "running"})
            else:
                out.print(f"drd {host} started (pid {proc.pid}); log: {log_file}")
            return OK
        if proc.poll() is not None:
            tail = log_file.read_text(encoding="utf-8", errors="replace").strip().splitlines()[-5:]
            for line in tail:
                err.print(Text(line, style="dim"))
            fail(f"drd {host} exited with code {proc.returncode} while starting; log: {log_file}")
        time.sleep(0.05)
    proc.kill()
    proc.wait(timeout=5)
    fail(f"drd {host} did not start serving within {READY_TIMEOUT:g} s; log: {log_file}")


@app.command()
def stop(
    host: str = typer.Option(None, "--host", help="Stop this host's daemon.", show_default=False),
    all_: bool = typer.Option(False, "--all", help="Stop every daemon of one cluster (--cluster, or the only one "
                                                  "in the run dir)."),
    cluster: str = typer.Option(None, "--cluster", help="The cluster whose daemons to stop, when the run dir holds "
                                                        "several.", show_default=False),
    run_dir_opt: Path = RunDirOption,
    timeout: float = typer.Option(10.0, "--timeout", min=0.0, max=MAX_WAIT, help="Seconds to wait before SIGKILL."),
    as_json: bool = typer.Option(False, "--json", help="Print what was stopped as JSON."),
) -> int:
    """Stop daemons started on this machine: SIGTERM, wait (bounded), then SIGKILL. Only one cluster's: two
    clusters sharing a machine never stop each other's daemons. With --all, the controller goes first and the
    others once it is gone (each step bounded by --timeout): its running missions stay journaled and the next
    `drd start` of the hosts resumes them (a simulated mission whose simulator stopped too ends instead, saying
    its world started again); `missionctl stop` first ends them."""
    from drd.daemon import runfiles

    if (host is None) == (not all_):
        fail("give either --host NAME or --all")
    rd = _looked_in(run_dir_opt)
    found = _one_cluster([(p, i) for p, i in runfiles.pidfiles(rd) if i is None or host is None or i.host == host],
                         cluster, host)
    if host is not None and not found:
        others = ", ".join(f"{i.host} ({i.cluster})" for _, i in runfiles.pidfiles(rd) if i is not None) or "none"
        fail(f"no drd for host {host} in {rd} (daemons there: {others})")
    if not found:
        if as_json:
            print_json({"run_dir": str(rd), "daemons": []})
        else:
            out.print(f"no drd running in {rd}")
        return OK
    infos = [i for _, i in found if i is not None]
    outcome = runfiles.stop(infos, timeout)
    rows: list[dict[str, object]] = []
    for path, info in found:
        if info is None:
            path.unlink(missing_ok=True)
            rows.append({"host": None, "pid": None, "outcome": "unreadable pidfile removed", "pidfile": str(path)})
            if not as_json:
                out.print(f"removed unreadable pidfile {path}")
            continue
        what = outcome[info.pid]
        if what != "stopped" or path.exists():
            runfiles.release(rd, info)  # the daemon removes its own on a clean stop
        rows.append({"host": info.host, "pid": info.pid, "outcome": what, "pidfile": str(path)})
        text = {"stopped": f"stopped {info.host} (pid {info.pid})",
                "killed": f"killed {info.host} (pid {info.pid}): it did not stop within {timeout:g} s",
                "not running": f"{info.host} was not running (stale pidfile removed)"}[what]
        if not as_json:
            out.print(text)
    if as_json:
        print_json({"run_dir": str(rd), "daemons": rows})
    return OK


def _looked_in(run_dir_opt: Path | None) -> Path:
    """The run dir `stop` and `status` read: a file there, or a `--run-dir` that does not exist, is refused (exit 2),
    since "no drd in it" would hide a typo; the default one not made yet just holds no daemon."""
    from drd.daemon import runfiles

    rd = runfiles.run_dir(run_dir_opt)
    if rd.exists() and not rd.is_dir():
        fail(f"{'--run-dir' if run_dir_opt is not None else 'run dir'} {rd}: not a folder",
             hint="the folder `drd start` keeps its pidfiles in")
    if run_dir_opt is not None and not rd.exists():
        fail(f"--run-dir {rd}: no such folder (looked at {rd.absolute()})",
             hint="the folder `drd start --run-dir` was given")
    return rd


def _one_cluster(found: list[tuple[Path, Any]], cluster: str | None, host: str | None) -> list[tuple[Path, Any]]:
    """The pidfiles of one cluster: `cluster`, else the only one among `found`; several and none named is refused,
    naming them (a bare `drd stop` must never stop another cluster's daemons)."""
    names = sorted({i.cluster for _, i in found if i is not None})
    if cluster is not None:
        return [(p, i) for p, i in found if i is not None and i.cluster == cluster]
    if len(names) > 1:
        what = f"host {host}" if host else "daemons"
        fail(f"{what} of {len(names)} clusters run here ({', '.join(names)}): say which", hint=f"drd stop "
             f"{'--host ' + host if host else '--all'} --cluster {names[0]}", clusters=names)
    return found


@app.command()
def status(
    run_dir_opt: Path = RunDirOption,
    as_json: bool = typer.Option(False, "--json", help="Print as JSON."),
) -> int:
    """List the daemons started on this machine (from their pidfiles). `missionctl status` shows the cluster."""
    from dataclasses import asdict

    from drd.daemon import runfiles

    rd = _looked_in(run_dir_opt)
    rows = [(i, i.running()) for _, i in runfiles.pidfiles(rd) if i is not None]
    if as_json:
        print_json([{**asdict(i), "alive": alive} for i, alive in rows])
        return OK
    if not rows:
        out.print(f"no drd in {rd}")
        return OK
    table = Table(title=f"daemons in {rd}", title_justify="left")
    for col in ("host", "cluster", "pid", "state", "config", "log"):
        table.add_column(col)
    for i, alive in rows:
        table.add_row(i.host, i.cluster, str(i.pid), i.state if alive else "dead (stale pidfile)", i.config, i.log)
    out.print(table)
    return OK


@app.command()
def sim(
    world: str = typer.Option(None, "--world", "-w", show_default=False,
                              help="A world name (worlds/NAME.yaml) or a path [default: the hosts file's "
                                   "cluster.world, else corridor]."),
    config: Path = typer.Option(Path("hosts.yaml"), "--config", "-c", "--hosts",
                                help="The hosts file whose robots are served (their devices and options)."),
    ros2: bool = typer.Option(False, "--ros2", help="Serve the robots as ROS 2 robots over rmw_zenoh (docs/ros2.md)."),
    listen: str = typer.Option("tcp/127.0.0.1:7447", "--listen",
                               help="The zenoh endpoint to listen on, as a robot's router does."),
    speed: float = typer.Option(1.0, "--speed", help="Sim time runs this many times real time."),
    domain: int = typer.Option(0, "--domain", help="The ROS domain id."),
    seed: int = typer.Option(0, "--seed", help="The simulation's seed."),
    as_json: bool = typer.Option(False, "--json", help="One JSON line when serving, one when stopped."),
    extra: list[Path] = ComponentsOption,
) -> int:
    """Run a world and serve its robots as ROS 2 robots (`--ros2`): `/<robot>/cmd_vel`, `odom`, `scan`, the camera
    and launcher topics of docs/ros2.md, in real time or at `--speed`, on a zenoh router that ROS 2 tools and drd's
    `ros2` drivers connect to. Stops on Ctrl-C or SIGTERM."""
    if not ros2:
        fail("drd sim serves a world over a protocol: give --ros2 (the only one so far)", hint="drd sim --ros2")
    if not (0 < speed < float("inf")):
        fail(f"--speed {speed:g}: expected a positive number")
    if not 0 <= domain <= 232:
        fail(f"--domain {domain}: a ROS domain id is 0 to 232")
    from drd.hosts import endpoint_problem

    if (problem := endpoint_problem(listen)) is not None:
        fail(f"--listen {listen}: {problem}", hint="e.g. --listen tcp/127.0.0.1:7447")
    cluster, sim_world, world_name = _served_team(config, world, extra)
    return _serve_ros2(cluster, sim_world, world_name, listen, speed, domain, seed, as_json)


def _served_team(config: Path, world: str | None, extra: list[Path]) -> tuple[Cluster, Any, str]:
    """The hosts file, the world it (or `--world`) names and its name, checked against each other; or a clear exit."""
    from drd.dryrun import locate_world
    from drd.sim import load_world
    from drd.sim.world import WorldError, check_hosts

    cat = catalog(extra)
    cluster = _load_cluster(config, cat)
    name = world or cluster.world
    found, tried = locate_world(name, [Path.cwd(), config.resolve().parent] if world else [config.resolve().parent])
    if found is None:
        fail(f"world {name!r}: no such file; looked at {', '.join(map(str, tried))}")
    try:
        sim_world = load_world(found)
    except WorldError as e:
        fail_all(e.problems)
    problems = check_hosts(sim_world, cluster)
    if problems:
        fail_all(problems)
    return cluster, sim_world, found.stem


def _serve_ros2(cluster: Cluster, sim_world: Any, world_name: str, listen: str, speed: float, domain: int,
                seed: int, as_json: bool) -> int:
    """Serve the robots until SIGTERM or Ctrl-C (`drd sim --ros2`); what any ROS 2 client sends is logged at most
    ten lines of a kind every ten seconds (`drd.daemon.logs.PEER_LOGGERS`)."""
    from drd.bus import BusError
    from drd.bus.ros2 import Ros2Session
    from drd.daemon import logs

    logs.install(*logs.PEER_LOGGERS)
    from drd.hw.ros2 import message_types
    from drd.sim import Simulation
    from drd.sim.ros2 import ServedRobots, serve
    from drd.sim.world import charged, hosts_charges

    try:  # the endpoint's form was checked (`endpoint_problem`): what fails here is the listening itself
        session = Ros2Session.listen(listen, types=message_types())
    except (BusError, ValueError) as e:
        unknown = "name or service not known" in str(e).lower() or "failed to lookup" in str(e).lower()
        fail(f"cannot listen on {listen}: {e}",  # the user's endpoint or their machine, not a bug of ours: 2
             hint="the host name does not resolve: listen on an address of this machine (tcp/127.0.0.1:PORT)"
             if unknown else "is another router or drd on that port?")
    stop = threading.Event()
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda _n, _f: set_soon(stop))
    try:
        served = ServedRobots(Simulation(charged(sim_world, hosts_charges(cluster)), seed=seed), cluster, session,
                              domain_id=domain)
        try:
            topics = {rid: r.topics for rid, r in served.robots.items()}
            if as_json:
                _json_line({"event": "serving", "endpoint": listen, "domain": domain, "world": world_name,
                            "speed": speed, "robots": {rid: [list(t) for t in ts] for rid, ts in topics.items()}})
            else:
                out.print(f"serving {world_name} as ROS 2 robots on {listen} (domain {domain}, {speed:g}x real "
                          f"time): {', '.join(topics) or 'no robot of the hosts file is in the world'}")
            sys.stdout.flush()
            reached = serve(served, stop, speed=speed)
        finally:
            served.close()
    finally:
        session.close()
    if as_json:
        _json_line({"event": "stopped", "sim_time": round(reached, 3)})
    else:
        out.print(f"stopped at {reached:.1f} s of sim time")
    return OK


def _json_line(data: dict[str, Any]) -> None:
    """One event of a long-running command as one JSON line (JSON Lines: a reader parses each as it comes)."""
    sys.stdout.write(json.dumps(data) + "\n")
    sys.stdout.flush()


def fast_start(argv: Sequence[str]) -> Callable[[], object] | None:
    """`drd start ...` parsed from the command's own typer signature, without typer's parameter building (its
    pydantic costs each daemon 0.07-0.1 s of CPU and 7.5 MB for good: 50 daemons starting on one machine pay it 50
    times). Only a plain, complete use: anything else (--help, a missing --host, an odd value) goes to typer."""
    from drd.cli.cluster import fast_command

    call = fast_command(app, argv, commands=("start",))
    if not isinstance(call, functools.partial) or any(v is ... for v in call.keywords.values()):
        return None
    return call


def main() -> None:
    run_app(app, "drd", fast=fast_start)


if __name__ == "__main__":
    main()
