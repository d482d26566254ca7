"""Several controllers, one acting (issue #16): the election's pure rule (`drd.cluster.election`), its fence, and
hosts.yaml's `cluster.store`.

The journal's two backends and the election against a real etcd (a process started there) are in
tests/e2e/test_election_etcd.py; the three-member cluster and real daemons in tests/e2e/test_controller_failover.py."""

from __future__ import annotations

import copy
import functools
from pathlib import Path
from typing import Any

import pytest
import yaml

from drd.bus import BusError, Ping, Pong, Query
from drd.bus.local import LocalNetwork
from drd.cluster.election import LEADER, STANDBY, ElectionState, FencedBus, LeaseClock
from drd.hosts import HostsError, Store, parse_hosts
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parents[2]

# -- the pure rule -------------------------------------------------------------------------------------------------


def test_a_lease_is_trusted_from_the_renewal_sent_not_from_its_answer() -> None:
    lease = LeaseClock(margin=0.25)
    lease.renewed(sent=10.0, ttl=2.0)
    assert lease.valid(11.7) and not lease.valid(11.75)
    lease.renewed(sent=9.0, ttl=2.0)  # an older renewal answered late never shortens it
    assert lease.valid(11.7)


def test_a_leader_whose_lease_ran_out_by_its_own_clock_is_fenced_once_and_acts_no_more() -> None:
    state = ElectionState()
    assert not state.acting(0.0)
    state.won(term=7, host="c1", renewed=100.0, ttl=2.0)
    assert state.role == LEADER and state.acting(101.0) and state.acting(101.0, term=7)
    assert not state.acting(101.0, term=6)  # a fence of an older term stays shut after a new election
    state.kept(sent=101.0, ttl=2.0)
    assert state.acting(102.5)
    assert not state.check(102.5)
    assert state.check(103.0)  # woke from a freeze: no renewal answered in time
    assert state.role == "fenced" and "ran out" in state.reason
    assert not state.check(103.0) and not state.fence("again")  # said once
    assert not state.acting(103.0)
    state.kept(sent=103.0, ttl=2.0)  # a late answer does not revive a fenced leader
    assert not state.acting(103.1)
    state.standby()
    assert state.role == STANDBY and state.term == 0 and not state.acting(103.1)


def test_a_standby_notes_each_new_holder_once() -> None:
    state = ElectionState()
    assert state.saw("c1", 3) and not state.saw("c1", 3)
    assert state.saw("c2", 9)


def echo(query: Query) -> Pong:
    assert isinstance(query.payload, Ping)
    return Pong(query.payload.nonce, "c1")


def test_the_fence_lets_nothing_out_once_the_controller_no_longer_acts() -> None:
    network = LocalNetwork()
    controller, other = network.session("c1"), network.session("ranger1")
    heard: list[str] = []
    other.subscribe("drd/t/mission/*/record", lambda s: heard.append(s.key))
    other.serve("drd/t/host/ranger1/creator", lambda q: Pong(0, "ranger1"))
    acting = [True]
    fenced = FencedBus(controller, lambda: acting[0], "controller c1 (term 7)")
    fenced.serve("drd/t/executive/status", echo)
    fenced.put("drd/t/mission/M/record", Ping(1))
    assert isinstance(fenced.call("drd/t/host/ranger1/creator", Ping(2)), Pong)
    assert isinstance(other.call("drd/t/executive/status", Ping(3)), Pong)
    assert len(heard) == 1
    acting[0] = False
    fenced.put("drd/t/mission/M/record", Ping(4))
    with pytest.raises(BusError, match="no longer acts"):
        fenced.call("drd/t/host/ranger1/creator", Ping(5))
    assert other.request("drd/t/executive/status", Ping(6), timeout=0.2) == []  # no answer at all, not an error
    assert len(heard) == 1 and fenced.dropped == 3
    fenced.close()
    assert not controller.closed  # the daemon owns its bus


# -- hosts.yaml: cluster.store -------------------------------------------------------------------------------------


@functools.cache
def hosts_yaml() -> dict[str, Any]:
    """hosts.yaml read once (each case below changes a deep copy of it)."""
    data: dict[str, Any] = yaml.safe_load((ROOT / "hosts.yaml").read_text())
    return data


def hosts_data(store: object = None, second_controller: bool = True) -> dict[str, Any]:
    data: dict[str, Any] = copy.deepcopy(hosts_yaml())
    if second_controller:
        data["hosts"]["controller2"] = {"endpoint": "tcp/127.0.0.1:7460", "roles": ["controller"]}
    if store is not None:
        data["cluster"]["store"] = store
    return data


def test_several_controllers_need_a_replicated_store(catalog: Catalog) -> None:
    with pytest.raises(HostsError) as e:
        parse_hosts(hosts_data(), "hosts.yaml", catalog)
    assert "hosts.yaml: hosts.controller2.roles: controller is already a role of host controller" in str(e.value)
    assert "several controllers need a replicated store" in str(e.value) and "cluster.store" in str(e.value)
    cluster = parse_hosts(hosts_data({"etcd": ["http://127.0.0.1:2379", "http://10.0.0.2:2379"]}), "hosts.yaml",
                          catalog)
    assert cluster.store == Store(("http://127.0.0.1:2379", "http://10.0.0.2:2379")) and cluster.store.replicated
    assert [h.name for h in cluster.controllers] == ["controller", "controller2"]
    assert not parse_hosts(hosts_data(second_controller=False), "hosts.yaml", catalog).store.replicated


@pytest.mark.parametrize(("store", "key", "says"), [
    ({"etcd": []}, "cluster.store.etcd", "non-empty list"),
    ({"etcd": "http://127.0.0.1:2379"}, "cluster.store.etcd", "non-empty list"),
    ({"etcd": ["127.0.0.1:2379"]}, "cluster.store.etcd[0]", "http://HOST:PORT"),
    ({"etcd": ["https://127.0.0.1:2379"]}, "cluster.store.etcd[0]", "http://HOST:PORT"),
    ({"etcd": ["http://127.0.0.1:99999"]}, "cluster.store.etcd[0]", "http://HOST:PORT"),
    ({"etcd": ["http://a:1", "http://a:1"]}, "cluster.store.etcd[1]", "listed twice"),
    ({"etcd": ["http://a:1"], "zookeeper": ["x"]}, "cluster.store.zookeeper", "unknown key"),
    ({}, "cluster.store.etcd", "required"),
    ("etcd", "cluster.store", "mapping"),
])
def test_a_bad_store_is_refused_naming_the_file_and_key(catalog: Catalog, store: object, key: str,
                                                        says: str) -> None:
    with pytest.raises(HostsError) as e:
        parse_hosts(hosts_data(store, second_controller=False), "hosts.yaml", catalog)
    text = str(e.value)
    assert f"hosts.yaml: {key}:" in text and says in text, text
