"""Bad input costs little and says where (issue #18): files that are not regular files, files too large, garbage
that once made the parser's recovery quadratic, string literals that once cost 370 bytes a byte, YAML alias
bombs. Bounds are checked structurally (recoveries counted, memory traced); a subprocess timeout only guards
against a hang, it measures nothing."""

from __future__ import annotations

import os
import random
import re
import subprocess
import sys
import tracemalloc
from pathlib import Path

import pytest

from drd.cli.common import SHOWN_ERRORS
from dsl import parser as mission_parser
from dsl.loader import MAX_FILE_BYTES

MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
ROOT = Path(__file__).resolve().parents[2]


def missionctl(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], cwd=cwd, capture_output=True, text=True, timeout=120, check=False)


@pytest.mark.parametrize("kind", ["fifo", "directory", "device-import"])
def test_a_mission_that_is_not_a_regular_file_is_refused_unread(tmp_path: Path, kind: str) -> None:
    if kind == "fifo":
        os.mkfifo(tmp_path / "m.mission")
        target, what = "m.mission", "m.mission is a FIFO, not a regular file"
    elif kind == "directory":
        (tmp_path / "m.mission").mkdir()
        target, what = "m.mission", "m.mission is a directory, not a regular file"
    else:
        (tmp_path / "m.mission").write_text('import "/dev/zero"\nmission M {\n    Wait(duration: 1s)\n}\n')
        target, what = "m.mission", "m.mission:1:1: error: /dev/zero is a character device, not a regular file"
    done = missionctl("validate", target, cwd=tmp_path)
    assert done.returncode == 2 and what in done.stdout + done.stderr


def test_a_mission_over_the_size_limit_is_refused(tmp_path: Path) -> None:
    (tmp_path / "big.mission").write_text("# " + "x" * MAX_FILE_BYTES + "\nmission M {\n    Wait(duration: 1s)\n}\n")
    done = missionctl("validate", "big.mission", cwd=tmp_path)
    assert done.returncode == 2 and "big.mission is larger than 1 MiB" in done.stdout + done.stderr


def garbage(n: int, newlines: bool) -> str:
    rng = random.Random(n)
    text = "".join(rng.choice('abc{}()[]:;=<>-+ 0123"\n') for _ in range(n))
    return text if newlines else text.replace("\n", " ")


@pytest.mark.parametrize("newlines", [False, True])
def test_recovery_from_garbage_is_bounded(monkeypatch: pytest.MonkeyPatch, newlines: bool) -> None:
    seen: list[int] = []
    original = mission_parser._Recovery.__call__

    def counting(self: mission_parser._Recovery, e: object) -> bool:
        seen.append(1)
        return original(self, e)  # type: ignore[arg-type]

    monkeypatch.setattr(mission_parser._Recovery, "__call__", counting)
    _tree, errors = mission_parser.Parser().parse(garbage(20_000, newlines), "garbage.mission")
    assert errors and all(e.span.file == "garbage.mission" for e in errors)
    assert len(seen) <= mission_parser.MAX_RECOVERIES


def test_a_string_literal_costs_memory_in_proportion_to_its_size() -> None:
    text = 'mission M {\n    Wait(duration: 1s) as w\n    w -> done / log "' + "a" * 1_000_000 + '"\n}\n'
    parser = mission_parser.Parser()
    parser.parse("mission W {\n    Wait(duration: 1s)\n}\n", "warm.mission")
    tracemalloc.start()
    try:
        tree, errors = parser.parse(text, "long.mission")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert tree is not None and errors == []
    assert peak < 40 * len(text), f"{peak / len(text):.0f} bytes of memory per byte of text"


def test_garbage_at_the_command_line_is_one_located_error_and_exit_2(tmp_path: Path) -> None:
    (tmp_path / "g.mission").write_text(garbage(300_000, newlines=False), encoding="utf-8")
    done = missionctl("validate", "g.mission", cwd=tmp_path)
    shown = done.stdout + done.stderr
    assert done.returncode == 2 and "g.mission:1:" in shown and "Traceback" not in shown
    assert shown.count(": error: ") <= SHOWN_ERRORS


def test_a_yaml_alias_bomb_in_a_hosts_file_is_refused_with_its_line(tmp_path: Path) -> None:
    lines = ['a0: &a0 ["x", "x", "x", "x", "x", "x", "x", "x", "x", "x"]']
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, 12)]
    (tmp_path / "hosts.yaml").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (tmp_path / "m.mission").write_text("mission M {\n    Wait(duration: 1s)\n}\n", encoding="utf-8")
    done = missionctl("dry-run", "m.mission", "--config", "hosts.yaml", cwd=tmp_path)
    assert done.returncode == 2
    assert "hosts.yaml:6: invalid YAML: its aliases expand to more than 1,000,000 values" in done.stderr


