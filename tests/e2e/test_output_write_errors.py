"""Files a run writes (recording, trace, picture, `plan -o`) that fail after the command started (fuzz audit D1, D2,
D6, D7, D8): one line naming the file, exit 2 (never 70, never a Rust panic), and the run's report still on stdout.
`/dev/full` stands in for a full disk: it opens, and every write fails with ENOSPC."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
CORRIDOR = str(ROOT / "missions" / "corridor_surveillance.mission")
HOSTS = str(ROOT / "hosts.yaml")
FULL = Path("/dev/full")

pytestmark = pytest.mark.skipif(not FULL.exists(), reason="needs Linux's /dev/full")


def missionctl(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False)


def assert_clean(stderr: str) -> None:
    """No internal error, no panic, no traceback: what a broken write path printed before."""
    for bad in ("internal error", "panicked", "stack backtrace", "Traceback", "error logging message"):
        assert bad not in stderr, stderr[-2000:]


def test_a_recording_on_a_full_disk_keeps_the_report_and_names_the_file(tmp_path: Path) -> None:
    run = missionctl("dry-run", CORRIDOR, "--config", HOSTS, "--until", "3", "--record", str(FULL), cwd=tmp_path)
    assert run.returncode == 2, run.stderr[-2000:]
    assert "mission CorridorSurveillance" in run.stdout  # the run's report, printed before the error
    assert_clean(run.stderr)
    errors = [line for line in run.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "/dev/full: cannot write the recording" in errors[0], run.stderr


def test_a_recording_on_a_full_disk_under_json_is_one_json_error(tmp_path: Path) -> None:
    run = missionctl("dry-run", CORRIDOR, "--config", HOSTS, "--until", "3", "--record", str(FULL), "--json",
                     cwd=tmp_path)
    assert run.returncode == 2, run.stderr[-2000:]
    assert json.loads(run.stdout)["mission"] == "CorridorSurveillance"
    error = json.loads(run.stderr)  # the whole of stderr is one JSON document (no panic text after it)
    assert error["code"] == 2 and error["error"].startswith("/dev/full: cannot write the recording")


def test_a_recording_that_fails_mid_run_says_where_its_readable_part_ends(tmp_path: Path) -> None:
    """Readers audit 13, D5: the error gave the time of the last message logged, a second past what the file
    holds. A file size limit (RLIMIT_FSIZE; SIGXFSZ ignored, so a write past it fails with EFBIG) stops the writes
    mid-run, as a full disk does; an independent reader says where the file's messages end."""
    import resource
    import signal

    from mcap.reader import NonSeekingReader

    def limited() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000))

    run = subprocess.run([*MISSIONCTL, "dry-run", CORRIDOR, "--config", HOSTS, "--until", "120", "--record",
                          "run.mcap"], cwd=tmp_path, capture_output=True, text=True, timeout=300, check=False,
                         preexec_fn=limited)
    assert run.returncode == 2 and "mission CorridorSurveillance" in run.stdout, run.stderr[-2000:]
    [error] = [line for line in run.stderr.splitlines() if line.startswith("error:")]
    said = float(error.split("it stops at ")[1].split(" s of sim time")[0])
    last = 0
    with (tmp_path / "run.mcap").open("rb") as fh:
        try:
            for _schema, _channel, message in NonSeekingReader(fh).iter_messages(log_time_order=False):
                last = max(last, message.log_time)
        except Exception:  # the chunk the failed write left open
            pass
    assert said > 5 and said == pytest.approx(last / 1e9, abs=0.05)  # the old code said 15.1 for 14.0


def test_a_recorder_whose_writes_fail_mid_run_stops_its_file_and_says_why(capfd: pytest.CaptureFixture[str]) -> None:
    """No world attachment: the first failure is a chunk written while logging (the SDK only logs it), then the
    flush each second refuses; the run goes on, the error keeps the OS's reason, nothing spams stderr."""
    from drd.outputs import failures
    from drd.record import Recorder

    failures()
    recorder = Recorder(FULL)
    for i in range(2000):
        recorder.json("/drd/light", i * 0.01, {"robot": "scout1", "at": i * 0.01, "fov": 1.0, "regions": [0.5] * 30})
        recorder.poses(i * 0.01, {"ranger1": (i * 0.01, 0.0, 0.0)})
    recorder.end([], 20.0)
    assert recorder.error is not None and "No space left on device" in recorder.error
    assert recorder.writer is None and failures() == [recorder.error]
    assert "error logging message" not in capfd.readouterr().err


