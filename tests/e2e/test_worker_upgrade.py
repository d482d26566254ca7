"""Workers of a daemon whose files change under it (an upgrade, a `git pull`): a new worker must not run the
daemon's main module again from disk (bus audit, defect 4), and a worker that cannot start is one host fault.

A probe process runs a `WorkerPool` as the daemon does (fork server, preloaded behavior module), from a copy of
the `drd` package in a temp dir, with its main module in that copy (`python -m upgrade_probe_main`). The test
changes the copy's files on disk between commands it sends the probe on stdin; the probe answers one JSON line
per command. Every process is ours: the probe kills its own fork server by pid, the test kills the probe by pid.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]

BEHAVIORS = '''
import os
from drd.runtime.component import Component, Status

class Pid(Component):
    """Says which process runs it."""

    def start(self):
        self.ctx.outputs["pid"] = os.getpid()

    def step(self, now):
        return Status.RUNNING
'''

PROBE = '''
import json, logging, os, sys, time
import psutil
from drd.cluster.pipe import Call, Run, Setup
from drd.cluster.workers import WorkerDied, WorkerPool

def run_one(pool):
    """Take a new worker (size 0: started now) and start a Pid component in it."""
    try:
        w = pool.take(timeout=30.0)
    except WorkerDied as e:
        return {"died": str(e), "fault": getattr(pool, "fault", None)}
    setup = Setup("upgrade_probe_behaviors:Pid", {}, {}, {})
    w.send(Run((Call("p", "start", 0.0, "", None, None, None, {}, setup, None),), {}))
    reply = w.recv(30.0).replies[0]
    pool.release(w)
    return {"worker": w.pid, "outputs": reply.outputs, "error": reply.error,
            "fault": getattr(pool, "fault", None)}

def kill_forkserver():
    """Our fork server, by pid: the next start begins a new one, which imports from disk. Not reaped here:
    multiprocessing reaps it (waitpid) when it sees it gone."""
    for child in psutil.Process().children():
        if "forkserver" in " ".join(child.cmdline()):
            child.kill()
            for _ in range(1000):  # bounded: until it is a zombie
                if child.status() == psutil.STATUS_ZOMBIE:
                    break
                time.sleep(0.01)
    return {"killed": True}

if __name__ == "__main__":
    logging.basicConfig(stream=sys.stderr, level=logging.INFO)
    pool = WorkerPool(0, preload=["upgrade_probe_behaviors"], call_timeout=30.0)
    for line in sys.stdin:
        cmd = line.strip()
        if cmd == "quit":
            break
        out = run_one(pool) if cmd == "run" else kill_forkserver()
        print(json.dumps(out), flush=True)
    pool.close()
    print(json.dumps({"closed": True}), flush=True)
'''


class Probe:
    """The probe process, driven one command (a stdin line) at a time."""

    def __init__(self, copy: Path) -> None:
        env = {**os.environ, "PYTHONPATH": str(copy)}
        self.proc = subprocess.Popen([sys.executable, "-m", "upgrade_probe_main"], cwd=copy, env=env, text=True,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)

    def ask(self, cmd: str) -> dict[str, Any]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(cmd + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        assert line, f"the probe died: {self.stderr()}"
        answer: dict[str, Any] = json.loads(line)
        return answer

    def stderr(self) -> str:
        self.proc.kill()
        return self.proc.communicate(timeout=30)[1]


@pytest.fixture
def copy(tmp_path: Path) -> Path:
    """A private copy of the package (the daemon's installation), the probe as its main module."""
    shutil.copytree(ROOT / "drd", tmp_path / "drd", ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "upgrade_probe_main.py").write_text(PROBE)
    (tmp_path / "upgrade_probe_behaviors.py").write_text(BEHAVIORS)
    return tmp_path


@pytest.fixture
def probe(copy: Path) -> Iterator[Probe]:
    p = Probe(copy)
    yield p
    if p.proc.poll() is None:
        p.proc.kill()  # by pid: ours
    p.proc.wait(timeout=30)


def test_a_new_worker_starts_after_the_main_module_became_unimportable(copy: Path, probe: Probe) -> None:
    before = probe.ask("run")
    assert before["error"] == "" and before["outputs"]["pid"] == before["worker"]
    # the upgrade: the main module (and the CLI the daemon runs as main) now need what the running daemon lacks
    (copy / "upgrade_probe_main.py").write_text("raise ImportError('upgraded: not the running version')\n")
    (copy / "drd" / "cli" / "drd.py").write_text("from drd.cli.common import NOT_IN_THE_RUNNING_VERSION\n")
    after = probe.ask("run")
    assert "died" not in after, after  # before the fix: WorkerDied (exit code 1), the worker re-ran main
    assert after["error"] == "" and after["outputs"]["pid"] == after["worker"] != before["worker"]
    assert after["fault"] == ""
    assert probe.ask("quit") == {"closed": True}
    logs = probe.stderr()
    assert "upgraded: not the running version" not in logs and "Traceback" not in logs


def test_workers_that_cannot_start_are_one_host_fault_said_once(copy: Path, probe: Probe) -> None:
    workers = copy / "drd" / "cluster" / "workers.py"
    good = workers.read_text()
    assert probe.ask("run")["error"] == ""
    workers.write_text("raise ImportError('a broken installation')\n")  # a new fork server cannot load it
    probe.ask("killfs")
    failed = [probe.ask("run") for _ in range(4)]
    assert all("died" in f for f in failed), failed
    assert [f["fault"] != "" for f in failed] == [False, False, True, True]  # FAULT_AFTER = 3 in a row
    assert "this host's worker processes cannot start (died (exit code 1))" == failed[-1]["died"]
    assert failed[0]["died"].startswith("a worker process could not start")
    workers.write_text(good)  # repaired: the next start succeeds and the fault is over
    again = probe.ask("run")
    assert "died" not in again, (again, probe.stderr())
    assert again["error"] == "" and again["fault"] == ""
    probe.ask("quit")
    logs = probe.stderr()
    errors = [line for line in logs.splitlines() if line.startswith("ERROR:")]
    assert len(errors) == 1 and "worker processes cannot start (died (exit code 1)), 3 times" in errors[0], logs
    assert logs.count("worker processes start again") == 1
