"""Bus benchmark: request/reply through ZenohBus against a raw zenoh querier, in the same run.

Run `python bench/bus.py [--calls 1000] [--rounds 7]` (never by pytest). A server process (this
script with --serve) answers on two keys over tcp/127.0.0.1, as another daemon would:

- raw zenoh: a callback queryable echoing the request bytes, asked through a declared Querier
  (all targets, no consolidation); the bytes are a pre-encoded Ping, so the wire size is the same;
- ZenohBus: `serve` answering Ping with Pong, asked with `ZenohBus.call` (encode and its check,
  schema-checked decode on both sides, error containment, the Query the handler gets);
- raw zenoh + codec, for information: the raw path with drd's codec on both sides (the client
  encodes a Ping and decodes the Pong, the server decodes the Ping and encodes the Pong), and
  nothing else of the bus: the floor `ZenohBus.call` cannot go under with this codec.

The paths run in the same rounds, on the same sessions, interleaved in blocks of 50 calls
(which path goes first rotates block by block), so a change in the machine's load hits them
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
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import zenoh  # noqa: E402

from drd.bus import Ping, Pong, Query, decode, encode  # noqa: E402
from drd.bus.zenoh_bus import ZENOH_VERSION, ZenohBus  # noqa: E402

GOAL = 1.1
BUS_KEY, RAW_KEY, CODEC_KEY = "bench/bus/ping", "bench/raw/ping", "bench/codec/ping"


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

    def codec_pong(query: zenoh.Query) -> None:
        try:
            ping = decode(query.payload.to_bytes() if query.payload else b"")
            assert isinstance(ping, Ping)
            query.reply(query.key_expr, encode(Pong(ping.nonce, "server")))
        finally:
            query.drop()  # type: ignore[no-untyped-call]

    return [bus.serve(BUS_KEY, pong), bus.session.declare_queryable(RAW_KEY, raw_echo),
            bus.session.declare_queryable(CODEC_KEY, codec_pong)]


BLOCK = 50  # calls of one path in a row


def interleaved_us(paths: Sequence[Callable[[int], object]], calls: int) -> list[float]:
    """Median microseconds per call of each path in one round: blocks of BLOCK calls of each, the first
    path rotating block by block, so that none is always the one after another."""
    samples: list[list[float]] = [[] for _ in paths]
    order = list(zip(paths, samples, strict=True))
    for number, block in enumerate(range(0, calls, BLOCK)):
        first = number % len(order)
        for fn, out in order[first:] + order[:first]:
            for index in range(block, min(block + BLOCK, calls)):
                start = time.perf_counter_ns()
                fn(index)
                out.append((time.perf_counter_ns() - start) / 1_000)
    return [statistics.median(out) for out in samples]


def measure(client: ZenohBus, calls: int, rounds: int) -> list[list[float]]:
    """(raw µs, bus µs, raw + codec µs) of each round: medians per call."""
    options: dict[str, Any] = {
        "target": zenoh.QueryTarget.ALL,
        "consolidation": zenoh.QueryConsolidation(zenoh.ConsolidationMode.NONE),
        "timeout": 2.0,
    }
    querier = client.session.declare_querier(RAW_KEY, **options)
    codec_querier = client.session.declare_querier(CODEC_KEY, **options)
    wire = encode(Ping(1, 0.0))

    def raw(_index: int) -> None:
        replies = list(querier.get(payload=wire))
        assert len(replies) == 1 and replies[0].ok is not None

    def bus(index: int) -> None:
        assert client.call(BUS_KEY, Ping(index, 0.0), timeout=2.0) == Pong(index, "server")

    def codec(index: int) -> None:
        replies = [reply.ok.payload.to_bytes() for reply in codec_querier.get(payload=encode(Ping(index, 0.0)))
                   if reply.ok is not None]
        assert len(replies) == 1 and decode(replies[0]) == Pong(index, "server")

    deadline = time.monotonic() + 10
    while not (client.request(BUS_KEY, Ping(0), timeout=1.0) and list(querier.get(payload=wire))
               and list(codec_querier.get(payload=wire))):
        if time.monotonic() > deadline:
            sys.exit("the client never saw the server's queryables")
        time.sleep(0.05)
    for _ in range(200):  # warm up every path
        raw(0)
        bus(0)
        codec(0)
    results = [interleaved_us((raw, bus, codec), calls) for _ in range(rounds)]
    querier.undeclare()  # type: ignore[no-untyped-call]
    codec_querier.undeclare()  # type: ignore[no-untyped-call]
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
    ratios = sorted(bus / raw for raw, bus, _ in results)
    ratio = statistics.median(ratios)
    raw_us, bus_us, codec_us = (statistics.median(round_[path] for round_ in results) for path in range(3))
    floor = statistics.median(codec / raw for raw, _, codec in results)
    where = "server in this process (GIL shared)" if args.in_process else "server in its own process"
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"eclipse-zenoh {ZENOH_VERSION}, Python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load {load}")
    print(f"request/reply over tcp/127.0.0.1, {where}; {args.rounds} rounds of {args.calls:,} calls of each path,"
          f" interleaved in blocks of {BLOCK}; medians over the rounds")
    print(f"  raw zenoh querier  {raw_us:8.1f} µs/call  {1e6 / raw_us:8,.0f} calls/s")
    print(f"  ZenohBus.call      {bus_us:8.1f} µs/call  {1e6 / bus_us:8,.0f} calls/s")
    print(f"  raw zenoh + codec  {codec_us:8.1f} µs/call  {1e6 / codec_us:8,.0f} calls/s"
          f"  ({floor:.2f}x, for information: the floor of ZenohBus.call with this codec)")
    verdict = "for information" if args.in_process else ("PASS" if ratio <= GOAL else "MISS")
    print(f"  ratio              {ratio:8.2f}x  (goal <= {GOAL}x: {verdict};"
          f" rounds from {ratios[0]:.2f}x to {ratios[-1]:.2f}x)")


if __name__ == "__main__":
    main()
