"""A minimal bus peer process: holds a liveliness token and answers Ping with Pong.

Why: to check a cluster's bus by hand (is host X reachable, how fast) and to give the
contract tests a real second process to talk to and to kill. Prints ``ready`` on stdout once
declared, then runs until SIGTERM/SIGINT (a clean close: peers see the token go) or until
killed (peers see it go when the link drops, or after the lease).

    python -m drd.bus.peer --connect tcp/127.0.0.1:7447 --token drd/lab/host/probe \\
        --serve drd/lab/host/probe/ping
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from types import FrameType

from drd.signals import set_soon

from .base import Query, Reply
from .messages import Message, Ping, Pong


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drd.bus.peer", description=__doc__.splitlines()[0])
    parser.add_argument("--listen", action="append", default=[], help="zenoh endpoint to listen on (repeatable)")
    parser.add_argument("--connect", action="append", default=[], help="zenoh endpoint to connect to (repeatable)")
    parser.add_argument("--token", action="append", default=[], help="liveliness token key to hold (repeatable)")
    parser.add_argument("--serve", action="append", default=[], help="key expression answering Ping (repeatable)")
    parser.add_argument("--host", default="peer", help="host name put in Pong replies")
    parser.add_argument("--lease-ms", type=int, default=None, help="zenoh link lease (how fast a dead peer is noticed)")
    args = parser.parse_args(argv)

    from .zenoh_bus import ZenohBus  # here, so --help works without eclipse-zenoh

    stop = threading.Event()

    def on_signal(_signum: int, _frame: FrameType | None) -> None:
        set_soon(stop)

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)

    def pong(query: Query) -> Reply | Message:
        if isinstance(query.payload, Ping):
            return Pong(query.payload.nonce, args.host)
        return query.error(f"expected drd.ping, got {type(query.payload).__name__}")

    with ZenohBus(listen=args.listen, connect=args.connect, lease_ms=args.lease_ms, name=args.host) as bus:
        for key in args.serve:
            bus.serve(key, pong)
        for key in args.token:
            bus.declare_token(key)
        print("ready", flush=True)
        while not stop.wait(0.5):
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
