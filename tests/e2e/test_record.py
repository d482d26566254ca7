"""`dry-run --record run.mcap` and `missionctl replay run.mcap` (issue #13, first part): the recording is an MCAP
file any MCAP reader opens (here the `mcap` library's own reader), with sim-time log times and Foxglove's frame
transforms, and a replay rebuilds the very report the run printed, from the recording alone."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
CORRIDOR = ROOT / "missions" / "corridor_surveillance.mission"


def missionctl(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False)


def test_a_replay_prints_the_report_the_run_printed(tmp_path: Path) -> None:
    run = missionctl("dry-run", str(CORRIDOR), "--config", str(ROOT / "hosts.yaml"), "--inject",
                     "lose scout1 at 40s", "--record", "run.mcap", "--trace", "run.jsonl", "--json", cwd=tmp_path)
    assert run.returncode in (0, 1), run.stderr[-2000:]
    (tmp_path / "elsewhere").mkdir()  # no hosts file, no world: the recording alone
    replay = missionctl("replay", str(tmp_path / "run.mcap"), "--json", cwd=tmp_path / "elsewhere")
    assert replay.returncode == run.returncode, replay.stderr[-2000:]
    assert json.loads(replay.stdout) == json.loads(run.stdout)
    # worlds audit 17, D8: the lost Scout is said lost, and the recording has no pose of it after its loss
    [lost] = [s for s in json.loads(run.stdout)["scouts"] if s["scout"] == "scout1"]
    assert lost.get("lost") is True
    with (tmp_path / "run.mcap").open("rb") as fh:
        frames = [message.log_time for _s, channel, message in make_reader(fh).iter_messages()
                  if channel.topic == "/drd/tf" and b"scout1" in message.data]
    assert frames and max(frames) < 40.05e9
    text_run = missionctl("replay", str(tmp_path / "run.mcap"), cwd=tmp_path / "elsewhere")
    assert text_run.stdout.startswith("mission CorridorSurveillance  ")


def test_the_recording_is_plain_mcap_with_sim_time_and_foxglove_transforms(tmp_path: Path) -> None:
    run = missionctl("dry-run", str(CORRIDOR), "--config", str(ROOT / "hosts.yaml"), "--until", "20", "--record",
                     "run.mcap", "--trace", "run.jsonl", cwd=tmp_path)
    assert run.returncode == 1, run.stderr[-2000:]  # stopped at --until
    trace = [json.loads(line) for line in (tmp_path / "run.jsonl").read_text().splitlines()]
    with (tmp_path / "run.mcap").open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None
        topics = {c.topic: c for c in summary.channels.values()}
        assert topics["/drd/tf"].message_encoding == "protobuf"
        assert summary.schemas[topics["/drd/tf"].schema_id].name == "foxglove.FrameTransforms"
        assert summary.schemas[topics["/drd/world"].schema_id].name == "foxglove.SceneUpdate"
        assert summary.schemas[topics["/drd/records"].schema_id].name == "drd.Record"
        counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
        # the scene, then scout1's camera view when its camera is first read (its brightness, before any frame)
        assert counts["/drd/world"] == 2 and counts["/drd/runs"] == 1
        records, tf_times = [], []
        for _schema, channel, message in reader.iter_messages():
            if channel.topic == "/drd/records":
                records.append(json.loads(message.data))
                assert message.log_time == max(0, int(round(records[-1]["at"] * 1e9)))  # sim time, in ns
                records[-1]["at"] = round(records[-1]["at"], 6)  # exact in the recording, rounded in a trace
            elif channel.topic == "/drd/tf":
                tf_times.append(message.log_time)
    assert records == trace  # every record, as the trace has it
    # every robot where it starts at 0 (readers audit 16, D8: `replay --at 0` showed none), then each cycle
    assert len(tf_times) == 201 and tf_times == sorted(tf_times) and tf_times[0] == 0
    assert tf_times[-1] == 20_000_000_000


def test_a_file_that_is_not_a_recording_is_refused_clearly(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_bytes(b"not an mcap file at all")
    done = missionctl("replay", "x.mcap", cwd=tmp_path)
    assert done.returncode == 2 and "x.mcap: cannot read it as a drd recording" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize(("data", "why"), [
    (b"", "the file is empty"),
    (b"\x89MCAP0\r\n\x01\x10\x00\x00\x00\x00\x00\x00\x00\x00",
     "it ends after 18 bytes, before its first complete MCAP record (cut short, or not MCAP)")])
def test_an_empty_or_very_short_file_says_so(tmp_path: Path, data: bytes, why: str) -> None:
    """Interfaces audit D5: an empty file's reason was empty, a 20-byte one's was `struct`'s "unpack requires a
    buffer of 4 bytes"."""
    (tmp_path / "x.mcap").write_bytes(data)
    done = missionctl("replay", "x.mcap", cwd=tmp_path)
    assert done.returncode == 2 and f"x.mcap: cannot read it as a drd recording: {why}" in done.stderr, done.stderr


