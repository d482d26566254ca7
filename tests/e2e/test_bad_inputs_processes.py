"""Robustness audit 3 (bad input) through the real commands: a malformed --connect on every command that takes it
(D3), `missionctl run` of a folder (D11), `drd status`/`drd stop` of a run dir that is a file or missing (D11).
Each fails on the code before the fix (exit 70 with zenoh's Rust paths; "no such file"; exit 0)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from tests.cluster_support import DRD, MISSIONCTL
from tests.conftest import ROOT


def run(cmd: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)


@pytest.mark.parametrize("args", [["hosts"], ["status"], ["components"], ["resources"],
                                  ["run", "missions/corridor_surveillance.mission"], ["stop", "X-1"]])
def test_a_malformed_connect_is_refused_naming_the_option(args: list[str]) -> None:
    r = run([*MISSIONCTL, *args, "--connect", "garbage", "--timeout", "0.5"])
    assert r.returncode == 2, r.stdout + r.stderr
    assert "error: --connect garbage: expected tcp/HOST:PORT or udp/HOST:PORT" in r.stderr
    assert ".rs:" not in r.stderr and "Json5Err" not in r.stderr


def test_a_malformed_connect_under_json_is_one_json_error() -> None:
    r = run([*MISSIONCTL, "status", "--json", "--connect", "tcp/host:99999", "--timeout", "0.5"])
    assert r.returncode == 2
    assert json.loads(r.stderr)["error"] == "--connect tcp/host:99999: port 99999 is out of range (1 to 65535)"


def test_run_of_a_folder_says_it_is_a_directory(tmp_path: Path) -> None:
    folder = tmp_path / "m.mission"
    folder.mkdir()
    r = run([*MISSIONCTL, "run", str(folder), "--connect", "tcp/127.0.0.1:9"])
    assert r.returncode == 2 and "is a directory" in r.stderr and "no such file" not in r.stderr


def test_drd_status_and_stop_refuse_a_run_dir_that_is_a_file_or_missing(tmp_path: Path) -> None:
    a_file = tmp_path / "f"
    a_file.write_text("x")
    r = run([*DRD, "status", "--run-dir", str(a_file)])
    assert r.returncode == 2 and f"--run-dir {a_file}: not a folder" in r.stderr
    r = run([*DRD, "stop", "--all", "--run-dir", str(tmp_path / "none")])
    assert r.returncode == 2 and "no such folder" in r.stderr
    r = run([*DRD, "status", "--run-dir", str(tmp_path)])
    assert r.returncode == 0 and "no drd in" in r.stdout  # an empty run dir is no error


def test_components_of_a_file_says_it_is_not_a_folder(tmp_path: Path) -> None:
    a_file = tmp_path / "manifest.yaml"
    a_file.write_text("name: X\n")
    r = run([*DRD, "components", "-C", str(a_file)])
    assert r.returncode == 2 and "not a folder" in r.stderr and "no such" not in r.stderr, r.stderr
