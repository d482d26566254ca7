"""CLI traps a newcomer met (issue #12), each through the real command: a file that is not a mission, an empty
one, values that make no sense, `--version`."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT

MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
DRD = [sys.executable, "-m", "drd.cli.drd"]


def missionctl(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)


@pytest.mark.parametrize("command", ["validate", "plan", "dry-run"])
def test_a_yaml_or_markdown_file_given_as_a_mission_says_so(command: str) -> None:
    r = missionctl(command, "hosts.yaml")
    assert r.returncode == 2, r.stdout + r.stderr
    assert "hosts.yaml is a YAML file, not a mission" in r.stderr and "--config" in r.stderr
    assert "Traceback" not in r.stderr
    r = missionctl(command, "README.md")
    assert r.returncode == 2 and "README.md is a Markdown file, not a mission" in r.stderr


@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n   # and another\n"])
def test_an_empty_or_comment_only_file_declares_no_mission(text: str, tmp_path: Path) -> None:
    empty = tmp_path / "empty.mission"
    empty.write_text(text)
    for command in ("validate", "dry-run"):
        r = missionctl(command, str(empty))
        assert r.returncode == 2, r.stdout + r.stderr
        assert "declares no mission" in r.stderr and "empty.mission:1:1" in r.stderr


@pytest.mark.parametrize(("option", "value"), [("--speed", "0"), ("--speed", "-1"), ("--until", "-5"),
                                               ("--until", "0"), ("--until", "inf"), ("--speed", "inf")])
@pytest.mark.parametrize("command", ["dry-run", "run"])
def test_values_that_make_no_sense_are_refused_before_anything_runs(command: str, option: str, value: str) -> None:
    r = missionctl(command, "missions/corridor_surveillance.mission", option, value)
    assert r.returncode == 2, r.stdout + r.stderr
    assert f"Invalid value for '{option}'" in r.stderr
    assert "mission" not in r.stdout.lower(), "nothing ran"


@pytest.mark.parametrize("command", ["status", "hosts", "resources"])
@pytest.mark.parametrize("value", ["inf", "1e308"])
def test_a_wait_for_ever_is_refused_before_anything_is_asked(command: str, value: str) -> None:
    """Cli audit 24, #3: `--timeout inf` was taken, and with no daemon answering the command never returned."""
    r = subprocess.run([*MISSIONCTL, command, "--timeout", value, "--connect", "tcp/127.0.0.1:9"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 2 and "Invalid value for '--timeout'" in r.stderr, r.stderr


def test_both_tools_say_their_version() -> None:
    from importlib.metadata import version

    r = missionctl("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"missionctl (drd) {version('drd')}"
    r = subprocess.run([*DRD, "--version"], cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 0 and r.stdout.strip() == f"drd (drd) {version('drd')}"


#: A child that runs `missionctl validate --json` through its console entry point, with a Ctrl-C landing where
#: `{where}` says: while the tool imports itself, or in the command (typer then answered exit 130 without a word).
CTRL_C_CHILD = """
import builtins, os, signal, sys
sys.argv = ["missionctl", "validate", "--json", "missions/corridor_surveillance.mission"]
real = builtins.__import__
def importing(name, *args, **kwargs):
    if name == "{where}":
        os.kill(os.getpid(), signal.SIGINT)
    return real(name, *args, **kwargs)
builtins.__import__ = importing
from drd.cli.entry import missionctl
missionctl()
"""


@pytest.mark.parametrize("where", ["drd.cli.missionctl", "drd.manifests"], ids=["while-importing", "in-the-command"])
def test_a_ctrl_c_at_any_moment_is_said_in_one_line_never_a_traceback(where: str) -> None:
    """Cli audit 24, #6: a Ctrl-C in the first tenths of a second printed a Python traceback (the tool was still
    importing itself, before its safety net), and one in a command was exit 130 and not a word."""
    r = subprocess.run([sys.executable, "-c", CTRL_C_CHILD.format(where=where)], cwd=ROOT, capture_output=True,
                       text=True, timeout=120, check=False)
    assert r.returncode == 130, (r.stdout, r.stderr[-2000:])
    assert "Traceback" not in r.stderr and json.loads(r.stderr) == {"error": "interrupted", "code": 130}, r.stderr


@pytest.mark.parametrize("args", [["status", "--config", "{d}"], ["hosts", "--config", "{d}"],
                                  ["dry-run", "missions/corridor_surveillance.mission", "--world", "{d}"]],
                         ids=["status", "hosts", "dry-run-world"])
def test_a_folder_given_as_a_file_is_called_a_folder(args: list[str], tmp_path: Path) -> None:
    """Cli audit 24, #7: a folder given as `--config` or `--world` was "no such file", though the path exists."""
    folder = tmp_path / "site.yaml"
    folder.mkdir()
    r = missionctl(*[a.format(d=folder) for a in args])
    said = r.stderr.replace(f"{folder}: is", f"{folder} is")  # `FILE: is a folder` (hosts), `FILE is a folder`
    assert r.returncode == 2 and f"{folder} is a folder" in said and "no such file" not in said, r.stderr


@pytest.mark.parametrize("command", [["validate", "--json"], ["plan", "--json"], ["plan", "--format", "json"]])
def test_json_on_stdout_stays_utf8_with_a_file_name_that_is_not(command: list[str], tmp_path: Path) -> None:
    """Cli audit 24, #5: a file name's byte 0xE9 went raw into the JSON result, which a strict reader refused."""
    name = os.fsdecode(b"caf\xe9.mission")
    (tmp_path / name).write_text("mission Cafe {\n    needs r: Ranger\n    Calibrate\n}\n")
    r = subprocess.run([*MISSIONCTL, *command, name], cwd=tmp_path, capture_output=True, timeout=120, check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "caf\udce9.mission" in json.dumps(json.loads(r.stdout.decode("utf-8")), ensure_ascii=False)