def test_a_hosts_file_that_is_a_fifo_is_refused(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "hosts.yaml")
    (tmp_path / "m.mission").write_text("mission M {\n    Wait(duration: 1s)\n}\n", encoding="utf-8")
    done = missionctl("dry-run", "m.mission", "--config", "hosts.yaml", cwd=tmp_path)
    assert done.returncode == 2 and "not a regular file" in done.stderr


def test_a_long_source_line_is_shown_as_a_window_with_the_caret_under_the_span() -> None:
    from dsl.errors import EXCERPT_WIDTH, Span, excerpt

    line = "x" * 5000 + "BAD" + "y" * 5000
    shown = excerpt(Span("f.mission", 1, 5001, 1, 5004), {"f.mission": line})
    assert shown is not None
    assert len(shown.text) <= EXCERPT_WIDTH + 2 and shown.text.startswith("…") and shown.text.endswith("…")
    assert shown.text[shown.pad:shown.pad + shown.width] == "BAD"
    short = excerpt(Span("f.mission", 1, 3, 1, 6), {"f.mission": "a  BAD b"})
    assert short is not None and short.text == "a  BAD b" and (short.pad, short.width) == (2, 3)


def test_a_multiplicity_evaluated_above_the_limit_fails_at_its_start_without_creating_instances(
        tmp_path: Path) -> None:
    (tmp_path / "many.mission").write_text("mission Many {\n    var n: int = 5000\n    Wait(duration: 1s)[n]\n}\n",
                                           encoding="utf-8")
    (tmp_path / "trace.jsonl").touch()
    done = missionctl("dry-run", "many.mission", "--config", str(ROOT / "hosts.yaml"), "--json",
                      "--trace", "trace.jsonl", cwd=tmp_path)
    import json

    report = json.loads(done.stdout)
    assert done.returncode == 1 and report["outcome"] == "failure"
    assert report["reason"] == "Wait would create 5000 instances, above the limit of 1000"
    leaf = [c for c in report["failure_chain"] if c["leaf"]]  # the leaf says it too (its `exited` carries why)
    assert leaf == [{"path": "Many/Wait", "reason": "Wait would create 5000 instances, above the limit of 1000",
                     "leaf": True}]
    entered = [json.loads(line)["path"] for line in (tmp_path / "trace.jsonl").read_text().splitlines()
               if json.loads(line)["kind"] == "entered"]
    assert not any("[" in path for path in entered), "no instance may be created"


def chain_of_waits(states: int) -> str:
    lines = ["mission Chain {", "    start -> s0"]
    for i in range(states):
        lines += [f"    Wait(duration: 1s) as s{i}", f"    s{i} -> s{i + 1}"]
    return "\n".join([*lines, f"    Wait(duration: 1s) as s{states}", "}"]) + "\n"


def test_a_compile_past_its_budget_stops_with_one_located_error() -> None:
    """What a controller compiles for a client has a budget (`compile_text(..., budget=)`): past it the compiler
    stops where it is, at whichever stage, and says so there; with no budget the same text compiles."""
    from drd.manifests import load_catalog
    from dsl import compile_text

    catalog, text = load_catalog(), chain_of_waits(2_000)
    spent = compile_text(text, catalog, "chain.mission", budget=0.0)
    assert not spent.ok and spent.statechart is None
    [stop] = spent.diagnostics
    assert stop.code == "budget" and stop.span.file == "chain.mission"
    assert 1 <= stop.span.line <= text.count("\n") and "budget of 0 s" in stop.message
    assert "chain.mission:" in stop.render(spent.sources)
    assert compile_text(text, catalog, "chain.mission").ok


DRD = [sys.executable, "-c", "from drd.cli.drd import main; main()"]


def hosts_with(tmp_path: Path, old: str, new: str) -> Path:
    text = (ROOT / "hosts.yaml").read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "hosts.yaml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


def test_a_pasted_blob_as_a_driver_is_refused_naming_the_key_and_shown_cut(tmp_path: Path) -> None:
    hosts = hosts_with(tmp_path, "driver: sim, slice", "driver: " + "x" * 100_000 + ", slice")
    done = missionctl("dry-run", str(ROOT / "missions" / "corridor_surveillance.mission"), "--hosts", str(hosts),
                      cwd=tmp_path)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert re.search(r"hosts.yaml:\d+: hosts.ranger1.devices.drive.driver: 'x+… \(100,000 characters\) is too long"
                     r" for a name \(at most 64 characters\)", done.stderr), done.stderr
    assert max(len(line) for line in done.stderr.splitlines()) < 400  # the value cut, not echoed whole


