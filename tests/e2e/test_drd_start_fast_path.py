"""`drd start`, light (issue #15: fifty daemons on one machine). It parses its options without typer's parameter
building when the use is plain (each daemon paid pydantic's import), and leaves everything else to typer, which
answers as before: the fast path must hand the command exactly what typer would, and decline what it is unsure of.
Its preflight imports every manifest's entry point in a forked child, so the daemon never holds the behaviors'
modules (its workers import them), while a broken entry point is refused as before."""

from __future__ import annotations

import functools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import typer

from drd.cli import drd
from tests.conftest import ROOT


def _recording_app() -> tuple[typer.Typer, dict[str, Any]]:
    """A typer app whose `start` has the real command's signature and records what typer passes."""
    seen: dict[str, Any] = {}

    @functools.wraps(drd.start)
    def recorder(**kwargs: Any) -> int:
        seen.update(kwargs)
        return 0

    app = typer.Typer(add_completion=False)
    app.command("start")(recorder)
    app.command("stop")(lambda: 0)  # two commands, as drd has: the name is then required
    return app, seen


@pytest.mark.parametrize("argv", [
    ["start", "--host", "ranger1"],
    ["start", "--host=ranger7", "--config", "fleet/hosts.yaml", "--run-dir", "/tmp/r", "--load-period", "0.2",
     "--peer-grace", "1"],
    ["start", "--host", "controller", "-c", "h.yaml", "-d", "--log-file", "a b.log", "--log-level", "debug",
     "--json", "-C", "extra1", "--components", "extra2"],
    ["start", "--hosts", "x.yaml", "--host", "r", "--load-period=1"],
])
def test_the_fast_path_passes_what_typer_passes(argv: list[str], monkeypatch: pytest.MonkeyPatch) -> None:
    app, seen = _recording_app()
    monkeypatch.setattr(drd, "app", app)
    call = drd.fast_start(argv)
    assert isinstance(call, functools.partial)
    assert app(argv, prog_name="drd", standalone_mode=False) == 0
    assert call.keywords == seen
    assert {k: type(v) for k, v in call.keywords.items()} == {k: type(v) for k, v in seen.items()}


@pytest.mark.parametrize("argv", [
    ["start"], ["start", "--config", "h.yaml"], ["start", "--host", "r", "--help"],
    ["start", "--host", "r", "--load-period", "0.001"], ["start", "--host", "r", "--load-period", "1e-1"],
    ["start", "--host", "r", "--json", "--json"], ["start", "--host", "r", "--host", "s"],
    ["start", "--host"], ["start", "--host", "r", "extra"], ["start", "--host", "r", "--peer-grace", "-1"],
    ["stop", "--all"], ["status"], ["--help"], [],
])
def test_the_fast_path_leaves_the_rest_to_typer(argv: list[str]) -> None:
    assert drd.fast_start(argv) is None


def test_drd_start_runs_without_pydantic_and_fails_as_before(tmp_path: Path) -> None:
    """The real entry point takes the fast path, and an unknown host is refused with the usual message."""
    hosts = tmp_path / "hosts.yaml"
    hosts.write_text("cluster: {name: fast, security: {mode: none}}\nhosts:\n"
                     "  controller: {endpoint: tcp/127.0.0.1:7447, roles: [controller]}\n")
    code = ("import atexit, sys\n"
            "atexit.register(lambda: print('pydantic loaded' if 'pydantic' in sys.modules else 'no pydantic'))\n"
            "sys.argv = ['drd', 'start', '--host', 'nohost', '--config', sys.argv[1], '--run-dir', sys.argv[2]]\n"
            "from drd.cli.drd import main\nmain()\n")
    r = subprocess.run([sys.executable, "-c", code, str(hosts), str(tmp_path / "run")], capture_output=True,
                       text=True, timeout=60, cwd=ROOT, check=False)
    assert r.returncode == 2, r.stderr
    assert "no host 'nohost'" in r.stderr and "hosts: controller" in r.stderr and "Traceback" not in r.stderr
    assert r.stdout.strip() == "no pydantic"
    r = subprocess.run([sys.executable, "-m", "drd.cli.drd", "start", "--config", str(hosts)], capture_output=True,
                       text=True, timeout=60, cwd=ROOT, check=False)
    assert r.returncode == 2 and "Missing option '--host'" in r.stderr  # typer's own answer, as before


MARKED = """name: MarkedWait
kind: behavior
description: A Wait whose module says which processes import it.
entry_point: marked_wait:MarkedWait
process: container
movable: true
"""


def test_the_daemon_itself_never_imports_the_behaviors_its_preflight_checks(tmp_path: Path) -> None:
    """A behavior module that writes the pid of every process importing it: the preflight's child and the worker
    pool's fork server do, the daemon does not."""
    (tmp_path / "extra" / "MarkedWait").mkdir(parents=True)
    (tmp_path / "extra" / "MarkedWait" / "manifest.yaml").write_text(MARKED)
    (tmp_path / "marked_wait.py").write_text(
        "import os\nfrom pathlib import Path\n\n"
        "with Path(os.environ['MARKER']).open('a') as f:\n    f.write(f'{os.getpid()}\\n')\n\n"
        "from components.behaviors.wait import Wait as MarkedWait  # noqa: E402,F401\n")
    hosts = tmp_path / "hosts.yaml"
    hosts.write_text("cluster: {name: marked, security: {mode: none}}\nhosts:\n"
                     f"  solo: {{endpoint: tcp/127.0.0.1:{free_port()}, roles: [controller, worker]}}\n")
    marker = tmp_path / "imported_by"
    env = {**os.environ, "MARKER": str(marker), "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    proc = subprocess.Popen([sys.executable, "-m", "drd.cli.drd", "start", "--host", "solo", "--config", str(hosts),
                             "-C", str(tmp_path / "extra"), "--run-dir", str(tmp_path / "run")], cwd=tmp_path, env=env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        pidfile = tmp_path / "run" / "marked" / "solo.pid"
        deadline = time.monotonic() + 60
        while not (pidfile.exists() and json.loads(pidfile.read_text() or "{}").get("state") == "running"):
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read() if proc.stderr else ""
            time.sleep(0.05)
        while len(marker.read_text().split()) < 2 and time.monotonic() < deadline:  # the fork server, warm at start
            time.sleep(0.05)
        pids = [int(p) for p in marker.read_text().split()]
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)
    assert len(pids) >= 2 and proc.pid not in pids, (proc.pid, pids)


def test_a_broken_entry_point_is_still_refused_with_its_manifest(tmp_path: Path) -> None:
    """The child's answer is the parent's refusal: exit 2, the manifest named, no traceback, no pidfile."""
    (tmp_path / "extra" / "Broken").mkdir(parents=True)
    (tmp_path / "extra" / "Broken" / "manifest.yaml").write_text(
        MARKED.replace("MarkedWait", "Broken").replace("marked_wait:", "broken_mod:"))
    (tmp_path / "broken_mod.py").write_text("raise RuntimeError('half-written')\n")
    r = subprocess.run([sys.executable, "-m", "drd.cli.drd", "start", "--host", "controller", "--config",
                        str(ROOT / "hosts.yaml"), "-C", str(tmp_path / "extra"), "--run-dir", str(tmp_path / "run")],
                       cwd=tmp_path, capture_output=True, text=True, timeout=120, check=False,
                       env={**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])})
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "Broken/manifest.yaml: entry_point: module broken_mod failed to import: RuntimeError: half-written" \
        in r.stderr
    assert not list((tmp_path / "run").rglob("*.pid"))


def free_port() -> int:
    from net_support import free_ports

    return free_ports(1)[0]
