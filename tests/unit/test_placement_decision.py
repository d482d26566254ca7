"""Placement as filters then scores (issue #15): the decision record, the worker-role filter, device affinity, the
controller's log of decisions and their lines in `missionctl status`. Pure: no bus, no process."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import pytest

from drd.cli.report import PLACEMENTS_SHOWN, placement_lines
from drd.daemon.placements import KEPT_PER_MISSION, PlacementLog, near_devices, status_entry
from drd.hosts import HostsError, Placement, parse_hosts
from drd.placement import (
    AFFINITY_SCALE,
    Decision,
    HostView,
    Placed,
    Recent,
    Unplaceable,
    place,
    refused_last,
    score,
    shares,
    with_recent,
)
from dsl.catalog import Catalog, ComponentType, Kind

WAIT = ComponentType("Wait", Kind.BEHAVIOR)
W = Placement()


def hv(name: str, cpu: float = 0.0, instances: int = 0, roles: tuple[str, ...] = ("worker",),
       up: bool = True) -> HostView:
    return HostView(name, cpu, 0.0, instances, up, roles=frozenset(roles))


def test_the_decision_records_the_candidates_the_filtered_hosts_and_every_scored_part() -> None:
    hosts = [hv("w2", cpu=40), hv("controller", roles=("controller",)), hv("w1", cpu=12), hv("gone", up=False)]
    decision = place(WAIT, hosts, W, role="worker")
    assert isinstance(decision, Placed) and decision.host == "w1"
    record = decision.decision
    assert record is not None
    assert record.candidates == ("controller", "gone", "w1", "w2")
    assert dict(record.filtered) == {"controller": ("no worker role",), "gone": ("down",)}
    assert [s.host for s in record.scored] == ["w1", "w2"] and record.winner == "w1"
    assert [(p.plugin, p.weight, p.value) for p in record.scored[0].parts] == [
        ("cpu", 1.0, 12.0), ("memory", 0.5, 0.0), ("instances", 0.2, 0.0), ("preferred", 1.0, 0.0),
        ("affinity", 0.2, 0.0)]
    assert record.summary() == ("w1 (score 12 vs w2 40: cpu 12 vs 40; filtered controller: no worker role; "
                                "gone: down)")
    assert record.as_dict()["scored"][1]["total"] == 40.0


def test_the_worker_role_filters_only_when_some_host_has_it() -> None:
    hosts = [hv("controller", roles=("controller",)), hv("ranger1", cpu=90, roles=("worker", "simulator"))]
    decision = place(WAIT, hosts, W, role="worker")
    assert isinstance(decision, Placed) and decision.host == "ranger1", "the idle controller is not a worker"
    nobody = [hv("a", cpu=50, roles=()), hv("b", cpu=10, roles=())]
    decision = place(WAIT, nobody, W, role="worker")
    assert isinstance(decision, Placed) and decision.host == "b", "no worker anywhere: every host may take it"


def test_device_affinity_draws_the_instance_to_its_robots_host_while_that_is_cheaper() -> None:
    hosts = [hv("ranger1", cpu=15), hv("spare", cpu=5)]
    assert place(WAIT, hosts, W).host == "spare"  # type: ignore[union-attr]
    near = shares({"ranger1": 3})
    decision = place(WAIT, hosts, W, near=near)
    assert isinstance(decision, Placed) and decision.host == "ranger1"
    assert decision.score == pytest.approx(15 - W.affinity * AFFINITY_SCALE)
    assert decision.reasons[0] == "ranger1: score -5 = cpu 1*15 + memory 0.5*0 + instances 0.2*0*10 - affinity 0.2*100"
    assert decision.decision is not None and "affinity -20 vs 0" in decision.decision.summary()
    busy = [hv("ranger1", cpu=35), hv("spare", cpu=5)]
    decision = place(WAIT, busy, W, near=near)
    assert isinstance(decision, Placed) and decision.host == "spare", "a far busier robot host loses"
    off = place(WAIT, hosts, Placement(affinity=0.0), near=near)
    assert isinstance(off, Placed) and off.host == "spare", "affinity 0: devices do not count"


def test_shares_split_the_devices_between_hosts_and_odd_figures_are_clamped() -> None:
    assert shares({"ranger1": 3, "ranger2": 1, "none": 0}) == {"ranger1": 0.75, "ranger2": 0.25}
    assert shares({}) == {} and shares({"a": 0}) == {}
    assert score(hv("a"), W, near={"a": 7.0}) == -W.affinity * AFFINITY_SCALE
    assert score(hv("a"), W, near={"a": float("nan")}) == 0.0


def test_an_unplaceable_answer_carries_its_record() -> None:
    decision = place(WAIT, [hv("a", up=False)], W)
    assert isinstance(decision, Unplaceable) and decision.decision is not None
    assert decision.decision.winner is None and decision.decision.summary() == "unplaceable: a: down"


# ---------------------------------------------------------------- the devices near an instance


@dataclass(eq=False)
class Proxy:
    movable: bool = True
    host: str | None = None


@dataclass(eq=False)
class N:
    """The part of a live node (`drd.runtime.tree.Node`) that near_devices reads."""

    path: str
    component_name: str | None = None
    grant: dict[str, str] | None = None
    units: tuple[str, ...] = ()
    component: Proxy | None = None
    parent: N | None = None
    children: list[N] = field(default_factory=list)

    @property
    def state(self) -> Any:
        return type("S", (), {"component": self.component_name})()

    def add(self, child: N) -> N:
        child.parent = self
        self.children.append(child)
        return child

    def ancestors(self) -> list[N]:
        return [self.parent, *self.parent.ancestors()] if self.parent else []

    def subtree(self) -> Iterator[N]:
        yield self
        for c in self.children:
            yield from c.subtree()


def test_the_devices_near_an_instance_are_its_ancestors_and_its_siblings_grants() -> None:
    hosts_of = {"ranger1": "ranger1", "ranger1.camera": "ranger1", "scout1": "scout1", "ranger2": "ranger2"}
    root = N("M")
    escort = root.add(N("M/Escort", grant={"ranger": "ranger1"}))
    escort.add(N("M/Escort/Watch", "Watch", grant={"camera": "ranger1.camera"}, component=Proxy(False, "ranger1")))
    waiting = escort.add(N("M/Escort/Wait", "Wait", component=Proxy()))
    root.add(N("M/Other", grant={"ranger": "ranger2"}))  # a cousin: not near
    escort.add(N("M/Escort/Scout", grant={"s": "scout1"}))
    assert near_devices(root, "Wait", hosts_of) == ("M/Escort/Wait", {"ranger1": 2, "scout1": 1})
    waiting.component = Proxy(host="spare")  # placed already: nothing is being placed
    assert near_devices(root, "Wait", hosts_of) == (None, {})
    assert near_devices(None, "Wait", hosts_of) == (None, {})


# ---------------------------------------------------------------- the controller's log and the status lines


def _decision(winner: str) -> Decision:
    outcome = place(WAIT, [hv(winner), hv("zz", cpu=50), hv("controller", roles=("controller",))], W, role="worker")
    assert outcome.decision is not None
    return outcome.decision


def test_the_log_keeps_the_last_decision_per_instance_and_drops_forgotten_missions() -> None:
    known = {"M-1", "M-2"}
    log = PlacementLog(lambda: known)
    log.note("M-1", "M/a", _decision("a"))
    log.note("M-1", "M/a", _decision("b"))
    log.note("M-2", "N/x", _decision("a"))
    entries = log.of("M-1")
    assert [(e["instance"], e["host"], e["how"]) for e in entries] == [("M/a", "b", "re-placed")]
    assert entries[0]["decision"]["filtered"] == {"controller": ["no worker role"]}
    known.discard("M-1")
    log.note("M-2", "N/y", _decision("a"))
    assert log.of("M-1") == [] and log.extras("M-1") == {}
    assert [e["instance"] for e in log.extras("M-2")["placements"]] == ["N/x", "N/y"]
    for i in range(KEPT_PER_MISSION + 5):
        log.note("M-2", f"N/{i}", _decision("a"))
    assert len(log.of("M-2")) == KEPT_PER_MISSION and log.of("M-2")[-1]["instance"] == f"N/{KEPT_PER_MISSION + 4}"


def test_a_status_entry_shows_a_few_hosts_and_counts_the_others() -> None:
    many = [hv(f"w{i:02d}", cpu=i) for i in range(9)] + [hv(f"c{i}", roles=()) for i in range(7)]
    outcome = place(WAIT, many, W, role="worker")
    assert outcome.decision is not None
    entry = status_entry("M/a", "placed", outcome.decision, shown=3)
    assert [s["host"] for s in entry["decision"]["scored"]] == ["w00", "w01", "w02"]
    assert list(entry["decision"]["filtered"]) == ["c0", "c1", "c2"]
    assert entry["decision"]["left_out"] == {"scored": 6, "filtered": 4}


def test_status_lines_one_per_placement_of_a_running_mission_all_with_explain() -> None:
    entries = [status_entry(f"Near/Escort/Wait{i}", "placed", _decision("ranger1")) for i in range(6)]
    running = {"mission": "Near", "outcome": None, "placements": entries}
    lines = [t.plain for t in placement_lines(running, 120)]
    assert len(lines) == PLACEMENTS_SHOWN + 1
    assert lines[0] == ("placement Escort/Wait2 -> ranger1 (score 0 vs zz 50: cpu 0 vs 50; filtered controller: "
                        "no worker role)")
    assert lines[-1].startswith("… 2 more placements")
    assert placement_lines({**running, "outcome": "success"}) == [], "finished: only with --explain"
    explained = [t.plain for t in placement_lines({**running, "outcome": "success"}, 120, explain=True)]
    assert "    zz 50 = cpu 50" in explained and "    controller filtered: no worker role" in explained
    assert sum(line.startswith("placement ") for line in explained) == 6


def test_the_affinity_weight_is_configured_in_hosts_yaml_with_a_range(catalog: Catalog) -> None:
    def cluster(placement: dict[str, Any]) -> dict[str, Any]:
        return {"cluster": {"name": "lab", "placement": placement},
                "hosts": {"ctl": {"endpoint": "tcp/127.0.0.1:7447", "roles": ["controller"]}}}

    assert parse_hosts(cluster({}), "hosts.yaml", catalog).placement.affinity == 0.2
    assert parse_hosts(cluster({"affinity": 5}), "hosts.yaml", catalog).placement == Placement(affinity=5.0)
    for bad, message in (({"affinity": -1}, "cluster.placement.affinity: -1 is out of range: 0..1000"),
                         ({"afinity": 1}, "cluster.placement.afinity: unknown key (did you mean affinity?)"),
                         ({"cpu": 0, "memory": 0, "instances": 0, "affinity": 3},
                          "cluster.placement: at least one weight must be positive")):
        with pytest.raises(HostsError) as e:
            parse_hosts(cluster(bad), "hosts.yaml", catalog)
        assert [str(p) for p in e.value.problems] == [f"hosts.yaml: {message}"]


def test_a_host_that_does_not_offer_the_type_is_filtered_with_that_reason() -> None:
    """Fleet audit defect 2: a host whose daemon has no manifest of the type refuses its start; the policy knows it
    from the host's announcement, so it never picks it, even when it scores best. A host that announced nothing yet
    (offers None) is not refused for it, and one lacking the devices is refused for those only."""
    hosts = [hv("a"), HostView("b", 50.0, roles=frozenset({"worker"}), offers=frozenset({"Wait"})),
             HostView("c", roles=frozenset({"worker"}), offers=frozenset({"Watch"}))]
    decision = place(WAIT, hosts, W, role="worker")
    assert isinstance(decision, Placed) and decision.host == "a"
    decision = place(WAIT, hosts[1:], W, role="worker")
    assert isinstance(decision, Placed) and decision.host == "b", "c scores better but does not offer Wait"
    assert decision.decision is not None
    assert dict(decision.decision.filtered) == {
        "c": ("does not offer Wait (its daemon has no manifest of it, or cannot import its module)",)}
    camera = ComponentType("Camera", Kind.RC)
    refused = place(camera, hosts[2:], W)
    assert isinstance(refused, Unplaceable) and dict(refused.refused) == {"c": ("no Camera device",)}


def test_an_excluded_host_is_shown_with_why_its_start_failed() -> None:
    hosts = [hv("a"), hv("b", cpu=30), hv("c", cpu=60)]
    why = "a's Creator refused start of M/Wait: Wait has no parameter 'duration'"
    decision = place(WAIT, hosts, W, exclude={"a": why, "b": ""})
    assert isinstance(decision, Placed) and decision.host == "c" and decision.decision is not None
    assert dict(decision.decision.filtered) == {"a": (f"excluded (its start there failed: {why})",),
                                                "b": ("excluded (a start there failed or timed out)",)}
    assert f"a: excluded (its start there failed: {why})" in decision.decision.summary()


def test_a_recent_placement_counts_once_until_its_host_announces_it() -> None:
    """Fleet audit defect 3: the controller added the placements of the last 3 s on top of the hosts' announced
    instances, so an instance its host already announced counted twice (`instances` 20 for one)."""
    placed = [Recent("b", "Wait", 0)]  # b ran no Wait when it was placed there
    [before] = with_recent([HostView("b", running={}, instances=0)], placed)
    [after] = with_recent([HostView("b", running={"Wait": 1}, instances=1)], placed)
    assert (before.instances, after.instances) == (1, 1) and after.running == {"Wait": 1}
    two = [Recent("b", "Wait", 2), Recent("b", "Wait", 2), Recent("c", "Wait", 0)]
    views = [HostView("b", running={"Wait": 3, "Nap": 1}, instances=4), HostView("c"), HostView("d")]
    assert [v.instances for v in with_recent(views, two)] == [5, 1, 0], "one of b's two is announced, c's is not"
    decision = place(WAIT, with_recent([hv("b", instances=1), hv("c", instances=1)], [Recent("b", "Wait", 0)]), W)
    assert isinstance(decision, Placed) and decision.decision is not None
    parts = {s.host: s.part("instances") for s in decision.decision.scored}
    assert parts["b"] is not None and parts["b"].value == 10.0 * 2, "b's announced one plus the pending one"


def test_an_instance_that_ended_counts_no_more_though_its_host_still_announces_it() -> None:
    """Placement audit 24, #3: the next state's instance, placed in the instant the last one ended, counted the
    ended one still on its host (`ranger2 10 = instances 10`, running nothing) and went to a busier host."""
    ended = [Recent("b", "Wait", 1)]  # b announced one Wait when it ended
    [still] = with_recent([HostView("b", running={"Wait": 1}, instances=1)], [], ended)
    [said] = with_recent([HostView("b", running={}, instances=0)], [], ended)
    assert (still.instances, still.running) == (0, {"Wait": 0}) and (said.instances, said.running) == (0, {})
    busy = [dataclasses.replace(hv(name, instances=1), running={"Wait": 1}) for name in ("a", "b")]
    decision = place(WAIT, with_recent(busy, [], ended), W)
    assert isinstance(decision, Placed) and decision.host == "b", "b runs nothing now; a runs one"
    # the next one placed on b at once, b still announcing the ended one (or already neither): one runs there
    for announced in ({"Wait": 1}, {}):
        [b] = with_recent([HostView("b", running=announced, instances=len(announced))], [Recent("b", "Wait", 1)],
                          ended)
        assert b.running.get("Wait") == 1 and b.instances == 1, (announced, b)


def test_a_refused_start_is_recognised_by_its_retry_so_it_counts_nowhere() -> None:
    """Fleet audit defect 3: a refused start was counted on its host for 3 s (a phantom instance). The retry that
    follows it excludes that host: then, and only then, the latest placement is the refused one."""
    recent = [Recent("w3", "Nap", 0, 1.0), Recent("bravo", "Nap", 0, 2.0)]
    assert refused_last(recent, "Nap", {"bravo": "bravo's Creator refused start"})
    assert not refused_last(recent, "Nap", {}), "a new instance's first placement"
    assert not refused_last(recent, "Wait", {"bravo": ""}), "another type's placement"
    assert not refused_last(recent[:1], "Nap", {"bravo": ""}) and not refused_last([], "Nap", {"bravo": ""})