def _forged(path: Path, topic: str, *messages: bytes) -> None:
    """An intact MCAP file with `messages` on drd's JSON channel `topic`, as another tool could write one."""
    from mcap.writer import Writer

    with path.open("wb") as f:
        w = Writer(f)
        w.start(profile="", library="a test")
        schema = w.register_schema(name="drd.Thing", encoding="jsonschema", data=b'{"type":"object"}')
        channel = w.register_channel(topic=topic, message_encoding="json", schema_id=schema)
        for i, data in enumerate(messages):
            w.add_message(channel, log_time=i, publish_time=i, data=data)
        w.finish()


@pytest.mark.parametrize(("topic", "messages", "why"), [
    ("/drd/runs", [b'{"format":"drd-run-1","mission":"M","records":"M-1","sim_time":"x"}'],
     "a run summary (mission 'M') has sim_time 'x', not a number"),
    ("/drd/records", [b'{"kind":"entered","at":0,"path":"X","state":"X","mission":"X-1"}',
                      b'{"kind":"granted","at":NaN,"path":"X","mission":"X-1"}'],
     "a message on /drd/records holds NaN, which is not JSON"),
    ("/drd/records", [b'{"kind":"entered","at":0,"path":"X","state":"X","mission":"X-1"}', b"\xff\xfe not json"],
     "a message on /drd/records is not JSON"),
    ("/drd/records", [b'{"kind":"granted","at":1,"path":"X","mission":"X-1"}'],
     "a message on /drd/records: `granted` record without `resources`"),
    ("/drd/records", [b'{"kind":"entered","at":"1","path":"X","state":"X"}'],
     "a message on /drd/records: `entered` record: `at` is \"1\", not a number"),
    # records audit 26, D2: every field `rebuilt` reads is checked (these were exit 70, or passed into the report)
    *((("/drd/runs", [b'{"format":"drd-run-1","mission":"M","records":"M-1","sim_time":1,' + field + b'}'],
        "a run summary (mission 'M') has " + said)
       for field, said in ((b'"priority":"high"', "priority 'high', not an integer of 1 or more"),
                           (b'"injections":5', "injections 5, not a list of objects"),
                           (b'"scouts":[1,2]', "scouts [1, 2], not a list of objects"),
                           (b'"speed":"fast"', "speed 'fast', not a positive number"),
                           (b'"wall_time":-5', "wall_time -5, not a number of 0 or more"),
                           (b'"controller_away":1e400', "controller_away inf, not a number of 0 or more")))),
    # D3, D4: a camera frame that is no object, and nesting no drd message has, were exit 70 or "damage"
    ("/drd/camera", [b'[1, 2]'], "a message on /drd/camera is not an object with a number fov"),
    ("/drd/records", [b"[" * 50_000 + b"]" * 50_000], "a message on /drd/records is nested too deeply"),
], ids=["summary-time-not-a-number", "nan", "not-json", "record-without-a-field", "record-time-a-string",
        "priority", "injections", "scouts", "speed", "wall-time", "away", "camera-not-an-object", "too-deep"])
