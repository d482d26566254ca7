"""The daemon's pure cores (the cluster view, hot-plug membership, rate-limited logs, security files,
pidfiles) and the daemon shell on an in-process LocalBus: no zenoh, no processes, milliseconds."""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import pytest
import yaml

from drd.bus import LoadReport, LocalNetwork, Ping
from drd.bus.messages import encode
from drd.cluster.keys import ClusterKeys, cluster_of
from drd.daemon.controller import Membership, resources_reply
from drd.daemon.daemon import CLAIM_TRIES, MAX_REJECTED_KINDS, Daemon, DaemonConfig, config_digest
from drd.daemon.logs import RateLimit
from drd.daemon.messages import Announcement, ComponentsReply, HostsReply, Location, Lookup, TraderRequest
from drd.daemon.peers import REFUSED, diagnose, parse_endpoint
from drd.daemon.security import SecurityError, read_password, transport
from drd.daemon.view import ClusterView, HostState
from drd.hosts import Cluster, SecurityMode, parse_hosts
from drd.rcm import NeedRequest, Request, ResourceManager
from drd.runtime.clock import SimClock
from drd.runtime.pool import ResourcePool
from dsl.catalog import Catalog
from tests.cluster_support import hosts_yaml

LEASE = 1.0


@pytest.fixture(scope="module")
def cluster(catalog: Catalog) -> Cluster:
    text = hosts_yaml("lab", ["controller", "ranger1", "ranger2"], [7447, 7448, 7449], lease=LEASE)
    return parse_hosts(yaml.safe_load(text), "hosts.yaml", catalog)


def report(host: str, cpu: float = 10.0) -> LoadReport:
    return LoadReport(host, cpu, 20.0, 0.5, 0, 1.0)


def announcement(host: str, digest: str = "", cluster: str = "lab") -> Announcement:
    return Announcement(host, cluster, 1, 0.0, ["worker"], ["Camera"], [], {f"{host}.db": "k"}, digest)


# --- the cluster view ------------------------------------------------------------------------------


def test_a_host_is_up_with_its_token_and_down_when_the_token_goes(cluster: Cluster) -> None:
    view = ClusterView(cluster, "controller")
    assert view.up() == ["controller"]
    assert view.state("ranger1") is HostState.DOWN and view.records["ranger1"].reason == "never seen"
    [change] = view.token("ranger1", True, 10.0)
    assert (change.kind, change.host, change.detail, change.at) == ("up", "ranger1", "joined", 10.0)
    assert view.token("ranger1", True, 10.1) == []  # a replayed token changes nothing
    [change] = view.token("ranger1", False, 10.2)
    assert (change.kind, change.detail) == ("down", "lost: its liveliness token vanished")


def test_a_silent_host_goes_down_after_the_lease_and_comes_back_when_it_reports(cluster: Cluster) -> None:
    view = ClusterView(cluster, "controller")
    view.token("ranger1", True, 0.0)
    assert view.load(report("ranger1"), 0.5) == []
    assert view.tick(0.5 + LEASE) == []  # exactly the lease: still fresh
    [change] = view.tick(0.5 + LEASE + 0.05)
    assert change.kind == "down" and change.detail.startswith("silent: no load report for 1.05 s (lease 1 s)")
    assert view.tick(2.0) == []  # reported once
    [change] = view.load(report("ranger1"), 6.0)
    assert (change.kind, change.detail) == ("up", "reporting again")


def test_a_token_without_reports_gets_one_lease_of_grace(cluster: Cluster) -> None:
    view = ClusterView(cluster, "controller")
    view.token("ranger2", True, 0.0)
    assert view.tick(0.9) == []
    assert [c.kind for c in view.tick(1.1)] == ["down"]


def test_reports_alone_do_not_make_a_host_up(cluster: Cluster) -> None:
    view = ClusterView(cluster, "controller")
    assert view.load(report("ranger1"), 1.0) == []
    assert view.state("ranger1") is HostState.DOWN


def test_a_clean_stop_is_told_apart_from_a_loss(cluster: Cluster) -> None:
    view = ClusterView(cluster, "controller")
    view.token("ranger1", True, 0.0)
    view.leaving("ranger1", "drd stop", 0.1)
    [change] = view.token("ranger1", False, 0.2)
    assert change.detail == "stopped: drd stop"
    [change] = view.token("ranger1", True, 0.3)  # it restarts: the goodbye is forgotten
    view.token("ranger1", False, 0.4)
    assert view.records["ranger1"].reason.startswith("lost")


