"""Bus benchmark: request/reply through ZenohBus against a raw zenoh querier, in the same run.

Run `python bench/bus.py [--calls 1000] [--rounds 7]` (never by pytest). A server process (this
script with --serve) answers on two keys over tcp/127.0.0.1, as another daemon would:

- raw zenoh: a callback queryable echoing the request bytes, asked through a declared Querier
  (all targets, no consolidation); the bytes are a pre-encoded Ping, so the wire size is the same;
- ZenohBus: `serve` answering Ping with Pong, asked with `ZenohBus.call` (encode, schema-checked
  decode on both sides, error containment, Reply objects).

Both paths run in the same rounds, on the same sessions, interleaved in blocks of 50 calls
(which path goes first alternates block by block), so a change in the machine's load hits both
alike. Each round gives a ratio: its median ZenohBus.call over its median raw call. Goal: the
median of the rounds' ratios <= 1.1 (issue #14; the spread of the rounds is shown too, and the load
average: on a loaded machine the figure is not worth much). Nothing is pinned to a CPU.
`--in-process` runs the server in this process instead: the two sides then contend for one GIL,
which penalizes every microsecond of Python work, so that figure is shown for information, not
judged.
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

GOAL = 1.1
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


BLOCK = 50  # calls of one path in a row


def interleaved_us(raw: Callable[[int], object], bus: Callable[[int], object], calls: int) -> tuple[float, float]:
    """Median microseconds per call of each path in one round: blocks of BLOCK calls of each,
    the first path alternating block by block, so that neither is always the one after the other."""
    samples: tuple[list[float], list[float]] = ([], [])
    paths = ((raw, samples[0]), (bus, samples[1]))
    for number, block in enumerate(range(0, calls, BLOCK)):
        for fn, out in paths if number % 2 == 0 else paths[::-1]:
            for index in range(block, min(block + BLOCK, calls)):
                start = time.perf_counter_ns()
                fn(index)
                out.append((time.perf_counter_ns() - start) / 1_000)
    return statistics.median(samples[0]), statistics.median(samples[1])


def measure(client: ZenohBus, calls: int, rounds: int) -> list[tuple[float, float]]:
    """(raw µs, bus µs) of each round: medians per call."""
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
    results = [interleaved_us(raw, bus, calls) for _ in range(rounds)]
    querier.undeclare()
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=1000, help="calls of each path per round")
    parser.add_argument("--rounds", type=int, default=7, help="rounds (the median of their ratios is judged)")
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
            results = measure(client, args.calls, args.rounds)
    finally:
        if proc is not None:
            proc.communicate(timeout=10)  # closes its stdin: it exits
        if server is not None:
            del kept
            server.close()
    ratios = sorted(bus / raw for raw, bus in results)
    ratio = statistics.median(ratios)
    raw_us = statistics.median(raw for raw, _ in results)
    bus_us = statistics.median(bus for _, bus in results)
    where = "server in this process (GIL shared)" if args.in_process else "server in its own process"
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"eclipse-zenoh {ZENOH_VERSION}, Python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load {load}")
    print(f"request/reply over tcp/127.0.0.1, {where}; {args.rounds} rounds of {args.calls:,} calls of each path,"
          f" interleaved in blocks of {BLOCK}; medians over the rounds")
    print(f"  raw zenoh querier  {raw_us:8.1f} µs/call  {1e6 / raw_us:8,.0f} calls/s")
    print(f"  ZenohBus.call      {bus_us:8.1f} µs/call  {1e6 / bus_us:8,.0f} calls/s")
    verdict = "for information" if args.in_process else ("PASS" if ratio <= GOAL else "MISS")
    print(f"  ratio              {ratio:8.2f}x  (goal <= {GOAL}x: {verdict};"
          f" rounds from {ratios[0]:.2f}x to {ratios[-1]:.2f}x)")


if __name__ == "__main__":
    main()
