"""Who of the configured peers is unreachable, and why: `zenoh.open()` succeeds even when every peer
refused us, so the daemon checks for itself.

A peer is reachable when the cluster view has it up (its token and load reports arrive). For one
that is not, a plain TCP connection to its endpoint tells the likely cause apart: nothing listens
(its daemon is not started), no answer (host down, firewall), or it accepts connections but no
zenoh session came of it: the two sides refused each other's credentials (a different password,
certificate or security mode).
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Collection, Mapping


def parse_endpoint(endpoint: str) -> tuple[str, str, int] | None:
    """`tcp/127.0.0.1:7447` -> ("tcp", "127.0.0.1", 7447); the brackets of an IPv6 address are removed."""
    proto, sep, rest = endpoint.partition("/")
    address, colon, port = rest.rpartition(":")
    if not sep or not colon or not port.isdigit() or not address:
        return None
    return proto, address.removeprefix("[").removesuffix("]"), int(port)


def probe(endpoint: str, timeout: float = 0.5) -> str | None:
    """None when something accepts TCP connections at `endpoint`, else why not (one phrase)."""
    parsed = parse_endpoint(endpoint)
    if parsed is None:
        return f"cannot parse the endpoint {endpoint!r}"
    proto, address, port = parsed
    if proto not in ("tcp", "tls"):
        return f"no session ({proto} endpoints cannot be probed)"
    try:
        with socket.create_connection((address, port), timeout=timeout):
            return None
    except ConnectionRefusedError:
        return "connection refused: nothing listens there (is its drd started?)"
    except TimeoutError:
        return f"no answer within {timeout:g} s (is the host down, or a firewall in the way?)"
    except OSError as e:
        return f"cannot connect: {e.strerror or e}"


REFUSED = ("it accepts connections but no session was established: the peers refused each other's"
           " credentials (a different password file, certificate or security mode?), or its handshakes are all"
           " taken (many connections to it that never complete one)")
UNRESPONSIVE = ("unresponsive: its session was up, then it went silent, and its port still accepts connections (a"
                " frozen or SIGSTOPped daemon, or one too loaded to answer)")


def diagnose(down: Mapping[str, str], probe_fn: Callable[[str], str | None] = probe,
             silent: Collection[str] = ()) -> dict[str, str]:
    """For each down host (host -> endpoint), why it is unreachable. A `silent` one (it had a session, then stopped
    reporting while its link stayed open) that still accepts connections is unresponsive, not refusing our
    credentials: its kernel accepts for it while the process does nothing."""
    out = {}
    for host, endpoint in down.items():
        why = probe_fn(endpoint)
        out[host] = f"{endpoint}: {(UNRESPONSIVE if host in silent else REFUSED) if why is None else why}"
    return out