def test_its_own_host_is_always_up(cluster: Cluster) -> None:
    view = ClusterView(cluster, "ranger1")
    assert view.token("ranger1", False, 1.0) == [] and view.tick(100.0) == []
    assert view.state("ranger1") is HostState.UP


@pytest.mark.parametrize("feed, detail", [
    (lambda v: v.token("intruder", True, 0.0), "a host token from a host not in the hosts file"),
    (lambda v: v.load(report("intruder"), 0.0), "a load report from a host not in the hosts file"),
    (lambda v: v.load(report("ranger1"), 0.0, "ranger2"), "a load report for ranger1 published under ranger2"),
    (lambda v: v.load(LoadReport("ranger1", -1.0, 0.0, 0.0, 0, 0.0), 0.0), "a load report with out-of-range values"),
    # wire audit 10, D4: the JSON decoder takes any integer; a 400-digit count was stored and shown
    (lambda v: v.load(LoadReport("ranger1", 1.0, 0.0, 0.0, 10 ** 400, 0.0), 0.0),
     "a load report with out-of-range values"),
    (lambda v: v.announce(announcement("ranger1", cluster="other"), 0.0), "an announcement for cluster 'other'"),
    (lambda v: v.announce(announcement("ranger1"), 0.0, "ranger2"),
     "an announcement for ranger1 published under ranger2"),
], ids=["token", "load", "load-key", "load-values", "load-huge-count", "cluster", "announce-key"])
def test_what_does_not_belong_is_rejected(cluster: Cluster, feed: object, detail: str) -> None:
    view = ClusterView(cluster, "controller")
    [change] = feed(view)  # type: ignore[operator]
    assert (change.kind, change.detail) == ("rejected", detail)
    assert view.up() == ["controller"]


def test_a_different_hosts_file_is_reported_once(cluster: Cluster) -> None:
    view = ClusterView(cluster, "controller", digest="a" * 64)
    [change] = view.announce(announcement("ranger1", "b" * 64), 0.0)
    assert change.kind == "config-mismatch" and "bbbbbbbbbbbb" in change.detail
    assert view.announce(announcement("ranger1", "b" * 64), 1.0) == []
    assert view.announce(announcement("ranger2", "a" * 64), 1.0) == []


def test_offers_and_runnable_components_come_from_the_hosts_that_are_up(cluster: Cluster, catalog: Catalog) -> None:
    from drd.trader import query

    view = ClusterView(cluster, "controller")
    for host, cpu in (("ranger1", 70.0), ("ranger2", 20.0)):
        view.token(host, True, 0.0)
        view.load(report(host, cpu), 0.0)
    found = query("Camera where resolution >= 640 prefer min(host.load)", view.offers(), catalog=catalog)
    assert [o.id for o in found] == ["ranger2.camera", "ranger1.camera"]
    assert found[0].host["load"] == pytest.approx(0.2)
    assert view.runnable(catalog)["Ranger"] == ["ranger1", "ranger2"]
    assert "Robot" not in view.runnable(catalog) and "Sensor" not in view.runnable(catalog)  # abstract (audit 24, #8)
    view.token("ranger2", False, 0.5)
    assert [o.id for o in query("Camera", view.offers(), catalog=catalog)] == ["ranger1.camera"]
    views = {v.name: v for v in view.host_views()}
    assert views["ranger1"].up and not views["ranger2"].up and views["ranger1"].cpu == 70.0


def test_the_name_service_finds_services_of_hosts_that_are_up(cluster: Cluster) -> None:
    view = ClusterView(cluster, "controller")
    view.token("ranger1", True, 0.0)
    view.announce(announcement("ranger1"), 0.0)
    assert view.lookup("ranger1.db") == Location("ranger1.db", "service", "ranger1", "k")
    assert view.lookup("nothing") is None
    view.token("ranger1", False, 1.0)
    assert view.lookup("ranger1.db") is None


def test_config_digest_ignores_the_file_but_not_the_hosts(cluster: Cluster) -> None:
    from dataclasses import replace

    assert config_digest(cluster) == config_digest(replace(cluster, source="elsewhere/hosts.yaml"))
    assert config_digest(cluster) != config_digest(replace(cluster, hosts=cluster.hosts[:2]))


