"""`missionctl check-trace` and the hosts file it reads sharable units from (docs audit 2, item 1): a `--config`
that does not exist is an error (exit 2, naming it); a trace's `granted` records say which units are shares, so
without any hosts file the check (and ../shared/tools/check_ownership.py) needs nothing more; an older trace
without `shares` gets a note that sharable units are unknown, so a shared radio's holders read as double holds
with a reason, not as a silent verdict. A real dry-run writes the trace; check-trace runs as a process from a
folder with no hosts.yaml."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]


def missionctl(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], cwd=cwd, capture_output=True, text=True, timeout=180, check=False)


@pytest.fixture(scope="module")
def trace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The corridor mission's trace: every RoomSurveillance holds ranger1.radio, which hosts.yaml marks sharable."""
    path = tmp_path_factory.mktemp("trace") / "run.jsonl"
    r = missionctl("dry-run", str(ROOT / "missions" / "corridor_surveillance.mission"), "--config",
                   str(ROOT / "hosts.yaml"), "--trace", str(path), cwd=ROOT)
    assert r.returncode == 0, r.stderr
    return path


def test_a_config_that_does_not_exist_exits_2_naming_it(trace: Path, tmp_path: Path) -> None:
    r = missionctl("check-trace", str(trace), "--config", "nonexist.yaml", cwd=tmp_path)
    assert r.returncode == 2, r.stdout
    assert f"nonexist.yaml: no such file (looked at {tmp_path / 'nonexist.yaml'})" in r.stderr
    assert "breach" not in r.stdout
    j = missionctl("check-trace", str(trace), "--config", "nonexist.yaml", "--json", cwd=tmp_path)
    assert j.returncode == 2 and json.loads(j.stderr)["looked"] == [str(tmp_path / "nonexist.yaml")]


def test_without_a_hosts_file_the_trace_says_which_grants_are_shares(trace: Path, tmp_path: Path) -> None:
    granted = [json.loads(line) for line in trace.read_text().splitlines() if '"granted"' in line]
    assert all("ranger1.radio" not in g["resources"].values() for g in granted)  # a share is not a hold ...
    assert {g["shares"].get("scout.radio") for g in granted} == {"ranger1.radio"}  # ... it is said as one
    r = missionctl("check-trace", str(trace), cwd=tmp_path)
    assert r.returncode == 0 and "0 breaches" in r.stdout and "unknown" not in r.stdout, r.stdout
    tool = ROOT.parent / "shared" / "tools" / "check_ownership.py"
    if tool.is_file():  # the outside checker, with no --sharable: no double hold either
        out = subprocess.run([sys.executable, str(tool), str(trace)], capture_output=True, text=True, timeout=60,
                             check=False)
        assert out.returncode == 0 and "0 from a non-holder, 0 double holds" in out.stdout, out.stdout


def test_an_older_trace_without_a_hosts_file_says_sharable_units_are_unknown(trace: Path, tmp_path: Path) -> None:
    older = tmp_path / "older.jsonl"  # as drd wrote it before `shares`: the radio among the held resources
    lines = []
    for line in trace.read_text().splitlines():
        r = json.loads(line)
        if r["kind"] == "granted":
            r["resources"] = {**r["resources"], **r.pop("shares")}
        lines.append(json.dumps(r))
    older.write_text("\n".join(lines) + "\n")
    r = missionctl("check-trace", str(older), cwd=tmp_path)
    assert r.returncode == 1  # the radio's holders are double holds when nothing says it is sharable ...
    assert "double hold: ranger1.radio" in r.stdout
    assert "sharable units unknown: no hosts file" in r.stdout  # ... and the output says why
    assert "--config" in r.stdout and "--sharable" in r.stdout
    j = missionctl("check-trace", str(older), "--json", cwd=tmp_path)
    [result] = json.loads(j.stdout)
    assert result["sharable"] is None and "sharable units unknown" in result["note"]


def test_with_the_hosts_file_the_radio_is_shared_and_nothing_is_said(trace: Path, tmp_path: Path) -> None:
    r = missionctl("check-trace", str(trace), "--config", str(ROOT / "hosts.yaml"), cwd=tmp_path)
    assert r.returncode == 0, r.stdout
    assert "unknown" not in r.stdout and "0 breaches" in r.stdout
    j = missionctl("check-trace", str(trace), "--sharable", "ranger1.radio", "--json", cwd=tmp_path)
    [result] = json.loads(j.stdout)
    assert j.returncode == 0 and result["sharable"] == ["ranger1.radio"] and "note" not in result


def test_a_trace_cut_at_a_lines_end_is_no_pass(trace: Path, tmp_path: Path) -> None:
    """Clients audit 9, D4: every line of the first 500 is a whole record, so the cut went unseen and the trace
    passed; a mission with records and no `finished` is the sign of a cut (docs/trace.md: never a pass)."""
    cut = tmp_path / "cut.jsonl"
    cut.write_text("".join(trace.read_text().splitlines(keepends=True)[:500]))
    r = missionctl("check-trace", str(cut), "--config", str(ROOT / "hosts.yaml"), "--json", cwd=tmp_path)
    [result] = json.loads(r.stdout)
    assert r.returncode == 1 and not result["ok"], r.stdout
    assert [b["kind"] for b in result["breaches"]] == ["unfinished"]
    assert "CorridorSurveillance-1 has no `finished` record" in result["breaches"][0]["detail"]
    whole = missionctl("check-trace", str(trace), "--config", str(ROOT / "hosts.yaml"), cwd=tmp_path)
    assert whole.returncode == 0, whole.stdout
