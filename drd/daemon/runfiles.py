"""Pidfiles of the daemons running on this machine: `<run dir>/<cluster>/<host>.pid`, JSON.

Keyed by cluster and host, so two clusters on one machine (two checkouts, a test beside a deployment) never
refuse or stop each other's daemons; `drd stop --all` stops one cluster's.

The run dir is `--run-dir`, else `$DRD_RUN_DIR`, else `~/.drd/run`. A pidfile records the pid and
the process's creation time, so a stale file whose pid was reused by another program is never
taken for a running daemon (and never signalled). `drd stop` sends SIGTERM, waits (bounded), then
SIGKILL; the controllers first (by the roles their pidfiles record), and the others once they are gone: a
controller that sees its workers leave first fails the missions they ran, rather than keep them journaled
for the next start.
"""

from __future__ import annotations

import json
import os
import signal
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import psutil

from drd.errors import DrdError

ENV = "DRD_RUN_DIR"


def run_dir(explicit: Path | None = None) -> Path:
    """Where pidfiles (and detached daemons' logs) go."""
    if explicit is not None:
        return explicit
    env = os.environ.get(ENV)
    return Path(env) if env else Path.home() / ".drd" / "run"


def prepare(directory: Path, cluster: str) -> Path:
    """`directory`'s folder for `cluster`, created if need be and checked writable (a file made and removed): a
    start refuses here, naming the folder, rather than fail later with an error about some file in it.

    Raises:
        OSError: it cannot be made or written (not a folder, read-only, no permission).
    """
    folder = directory / cluster
    folder.mkdir(parents=True, exist_ok=True)
    probe = folder / f".probe-{os.getpid()}"
    probe.write_bytes(b"")
    probe.unlink()
    return folder


@dataclass(frozen=True, slots=True)
class PidFile:
    """One daemon's pidfile; `state` is `starting` until its services are declared, then `running`."""

    pid: int
    host: str
    cluster: str
    config: str
    started: float
    create_time: float
    state: str = "starting"
    log: str = ""
    roles: tuple[str, ...] = ()  # the host's roles (an older drd's pidfile: none known)

    def running(self) -> bool:
        """The process is alive (not a zombie) and is the one that wrote the file."""
        try:
            proc = psutil.Process(self.pid)
            return abs(proc.create_time() - self.create_time) < 0.05 and proc.status() != psutil.STATUS_ZOMBIE
        except psutil.Error:
            return False


class AlreadyRunning(DrdError):
    """A daemon for this host already runs from this run dir."""

    def __init__(self, info: PidFile, path: Path) -> None:
        super().__init__(f"drd for host {info.host} is already running (pid {info.pid}, pidfile {path})")
        self.info, self.path = info, path


def path_of(directory: Path, cluster: str, host: str) -> Path:
    return directory / cluster / f"{host}.pid"


def read(path: Path) -> PidFile | None:
    """The pidfile at `path`, or None when it is missing or not a pidfile."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return PidFile(**{**data, "roles": tuple(data.get("roles", ()))})
    except (OSError, ValueError, TypeError):
        return None


def write(path: Path, info: PidFile) -> None:
    """Write atomically (a reader never sees half a file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(asdict(info)), encoding="utf-8")
    os.replace(tmp, path)


def claim(directory: Path, host: str, cluster: str, config: str, log: str = "",
          roles: Sequence[str] = ()) -> PidFile:
    """Write this process's pidfile for `host`; a stale one is replaced.

    Raises:
        AlreadyRunning: a live daemon holds the pidfile.
    """
    path = path_of(directory, cluster, host)
    old = read(path)
    if old is not None and old.pid != os.getpid() and old.running():
        raise AlreadyRunning(old, path)
    me = psutil.Process(os.getpid())
    info = PidFile(os.getpid(), host, cluster, config, time.time(), me.create_time(), "starting", log, tuple(roles))
    write(path, info)
    return info


def mark(directory: Path, info: PidFile, state: str) -> PidFile:
    new = replace(info, state=state)
    write(path_of(directory, info.cluster, info.host), new)
    return new


def release(directory: Path, info: PidFile) -> None:
    """Remove our pidfile (only if it is still ours)."""
    path = path_of(directory, info.cluster, info.host)
    current = read(path)
    if current is not None and current.pid == info.pid:
        path.unlink(missing_ok=True)


def pidfiles(directory: Path) -> list[tuple[Path, PidFile | None]]:
    """Every pidfile in the run dir (each cluster's folder, and the top level where older versions wrote them),
    sorted by cluster then host; None for one that cannot be read."""
    if not directory.is_dir():
        return []
    return [(p, read(p)) for p in sorted([*directory.glob("*/*.pid"), *directory.glob("*.pid")])]


def stop(infos: Sequence[PidFile], timeout: float = 10.0, poll: float = 0.05) -> dict[int, str]:
    """Stop daemons: the controllers first (SIGTERM, wait up to `timeout`, then SIGKILL the stragglers), then the
    others the same way. A controller stopped while its workers still run keeps its running missions journaled
    as running, and the next start resumes them; workers stopped first would be lost hosts to it, and their
    missions' states would fail.

    Returns pid -> `stopped`, `killed` or `not running`.
    """
    first = [i for i in infos if "controller" in i.roles]
    out = _stop_group(first, timeout, poll) if first else {}
    return out | _stop_group([i for i in infos if i not in first], timeout, poll)


def _stop_group(infos: Sequence[PidFile], timeout: float, poll: float) -> dict[int, str]:
    """SIGTERM to each of `infos` at once, wait up to `timeout`, then SIGKILL the stragglers."""
    out: dict[int, str] = {}
    for info in infos:
        try:
            if info.running():
                os.kill(info.pid, signal.SIGTERM)
                continue
        except ProcessLookupError:
            pass
        out[info.pid] = "not running"
    waiting = [i for i in infos if i.pid not in out]
    deadline = time.monotonic() + timeout
    while waiting and time.monotonic() < deadline:
        for info in [i for i in waiting if not i.running()]:
            out[info.pid] = "stopped"
            waiting.remove(info)
        if waiting:
            time.sleep(poll)
    for info in waiting:
        try:
            os.kill(info.pid, signal.SIGKILL)
            out[info.pid] = "killed"
        except ProcessLookupError:
            out[info.pid] = "stopped"
    kill_deadline = time.monotonic() + 5.0
    while any(i.running() for i in waiting) and time.monotonic() < kill_deadline:
        time.sleep(poll)
    return out