def test_keys() -> None:
    keys = ClusterKeys("lab")
    assert keys.host("ranger1") == "drd/lab/host/ranger1"
    assert keys.db("ranger1", "query") == "drd/lab/host/ranger1/db/query"
    assert cluster_of("drd/lab/host/ranger1") == ("lab", "ranger1")
    assert cluster_of("drd/lab/host/ranger1/load") is None
    with pytest.raises(ValueError):
        keys.db("ranger1", "drop")
    with pytest.raises(ValueError):
        keys.host("a/b")


# --- hot-plug of the manager ---------------------------------------------------------------------------


def test_membership_removes_a_host_one_lease_after_it_went_down() -> None:
    m = Membership(3.0, {"controller"})
    assert [(a.kind, a.host) for a in m.up("ranger1", 0.0)] == [("add", "ranger1")]
    assert m.up("ranger1", 0.5) == []
    assert [(a.kind, a.host) for a in m.down("ranger1", 1.0)] == [("offline", "ranger1")]
    assert m.down("ranger1", 1.5) == []  # seen down again: still one removal, one lease after the first
    assert m.pending(2.0) == {"ranger1": 2.0}
    assert m.due(3.9) == []
    assert [(a.kind, a.host) for a in m.due(4.0)] == [("remove", "ranger1")]
    assert [(a.kind, a.host) for a in m.up("ranger1", 5.0)] == [("add", "ranger1")]


def test_membership_keeps_a_host_that_comes_back_within_the_lease() -> None:
    m = Membership(3.0, {"ranger1"})
    m.down("ranger1", 0.0)
    assert [(a.kind, a.host) for a in m.up("ranger1", 1.0)] == [("online", "ranger1")]
    assert m.up("ranger1", 1.5) == []
    assert m.due(10.0) == [] and m.present == {"ranger1"}


def test_resources_reply_lists_holders_queue_and_epochs(cluster: Cluster) -> None:
    rcm = ResourceManager(lease=LEASE)
    ResourcePool(rcm).add(cluster.resources(), 0.0)
    for holder, priority in (("m/a", 1), ("m/b", 2)):
        need = NeedRequest("cam", "Camera", where=lambda c, _view: c.id == "ranger1.camera")
        rcm.request(Request(holder, priority, (need,)), 0.0)
    reply = resources_reply(rcm.snapshot(), "lab", "controller", {})
    cam = next(u for u in reply.units if u.id == "ranger1.camera")
    assert cam.holders == ["m/a"] and cam.epoch == 1 and cam.queue == ["m/b"]
    assert [w.holder for w in reply.queue] == ["m/b"]
    assert {r.id for r in reply.robots} == {"ranger1", "ranger2"}


# --- logs, security, peers, pidfiles --------------------------------------------------------------------


def test_rate_limit_drops_floods_and_says_how_many() -> None:
    now = [0.0]
    limit = RateLimit(burst=3, window=10.0, clock=lambda: now[0])

    def rejected(subject: str, why: int) -> logging.LogRecord:
        return logging.LogRecord("drd.bus", logging.WARNING, "f", 1, "rejected %s: %s", (subject, why), None)

    records = [rejected("host/r1/load", i) for i in range(10)]
    assert [limit.filter(r) for r in records] == [True] * 3 + [False] * 7
    # wire audit 10, D2: the junk on one key used the template's whole budget, and a forged token went unnamed
    forged = rejected("host/intruder/live", 0)
    assert limit.filter(forged) and forged.getMessage() == "rejected host/intruder/live: 0 [7 messages of this" \
                                                            " kind suppressed]"
    varied = [limit.filter(rejected(f"k/{i}", i)) for i in range(20)]  # a peer varying its keys: still bounded
    assert sum(varied) == 3 * RateLimit.SUBJECTS - 4  # 15 a window for the template; 4 passed before
    now[0] = 11.0
    late = rejected("host/r1/load", 99)
    assert limit.filter(late) and "suppressed]" in late.getMessage()
    other = logging.LogRecord("drd.bus", logging.WARNING, "f", 1, "another %s", (1,), None)
    assert limit.filter(other)
    # wire audit 17, D2: the bus's lines name the bus first; their subject is the key they give
    bus_line = "bus %s: rejected malformed %s on %r: %s"
    junk = [logging.makeLogRecord({"name": "drd.bus", "msg": bus_line, "subject": "host/controller/live",
                                   "args": ("ranger1", "publication", "host/controller/live", "bad JSON")})
            for _ in range(5)]
    assert [limit.filter(r) for r in junk] == [True] * 3 + [False] * 2
    load = logging.makeLogRecord({"name": "drd.bus", "msg": bus_line, "subject": "host/ranger1/load",
                                  "args": ("ranger1", "publication", "host/ranger1/load", "bad JSON")})
    assert limit.filter(load) and "host/ranger1/load" in load.getMessage()


