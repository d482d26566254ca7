"""`RemoteComponent` placement on the in-process bus: where a movable component starts, the retry on another
host when one does not answer, and the new start after its host is lost. Hosts are queryables on a `LocalBus`
that answer as a Creator does (the Creator itself is tested across real processes in test_cluster_*.py)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator, Mapping
from typing import Any

import pytest

from drd.bus import Message, Query, Reply
from drd.bus.local import LocalBus
from drd.cluster import remote
from drd.cluster.remote import (
    ComponentBatch,
    ComponentBatchReply,
    ComponentCall,
    ComponentError,
    ComponentReply,
    ComponentRouter,
    HostDown,
    RemoteComponent,
)
from drd.runtime.component import Context, Status


class Hosts:
    """Creators on named hosts, recording (host, op) of every call; `order` is the placer's preference."""

    def __init__(self, bus: LocalBus, serving: list[str], order: list[str]) -> None:
        self.bus, self.order = bus, order
        self.calls: list[tuple[str, str]] = []
        self.dead: set[str] = set()
        self.asked: list[frozenset[str]] = []
        self.why: list[dict[str, str]] = []  # each call's exclusions with their reasons
        self.failing: set[str] = set()  # hosts whose Creator answers a start with an error
        self.raising: set[str] = set()  # hosts where the component's own start raises
        self.silent: set[str] = set()  # hosts whose Creator takes calls and answers none (gone as they came)
        self.slow: set[str] = set()  # hosts whose Creator takes 0.2 s over a start (longer than it is given)
        self.retired: set[str] = set()  # hosts that retired their instances: other calls than a start are `lost`
        self.killed: dict[str, str] = {}  # hosts whose worker was killed: every call after a start fails so
        self.terms: list[tuple[str, float, int]] = []  # (op, term, generation) of every call
        self.queryables = {host: self.serve(host) for host in serving}

    def serve(self, host: str) -> Any:
        """`host`'s Creator, on the bus from now on."""
        return self.bus.serve(f"drd/t/host/{host}/creator", self._creator(host))

    def _creator(self, host: str) -> Any:
        def serve(query: Query) -> Message | Reply | None:
            msg = query.payload
            calls = msg.calls if isinstance(msg, ComponentBatch) else [msg]
            assert all(isinstance(c, ComponentCall) for c in calls)
            self.calls += [(host, c.op) for c in calls if isinstance(c, ComponentCall)]
            self.terms += [(c.op, c.term, c.generation) for c in calls if isinstance(c, ComponentCall)]
            if host in self.silent:
                return None
            if host in self.slow and any(isinstance(c, ComponentCall) and c.op == "start" for c in calls):
                time.sleep(0.2)
            if host in self.retired and all(isinstance(c, ComponentCall) and c.op != "start" for c in calls):
                lost = ComponentReply(error=f"{host}'s Creator refused it: no instance M/Wait of mission m on {host}",
                                      lost=True)
                return ComponentBatchReply([lost]) if isinstance(msg, ComponentBatch) else lost
            self.retired.discard(host)  # a start: it runs one again
            replies = [ComponentReply(status="running" if c.op == "step" else "",
                                      error="Wait failed to start here: no worker" if host in self.failing
                                      and c.op == "start" else self.killed.get(host, "") if c.op != "start"
                                      else "") for c in calls]
            if host in self.raising:
                jammed = ComponentReply(error="component raised RuntimeError: jammed (at kit/w.py:7, in start)",
                                        raised=True)
                replies = [jammed if c.op == "start" else r for c, r in zip(calls, replies, strict=True)]
            return ComponentBatchReply(replies) if isinstance(msg, ComponentBatch) else replies[0]
        return serve

    def place(self, component: str, params: Mapping[str, Any], exclude: Mapping[str, str]) -> str:
        self.asked.append(frozenset(exclude))
        self.why.append(dict(exclude))
        for host in self.order:
            if host not in exclude and host not in self.dead:
                return host
        raise ComponentError(f"no host can run {component}: all excluded")


