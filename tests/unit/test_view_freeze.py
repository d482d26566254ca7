"""A daemon frozen for longer than the lease (SIGSTOP, a suspended VM, a starved process) heard nothing meanwhile: the
others' silence over its own gap is not evidence (bus audit defect 5). Pure `ClusterView` logic, fake times."""

from __future__ import annotations

import pytest
import yaml

from drd.bus import LoadReport
from drd.daemon.view import Change, ClusterView, HostState
from drd.hosts import Cluster, parse_hosts
from dsl.catalog import Catalog

LEASE = 3.0


@pytest.fixture(scope="module")
def cluster(catalog: Catalog) -> Cluster:
    hosts = {name: {"endpoint": f"tcp/127.0.0.1:{port}", "roles": [role]}
             for name, port, role in (("controller", 7447, "controller"), ("ranger1", 7448, "worker"),
                                      ("spare", 7449, "worker"))}
    text = yaml.safe_dump({"cluster": {"name": "lab", "security": {"mode": "none"}, "lease": f"{LEASE:g}s"},
                           "hosts": hosts})
    return parse_hosts(yaml.safe_load(text), "hosts.yaml", catalog)


def report(host: str) -> LoadReport:
    return LoadReport(host, 10.0, 20.0, 0.5, 0, 1.0)


def running(cluster: Cluster, until: float) -> ClusterView:
    """The controller's view ticking every 0.25 s with ranger1 and spare reporting every second, up to `until`."""
    view = ClusterView(cluster, "controller")
    for host in ("ranger1", "spare"):
        view.token(host, True, 0.0)
    t = 0.0
    while t <= until:
        if t == int(t):
            for host in ("ranger1", "spare"):
                view.load(report(host), t)
        assert view.tick(t) == []
        t += 0.25
    return view


def ticking(view: ClusterView, start: float, end: float) -> list[Change]:
    """The view ticking every 0.25 s from `start` to `end` (listening all along): what changed."""
    out, t = [], start
    while t <= end + 1e-9:
        out += view.tick(t)
        t += 0.25
    return out


def test_a_gap_of_its_own_longer_than_the_lease_marks_nobody_down_and_is_reported_once(cluster: Cluster) -> None:
    view = running(cluster, 18.0)  # last reports at 18 s; then the controller is frozen until 28.39 s
    [frozen] = view.tick(28.39)
    assert (frozen.kind, frozen.host) == ("frozen", "controller")
    assert "did not run for 10.39 s" in frozen.detail
    assert view.up() == ["controller", "ranger1", "spare"]
    assert view.tick(28.6) == []  # said once, and the others are still in their grace
    for host in ("ranger1", "spare"):  # their reports come in again after the wake-up
        view.load(report(host), 29.0)
    assert view.tick(31.5) == []  # past the grace: their fresh reports keep them up
    assert view.up() == ["controller", "ranger1", "spare"]


def test_real_silence_after_the_wake_up_still_counts_after_its_grace(cluster: Cluster) -> None:
    view = running(cluster, 18.0)
    assert [c.kind for c in view.tick(28.39)] == ["frozen"]
    view.load(report("spare"), 29.0)  # spare reports again; ranger1 stays silent
    assert ticking(view, 28.64, 28.39 + LEASE) == []  # exactly a lease after the wake-up: not yet
    [down] = view.tick(28.39 + LEASE + 0.01)
    assert (down.kind, down.host) == ("down", "ranger1")
    assert down.detail.startswith("silent: no load report for 13.40 s")
    assert view.shown_state("ranger1") == "unresponsive" and view.up() == ["controller", "spare"]


def test_a_token_lost_in_the_grace_is_judged_when_it_ends_unless_it_comes_back(cluster: Cluster) -> None:
    view = running(cluster, 18.0)
    # zenoh dropped the frozen daemon's links: the tokens vanish as it wakes, before its first tick
    [frozen] = view.token("ranger1", False, 28.4)
    assert frozen.kind == "frozen"
    assert view.token("spare", False, 28.41) == []
    assert view.up() == ["controller", "ranger1", "spare"]
    assert view.token("ranger1", True, 28.9) == []  # the link is back: nothing happened
    view.load(report("ranger1"), 29.0)
    assert view.tick(31.0) == []
    [down] = view.tick(28.4 + LEASE + 0.1)  # spare's never came back: gone, as a vanished token is
    assert (down.kind, down.host, down.detail) == ("down", "spare", "lost: its liveliness token vanished")
    assert view.shown_state("spare") == "down" and view.state("ranger1") is HostState.UP


def test_a_goodbye_is_not_held_by_the_grace(cluster: Cluster) -> None:
    view = running(cluster, 18.0)
    assert [c.kind for c in view.tick(28.39)] == ["frozen"]
    view.leaving("spare", "SIGTERM", 28.5)
    [down] = view.token("spare", False, 28.6)
    assert (down.kind, down.host, down.detail) == ("down", "spare", "stopped: SIGTERM")


def test_a_gap_within_the_lease_is_no_freeze_and_its_silence_is_not_counted(cluster: Cluster) -> None:
    """Faults audit 23, #1: a worker frozen for 2.85 s (lease 3 s) woke, and at its first tick took its controller,
    last heard 0.85 s before the freeze, for dead ("silent: no load report for 3.70 s"). The view's own gap is not
    the others' silence: it is left out of theirs, and no freeze is reported."""
    view = running(cluster, 18.0)  # the last reports at 18 s, then a gap of its own until 20.85 s
    assert view.tick(18.0 + LEASE - 0.15) == [] and view.tick(18.0 + LEASE + 0.05) == []
    assert view.up() == ["controller", "ranger1", "spare"]
    view.load(report("spare"), 21.1)  # what spare sent meanwhile comes in; ranger1 is really silent
    assert ticking(view, 21.3, 23.55) == []  # silent for less than a lease while the view listened
    [down] = view.tick(23.65)  # the gap but its first tick period (2.6 s) left out: a lease of listening
    assert (down.kind, down.host) == ("down", "ranger1") and view.up() == ["controller", "spare"]
    assert down.detail.startswith("silent: no load report for 5.65 s")


def test_a_tick_a_little_late_is_no_gap(cluster: Cluster) -> None:
    """Two tick periods apart at most: with a lease of 1 s, excusing every late tick would keep a silent host up."""
    view = running(cluster, 18.0)
    assert view.tick(18.5) == []  # a tick a quarter second late: within what a loaded machine does
    [down, _] = ticking(view, 18.75, 18.0 + LEASE + 0.25)  # the silence counts as it always did
    assert down.kind == "down" and down.detail.startswith("silent: no load report for 3.")


def test_whoever_timed_out_across_the_freeze_can_ask_whether_this_host_was_frozen(cluster: Cluster) -> None:
    view = running(cluster, 18.0)
    assert view.frozen_since(17.0, 18.1) == 0.0  # ticking: never frozen
    assert view.frozen_since(17.0, 28.39) == pytest.approx(10.39)  # woken, not yet ticked (another thread first)
    view.tick(28.39)
    assert view.frozen_since(17.0, 28.5) == pytest.approx(10.39)  # a call begun before the wake-up
    # one begun after it, within a lease: the others dropped their links to us meanwhile, and a call gets no answer
    # at once until they are made again (measured: 1.4 ms after SIGCONT), so that is still our freeze's doing
    assert view.frozen_since(28.45, 28.5) == pytest.approx(10.39)
    view.tick(30.0)
    view.tick(31.5)
    assert view.frozen_since(31.5, 31.6) == 0.0  # a lease after the wake-up, a silence is the callee's again