def test_a_driver_that_does_not_exist_fails_the_dry_run_before_it_starts(tmp_path: Path) -> None:
    hosts = hosts_with(tmp_path, "scout3.foot: {type: Jump, driver: sim", "scout3.foot: {type: Jump, driver: serial")
    done = missionctl("dry-run", str(ROOT / "missions" / "corridor_surveillance.mission"), "--hosts", str(hosts),
                      "--json", cwd=tmp_path)
    assert done.returncode == 2 and done.stdout == ""  # no report: nothing ran
    assert "hosts.yaml: hosts.ranger1.devices.scout3.foot.driver: no module components.serial" in done.stderr


@pytest.mark.parametrize("where", ["under-a-file", "missing-parent"])
def test_a_run_directory_that_cannot_be_written_stops_drd_start_before_anything_starts(tmp_path: Path,
                                                                                      where: str) -> None:
    (tmp_path / "a-file").write_text("")
    run_dir = tmp_path / "a-file" / "run" if where == "under-a-file" else Path("/proc/drd-no-such/run")
    done = subprocess.run([*DRD, "start", "--host", "controller", "--config", str(ROOT / "hosts.yaml"),
                           "--run-dir", str(run_dir)], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          check=False)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert f"run directory {run_dir}: cannot write there" in done.stderr and "--run-dir" in done.stderr
    assert "started" not in done.stderr  # no daemon, no bus session: it refused first


def bogus_components(tmp_path: Path) -> Path:
    folder = tmp_path / "my_components" / "Bogus"  # not `components`: `python -c` would import it as drd's own
    folder.mkdir(parents=True)
    (folder / "manifest.yaml").write_text("name: Bogus\nkind: behavior\ndescription: Its code is not there.\n"
                                          "entry_point: nowhere.bogus:Bogus\nprocess: container\n")
    return folder.parent


