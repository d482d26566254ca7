"""`drd start` parses its options without typer's parameter building when the use is plain (issue #15: fifty
daemons starting on one machine each paid pydantic's import), and leaves everything else to typer, which answers
as before. The fast path must hand the command exactly what typer would, and decline what it is unsure of."""

from __future__ import annotations

import functools
import subprocess
import sys
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
