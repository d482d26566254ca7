"""Bus benchmark: request/reply through ZenohBus against a raw zenoh querier, in the same run.

Run `python bench/bus.py [--calls 2000] [--rounds 5]` (never by pytest). A server process (this
script with --serve) answers on two keys over tcp/127.0.0.1, as another daemon would:

- raw zenoh: a callback queryable echoing the request bytes, asked through a declared Querier
  (all targets, no consolidation); the bytes are a pre-encoded Ping, so the wire size is the same;
- ZenohBus: `serve` answering Ping with Pong, asked with `ZenohBus.call` (encode, schema-checked
  decode on both sides, error containment, Reply objects).

Each round alternates blocks of 50 calls of each path on the same sessions. Goal: ZenohBus.call / raw querier <= 1.25
(median per call, best round of each). `--in-process` runs the server in this process instead:
the two sides then contend for one GIL, which penalizes every microsecond of Python work, so
that figure is shown for information, not judged.
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import zenoh  # noqa: E402

from drd.bus import Ping, Pong, Query, encode  # noqa: E402
from drd.bus.zenoh_bus import ZENOH_VERSION, ZenohBus  # noqa: E402

GOAL = 1.25
BUS_KEY, RAW_KEY = "bench/bus/ping", "bench/raw/ping"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def serve(bus: ZenohBus) -> list[object]:
    """Declare both servers on `bus`; returns what must stay referenced."""

    def pong(query: Query) -> Pong:
        assert isinstance(query.payload, Ping)
        return Pong(query.payload.nonce, "server")

    def raw_echo(query: zenoh.Query) -> None:
        try:
            query.reply(RAW_KEY, query.payload.to_bytes() if query.payload else b"")
        finally:
            query.drop()  # type: ignore[no-untyped-call]

    return [bus.serve(BUS_KEY, pong), bus.session.declare_queryable(RAW_KEY, raw_echo)]


def interleaved_us(raw: Callable[[int], object], bus: Callable[[int], object], calls: int) -> tuple[float, float]:
    """Median microseconds per call of each path, alternating blocks of 50 calls so that a
    change in the machine's load during the round hits both paths alike."""
    samples: tuple[list[float], list[float]] = ([], [])
    for block in range(0, calls, 50):
        for fn, out in ((raw, samples[0]), (bus, samples[1])):
            for index in range(block, min(block + 50, calls)):
                start = time.perf_counter_ns()
                fn(index)
                out.append((time.perf_counter_ns() - start) / 1_000)
    return statistics.median(samples[0]), statistics.median(samples[1])


def measure(client: ZenohBus, calls: int, rounds: int) -> tuple[float, float]:
    querier = client.session.declare_querier(
        RAW_KEY,
        target=zenoh.QueryTarget.ALL,
        consolidation=zenoh.QueryConsolidation(zenoh.ConsolidationMode.NONE),
        timeout=2.0,
    )
    wire = encode(Ping(1, 0.0))

    def raw(_index: int) -> None:
        replies = list(querier.get(payload=wire))
        assert len(replies) == 1 and replies[0].ok is not None

    def bus(index: int) -> None:
        assert client.call(BUS_KEY, Ping(index, 0.0), timeout=2.0) == Pong(index, "server")

    deadline = time.monotonic() + 10
    while not (client.request(BUS_KEY, Ping(0), timeout=1.0) and list(querier.get(payload=wire))):
        if time.monotonic() > deadline:
            sys.exit("the client never saw the server's queryables")
        time.sleep(0.05)
    for _ in range(200):  # warm up both paths
        raw(0)
        bus(0)
    raw_best, bus_best = float("inf"), float("inf")
    for _ in range(rounds):
        raw_us, bus_us = interleaved_us(raw, bus, calls)
        raw_best, bus_best = min(raw_best, raw_us), min(bus_best, bus_us)
    querier.undeclare()
    return raw_best, bus_best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=2000, help="calls per round")
    parser.add_argument("--rounds", type=int, default=5, help="rounds (best one kept)")
    parser.add_argument("--in-process", action="store_true", help="run the server in this process")
    parser.add_argument("--serve", metavar="ENDPOINT", help=argparse.SUPPRESS)  # the server process
    args = parser.parse_args()

    if args.serve:
        with ZenohBus(listen=[args.serve], name="server") as server:
            kept = serve(server)
            print("ready", flush=True)
            sys.stdin.read()  # until the parent closes our stdin
            del kept
        return

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = None
    server = None
    if args.in_process:
        server = ZenohBus(listen=[endpoint], name="server")
        kept = serve(server)
    else:
        cmd = [sys.executable, __file__, "--serve", endpoint]
        proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    try:
        with ZenohBus(connect=[endpoint], options={"scouting/delay": 50}, name="client") as client:
            raw_best, bus_best = measure(client, args.calls, args.rounds)
    finally:
        if proc is not None:
            proc.communicate(timeout=10)  # closes its stdin: it exits
        if server is not None:
            del kept
            server.close()
    ratio = bus_best / raw_best
    where = "server in this process (GIL shared)" if args.in_process else "server in its own process"
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"eclipse-zenoh {ZENOH_VERSION}, Python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load {load}")
    print(f"request/reply over tcp/127.0.0.1, {where}; median of {args.calls:,} calls, best of {args.rounds} rounds")
    print(f"  raw zenoh querier  {raw_best:8.1f} µs/call  {1e6 / raw_best:8,.0f} calls/s")
    print(f"  ZenohBus.call      {bus_best:8.1f} µs/call  {1e6 / bus_best:8,.0f} calls/s")
    verdict = "for information" if args.in_process else ("PASS" if ratio <= GOAL else "MISS")
    print(f"  ratio              {ratio:8.2f}x  (goal <= {GOAL}x: {verdict})")


if __name__ == "__main__":
    main()