def test_drd_start_refuses_a_manifest_whose_entry_point_is_missing_before_anything_starts(tmp_path: Path) -> None:
    done = subprocess.run([*DRD, "start", "--host", "controller", "--config", str(ROOT / "hosts.yaml"), "-C",
                           str(bogus_components(tmp_path)), "--run-dir", str(tmp_path / "run")], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "Bogus/manifest.yaml: entry_point: no module nowhere.bogus" in done.stderr
    assert not list((tmp_path / "run").rglob("*.pid"))  # no pidfile: it refused before claiming the host


def test_drd_start_of_the_simulators_host_refuses_a_world_that_is_not_there(tmp_path: Path) -> None:
    hosts = hosts_with(tmp_path, "world: corridor ", "world: nowhere ")
    done = subprocess.run([*DRD, "start", "--host", "ranger1", "--config", str(hosts), "--run-dir",
                           str(tmp_path / "run")], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          check=False)
    assert done.returncode == 2 and "hosts.yaml: cluster.world: no world 'nowhere'" in done.stderr


def test_a_dry_run_of_a_component_whose_code_is_missing_is_refused_before_it_runs(tmp_path: Path) -> None:
    (tmp_path / "m.mission").write_text("mission UsesBogus {\n    Bogus\n}\n")
    done = missionctl("dry-run", "m.mission", "--hosts", str(ROOT / "hosts.yaml"), "-C",
                      str(bogus_components(tmp_path)), "--json", cwd=tmp_path)
    assert done.returncode == 2 and done.stdout == ""
    assert "Bogus/manifest.yaml: entry_point: no module nowhere.bogus" in done.stderr


NESTED = """mission Nested {{
    Outer[{outer}]
}}
behavior Outer {{
    var n: int = {inner}
    Inner[{count}]
}}
behavior Inner {{
    Wait(duration: 1s)
}}
"""


def test_nested_multiplicities_are_bounded_together_where_written_and_when_evaluated(tmp_path: Path) -> None:
    """Semantics audit 18, #2: each multiplicity within the limit alone, `Outer[1000] { Inner[1000] }` validated as a
    million instances, and a tenth of it took 36 s and 1 GB for 2 s of sim time."""
    import json

    (tmp_path / "written.mission").write_text(NESTED.format(outer=1000, inner=0, count=1000))
    refused = missionctl("validate", "written.mission", cwd=tmp_path)
    assert refused.returncode == 2
    assert ("written.mission:6:10: error: Inner[1000] inside Outer[1000] makes 1,001,000 instances alive at once, "
            "above the limit of 1,000 in a mission") in refused.stderr, refused.stderr
    (tmp_path / "evaluated.mission").write_text(NESTED.format(outer=40, inner=30, count="n"))
    assert missionctl("validate", "evaluated.mission", cwd=tmp_path).returncode == 0  # n is not known before
    ran = missionctl("dry-run", "evaluated.mission", "--config", str(ROOT / "hosts.yaml"), "--json", cwd=tmp_path)
    report = json.loads(ran.stdout)
    assert ran.returncode == 1 and report["sim_time"] == 0.0, ran.stderr[-1000:]
    assert "Inner would create 30 instances, with 1000 already alive in the mission: above the limit of 1000 " \
           "instances in all" in report["reason"], report["reason"]
    # the count comes back as instances end: two multiplicities of 600 one after the other both run
    (tmp_path / "sequence.mission").write_text(
        "mission Sequence {\n    start -> First\n    Wait(duration: 1s)[600] as First\n"
        "    Wait(duration: 1s)[600] as Second\n    First -> Second\n    Second -> done\n}\n")
    ran = missionctl("dry-run", "sequence.mission", "--config", str(ROOT / "hosts.yaml"), "--json", cwd=tmp_path)
    assert ran.returncode == 0 and json.loads(ran.stdout)["outcome"] == "success", ran.stdout[-2000:]


def test_a_cluster_raises_the_instance_limit_for_its_missions_and_validate_checks_against_it(tmp_path: Path) -> None:
    """`cluster.limits.instances`: the written bound, the evaluated one and `validate --config` all follow it."""
    import json

    hosts = hosts_with(tmp_path, "  lease: 3s\n", "  lease: 3s\n  limits: {instances: 1500, compile: 30s}\n")
    (tmp_path / "written.mission").write_text("mission Written {\n    Wait(duration: 1s)[1200]\n}\n")
    (tmp_path / "evaluated.mission").write_text("mission Evaluated {\n    var n: int = 1600\n"
                                                "    Wait(duration: 1s)[n]\n}\n")
    refused = missionctl("validate", "written.mission", cwd=tmp_path)
    assert refused.returncode == 2 and "multiplicity 1200 is above the limit of 1000 instances" in refused.stderr
    assert "cluster.limits" in refused.stderr  # the hint says how to raise it
    assert missionctl("validate", "written.mission", "--config", str(hosts), cwd=tmp_path).returncode == 0
    ran = missionctl("dry-run", "written.mission", "--config", str(hosts), "--json", cwd=tmp_path)
    assert ran.returncode == 0 and json.loads(ran.stdout)["outcome"] == "success", ran.stderr[-1000:]
    over = missionctl("dry-run", "evaluated.mission", "--config", str(hosts), "--json", cwd=tmp_path)
    assert over.returncode == 1
    assert json.loads(over.stdout)["reason"] == "Wait would create 1600 instances, above the limit of 1500"


@pytest.mark.parametrize(("limits", "message"), [
    ("{instances: 0}", "cluster.limits.instances: 0 is out of range: 1..100000 instances"),
    ("{compile: 1h}", "hosts.yaml:8: cluster.limits.compile: 1h is out of range: 1s..10min"),
    ("{instance: 5}", "cluster.limits.instance: unknown key (did you mean instances?)"),
])
def test_bad_cluster_limits_are_refused_naming_the_key(tmp_path: Path, limits: str, message: str) -> None:
    from drd.config import ConfigError
    from drd.hosts import load_hosts
    from drd.manifests import load_catalog

    hosts = hosts_with(tmp_path, "  lease: 3s\n", f"  lease: 3s\n  limits: {limits}\n")
    with pytest.raises(ConfigError) as e:
        load_hosts(hosts, load_catalog())
    assert any(message in str(p) for p in e.value.problems), [str(p) for p in e.value.problems]


#: The inputs of issue #18, each with the located message `missionctl validate` gives (exit 2), or "" for one that
#: is valid and only had to cost little.
ISSUE_INPUTS = {
    "waits": ("mission M {\n    Wait(duration: 1s)[10000]\n}\n",
              ":2:23: error: multiplicity 10000 is above the limit of 1000 instances"),
    "billion": ("mission M {\n    Wait(duration: 1s)[1000000000]\n}\n",
                ":2:23: error: multiplicity 1000000000 is above the limit"),
    "braces": ("}" * 990_000, ":1:1: error: syntax: expected behavior, import or mission, got `}`"),
    "brackets": ("mission M {\n    var x: int = 0\n    Wait(duration: 1s) as w\n    w -> done when " + "[" * 10_000
                 + "\n}\n", ":4:20: error: syntax: expected a condition after when"),
    "errors": ("mission M {\n" + "    Wait(duration: ) )\n" * 10_000 + "}\n", ":2:20: error: syntax: expected"),
    "integer": ("mission M {\n    var n: int = " + "9" * 5000 + "\n    Wait(duration: 1s)\n}\n",
                ":2:18: error: integer 99999999999999999999999… is too large (5000 digits, at most 18)"),
    "quantity": ("mission M {\n    needs radio: RadioChannel quantity -5\n    Wait(duration: 1s)\n}\n",
                 ":2:40: error: quantity -5 asks for nothing: it must be above 0"),
    "slice": ("mission M {\n    needs radio: RadioChannel for 0s\n    Wait(duration: 1s)\n}\n",
              ":2:35: error: a time slice of 0s never lets the holder run"),
    "negative": ("mission M {\n    Wait(duration: -1s)\n}\n",
                 ":2:10: error: duration: a duration cannot be negative (-1 s)"),
    "modulo": ("mission M {\n    var x: int = 3\n    Wait(duration: 1s) as w\n    w -> done / set x = x % 0\n}\n",
               ":4:29: error: remainder by zero"),
    "string": ('mission M {\n    Wait(duration: 1s) as w\n    w -> done / log "' + "ab" * 450_000 + '"\n}\n', ""),
    "parentheses": ("mission M {\n    var x: int = 0\n    Wait(duration: 1s) as w\n    w -> done when "
                    + "(" * 10_000 + "x > 1" + ")" * 10_000 + "\n}\n", ""),
}
#: The address space each `missionctl validate` may use (Python, lark and the mission: about 70 MB resident).
MEMORY_CAP = 512 << 20


def capped() -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP, MEMORY_CAP))