def secured(tmp_path: Path, catalog: Catalog, security: str) -> Cluster:
    from drd.hosts import load_hosts

    path = tmp_path / "hosts.yaml"
    path.write_text(hosts_yaml("lab", ["controller", "ranger1"], [7447, 7448], security=security))
    return load_hosts(path, catalog)


def test_password_mode_reads_the_users_line(tmp_path: Path, catalog: Catalog) -> None:
    (tmp_path / "users").write_text("other:x\n\ndrd:se:cret\n")
    tr = transport(secured(tmp_path, catalog, "{mode: password, user: drd, password_file: users}"))
    assert tr.mode is SecurityMode.PASSWORD
    assert tr.options["transport/auth/usrpwd/password"] == "se:cret"
    assert tr.options["transport/auth/usrpwd/dictionary_file"] == str(tmp_path / "users")


@pytest.mark.parametrize("content, message", [
    ("other:x\n", "no line drd:PASSWORD for user 'drd'"),
    ("drd\n", ":1: expected user:password"),
    ("# users\ndrd:x\n", ":1: expected user:password"),
], ids=["no-user", "no-colon", "comment"])
def test_a_bad_password_file_is_refused(tmp_path: Path, content: str, message: str) -> None:
    (tmp_path / "users").write_text(content)
    with pytest.raises(SecurityError) as e:
        read_password("hosts.yaml", str(tmp_path / "users"), "drd")
    assert message in str(e.value) and "cluster.security.password_file" in str(e.value)


def test_missing_security_files_are_named(tmp_path: Path, catalog: Catalog) -> None:
    with pytest.raises(SecurityError) as e:
        transport(secured(tmp_path, catalog, "{mode: tls, ca: ca.pem, cert: host.pem, key: host.key}"))
    text = str(e.value)
    for key, name in (("ca", "ca.pem"), ("cert", "host.pem"), ("key", "host.key")):
        assert f"cluster.security.{key}: no such file: {tmp_path / name}" in text


def test_tls_mode_moves_every_endpoint_to_tls(tmp_path: Path, catalog: Catalog) -> None:
    from test_daemon_tls import Authority, pki_backend

    Authority(tmp_path / "pki", "test-ca", pki_backend()).issue(tmp_path / "tls", "drd-daemon")
    tr = transport(secured(tmp_path, catalog, "{mode: tls, ca: tls/ca.pem, cert: tls/host.pem, key: tls/host.key}"))
    assert tr.endpoints == {"controller": "tls/127.0.0.1:7447", "ranger1": "tls/127.0.0.1:7448"}
    assert tr.options["transport/link/protocols"] == ["tls"] and tr.options["transport/link/tls/enable_mtls"]
    assert tr.others("controller") == {"ranger1": "tls/127.0.0.1:7448"}
    assert tr.identity == "drd-daemon"  # the certificate's common name: what the daemons' access control knows


def test_a_pem_block_that_is_no_certificate_is_refused_naming_the_key(tmp_path: Path, catalog: Catalog) -> None:
    for name, label in (("ca.pem", "CERTIFICATE"), ("host.pem", "CERTIFICATE"), ("host.key", "PRIVATE KEY")):
        (tmp_path / name).write_text(f"-----BEGIN {label}-----\nAA==\n-----END {label}-----\n")
    with pytest.raises(SecurityError) as refused:
        transport(secured(tmp_path, catalog, "{mode: tls, ca: ca.pem, cert: host.pem, key: host.key}"))
    [problem] = [str(p) for p in refused.value.problems]
    assert "cluster.security.cert" in problem and "host.pem: not a readable certificate" in problem, problem


