"""`missionctl dry-run --foxglove HOST:PORT` (issue #13): the run served live over the Foxglove WebSocket protocol.
A WebSocket client (the `websockets` package: the Foxglove SDK has a server, not a client) subscribes to the scan,
records and world channels while a dry-run runs and decodes what it receives; the server listens on the loopback
port given and nowhere else. Every process is ours and killed by pid."""

from __future__ import annotations

import base64
import json
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import psutil
import pytest
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory
from websockets.sync.client import ClientConnection, connect

from drd.cli.missionctl import live_default

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
CORRIDOR = ROOT / "missions" / "corridor_surveillance.mission"
#: The subprotocols of the Foxglove WebSocket protocol: the SDK's server speaks the first.
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def connect_when_up(port: int, proc: subprocess.Popen[bytes], limit: float = 60.0) -> ClientConnection:
    deadline = time.monotonic() + limit
    while True:
        try:
            return connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, open_timeout=5)
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def receive(ws: ClientConnection, wanted: dict[str, int], limit: float = 60.0) -> dict[str, list[tuple[int, Any]]]:
    """Subscribe to each wanted topic as it is advertised; (log time, decoded message) of each topic, until every
    topic has its count."""
    channels: dict[int, dict[str, Any]] = {}  # subscription id -> the channel advertised
    got: dict[str, list[tuple[int, Any]]] = {topic: [] for topic in wanted}
    factory = DecoderFactory()
    deadline = time.monotonic() + limit
    while any(len(got[t]) < n for t, n in wanted.items()):
        assert time.monotonic() < deadline, {t: len(m) for t, m in got.items()}
        frame = ws.recv(timeout=limit)
        if isinstance(frame, str):
            op = json.loads(frame)
            for c in op.get("channels", []) if op["op"] == "advertise" else []:
                if c["topic"] in wanted and all(x["topic"] != c["topic"] for x in channels.values()):
                    channels[len(channels) + 1] = c
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": len(channels),
                                                                              "channelId": c["id"]}]}))
            continue
        assert frame[0] == 1  # message data: opcode, subscription id, log time, payload
        sub, log_time = struct.unpack_from("<IQ", frame, 1)
        c, payload = channels[sub], frame[13:]
        if c["encoding"] == "json":
            got[c["topic"]].append((log_time, json.loads(payload)))
        else:
            schema = Schema(id=sub, name=c["schemaName"], encoding=c["schemaEncoding"],
                            data=base64.b64decode(c["schema"]))
            decode = factory.decoder_for(c["encoding"], schema)
            assert decode is not None
            got[c["topic"]].append((log_time, decode(payload)))
    return got


def test_the_live_view_serves_scans_records_and_the_world_while_a_dry_run_runs(tmp_path: Path) -> None:
    port = free_port()
    with (tmp_path / "stderr").open("wb") as stderr:
        proc = subprocess.Popen([*MISSIONCTL, "dry-run", str(CORRIDOR), "--config", str(ROOT / "hosts.yaml"),
                                 "--foxglove", f"127.0.0.1:{port}", "--speed", "4", "--until", "300"], cwd=tmp_path,
                                stdout=subprocess.DEVNULL, stderr=stderr)
        try:
            with connect_when_up(port, proc) as ws:
                got = receive(ws, {"/drd/scan/ranger1": 3, "/drd/records": 3, "/drd/world": 1, "/drd/tf": 3})
                listening = [(c.laddr.ip, c.laddr.port) for c in psutil.Process(proc.pid).net_connections("inet")
                             if c.status == psutil.CONN_LISTEN]
        finally:
            proc.kill()
            proc.wait(timeout=30)
    assert listening == [("127.0.0.1", port)]  # the port given, on loopback, and nothing else
    assert f"live view on ws://127.0.0.1:{port}" in (tmp_path / "stderr").read_text()
    records = [m for _t, m in got["/drd/records"]]
    assert all(m["path"].startswith("CorridorSurveillance") and m["mission"] == "CorridorSurveillance-1"
               for m in records)
    assert all(t == round(m["at"] * 1e9) for t, m in got["/drd/records"])  # sim time
    for t, scan in got["/drd/scan/ranger1"]:
        assert scan.frame_id == "ranger1" and len(scan.ranges) == 181 and scan.timestamp.ToNanoseconds() == t
    [(_t, world), *_] = got["/drd/world"]  # sent again to a viewer that came after the start
    assert {"walls", "door/door_n1", "body/ranger1"} <= {e.id for e in world.entities}


@contextmanager
def recorded_and_served(tmp_path: Path, port: int) -> Iterator[subprocess.Popen[bytes]]:
    """The corridor dry-run's first 12 s at twice real time, recorded into `run.mcap` and served live on `port`."""
    with (tmp_path / "stderr").open("wb") as stderr:
        proc = subprocess.Popen([*MISSIONCTL, "dry-run", str(CORRIDOR), "--config", str(ROOT / "hosts.yaml"),
                                 "--foxglove", f"127.0.0.1:{port}", "--speed", "2", "--until", "12", "--record",
                                 "run.mcap"], cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=stderr)
        try:
            yield proc
        finally:  # ours, killed by pid whatever happened
            proc.kill()
            proc.wait(timeout=30)


