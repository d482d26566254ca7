"""`--inject`: reading failures to inject, and what each does to a dry-run."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any, cast

import pytest

from drd.inject import Action, Injection, InjectionError, parse, parse_all
from tests.conftest import ROOT, shared_examples

KNOWN = {"hosts": {"controller", "ranger1"}, "robots": {"ranger1", "scout1", "scout2"},
         "doors": {"door_n1", "door_s2"}}


@pytest.mark.parametrize(("text", "expected"), [
    ("kill ranger1 at 90s", Injection(90.0, Action.KILL, "ranger1")),
    ("join ranger1 at 10s", Injection(10.0, Action.JOIN, "ranger1")),
    ("lose scout2 at 2min", Injection(120.0, Action.LOSE, "scout2")),
    ("  BLOCK door_n1 at 1.5s ", Injection(1.5, Action.BLOCK, "door_n1")),
    ("close door_s2 at 500ms", Injection(0.5, Action.CLOSE, "door_s2")),
    ("open door_s2 at 1h", Injection(3600.0, Action.OPEN, "door_s2")),
])
def test_injections_are_read_with_the_languages_durations(text: str, expected: Injection) -> None:
    assert parse(text, **KNOWN) == expected


@pytest.mark.parametrize(("text", "message"), [
    ("kil ranger1 at 90s", "unknown injection 'kil' in 'kil ranger1 at 90s': use one of kill, join, restart, lose, "
                           "block, close, open (did you mean kill?)"),
    ("kill scout1 at 90s", "no host 'scout1' to kill"),
    ("lose scout3 at 1s", "(did you mean scout1?): known robots are ranger1, scout1, scout2"),
    ("block door_n9 at 1s", "no door 'door_n9' to block"),
    ("kill ranger1 at soon", "bad time 'soon'"),
    ("kill ranger1", "cannot read injection 'kill ranger1': write ACTION TARGET at TIME"),
    ("lose scout3 at 2 min", "cannot read injection 'lose scout3 at 2 min': a time has no space before its unit"
                             " (write 2min)"),  # newcomer audit L5
])
def test_a_bad_injection_says_what_is_wrong(text: str, message: str) -> None:
    with pytest.raises(InjectionError, match=None) as e:
        parse(text, **KNOWN)
    assert message in str(e.value)


def test_at_fleet_size_a_refusal_names_a_few_known_targets_and_its_hint_first() -> None:
    """Scale audit 11, D8: an unknown robot of a 1,000-robot building listed every id on one 10 kB line, the
    did-you-mean at its end."""
    robots = {f"scout{i}" for i in range(1, 1000)}
    with pytest.raises(InjectionError) as e:
        parse("lose scout99999 at 1s", hosts={"controller"}, robots=robots, doors=set())
    message = str(e.value)
    assert len(message) < 300 and message.endswith(" and 987 more"), message
    assert "known robots are scout1, scout10, scout100," in message


def test_all_problems_are_reported_together_and_good_ones_come_in_time_order() -> None:
    assert [i.at for i in parse_all(["open door_s2 at 9s", "kill ranger1 at 3s"], **KNOWN)] == [3.0, 9.0]
    with pytest.raises(InjectionError) as e:
        parse_all(["kill nobody at 1s", "lose ranger1 at 2s", "open nothing at 3s"], **KNOWN)
    assert len(str(e.value).splitlines()) == 2


def dry_run(mission: str, *args: str) -> tuple[int, dict[str, object], str]:
    r = subprocess.run(["missionctl", "dry-run", mission, "--json", *args], cwd=ROOT, capture_output=True,
                       text=True, timeout=300, check=False)
    return r.returncode, (json.loads(r.stdout) if r.stdout.strip() else {}), r.stderr


def test_killing_the_host_of_the_camera_fails_the_mission_at_that_time() -> None:
    """As on a cluster (cluster audit 19, #3 and 20, #1): hosts.yaml's ranger1 also runs the simulator, so the
    world is gone with it and the mission fails saying so, its grants given back as it exits."""
    code, report, _ = dry_run(str(shared_examples() / "shared_camera.mission"), "--inject", "kill ranger1 at 12s")
    assert code == 1 and report["outcome"] == "failure"
    assert report["reason"] == "host ranger1 is down: it ran the simulator, so the world is gone", report["reason"]
    assert report["injections"][0]["at"] == pytest.approx(12.0, abs=0.11)
    ends = {h["ended"] for h in report["holds"]}  # type: ignore[union-attr]
    assert "exited" in ends and "host lost" not in ends and report["sim_time"] == pytest.approx(12.0, abs=0.11)


def test_a_mission_waiting_for_a_killed_hosts_robot_waits_for_its_restart(tmp_path: Path) -> None:
    """Cluster audit 19, #1, #3 and #4, predicted: the holder of ranger2 fails with its host, a waiter for ranger2 is
    not granted it while its host is down; restarted within the lease, the host's resources are still there and the
    waiter gets ranger2; restarted after it, they left the manager at the lease's end and the waiter fails then,
    saying that the host is down."""
    hold = 'mission HoldTwo {\n    needs ranger: Ranger where ranger.id == "ranger2"\n    Observe(duration: 60s)\n}\n'
    wait = hold.replace("HoldTwo {", "Waiter priority 2 {").replace("60s", "2s")
    (tmp_path / "hold.mission").write_text(hold)
    (tmp_path / "wait.mission").write_text(wait)
    for restart in (7, 30):  # the lease is 3 s
        missions = [str(tmp_path / "hold.mission"), str(tmp_path / "wait.mission")]
        r = subprocess.run(["missionctl", "dry-run", *missions, "--config", str(ROOT / "hosts.two_rangers.yaml"),
                            "--json", "--inject", "kill ranger2 at 5s", "--inject", f"restart ranger2 at {restart}s"],
                           cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
        held, waiter = json.loads(r.stdout)
        assert held["reason"] == "host ranger2 is down: the component cannot run there", held["reason"]
        assert [(h["from"], h["ended"]) for h in held["holds"]] == [(0.0, "exited")], held["holds"]
        if restart == 7:
            assert waiter["outcome"] == "success", (waiter["outcome"], waiter["reason"])
            assert [h["from"] for h in waiter["holds"]] == [7.0], waiter["holds"]
            assert "back within its lease" in held["injections"][1]["effect"], held["injections"]
        else:
            assert (waiter["outcome"], waiter["sim_time"]) == ("failure", 8.0), waiter
            assert waiter["reason"].endswith("while host ranger2 is down (its resources are not in the manager)")


def test_killing_the_controller_ends_the_mission_as_on_a_cluster() -> None:
    """Issue #16: the dry-run predicted success where a cluster loses the mission (no journal yet): now both stop
    it at that time, and every device the mission held is halted."""
    code, report, _ = dry_run("missions/corridor_surveillance.mission", "--inject", "kill controller at 30s")
    assert code == 1 and report["outcome"] == "stopped"
    assert report["reason"].startswith("the controller (controller) was lost: every host stopped its robots")
    assert report["sim_time"] == pytest.approx(30.0, abs=0.11)
    assert all(h["to"] is not None and h["to"] <= 30.1 for h in report["holds"])  # type: ignore[union-attr]


def test_a_controller_started_again_resumes_the_mission_from_its_journal_as_on_a_cluster(tmp_path: Path) -> None:
    """Issue #16: killed at 60 s and started again at 70 s, the controller resumes the corridor mission where it
    was; the robots stood still meanwhile, and the trace shows one holder per device throughout."""
    trace, recording = tmp_path / "run.jsonl", tmp_path / "run.mcap"
    code, report, err = dry_run("missions/corridor_surveillance.mission", "--inject", "kill controller at 60s",
                                "--inject", "restart controller at 70s", "--trace", str(trace), "--record",
                                str(recording))
    assert code == 0 and report["outcome"] == "success", err
    effects = [i["effect"] for i in report["injections"]]  # type: ignore[union-attr]
    assert "1 mission(s) wait for the controller" in effects[0] and "1 mission(s) resumed" in effects[1], effects
    records = [json.loads(line) for line in trace.read_text().splitlines()]
    [restored] = [r for r in records if r["kind"] == "restored"]
    assert restored["at"] == pytest.approx(70.0, abs=0.11) and restored["since"] == pytest.approx(60.0, abs=0.11)
    assert not [r for r in records if 60.05 < r["at"] < 69.95], "a dead controller records nothing"
    # the hosts stopped what was moving, and said so (readers audit 13, D3: nothing in the trace said it stopped)
    moving = {r["device"] for r in records if r["kind"] == "command" and r["accepted"]
              and r["method"] == "set_velocity" and 59.5 < r["at"] <= 60.05}
    halted = {r["device"] for r in records if r["kind"] == "halted" and abs(r["at"] - 60.0) < 0.11
              and r["reason"] == "controller controller lost (killed)"}
    assert moving and moving <= halted, (moving, halted)
    released = [r for r in records if r["kind"] == "released" and r["reason"] == "controller lost"]
    assert released and all(r["at"] == restored["at"] for r in released)
    # users audit 17, D3: the entries the restore ended are closed in the report, the ones after it end as they did
    lost = [row for row in report["timeline"] if row["status"] == "controller lost"]  # type: ignore[union-attr]
    assert lost and all(row["exited"] == pytest.approx(60.0, abs=0.11) for row in lost), lost
    assert {row["path"] for row in lost} >= {"CorridorSurveillance", "CorridorSurveillance/RoomSurveillance[4]"}
    assert all(row["exited"] is not None for row in report["timeline"]), "a succeeded mission left rows active"  # type: ignore[union-attr]
    from drd.tracecheck import check

    assert check(records, {"ranger1.radio"}).ok
    from drd.record import read

    seen = read(recording)  # the robots' side: nothing moved while the controller was down
    for robot in ("ranger1", "scout1"):
        before, after = seen.pose(robot, 60.2), seen.pose(robot, 69.9)
        assert before is not None and after is not None
        assert abs(before[0] - after[0]) < 0.02 and abs(before[1] - after[1]) < 0.02, (robot, before, after)


def test_a_controller_started_again_after_a_robot_was_lost_resumes_without_it(tmp_path: Path) -> None:
    """Clients audit 9, D1: the restarted controller built every driver again, the lost Scout's too, whose `max_speed`
    the simulation refused: the run ended at 60 s with exit 2, no report and no `finished` in its trace."""
    trace = tmp_path / "run.jsonl"
    code, report, err = dry_run("missions/corridor_surveillance.mission", "--inject", "lose scout3 at 50s",
                                "--inject", "kill controller at 60s", "--inject", "restart controller at 70s",
                                "--trace", str(trace))
    assert code == 0 and report["outcome"] == "success", err
    assert [r["kind"] for r in map(json.loads, trace.read_text().splitlines())][-1] == "finished"
    assert any(h["ended"] == "resource lost" for h in report["holds"])  # type: ignore[union-attr]


def test_a_restart_needs_a_kill_before_it() -> None:
    code, _report, err = dry_run("missions/corridor_surveillance.mission", "--inject", "restart controller at 10s")
    assert code == 2 and "controller is not down then: write 'kill controller at ...' before it" in err, err


def test_a_lost_scout_fails_its_own_instance_not_the_mission() -> None:
    code, report, err = dry_run("missions/corridor_surveillance.mission", "--inject", "lose scout1 at 30s",
                                "--until", "60")
    assert code == 1 and report["outcome"] == "stopped", err  # the time limit, not the loss, ended it
    rows = {t["path"]: t for t in report["timeline"]}  # type: ignore[union-attr]
    lost = [h for h in report["holds"] if h["ended"] == "resource lost"]  # type: ignore[union-attr]
    assert len(lost) == 1 and lost[0]["to"] == pytest.approx(30.0, abs=0.11)
    holder = rows[lost[0]["path"]]
    assert holder["status"] == "failure" and holder["exited"] == pytest.approx(30.0, abs=0.11)
    assert rows["CorridorSurveillance"]["status"] == "stopped"
    assert report["degraded"] == [], "a stopped mission is explained by what was still active, not as degraded"
    survivors = [t for p, t in rows.items() if p.count("/") == 2 and p != lost[0]["path"]]
    assert survivors and all(t["status"] != "failure" for t in survivors)


def test_a_host_that_joins_late_grows_the_running_multiplicity() -> None:
    """ranger2's daemon starts at 40 s: until then its Scouts are unknown, so three RoomSurveillance instances
    run; then three more start, bound to ranger2 and its Scouts, and the mission still succeeds."""
    code, report, err = dry_run("missions/corridor_surveillance.mission", "--hosts", "hosts.two_rangers.yaml",
                                "--inject", "join ranger2 at 40s")  # its cluster.world: two_rangers
    assert code == 0 and report["outcome"] == "success", err
    rows = {t["path"]: t for t in report["timeline"]}  # type: ignore[union-attr]
    instances = {p: t for p, t in rows.items() if p.count("/") == 1 and p.endswith("]")}
    entered = sorted(t["entered"] for t in instances.values())
    assert len(entered) == 6 and entered[:3] == [0.0] * 3 and entered[3:] == [pytest.approx(40.0, abs=0.11)] * 3
    assert "18 resources joined" in report["injections"][0]["effect"]  # type: ignore[index]
    early = [h for h in report["holds"] if h["from"] < 39.9]  # type: ignore[union-attr]
    theirs = {"ranger2", "scout4", "scout5", "scout6"}
    assert early and not any(set(h["resources"].values()) & theirs or any(u.startswith(("ranger2.", "scout4.",
                             "scout5.", "scout6.")) for u in h["units"]) for h in early)
    late = [h for h in report["holds"] if set(h["resources"].values()) & theirs]  # type: ignore[union-attr]
    assert late and min(h["from"] for h in late) == pytest.approx(40.0, abs=0.11)


def test_bad_injections_are_invalid_input() -> None:
    code, _, err = dry_run(str(shared_examples() / "shared_camera.mission"), "--inject", "kill ranger9 at 1s",
                           "--inject", "explode door_n1 at 2s")
    assert code == 2 and "no host 'ranger9' to kill" in err and "unknown injection 'explode'" in err
    assert "Traceback" not in err


def test_a_success_that_lost_an_instance_says_so_first() -> None:
    """Issue #17: a mission is never reported success without saying what failed on the way."""
    code, report, _ = dry_run("missions/corridor_surveillance.mission", "--inject", "lose scout2 at 70s")
    assert code == 0 and report["outcome"] == "success"
    [lost] = report["degraded"]  # type: ignore[misc]
    assert lost["path"].endswith("]") and lost["at"] == pytest.approx(70.0, abs=0.11)
    assert "resource lost" in lost["reason"]
    text = subprocess.run(["missionctl", "dry-run", "missions/corridor_surveillance.mission", "--inject",
                           "lose scout2 at 70s"], cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    first = text.stdout.splitlines()[0]
    assert "success" in first and "degraded: 1 instance failed" in first, first


def test_an_injection_after_the_runs_end_is_refused_before_it_starts() -> None:
    """Issue #18: it was silently dropped."""
    with pytest.raises(InjectionError, match=r"'kill ranger1 at 2min' comes after the run ends \(--until 60 s\)"):
        parse_all(["kill ranger1 at 2min"], **KNOWN, until=60.0)
    code, _, err = dry_run("missions/corridor_surveillance.mission", "--until", "60", "--inject",
                           "kill ranger1 at 5000s")
    assert code == 2 and "comes after the run ends" in err and "Traceback" not in err


def test_an_injection_the_missions_ended_before_is_reported_not_injected(tmp_path: Path) -> None:
    mission = tmp_path / "short.mission"
    mission.write_text("mission Short {\n    Wait(duration: 2s)\n}\n")
    code, report, _ = dry_run(str(mission), "--inject", "kill ranger1 at 50s")
    assert code == 0 and report["sim_time"] == pytest.approx(2.0, abs=0.11)
    [row] = report["injections"]  # type: ignore[misc]
    assert row["skipped"] is True and row["target"] == "ranger1" and "the run ended at 2.0 s" in row["effect"]
    text = subprocess.run(["missionctl", "dry-run", str(mission), "--inject", "kill ranger1 at 50s"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300, check=False).stdout
    assert "not injected at 50.0 s" in text


def test_killing_the_simulators_host_fails_every_mission_as_on_a_cluster(tmp_path: Path) -> None:
    """Cluster audit 20, #1: `kill ranger1` (the simulator's host of the two-Ranger team) let a mission on ranger2 go
    on to success; on a cluster the world is gone with that host and every mission of it fails."""
    (tmp_path / "far.mission").write_text('mission Far {\n    needs r: Ranger where r.id == "ranger2"\n'
                                          "    Wait(duration: 40s)\n}\n")
    r = subprocess.run(["missionctl", "dry-run", str(tmp_path / "far.mission"), "--config",
                        str(ROOT / "hosts.two_rangers.yaml"), "--json", "--inject", "kill ranger1 at 10s"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 1, r.stderr[-2000:]
    report = json.loads(r.stdout)
    assert (report["outcome"], report["sim_time"]) == ("failure", 10.0), report
    assert report["reason"] == "host ranger1 is down: it ran the simulator, so the world is gone"


def test_a_need_through_the_carrier_of_a_host_down_is_told_that_the_host_is_down(tmp_path: Path) -> None:
    """Cluster audit 20, #5: a Scout needed by `s.carrier.id == "ranger2"` after ranger2's host left the manager
    failed "no Scout satisfies the constraint" (the carrier it names could not be read); a need by the Scout's own id
    said that the host was down."""
    (tmp_path / "late.mission").write_text(
        "mission Late {\n    plan {\n        Pause < TakeScout\n    }\n}\n\n"
        "behavior Pause {\n    Wait(duration: 10s)\n}\n\n"
        'behavior TakeScout {\n    needs s: Scout where s.carrier.id == "ranger2"\n    Wait(duration: 2s)\n}\n')
    code, report, err = dry_run(str(tmp_path / "late.mission"), "--config", str(ROOT / "hosts.two_rangers.yaml"),
                                "--inject", "kill ranger2 at 2s")
    assert code == 1, err[-2000:]
    assert report["reason"] == ("resource need s can never be satisfied: no Scout satisfies the constraint while host"
                                " ranger2 is down (its resources are not in the manager)"), report["reason"]


def test_a_host_killed_at_0s_is_down_before_the_first_grants(tmp_path: Path) -> None:
    """Cluster audit 20, #7: `kill ranger2 at 0s` took effect at 0.1 s, after ranger2 had been granted, and its
    holder failed with the host; now it is down from the start: the mission waits, and holds ranger2 from its
    restart."""
    (tmp_path / "hold.mission").write_text('mission HoldTwo {\n    needs ranger: Ranger where ranger.id == "ranger2"\n'
                                           "    Observe(duration: 5s)\n}\n")
    code, report, err = dry_run(str(tmp_path / "hold.mission"), "--config", str(ROOT / "hosts.two_rangers.yaml"),
                                "--inject", "kill ranger2 at 0s", "--inject", "restart ranger2 at 2s")
    holds, injections = cast(list[dict[str, Any]], report["holds"]), cast(list[dict[str, Any]], report["injections"])
    assert (code, report["outcome"]) == (0, "success"), (report.get("reason"), err[-2000:])
    assert [(h["from"], h["ended"]) for h in holds] == [(2.0, "exited")], holds
    assert [i["at"] for i in injections] == [0.0, 2.0], injections


def test_a_controller_restarted_waits_for_the_hosts_with_devices_as_drd_start_does(tmp_path: Path) -> None:
    """Cluster audit 20, #3 and #4: the dry-run's `restart controller` resumed at once, while ranger2 was still down,
    and the mission holding ranger2 failed "no Ranger satisfies the constraint"; `drd start` waits for the hosts with
    devices (two leases and 5 s at most). Back a second later, ranger2 is held again; never back, the mission fails
    when the wait ends, saying that ranger2's host is down."""
    (tmp_path / "hold.mission").write_text('mission Hold {\n    needs r: Ranger where r.id == "ranger2"\n'
                                           "    Wait(duration: 40s)\n}\n")
    base = ["missionctl", "dry-run", str(tmp_path / "hold.mission"), "--config", str(ROOT / "hosts.two_rangers.yaml"),
            "--json", "--inject", "kill ranger2 at 10s", "--inject", "kill controller at 11s", "--inject",
            "restart controller at 15s"]
    back = subprocess.run([*base, "--inject", "restart ranger2 at 16s"], cwd=ROOT, capture_output=True, text=True,
                          timeout=300, check=False)
    report = json.loads(back.stdout)
    assert report["outcome"] == "success", report["reason"]
    assert [(h["from"], h["ended"]) for h in report["holds"]] == [(0.0, "controller lost"), (16.0, "exited")]
    assert "waits for ranger2 (down) to resume the missions, until 26 s at most; at 16.0 s" in \
        report["injections"][2]["effect"], report["injections"]
    never = subprocess.run(base, cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    report = json.loads(never.stdout)
    assert (report["outcome"], report["sim_time"]) == ("failure", 26.0), report  # 15 s + two leases (3 s) + 5 s
    assert report["reason"].endswith("while host ranger2 is down (its resources are not in the manager)")