def test_peer_diagnosis() -> None:
    assert parse_endpoint("tcp/[::1]:7447") == ("tcp", "::1", 7447)
    assert parse_endpoint("tcp/nohost") is None
    found = diagnose({"a": "tcp/h:1", "b": "tcp/h:2"}, lambda e: None if e.endswith("1") else "connection refused")
    assert found == {"a": f"tcp/h:1: {REFUSED}", "b": "tcp/h:2: connection refused"}


def test_pidfiles_claim_refuse_and_forget_stale_ones(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from drd.daemon import runfiles

    info = runfiles.claim(tmp_path, "ranger1", "lab", "hosts.yaml")
    assert info.pid == os.getpid() and info.running()
    assert runfiles.mark(tmp_path, info, "running").state == "running"
    stale = runfiles.PidFile(2**22 + 7, "ranger2", "lab", "h", 0.0, 0.0)
    runfiles.write(runfiles.path_of(tmp_path, "lab", "ranger2"), stale)
    assert not stale.running()
    assert runfiles.stop([stale]) == {stale.pid: "not running"}
    assert [p.relative_to(tmp_path).as_posix() for p, _ in runfiles.pidfiles(tmp_path)] == [
        "lab/ranger1.pid", "lab/ranger2.pid"]
    other = runfiles.claim(tmp_path, "ranger1", "other-lab", "elsewhere/hosts.yaml")  # another cluster: no clash
    assert runfiles.path_of(tmp_path, "other-lab", "ranger1").exists()
    runfiles.release(tmp_path, other)
    runfiles.release(tmp_path, info)
    assert not runfiles.path_of(tmp_path, "lab", "ranger1").exists()
    monkeypatch.setenv("DRD_RUN_DIR", str(tmp_path / "env"))
    assert runfiles.run_dir(None) == tmp_path / "env" and runfiles.run_dir(tmp_path) == tmp_path
    monkeypatch.delenv("DRD_RUN_DIR")
    assert runfiles.run_dir(None) == Path.home() / ".drd" / "run"


# --- the daemon shell on a LocalBus ---------------------------------------------------------------------


class Clocks:
    """One fake monotonic clock for the view and the controller, and a fake wall clock."""

    def __init__(self) -> None:
        self.sim = SimClock(100.0)

    def mono(self) -> float:
        return self.sim.now()

    def wall(self) -> float:
        return 1_000_000.0 + self.sim.now()


def started(cluster: Cluster, catalog: Catalog, clocks: Clocks) -> tuple[LocalNetwork, dict[str, Daemon]]:
    """The controller's and ranger1's daemons on a LocalBus, started and stepped once (what starting made due is
    published: announcements to the newcomer); ranger2 is never started."""
    net = LocalNetwork()
    daemons = {h: Daemon(DaemonConfig(cluster, h, catalog, load_period=0.25), net.session(h), clock=clocks.mono,
                         wall=clocks.wall, controller_clock=clocks.sim) for h in ("controller", "ranger1")}
    for d in daemons.values():
        d.start()
    for d in daemons.values():
        d.step()
    return net, daemons


def test_daemons_on_a_local_bus_see_each_other_and_the_controller_follows(cluster: Cluster,
                                                                          catalog: Catalog) -> None:
    clocks = Clocks()
    net, daemons = started(cluster, catalog, clocks)
    ctl = daemons["controller"]
    try:
        assert ctl.view.up() == ["controller", "ranger1"]
        assert ctl.controller is not None
        units = {u.id for u in ctl.controller.resources().units}
        assert "ranger1.camera" in units and "ranger2.camera" not in units
        bus = net.session("tool")
        keys = ctl.keys
        hosts = bus.call(keys.db("ranger1", "hosts"))
        assert isinstance(hosts, HostsReply) and hosts.answered_by == "ranger1"
        assert {h.name: h.state for h in hosts.hosts} == {"controller": "up", "ranger1": "up", "ranger2": "down"}
        comps = bus.call(keys.db("controller", "components"))
        assert isinstance(comps, ComponentsReply) and "ranger1" in comps.types["Ranger"]
        assert bus.call(keys.db("ranger1", "lookup"), Lookup("executive")) == Location(
            "executive", "service", "controller", keys.executive)
        reply = bus.call(keys.db("controller", "query"), TraderRequest("Ranger where magazine == 0"))
        assert [o["id"] for o in reply.offers] == ["ranger1"]  # type: ignore[attr-defined]

        # A grant on ranger1's camera, then ranger1 goes silent: down at once, freed a lease later.
        broker = ctl.controller.executive.broker
        granted = broker.request(Request("m/a", 1, (NeedRequest("cam", "Camera"),)), clocks.sim.now())
        assert type(granted[0]).__name__ == "Granted"

        def advance(dt: float) -> None:  # the holder renews its lease, as the executive does; the controller's
            tick = ctl.config.tick  # daemon ticks meanwhile, as often as it does (a gap of its own is not listened
            while dt > 0:  # through: the others' silence over it does not count)
                clocks.sim.advance(min(dt, tick))
                dt -= tick
                broker.renew("m/a", clocks.sim.now())
                ctl.step()

        advance(LEASE + 0.1)
        ctl.step()
        assert ctl.view.state("ranger1") is HostState.DOWN
        assert [e.kind for e in ctl.events][-2:] == ["down", "resources-pending"]
        freed: list[object] = []
        broker.attach(freed.extend)
        advance(LEASE)
        ctl.step()
        assert [r for r in (getattr(d, "reason", None) for d in freed) if r] == ["host lost"]  # renewals aside
        assert "ranger1.camera" not in {u.id for u in ctl.controller.resources().units}
        assert ctl.events[-1].kind == "resources-removed"

        # ranger1 reports again: up, and its resources are back.
        daemons["ranger1"].step()
        assert ctl.view.state("ranger1") is HostState.UP
        assert "ranger1.camera" in {u.id for u in ctl.controller.resources().units}
    finally:
        for d in daemons.values():
            d.close()
    assert ctl.view.state("ranger1") is HostState.DOWN or ctl.bus.closed


def test_a_host_a_call_found_silent_is_granted_to_no_one_until_it_reports_again(cluster: Cluster,
                                                                                catalog: Catalog) -> None:
    """A frozen host stops answering a lease before its missing reports make it down: the call that timed out
    (`ComponentRouter(on_down=Controller.apply_offline)`) ends its holder, whose robot must go to no waiter then
    (CI: granted in that instant, the waiter failed at once); its next load report, through the daemon, brings it
    back. Asserted from the manager's decisions."""
    clocks = Clocks()
    _, daemons = started(cluster, catalog, clocks)
    ctl = daemons["controller"]
    try:
        assert ctl.controller is not None and ctl.view.state("ranger1") is HostState.UP
        broker = ctl.controller.executive.broker
        need = (NeedRequest("cam", "Camera"),)
        assert type(broker.request(Request("m/a", 1, need), clocks.sim.now())[0]).__name__ == "Granted"
        decided: list[object] = []
        broker.attach(decided.extend)
        broker.request(Request("m/b", 1, need), clocks.sim.now())  # waits: the one Camera is m/a's
        view = ctl.controller.resources()  # ranger2 never joined: its Camera would serve m/b (faults audit 21, #2)
        assert [(w.holder, [b.holder for b in w.blocked_by], w.offline) for w in view.queue] == [
            ("m/b", ["m/a"], ["ranger2"])]
        ctl.controller.apply_offline("ranger1")  # a call to ranger1 did not answer; the view still has it up
        assert ctl.view.state("ranger1") is HostState.UP and ctl.events[-1].kind == "resources-offline"
        broker.release("m/a", clocks.sim.now())  # the holder the call failed
        assert not [d for d in decided if type(d).__name__ == "Granted"], decided
        view = ctl.controller.resources()  # what `missionctl status` and `resources` are told
        assert [(w.holder, w.offline) for w in view.queue] == [("m/b", ["ranger1", "ranger2"])]
        assert {u.id for u in view.units if u.offline} == {u.id for u in view.units if u.host == "ranger1"} != set()
        clocks.sim.advance(0.3)
        daemons["ranger1"].step()  # its next load report
        assert ctl.events[-1].kind == "resources-online"
        assert [getattr(d, "holder", None) for d in decided if type(d).__name__ == "Granted"] == ["m/b"], decided
        assert not [u.id for u in ctl.controller.resources().units if u.offline]
    finally:
        for d in daemons.values():
            d.close()


def test_the_daemon_refuses_and_counts_what_it_cannot_use(cluster: Cluster, catalog: Catalog) -> None:
    net = LocalNetwork()
    daemon = Daemon(DaemonConfig(cluster, "controller", catalog), net.session("controller"))
    daemon.start()
    try:
        tool, keys = net.session("tool"), daemon.keys
        for key in (keys.ping("controller"), keys.status("controller"), keys.db("controller", "lookup"),
                    keys.db("controller", "query"), keys.resources, keys.executive):
            [bad] = tool.request_raw(key, b"{not json")
            assert bad.error is not None and bad.error.startswith("malformed request")
            [wrong] = tool.request_raw(key, encode(announcement("ranger1")))
            assert wrong.error is not None and "expected" in wrong.error
        tool.put_raw(keys.load("ranger1"), b"\x00")
        tool.put(keys.load("ranger1"), Ping(1))
        tool.put(keys.announce("ranger2"), announcement("ranger1"))
        [reply] = tool.request(keys.db("controller", "query"), TraderRequest("Camra"))
        assert reply.error is not None and "unknown type Camra (did you mean Camera?)" in reply.error
        tool.put(keys.announce("ranger2"), Announcement("controller", "lab", 1, 0.0, [], [], [], {}, ""))
        assert all(e.kind != "conflict" for e in daemon.events) and "conflict" not in daemon.stop_reason, (
            "a peer naming this host under another host's key is refused, not obeyed (security audit D1)")
        status = daemon.status()
        assert status.bus["malformed"] == 7
        assert sum(status.rejected.values()) == 9
        stop = threading.Event()
        daemon._stop = stop  # as `run` sets it: what a conflict sets
        claim = Announcement("controller", "lab", 1, 0.0, [], [], [], {}, "")
        tool.put(keys.announce("controller"), claim)  # forged, or replayed from a daemon gone since: nobody answers
        wait_until(lambda: sum(daemon.status().rejected.values()) == 10, "the unanswered claim to be refused",
                   timeout=CLAIM_TRIES * (2 + cluster.lease) + 5)
        assert not stop.is_set() and all(e.kind != "conflict" for e in daemon.events), (
            "an announcement alone stops no daemon (wire audit 17, D1)")
        assert "an announcement of another drd as host controller that no daemon answers for" in (
            daemon.status().rejected)  # one kind, whatever pid a forger names (review: the kinds grew unbounded)
        for pid in range(2, 2 + 2 * MAX_REJECTED_KINDS):
            daemon._reject("k", f"forged {pid}: junk")  # a peer varying what it sends: the kinds stay bounded
        assert len(daemon.status().rejected) == MAX_REJECTED_KINDS and daemon.status().rejected["other"] > 0
        for pid in range(100, 300):  # a flood of claims, each another pid: one thread checks them (review)
            tool.put(keys.announce("controller"), replace(claim, pid=pid))
        assert sum(t.name == "drd-claim-check" for t in threading.enumerate()) <= 1
        wait_until(lambda: not any(t.name == "drd-claim-check" for t in threading.enumerate()), "the checks' end",
                   timeout=2 * CLAIM_TRIES * (2 + cluster.lease) + 5)
        assert not stop.is_set()
        other = daemon.status()
        tool.serve(keys.status("controller"), lambda q: replace(other, pid=1, started=0.0))  # a daemon answers
        tool.put(keys.announce("controller"), claim)
        wait_until(stop.is_set, "the daemon started later to stop")
        assert daemon.events[-1].kind == "conflict" and "another drd (pid 1) runs as host controller" in (
            daemon.events[-1].detail) and daemon.stop_reason.startswith("conflict: another drd (pid 1)")
    finally:
        daemon.close()


def wait_until(done: Callable[[], bool], what: str, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


def test_drd_stop_never_touches_another_clusters_daemons(tmp_path: Path) -> None:
    """Issue #17: run files are per cluster, and `drd stop --all` with two clusters here names them and stops none
    until told which (the pidfiles are stale, so no process is signalled)."""
    import json
    import subprocess
    import sys

    from drd.daemon import runfiles

    for cluster, host in (("lab", "controller"), ("lab", "ranger1"), ("field", "controller")):
        runfiles.write(runfiles.path_of(tmp_path, cluster, host),
                       runfiles.PidFile(2**22 + 11, host, cluster, f"{cluster}/hosts.yaml", 0.0, 0.0))

    def drd(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "drd.cli.drd", *args, "--run-dir", str(tmp_path)],
                              capture_output=True, text=True, timeout=60, check=False)

    refused = drd("stop", "--all")
    assert refused.returncode == 2 and "daemons of 2 clusters run here (field, lab): say which" in refused.stderr
    assert len(list(tmp_path.rglob("*.pid"))) == 3
    refused = drd("stop", "--host", "controller")
    assert refused.returncode == 2 and "host controller of 2 clusters" in refused.stderr
    done = drd("stop", "--all", "--cluster", "lab", "--json")
    assert done.returncode == 0, done.stderr
    assert sorted(d["host"] for d in json.loads(done.stdout)["daemons"]) == ["controller", "ranger1"]
    assert [p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*.pid")] == ["field/controller.pid"]


def test_drd_start_refuses_a_driver_it_cannot_load_before_any_process_or_pidfile(tmp_path: Path) -> None:
    """Issue #18: a hosts file naming a driver that does not exist was only refused at the first mission."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[2]
    text = (root / "hosts.yaml").read_text(encoding="utf-8").replace(
        "drive: {type: Drive, driver: sim, slice: 60s", "drive: {type: Drive, driver: serial, slice: 60s")
    (tmp_path / "hosts.yaml").write_text(text, encoding="utf-8")
    done = subprocess.run([sys.executable, "-m", "drd.cli.drd", "start", "--host", "ranger1", "--config",
                           "hosts.yaml", "--run-dir", str(tmp_path / "run")], cwd=tmp_path, capture_output=True,
                          text=True, timeout=60, check=False)
    assert done.returncode == 2
    assert ("hosts.yaml: hosts.ranger1.devices.drive.driver: no module components.serial.drive "
            "(for components.serial.drive:SerialDrive)") in done.stderr
    assert not (tmp_path / "run").exists() and "Traceback" not in done.stderr


def test_load_reports_go_out_on_the_wall_clocks_multiples_of_the_period(cluster: Cluster, catalog: Catalog) -> None:
    """Every daemon reports on the same wall-clock instants, so a router receives a fleet's reports together and
    passes them on in a few batches; a step a little early is on time, one late does not shift the next."""
    net = LocalNetwork()
    clocks = Clocks()
    clocks.sim.set(100.3)  # the wall clock at 1,000,100.3: between two multiples of the period
    heard: list[float] = []
    tool = net.session("tool")
    tool.subscribe(ClusterKeys("lab").loads, lambda s: heard.append(round(s.payload.at - 1_000_000.0, 3)))
    daemon = Daemon(DaemonConfig(cluster, "controller", catalog, load_period=0.25), net.session("controller"),
                    clock=clocks.mono, wall=clocks.wall, controller_clock=clocks.sim)
    daemon.start()  # reports at once
    try:
        for at in (100.4, 100.49, 100.55, 100.74, 100.9, 101.1, 101.26, 101.4, 101.5):
            clocks.sim.set(at)
            daemon.step()
        assert heard == [100.3, 100.49, 100.74, 101.1, 101.26, 101.5]
    finally:
        daemon.close()


def test_all_peers_reachable_is_said_once_not_at_every_check(cluster: Cluster, catalog: Catalog,
                                                             caplog: pytest.LogCaptureFixture) -> None:
    """A fleet whose peers are all up says so once, not every 5 s in every daemon's log forever."""
    net = LocalNetwork()
    clocks = Clocks()
    hosts = ("controller", "ranger1", "ranger2")
    daemons = [Daemon(DaemonConfig(cluster, h, catalog), net.session(h), clock=clocks.mono, wall=clocks.wall,
                      controller_clock=clocks.sim) for h in hosts]
    caplog.set_level(logging.INFO, logger="drd.daemon")
    try:
        for d in daemons:
            d.start()
        for _ in range(80):  # 20 s: four peer checks or more in each daemon
            clocks.sim.advance(0.25)
            for d in daemons:
                d.step()
        assert all(d.view.up() == list(hosts) for d in daemons)
        said = [r for r in caplog.records if r.getMessage() == "all 2 peers reachable"]
        assert len(said) == len(daemons)
    finally:
        for d in daemons:
            d.close()