@pytest.mark.parametrize("name", sorted(ISSUE_INPUTS))
def test_each_input_of_the_issue_gets_its_located_error_within_a_memory_cap(tmp_path: Path, name: str) -> None:
    text, message = ISSUE_INPUTS[name]
    (tmp_path / f"{name}.mission").write_text(text, encoding="utf-8")
    done = subprocess.run([*MISSIONCTL, "validate", f"{name}.mission"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120, check=False, preexec_fn=capped)
    shown = done.stdout + done.stderr
    assert "Traceback" not in shown and "MemoryError" not in shown
    if message:
        assert done.returncode == 2 and f"{name}.mission{message}" in shown, shown[-1500:]
        assert shown.count(": error: ") <= SHOWN_ERRORS
    else:
        assert done.returncode == 0 and "valid" in shown, shown[-1500:]


#: A billion laughs inside `roles`: 81 aliases (under the alias limit) that stand for 387 million values.
LAUGHS = "roles: [controller, &x0 lol, " + ", ".join(f"&x{i} [" + ", ".join([f"*x{i - 1}"] * 9) + "]"
                                                    for i in range(1, 10)) + "]"
#: hosts.yaml inputs of issue #18: (what replaces what, the message `dry-run` names them with).
HOSTS_INPUTS = {
    "laughs": (("roles: [controller]", LAUGHS), "its aliases expand to more than 1,000,000 values"),
    "nested": (("cores: 2", "cores: " + "[" * 5000 + "]" * 5000), "nested deeper than 32 levels"),
    "lease": (("lease: 3s", "lease: 1e400s"), "cluster.lease: expected a duration such as 3s or 500ms"),
    "beams": (("beams: 181", "beams: 1000000000"), "beams: 1000000000 is out of range: 3..4096"),
    "name": (("name: corridor", "name: " + "x" * 100_000), "(100,000 characters) is too long for a name"),
}


@pytest.mark.parametrize("name", sorted(HOSTS_INPUTS))
def test_each_hosts_input_of_the_issue_is_refused_naming_the_file_within_a_memory_cap(tmp_path: Path,
                                                                                     name: str) -> None:
    (old, new), message = HOSTS_INPUTS[name]
    hosts = hosts_with(tmp_path, old, new)
    done = subprocess.run([*MISSIONCTL, "dry-run", str(ROOT / "missions" / "corridor_surveillance.mission"),
                           "--config", str(hosts)], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          check=False, preexec_fn=capped)
    assert done.returncode == 2 and "Traceback" not in done.stderr and "MemoryError" not in done.stderr
    assert "hosts.yaml" in done.stderr and message in done.stderr, done.stderr[-1500:]
    assert max(len(line) for line in done.stderr.splitlines()) < 1000  # values are shown cut