def test_a_viewer_from_the_start_gets_every_message_the_file_has_the_first_launch_and_the_summary(
        tmp_path: Path) -> None:
    """Readers audit 13, D1, D2: a channel made mid-run went out with its first message (the first launch, the first
    camera frame), which no viewer could have asked for, and `/drd/runs` never reached one."""
    from mcap.reader import make_reader

    port = free_port()
    with recorded_and_served(tmp_path, port) as proc:
        with connect_when_up(port, proc) as ws:
            got = receive(ws, {"/drd/runs": 1, "/drd/flights": 0, "/drd/tf": 0, "/drd/scan/ranger1": 0})
        proc.wait(timeout=60)
    since = got["/drd/tf"][0][0]  # the viewer had subscribed by then
    with (tmp_path / "run.mcap").open("rb") as fh:
        recorded = [(m.log_time, json.loads(m.data)) for _s, c, m in make_reader(fh).iter_messages()
                    if c.topic == "/drd/flights" and m.log_time >= since]
    with (tmp_path / "run.mcap").open("rb") as fh:  # the laser, advertised before the view started (audit 16, D1:
        scans = [m.log_time for _s, c, m in make_reader(fh).iter_messages() if c.topic == "/drd/scan/ranger1"]
    received = [t for t, _scan in got["/drd/scan/ranger1"]]  # a subscription refused got none of 724)
    assert received and received[0] <= 1_000_000_000, "the laser's channel from the run's first second"
    assert received == [t for t in scans if received[0] <= t <= received[-1]]  # and none lost on the way
    assert recorded and recorded[0][1]["kind"] == "launch", recorded  # the first launch is at 5.6 s
    assert got["/drd/flights"] == recorded
    [(_t, summary)] = got["/drd/runs"]
    assert summary["mission"] == "CorridorSurveillance" and summary["sim_time"] == pytest.approx(12.0, abs=0.11)


def test_a_live_view_that_cannot_be_served_says_where_and_why(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        done = subprocess.run([*MISSIONCTL, "dry-run", str(CORRIDOR), "--config", str(ROOT / "hosts.yaml"),
                               "--foxglove", f"127.0.0.1:{port}", "--until", "1"], cwd=tmp_path,
                              capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2 and f"cannot serve the live view on 127.0.0.1:{port}" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize(("argv", "expected"), [
    (["dry-run", "m.mission", "--foxglove"], ["dry-run", "m.mission", "--foxglove", "127.0.0.1:8765"]),
    (["dry-run", "--foxglove", "m.mission"], ["dry-run", "--foxglove", "127.0.0.1:8765", "m.mission"]),
    (["dry-run", "--foxglove", "--json", "m"], ["dry-run", "--foxglove", "127.0.0.1:8765", "--json", "m"]),
    (["run", "--foxglove", "0.0.0.0:9000", "m"], ["run", "--foxglove", "0.0.0.0:9000", "m"]),
    (["run", "--foxglove", "9000", "m"], ["run", "--foxglove", "9000", "m"]),
    (["run", "--foxglove", "[::1]:9000", "m"], ["run", "--foxglove", "[::1]:9000", "m"]),
    (["run", "--", "--foxglove"], ["run", "--", "--foxglove"]),
    # a bad address is the option's, which refuses it (it was taken as the mission file: fuzz audit D11)
    (["dry-run", "--foxglove", "notahost:abc", "m"], ["dry-run", "--foxglove", "notahost:abc", "m"]),
])
def test_foxglove_alone_is_loopbacks_default_port(argv: list[str], expected: list[str]) -> None:
    assert live_default(argv) == expected


def test_a_viewer_from_the_start_gets_the_messages_at_zero(tmp_path: Path) -> None:
    """Records audit 23, #1: the dry-run began as the port opened, and a viewer that connected and subscribed at once
    still missed the records, the scene and the poses at 0 in 3 tries of 4. A dry-run served live now waits for a
    first viewer (up to `FIRST_VIEWER` s) before its first message."""
    from mcap.reader import make_reader

    port = free_port()
    with recorded_and_served(tmp_path, port) as proc:
        with connect_when_up(port, proc) as ws:
            got = receive(ws, {"/drd/records": 3, "/drd/world": 1})
        proc.wait(timeout=60)
    assert "the run waits up to 3 s for a first viewer" in (tmp_path / "stderr").read_text()
    with (tmp_path / "run.mcap").open("rb") as fh:
        recorded = [json.loads(m.data) for _s, c, m in make_reader(fh).iter_messages() if c.topic == "/drd/records"]
    assert [m for _t, m in got["/drd/records"]] == recorded[:3] and recorded[0]["at"] == 0.0
    assert got["/drd/world"][0][0] == 0, "the scene at 0, not sent again at the viewer's arrival"


def test_what_a_late_viewer_is_sent_again_is_not_written_into_the_file(tmp_path: Path) -> None:
    """A viewer that joins after the start is sent the world's scene as it is now (and each active configuration);
    the file has them already, at their times: a second full scene in it at the join was a message the run never
    logged (records audit, D4)."""
    from mcap.reader import make_reader

    port = free_port()
    with recorded_and_served(tmp_path, port) as proc:
        with connect_when_up(port, proc) as first:  # a viewer from the start; another joins 2 s later
            receive(first, {"/drd/tf": 1})
            time.sleep(2.0)
            with connect_when_up(port, proc) as ws:
                got = receive(ws, {"/drd/world": 1, "/drd/tf": 1})
            proc.wait(timeout=60)
    [(sent_at, scene), *_] = got["/drd/world"]
    assert sent_at > 0 and "walls" in {e.id for e in scene.entities}, "the late viewer was sent the whole scene"
    factory = DecoderFactory()
    with (tmp_path / "run.mcap").open("rb") as fh:
        whole = [m.log_time for _s, _c, m, scene in make_reader(fh, decoder_factories=[factory])
                 .iter_decoded_messages(topics=["/drd/world"]) if "walls" in {e.id for e in scene.entities}]
    assert whole == [0], "the whole scene is in the file once, at the start"
