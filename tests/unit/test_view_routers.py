"""Through routers, a vanished liveliness token is not evidence at once (re-verification audit: killing one of two
routers made running missions fail, every worker taking the controller's token, gone through the dead router and
back through the other 4 ms later, for the controller's loss). Pure `ClusterView` logic, fake times."""

from __future__ import annotations

import pytest
import yaml

from drd.bus import LoadReport
from drd.daemon.view import ClusterView, HostState
from drd.hosts import Cluster, parse_hosts
from dsl.catalog import Catalog

LEASE = 1.0


def cluster_of(catalog: Catalog, routers: bool) -> Cluster:
    roles = {"hub": ["router"], "ctl": ["controller"], "w1": ["worker"]} if routers else \
        {"hub": ["worker"], "ctl": ["controller"], "w1": ["worker"]}
    hosts = {name: {"endpoint": f"tcp/127.0.0.1:{7447 + i}", "roles": role}
             for i, (name, role) in enumerate(roles.items())}
    text = yaml.safe_dump({"cluster": {"name": "lab", "security": {"mode": "none"}, "lease": f"{LEASE:g}s"},
                           "hosts": hosts})
    return parse_hosts(yaml.safe_load(text), "hosts.yaml", catalog)


def worker_view(cluster: Cluster) -> ClusterView:
    view = ClusterView(cluster, "w1")
    view.token("ctl", True, 0.0)
    view.load(LoadReport("ctl", 10.0, 20.0, 0.5, 0, 1.0), 0.0)
    assert view.tick(0.1) == []
    return view


@pytest.mark.parametrize("routers", [True, False], ids=["routers", "a mesh"])
def test_a_token_that_comes_back_within_a_lease_through_routers_is_no_loss(catalog: Catalog, routers: bool) -> None:
    view = worker_view(cluster_of(catalog, routers))
    lost = view.token("ctl", False, 0.5)  # its router died
    back = view.token("ctl", True, 0.504)  # through the other router
    downs = [c for c in [*lost, *back, *view.tick(0.6), *view.tick(2.0)] if c.kind == HostState.DOWN]
    if routers:
        assert downs == [] and view.records["ctl"].state is HostState.UP
    else:  # peers are linked directly: a vanished token is a closed link, at once
        assert [c.host for c in downs] == ["ctl"]


def test_through_routers_a_token_still_gone_after_a_lease_is_a_loss(catalog: Catalog) -> None:
    view = worker_view(cluster_of(catalog, True))
    assert [c for c in view.token("ctl", False, 0.5) if c.kind == HostState.DOWN] == []
    assert view.tick(1.4) == []  # within the lease from the loss
    [down] = view.tick(1.6)
    assert (down.kind, down.host) == (HostState.DOWN, "ctl") and "liveliness token vanished" in down.detail


def test_through_routers_a_goodbye_still_counts_at_once(catalog: Catalog) -> None:
    view = worker_view(cluster_of(catalog, True))
    view.leaving("ctl", "drd stop", 0.4)
    [down] = view.token("ctl", False, 0.5)
    assert (down.kind, down.host, down.detail) == (HostState.DOWN, "ctl", "stopped: drd stop")