def _damage_a_chunk(recording: Path, nth: int = 4) -> int:
    """Flip a byte near the end of the `nth` chunk's compressed data (its lz4 checksum); the byte's offset."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    with recording.open("rb") as fh:
        chunks = 0
        for record in StreamReader(fh, emit_chunks=True).records:
            if isinstance(record, Chunk):
                chunks += 1
                if chunks == nth:
                    end = fh.tell()
                    break
        else:
            pytest.fail(f"{recording} has fewer than {nth} chunks")
    data = bytearray(recording.read_bytes())
    data[end - 6] ^= 0xFF
    recording.write_bytes(bytes(data))
    return end - 6


def test_replay_of_a_damaged_chunk_keeps_the_chunks_before_it(tmp_path: Path) -> None:
    run = missionctl("dry-run", CORRIDOR, "--config", HOSTS, "--until", "30", "--record", "run.mcap", "--json",
                     cwd=tmp_path)
    assert run.returncode in (0, 1), run.stderr[-2000:]
    _damage_a_chunk(tmp_path / "run.mcap")
    replay = missionctl("replay", "run.mcap", cwd=tmp_path)
    assert replay.returncode == 1, replay.stderr[-2000:]  # unfinished: the summary came after the damage
    assert_clean(replay.stderr)
    assert "mission CorridorSurveillance" in replay.stdout and "the recording ends at" in replay.stdout
    assert "run.mcap: the recording is cut or damaged (stopped reading at byte" in replay.stderr
    as_json = missionctl("replay", "run.mcap", "--json", cwd=tmp_path)
    assert as_json.returncode == 1 and json.loads(as_json.stdout)["mission"] == "CorridorSurveillance"
    assert json.loads(as_json.stderr)["warning"].startswith("run.mcap: the recording is cut or damaged")


def test_plan_with_config_writes_its_output_file(tmp_path: Path) -> None:
    text = missionctl("plan", CORRIDOR, "--config", HOSTS, "-o", "plan.txt", cwd=tmp_path)
    assert text.returncode == 0 and text.stdout == "", text.stderr[-2000:]
    written = (tmp_path / "plan.txt").read_text()
    assert written.startswith("CorridorSurveillance") and "at start on cluster" in written and "\x1b[" not in written
    as_json = missionctl("plan", CORRIDOR, "--config", HOSTS, "-o", "plan.json", cwd=tmp_path)
    assert as_json.returncode == 0 and as_json.stdout == ""
    assert json.loads((tmp_path / "plan.json").read_text())["preview"]["cluster"]


def test_plan_output_on_a_full_disk_names_the_file(tmp_path: Path) -> None:
    run = missionctl("plan", CORRIDOR, "-o", str(FULL), cwd=tmp_path)
    assert run.returncode == 2
    assert_clean(run.stderr)
    assert "error: /dev/full: cannot write the plan: No space left on device" in run.stderr


@pytest.mark.parametrize("where", ["missing/r.png", "afile/r.png"])
def test_render_where_it_cannot_be_written_is_refused_before_the_run(tmp_path: Path, where: str) -> None:
    (tmp_path / "afile").write_text("not a folder")
    run = missionctl("dry-run", CORRIDOR, "--config", HOSTS, "--until", "3", "--render", where, "--trace",
                     "t.jsonl", cwd=tmp_path)
    assert run.returncode == 2 and run.stdout == ""
    assert f"--render {where}: cannot write the picture" in run.stderr
    assert_clean(run.stderr)
    assert not (tmp_path / "t.jsonl").exists()  # refused before the trace opened: nothing ran


def test_a_picture_that_fails_after_the_run_keeps_the_report(tmp_path: Path) -> None:
    os.symlink(FULL, tmp_path / "r.png")  # a writable path whose writes fail: the disk filled up during the run
    run = missionctl("dry-run", CORRIDOR, "--config", HOSTS, "--until", "3", "--render", "r.png", cwd=tmp_path)
    assert run.returncode == 2, run.stderr[-2000:]
    assert "mission CorridorSurveillance" in run.stdout
    assert "--render r.png: cannot write the picture: No space left on device" in run.stderr
    assert_clean(run.stderr)


def test_a_trace_on_a_full_disk_keeps_the_report_and_names_the_file(tmp_path: Path) -> None:
    run = missionctl("dry-run", CORRIDOR, "--config", HOSTS, "--until", "5", "--trace", str(FULL), cwd=tmp_path)
    assert run.returncode == 2, run.stderr[-2000:]
    assert "mission CorridorSurveillance" in run.stdout
    assert "error: /dev/full: cannot write the trace: No space left on device" in run.stderr
    assert_clean(run.stderr)
