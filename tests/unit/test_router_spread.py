"""Clients spread over the routers (issue #15, found at 50 daemons: every client linked to the first router listed,
so the second was only a standby). A client connects to the first router it reaches: each client's list starts at
a router chosen by its name, the same on every start, and still lists every router to fall back on."""

from __future__ import annotations

from collections import Counter

from drd.daemon.security import Transport
from drd.hosts import SecurityMode

ROUTERS = ("router1", "router2")


def fleet(clients: int) -> Transport:
    endpoints = {name: f"tcp/127.0.0.1:{7000 + n}" for n, name in enumerate([*ROUTERS, *(f"host{i:02d}"
                                                                                      for i in range(clients))])}
    return Transport(SecurityMode.NONE, endpoints, routers=ROUTERS)


def test_the_clients_start_at_different_routers_and_keep_them_all() -> None:
    tr = fleet(48)
    firsts = Counter(next(iter(tr.others(f"host{i:02d}"))) for i in range(48))
    assert set(firsts) == set(ROUTERS) and min(firsts.values()) >= 12, firsts
    assert all(sorted(tr.others(f"host{i:02d}")) == sorted(ROUTERS) for i in range(48))
    assert tr.others("host07") == tr.others("host07")  # the same list on every start


def test_a_router_connects_to_the_other_routers_and_a_mesh_is_unchanged() -> None:
    tr = fleet(3)
    assert tr.others("router1") == {"router2": "tcp/127.0.0.1:7001"}
    mesh = Transport(SecurityMode.NONE, {"a": "tcp/127.0.0.1:1", "b": "tcp/127.0.0.1:2", "c": "tcp/127.0.0.1:3"})
    assert mesh.others("b") == {"a": "tcp/127.0.0.1:1", "c": "tcp/127.0.0.1:3"}


def test_each_pair_has_one_dialer_the_one_listed_later() -> None:
    """Two peers that dial each other can be left split by zenoh after a freeze (issue #2806): one dialer per pair."""
    mesh = Transport(SecurityMode.NONE, {n: f"tcp/127.0.0.1:{i}" for i, n in enumerate("abcd", 1)})
    assert mesh.dials("a") == {} and mesh.dials("c") == {"a": "tcp/127.0.0.1:1", "b": "tcp/127.0.0.1:2"}
    pairs = [(x, y) for x in "abcd" for y in mesh.dials(x)]
    assert len(pairs) == 6 and {frozenset(p) for p in pairs} == {frozenset((x, y)) for x in "abcd" for y in "abcd"
                                                                 if x < y}
    tr = fleet(3)
    assert tr.dials("router1") == {} and tr.dials("router2") == {"router1": "tcp/127.0.0.1:7000"}
    assert tr.dials("host01") == tr.others("host01")  # a client of the routers dials them all (it holds one link)
