"""What every test of processes and sessions needs: free loopback ports and a bounded wait (one copy, imported by
the cluster, etcd and ROS 2 helpers and by the bus tests)."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable

import pytest


def eventually(predicate: Callable[[], object], what: str, timeout: float = 10.0, poll: float = 0.02,
               explain: Callable[[], str] | None = None) -> None:
    """Wait (bounded) until `predicate()` is true; fail naming `what`, with `explain()` (the daemons' logs, say):
    a failure seen once on a CI machine must say what the processes were doing."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout:g} s waiting for {what}" + (f"\n{explain()}" if explain else ""))
        time.sleep(poll)


def free_ports(n: int) -> list[int]:
    """`n` distinct free ports on 127.0.0.1 (held open together, so they differ)."""
    socks = [socket.socket() for _ in range(n)]
    try:
        for sock in socks:
            sock.bind(("127.0.0.1", 0))
        return [sock.getsockname()[1] for sock in socks]
    finally:
        for sock in socks:
            sock.close()


def free_port() -> int:
    """One free port on 127.0.0.1."""
    return free_ports(1)[0]