def test_an_intact_file_whose_messages_break_their_schema_is_refused_as_input(tmp_path: Path, topic: str,
                                                                              messages: list[bytes], why: str) -> None:
    """Records audit 23, #2 and #4: a summary whose sim_time was a string crashed replay (exit 70, "could not convert
    string to float"), a NaN time was kept (and written as null into `replay --trace`), and a message that is not
    JSON was said to be the file's damage ("cut or damaged"), though the reader read it whole."""
    _forged(tmp_path / "x.mcap", topic, *messages)
    done = missionctl("replay", "x.mcap", cwd=tmp_path)
    assert done.returncode == 2 and f"x.mcap: cannot read it as a drd recording: {why}" in done.stderr, done.stderr
    assert "cut" not in done.stderr and "damaged" not in done.stderr


def test_replay_at_shows_the_mission_and_every_robot_at_that_time(tmp_path: Path) -> None:
    run = missionctl("dry-run", str(CORRIDOR), "--config", str(ROOT / "hosts.yaml"), "--until", "30", "--record",
                     "run.mcap", cwd=tmp_path)
    assert run.returncode == 1, run.stderr[-2000:]

    def at(when: str) -> dict[str, object]:
        done = missionctl("replay", "run.mcap", "--at", when, "--json", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        state: dict[str, object] = json.loads(done.stdout)
        return state

    assert set(at("0")["robots"]) == {"ranger1", *(f"scout{i}" for i in range(1, 7))}  # readers audit 16, D8
    start, later = at("0.1"), at("10s")
    robots0, robots10 = start["robots"], later["robots"]
    assert isinstance(robots0, dict) and isinstance(robots10, dict)
    assert set(robots0) == {"ranger1", *(f"scout{i}" for i in range(1, 7))}
    assert robots0["ranger1"]["x"] == pytest.approx(1.0, abs=0.1)  # the world's spawn point
    assert robots10["ranger1"]["x"] > robots0["ranger1"]["x"] + 1  # it drove east along the corridor
    [mission] = later["missions"]  # type: ignore[misc]
    assert mission["outcome"] is None
    assert any(row["path"].endswith("/FindNewDoor/FollowCorridor") and row["state"] == "running"
               for row in mission["active"])
    assert any(held.get("ranger") == "ranger1" for held in mission["holds"].values())  # someone drives it
    after = at("1h")
    assert after["missions"][0]["outcome"] == "stopped"  # type: ignore[index]
    assert after["ends"] == pytest.approx(30.0, abs=0.2) and start["ends"] == after["ends"]  # newcomer audit L6
    text = missionctl("replay", "run.mcap", "--at", "1h", cwd=tmp_path).stdout
    assert "after the recording's end, at 30.0 s: this is the run as it ended" in text
    assert "recording's end" not in missionctl("replay", "run.mcap", "--at", "10s", cwd=tmp_path).stdout
    refused = missionctl("replay", "run.mcap", "--at", "soon", cwd=tmp_path)
    assert refused.returncode == 2 and "expected a time such as 90s" in refused.stderr


def test_replay_writes_the_trace_back_out_and_draws_the_run_from_the_recording_alone(tmp_path: Path) -> None:
    run = missionctl("dry-run", str(CORRIDOR), "--config", str(ROOT / "hosts.yaml"), "--until", "60", "--record",
                     "run.mcap", "--trace", "run.jsonl", cwd=tmp_path)
    assert run.returncode == 1, run.stderr[-2000:]
    (tmp_path / "elsewhere").mkdir()
    done = missionctl("replay", str(tmp_path / "run.mcap"), "--trace", "again.jsonl", "--render", "run.png",
                      cwd=tmp_path / "elsewhere")
    assert done.returncode == 1, done.stderr[-2000:]
    assert (tmp_path / "elsewhere" / "again.jsonl").read_text() == (tmp_path / "run.jsonl").read_text()
    png = (tmp_path / "elsewhere" / "run.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 10_000
    assert "drew run.png" in done.stderr


def test_the_trace_written_back_keeps_the_order_of_several_missions(tmp_path: Path) -> None:
    """Clients audit 9, D2: the trace came back mission by mission, so one mission's `released` could follow
    another's `granted` of what it freed; it comes back in the run's (causal) order, line for line."""
    (tmp_path / "early.mission").write_text("mission Early {\n    start -> First\n    Wait(duration: 1s) as First\n"
                                            "    First -> Second\n    Wait(duration: 3s) as Second\n}\n")
    (tmp_path / "late.mission").write_text("mission Late {\n    Wait(duration: 2s) as Only\n}\n")
    run = missionctl("dry-run", "early.mission", "late.mission", "--config", str(ROOT / "hosts.yaml"), "--record",
                     "run.mcap", "--trace", "run.jsonl", "--json", cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    missions = [json.loads(line)["mission"] for line in (tmp_path / "run.jsonl").read_text().splitlines()]
    assert missions != sorted(missions), "the missions' records interleave in the run's trace"
    done = missionctl("replay", "run.mcap", "--trace", "again.jsonl", "--json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "again.jsonl").read_text() == (tmp_path / "run.jsonl").read_text()
    # the reports in the order given, as the run printed them, though Late ended first (readers audit 16, D3)
    assert [r["id"] for r in json.loads(done.stdout)] == [r["id"] for r in json.loads(run.stdout)] == \
        ["Early-1", "Late-2"]


def test_a_recording_cut_short_by_a_crash_replays_what_it_holds(tmp_path: Path) -> None:
    """Small chunks, flushed each second of sim time: a file cut at 60 % (a crash mid-write) still reads."""
    run = missionctl("dry-run", str(CORRIDOR), "--config", str(ROOT / "hosts.yaml"), "--record", "run.mcap",
                     "--json", cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    data = (tmp_path / "run.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[:len(data) * 6 // 10])
    replay = missionctl("replay", "cut.mcap", "--json", cwd=tmp_path)
    assert replay.returncode == 1, replay.stderr[-2000:]
    report = json.loads(replay.stdout)
    full = json.loads(run.stdout)
    assert report["outcome"] == "unfinished" and report["reason"].startswith("the recording ends at ")
    assert 30 < report["sim_time"] < full["sim_time"]
    kept = [row for row in full["timeline"] if row["entered"] <= report["sim_time"] - 2]
    assert {row["path"] for row in kept} <= {row["path"] for row in report["timeline"]}
    # the Scouts it launched, each where the recording last had it (readers audit 13, D6: none were listed)
    launched = [s["scout"] for s in full["scouts"] if s["at"] <= report["sim_time"] - 2]
    assert launched and [s["scout"] for s in report["scouts"]][:len(launched)] == launched
    assert all(isinstance(s["x"], float) and isinstance(s["y"], float) for s in report["scouts"])
    # past its end, the run as far as it was recorded, not "as it ended" (D7)
    at = missionctl("replay", "cut.mcap", "--at", "1h", cwd=tmp_path).stdout
    assert "it was cut short, before the run ended: this is the run as far as it was recorded" in at, at
    assert json.loads(missionctl("replay", "cut.mcap", "--at", "1h", "--json", cwd=tmp_path).stdout)["cut"] is True


def test_a_damaged_summary_section_loses_the_world_not_the_run(tmp_path: Path) -> None:
    """Readers audit 16, D4: one byte flipped in the attachment index's media type (near the file's end) made
    `replay` refuse a file whose every message was intact ("'utf-8' codec can't decode byte")."""
    run = missionctl("dry-run", str(CORRIDOR), "--config", str(ROOT / "hosts.yaml"), "--until", "10", "--record",
                     "run.mcap", "--json", cwd=tmp_path)
    data = bytearray((tmp_path / "run.mcap").read_bytes())
    at = data.rfind(b"application/yaml")
    assert at > len(data) // 2, "the attachment index is in the summary section"
    data[at] = 0x92
    (tmp_path / "flipped.mcap").write_bytes(bytes(data))
    replay = missionctl("replay", "flipped.mcap", "--json", cwd=tmp_path)
    assert replay.returncode == 1, replay.stderr[-2000:]  # stopped at --until, as the run
    assert json.loads(replay.stdout)["timeline"] == json.loads(run.stdout)["timeline"]