@pytest.fixture(autouse=True)
def quick_start(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """A start is given the router's 0.05 s here, not 5 s: a host that does not answer it is not asked again."""
    monkeypatch.setattr(remote, "START_TIMEOUT", 0.05)
    yield


def movable(hosts: Hosts, timeout: float = 0.05, **kw: Any) -> tuple[RemoteComponent, list[str]]:
    router = ComponentRouter(hosts.bus, "t", {}, "controller", local={}, mission="m",
                             world="corridor", timeout=timeout, dead=lambda h: h in hosts.dead, place=hosts.place, **kw)
    comp = RemoteComponent("Wait", router)
    logs: list[str] = []
    comp.setup(Context("M/Wait", {"duration": 5.0}, {}, lambda ev, **f: None, logs.append, lambda: 0.0))
    return comp, logs


def test_a_movable_component_starts_where_the_policy_says() -> None:
    hosts = Hosts(LocalBus(), ["a", "b"], ["b", "a"])
    comp, _ = movable(hosts)
    comp.start()
    assert comp.movable and comp.host == "b"
    assert comp.step(0.1) is Status.RUNNING
    assert hosts.calls == [("b", "start"), ("b", "step")]
    assert list(comp.router.placed) == [("M/Wait", "b", "placed")]


def test_a_host_that_does_not_answer_the_start_is_excluded_and_the_next_one_tried() -> None:
    hosts = Hosts(LocalBus(), ["b"], ["a", "b"])  # a has no Creator: its start times out
    comp, _ = movable(hosts)
    comp.start()
    assert comp.host == "b"
    assert hosts.asked == [frozenset(), frozenset({"a"})]
    assert hosts.calls == [("b", "start")]
    assert "a" not in comp.router.gone, "a slow start excludes a from this placement only, not from the mission"


def test_a_host_whose_start_fails_is_excluded_and_the_next_one_tried() -> None:
    """Issue #15: a start that fails there (rather than timing out) is retried on the next host by policy."""
    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    hosts.failing.add("a")
    comp, _ = movable(hosts)
    comp.start()
    assert comp.host == "b"
    assert hosts.asked == [frozenset(), frozenset({"a"})]
    assert hosts.calls == [("a", "start"), ("b", "start")]


def test_a_start_whose_component_raised_fails_as_in_process_and_is_not_tried_elsewhere() -> None:
    """Users audit 22, #3: the component's own `start` raising was taken for a host refusing it, so its start (and
    whatever it does) ran again on every worker host, and the reason became "no host can run it"."""
    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    hosts.raising.update({"a", "b"})
    comp, _ = movable(hosts)
    with pytest.raises(ComponentError) as raised:
        comp.start()
    assert str(raised.value) == "component raised RuntimeError: jammed (at kit/w.py:7, in start)"
    assert hosts.calls == [("a", "start")] and comp.host == "a"  # where it ran: its stop goes there


def test_a_call_that_reached_nothing_is_asked_again_until_the_host_answers(monkeypatch: pytest.MonkeyPatch) -> None:
    """A router lost on the way (two routers, e2e test_cluster_two_routers): the routes come back through the
    other one a moment later. The start goes to the host the policy chose once its Creator is reachable again,
    and a step does too, its host not taken for lost (both used to fail at once and exclude the host)."""
    monkeypatch.setattr(remote, "START_TIMEOUT", 5.0)
    hosts = Hosts(LocalBus(), ["b"], ["a", "b"])
    threading.Timer(0.2, lambda: hosts.queryables.update(a=hosts.serve("a"))).start()
    comp, _ = movable(hosts, timeout=5.0)
    comp.start()
    assert comp.host == "a" and hosts.asked == [frozenset()] and hosts.calls == [("a", "start")]
    hosts.queryables.pop("a").close()
    threading.Timer(0.2, lambda: hosts.queryables.update(a=hosts.serve("a"))).start()
    assert comp.step(0.1) is Status.RUNNING
    assert comp.host == "a" and not comp.router.gone and hosts.calls[-1] == ("a", "step")


def test_a_host_the_view_has_down_is_not_asked_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """Asking again is for a host the cluster view still has up: one whose token vanished where no router brings
    it back is down at once, and the next host is tried without waiting out the start's timeout."""
    monkeypatch.setattr(remote, "START_TIMEOUT", 5.0)
    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    hosts.silent.add("a")  # it takes the call, answers none, and its token vanishes meanwhile:
    hosts.queryables["a"] = hosts.bus.serve("drd/t/host/a/creator", lambda q: hosts.dead.add("a"))
    comp, _ = movable(hosts)
    comp.start()
    assert comp.host == "b" and hosts.asked == [frozenset(), frozenset({"a"})]
    assert [c for c in hosts.calls if c[1] == "start"] == [("a", "start"), ("b", "start")], "a asked once"


def test_the_instance_of_a_start_that_timed_out_is_terminated_with_the_starts_term() -> None:
    """The terminate sent after a start that timed out (the host may register the instance late) carries the
    start's term and generation: a Creator refuses a call of term 0 as an older controller's, so the late
    instance ran on unseen (it was sent without them)."""
    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    hosts.slow.add("a")
    comp, _ = movable(hosts, term=7.5, generation=3)
    comp.start()
    assert comp.host == "b"
    deadline = time.monotonic() + 10
    while ("terminate", 7.5, 3) not in hosts.terms and time.monotonic() < deadline:
        time.sleep(0.01)
    assert ("terminate", 7.5, 3) in hosts.terms and ("a", "terminate") in hosts.calls, hosts.terms


def test_hosts_that_timed_out_in_this_mission_are_not_offered_again() -> None:
    hosts = Hosts(LocalBus(), ["b"], ["a", "b"])
    comp, _ = movable(hosts)
    comp.router.gone.add("a")  # a step there timed out earlier
    comp.start()
    assert comp.host == "b" and hosts.asked == [frozenset({"a"})], "no try is spent on a"


def test_tries_go_on_while_an_untried_host_remains_and_each_refusal_is_passed_on_with_its_reason() -> None:
    """Fleet audit defect 2: three refusing hosts used up the 3 tries and failed the state while a fourth could
    run it. Each refusal excludes its host, with the Creator's words, and the placer is asked again."""
    names = [f"h{i}" for i in range(5)]
    hosts = Hosts(LocalBus(), names, names)
    hosts.failing |= set(names[:4])
    comp, _ = movable(hosts)
    comp.start()
    assert comp.host == "h4" and list(comp.router.placed) == [("M/Wait", "h4", "placed")]
    assert hosts.calls == [(h, "start") for h in names]
    assert hosts.why[-1] == dict.fromkeys(names[:4], "Wait failed to start here: no worker")


def test_the_start_fails_the_state_once_every_host_refused_it_with_the_placers_reasons() -> None:
    names = [f"h{i}" for i in range(5)]
    hosts = Hosts(LocalBus(), [], names)  # nobody answers
    comp, _ = movable(hosts)
    with pytest.raises(ComponentError) as err:
        comp.start()
    assert not isinstance(err.value, HostDown), "the state fails: no further placement"
    assert str(err.value) == "M/Wait: Wait could not be started: no host can run Wait: all excluded"
    assert len(hosts.asked) == len(names) + 1 and hosts.asked[-1] == frozenset(names)
    assert comp.host is None


def test_when_no_host_can_run_it_the_placers_reason_fails_the_state() -> None:
    hosts = Hosts(LocalBus(), ["a"], [])
    comp, _ = movable(hosts)
    with pytest.raises(ComponentError, match="all excluded"):
        comp.start()


def test_after_its_host_is_lost_the_next_call_starts_it_again_elsewhere() -> None:
    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    comp, logs = movable(hosts)
    comp.start()
    comp.step(0.1)
    hosts.dead.add("a")
    assert comp.step(0.2) is Status.RUNNING
    assert comp.host == "b"
    assert hosts.calls == [("a", "start"), ("a", "step"), ("b", "start"), ("b", "step")]
    assert list(comp.router.placed)[-1] == ("M/Wait", "b", "re-placed")
    assert any("placed again on b" in line and "a was lost" in line for line in logs)
    hosts.dead = {"b"}  # a came back, b is lost: a suspend now starts it again on a, then suspends it
    comp.suspend()
    assert hosts.calls[-2:] == [("a", "start"), ("a", "suspend")]
    comp.terminate(Status.SUCCESS)
    assert hosts.calls[-1] == ("a", "terminate")


def test_a_host_that_stops_answering_mid_mission_also_moves_it() -> None:
    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    comp, _ = movable(hosts)
    comp.start()
    hosts.queryables["a"].close()  # a's Creator is gone before the daemon saw the host go down
    assert comp.step(0.1) is Status.RUNNING
    assert comp.host == "b" and "a" in comp.router.gone
    assert hosts.calls == [("a", "start"), ("b", "start"), ("b", "step")]


@pytest.mark.parametrize("op", ["step", "suspend"])
def test_an_instance_its_host_no_longer_runs_starts_again_from_its_last_snapshot(op: str) -> None:
    """A host frozen past its lease retires its instances; on waking it answers that it runs none (`lost`): a
    movable one starts again where the policy says (that host may be chosen: it answers), from its last snapshot;
    before, the mission failed with the refusal."""
    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    comp, logs = movable(hosts)
    comp.start()
    comp.state = [{"left": 3.5}]  # the last snapshot its host sent
    hosts.retired.add("a")
    assert (comp.step(0.1) is Status.RUNNING) if op == "step" else comp.suspend() is None
    assert comp.host == "a" and "a" not in comp.router.gone
    assert hosts.calls == [("a", "start"), ("a", op), ("a", "start"), ("a", op)]
    assert list(comp.router.placed)[-1] == ("M/Wait", "a", "re-placed")
    assert any("placed again on a from its last snapshot: its host a no longer ran it" in line for line in logs)


def test_an_instance_its_host_no_longer_runs_ends_quietly_but_a_bound_one_fails() -> None:
    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    comp, _ = movable(hosts)
    comp.start()
    hosts.retired.add("a")
    comp.terminate(Status.SUCCESS)  # nothing runs there to stop
    assert hosts.calls[-1] == ("a", "terminate")
    bound, _ = movable(hosts)
    bound.start()
    bound.movable = False  # as one bound to a's devices is
    hosts.retired.add("a")
    with pytest.raises(remote.InstanceLost, match="no instance"):
        bound.terminate(Status.SUCCESS)
    with pytest.raises(ComponentError, match="no instance"):
        bound.step(0.1)



def test_a_bound_instance_whose_start_failed_ends_without_a_second_fault() -> None:
    """Users audit 21, #6: its module did not import on its host, so the start failed and no instance ran there;
    its terminate then logged "refused terminate ...: no instance", which read as a second fault."""
    from drd.runtime.ownership import Binding

    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    router = ComponentRouter(hosts.bus, "t", {"a.drive": "a"}, "controller", local={}, mission="m",
                             world="corridor", timeout=0.05, dead=lambda h: h in hosts.dead, place=hosts.place)
    bound = RemoteComponent("FollowCorridor", router)  # bound to a's drive: it runs there or nowhere
    bound.setup(Context("M/F", {}, {}, lambda ev, **f: None, lambda s: None, lambda: 0.0,
                        bindings={"drive": Binding("drive", "a.drive", "M")}))
    hosts.failing.add("a")
    with pytest.raises(ComponentError, match="failed to start here"):
        bound.start()
    hosts.retired.add("a")  # it answers that it runs no such instance
    bound.terminate(Status.FAILURE)  # nothing ran there: nothing to say
    assert hosts.calls[-1] == ("a", "terminate")


def test_a_component_bound_to_devices_is_never_moved() -> None:
    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    router = ComponentRouter(hosts.bus, "t", {"a.drive": "a"}, "controller", local={},
                             mission="m", world="corridor", timeout=0.05, dead=lambda h: h in hosts.dead,
                             place=hosts.place)
    comp = RemoteComponent("FollowCorridor", router)
    comp.setup(Context("M/F", {}, {}, lambda ev, **f: None, lambda s: None, lambda: 0.0))
    comp.host = "a"  # as `_resolve` finds it from the grant of a.drive
    hosts.dead.add("a")
    with pytest.raises(HostDown):
        comp.step(0.1)
    assert hosts.calls == []


def test_the_cycles_simulation_step_rides_on_a_batch_to_the_simulator_host_else_goes_alone() -> None:
    from types import SimpleNamespace

    steps: list[float] = []

    def step_sim(dt: float) -> Any:
        steps.append(dt)
        return SimpleNamespace(time=1.5, version=42)

    router = ComponentRouter(LocalBus(), "t", {}, "controller", local={}, mission="m",
                             world="corridor", dead=lambda h: h == "gone")
    router.simulator, router.step_sim = "ranger1", step_sim
    router.pending_step = 0.1
    assert router.step_first("ranger1") == 0.1 and steps == [] and router.pending_step == 0.0  # carried
    assert router.step_first("ranger1") == 0.0 and steps == []  # once per cycle
    router.pending_step = 0.1
    assert router.step_first("ranger2") == 0.0 and steps == [0.1]  # made alone, before the call
    assert (router.sim_time, router.sim_version) == (1.5, 42)
    router.simulator, router.pending_step = "gone", 0.1
    assert router.step_first("gone") == 0.0 and steps == [0.1, 0.1]  # a down simulator host carries nothing

    def down(dt: float) -> Any:
        raise TimeoutError("no answer")
    router.step_sim, router.pending_step = down, 0.1
    with pytest.raises(ComponentError, match="^host gone is down: it ran the simulator, so the world is gone$"):
        router.step_first(None)  # its host is down: the words the mission fails with
    assert isinstance(router.sim_error, TimeoutError)
    router.simulator, router.pending_step = "ranger1", 0.1
    with pytest.raises(ComponentError, match="^the simulator on host ranger1 did not step: no answer$"):
        router.step_first(None)


@pytest.mark.parametrize("steps", [True, False])
def test_a_batch_that_carries_the_step_brings_the_new_time_or_stops_the_cycle(steps: bool) -> None:
    bus, seen = LocalBus(), []

    def creator(query: Query) -> Message:
        msg = query.payload
        assert isinstance(msg, ComponentBatch)
        seen.append(msg.sim_step)
        replies = [ComponentReply(status="running") for _ in msg.calls]
        return ComponentBatchReply(replies, 2.0, 7) if steps else ComponentBatchReply(
            [ComponentReply(error="ValueError: no simulation is running")])
    bus.serve("drd/t/host/a/creator", creator)
    router = ComponentRouter(bus, "t", {"a.drive": "a"}, "controller", local={},
                             mission="m", world="corridor")
    router.simulator, router.pending_step = "a", 0.1
    comp = RemoteComponent("FollowCorridor", router)
    comp.setup(Context("M/F", {}, {}, lambda ev, **f: None, lambda s: None, lambda: 0.0))
    comp.host = "a"
    if steps:
        assert comp.step(0.1) is Status.RUNNING
        assert seen == [0.1] and (router.sim_time, router.sim_version) == (2.0, 7) and router.sim_error is None
    else:
        with pytest.raises(ComponentError, match="a did not step the simulation: ValueError: no simulation"):
            comp.step(0.1)
        assert isinstance(router.sim_error, ComponentError), "the mission loop stops the mission"


def test_a_killed_workers_reason_is_said_by_its_step_alone() -> None:
    """Users audit 12, D6: a stuck component's reason was logged twice on a cluster, by its failed step and again
    by its `terminate`, which the dead process's host answered with the same words."""
    hosts = Hosts(LocalBus(), ["a"], ["a"])
    comp, _ = movable(hosts)
    comp.start()
    hosts.killed["a"] = "component process of M/Wait did not answer within 0.8 s (killed)"
    with pytest.raises(ComponentError, match="did not answer within 0.8 s"):
        comp.step(0.1)
    comp.terminate(Status.FAILURE)  # said already: not raised again
    assert hosts.calls[-1] == ("a", "terminate")
    hosts.killed["a"] = "component process of M/Wait died (exit code -9)"  # something new is said
    with pytest.raises(ComponentError, match="exit code -9"):
        comp.terminate(Status.FAILURE)


def test_a_call_that_fails_as_its_host_is_seen_down_says_so_in_the_dry_runs_words() -> None:
    """Faults audit 21, #3: kill -9 of a worker mid-call: the reason said "did not answer step within 6 s (... the
    query ended after 0.0 s ...)", contradicting itself; the view had the host down by then."""
    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    asked: list[str] = []

    def dead(host: str) -> bool:  # up when the call is made, down when it has failed
        asked.append(host)
        return len(asked) > 1

    router = ComponentRouter(hosts.bus, "t", {"a.drive": "a"}, "controller", local={}, mission="m",
                             world="corridor", timeout=0.05, dead=dead, place=hosts.place)
    comp = RemoteComponent("FollowCorridor", router)
    comp.setup(Context("M/F", {}, {}, lambda ev, **f: None, lambda s: None, lambda: 0.0))
    comp.host = "a"
    hosts.silent.add("a")
    with pytest.raises(HostDown, match="^host a is down: the component cannot run there$"):
        comp.step(0.1)


def test_a_step_that_failed_as_the_simulators_host_went_down_says_the_world_is_gone() -> None:
    """Faults audit 21, #1: a camera reading of a leaf on a worker found the simulator gone with its host, and the
    leaf failed with `component raised BusTimeout: no reply on 'drd/<cluster>/sim' ... (at observe.py:49, in
    step)`, naming no host, where the dry-run says the world is gone."""
    from drd.runtime.ownership import Binding

    hosts = Hosts(LocalBus(), ["a", "b"], ["a", "b"])
    router = ComponentRouter(hosts.bus, "t", {"a.camera": "a"}, "controller", local={}, mission="m",
                             world="corridor", timeout=0.05, dead=lambda h: h in hosts.dead, place=hosts.place)
    router.simulator = "s"
    comp = RemoteComponent("Observe", router)
    comp.setup(Context("M/O", {}, {}, lambda ev, **f: None, lambda s: None, lambda: 0.0,
                       bindings={"camera": Binding("camera", "a.camera", "M")}))
    comp.start()
    hosts.killed["a"] = "component raised BusTimeout: no reply on 'drd/t/sim': nothing answers there now"
    with pytest.raises(ComponentError, match="BusTimeout"):  # the simulator's host is not seen down: as it is
        comp.step(0.1)
    hosts.dead.add("s")
    with pytest.raises(ComponentError, match="^host s is down: it ran the simulator, so the world is gone$"):
        comp.step(0.2)
