"""The placement policy (drd.placement): eligibility, the score, reasons, and its properties under hypothesis."""

from __future__ import annotations

import math
import random
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drd.hosts import Placement, load_hosts
from drd.placement import (
    INSTANCE_SCALE,
    PREFER_BONUS,
    HostView,
    Placed,
    Recent,
    Unplaceable,
    check_params,
    place,
    running_count,
    score,
    view_of,
    with_recent,
)
from dsl.catalog import Catalog, ComponentType, Kind, ParamSpec, Scheduling

ROOT = Path(__file__).resolve().parents[2]
CAMERA = ComponentType("Camera", Kind.RC, interfaces=("Camera",), multiplicity=1)
RANGER = ComponentType("Ranger", Kind.ARC, parts={"drive": "Drive", "camera": "Camera"})
WATCH = ComponentType("Watch", Kind.BEHAVIOR, params=(ParamSpec("duration", "duration", 10.0),
                                                      ParamSpec("zone", "str", required=True)))
W = Placement()


def hv(name: str, cpu: float = 0.0, memory: float = 0.0, instances: int = 0, up: bool = True,
       devices: tuple[str, ...] = (), running: dict[str, int] | None = None, cores: int | None = None) -> HostView:
    return HostView(name, cpu, memory, instances, up, frozenset(devices), running or {}, cores)


# ---------------------------------------------------------------- examples


def test_the_least_loaded_eligible_host_wins() -> None:
    hosts = [hv("a", cpu=50), hv("b", cpu=10, memory=10), hv("c", cpu=5, instances=3)]
    decision = place(WATCH, hosts, W, params={"zone": "hall"})
    # a: 50, b: 10 + 5 = 15, c: 5 + 0.2*3*10 = 11
    assert isinstance(decision, Placed)
    assert decision.host == "c" and decision.score == pytest.approx(11.0)
    assert decision.reasons[0] == "c: score 11 = cpu 1*5 + memory 0.5*0 + instances 0.2*3*10"
    assert decision.reasons[1] == "next: b 15, a 50"


def test_every_refused_host_is_named_with_its_reason() -> None:
    hosts = [hv("ranger1", devices=("Drive",)), hv("controller", up=False, devices=("Camera",)),
             hv("ranger2", devices=("Camera",), running={"Camera": 1})]
    decision = place(CAMERA, hosts, W)
    assert decision == Unplaceable(
        "no host can run Camera: controller: down; ranger1: no Camera device; ranger2: multiplicity 1 reached",
        {"ranger1": ("no Camera device",), "controller": ("down",),
         "ranger2": ("multiplicity 1 reached",)})


def test_devices_affinity_cores_and_exclusion() -> None:
    pinned = replace(WATCH, scheduling=Scheduling(cores=(3,)))
    hosts = [hv("a", devices=("Drive",)), hv("b", devices=("Drive", "Camera"), cores=2), hv("c", cpu=90)]
    assert place(RANGER, hosts, W) == Placed("b", 0.0, ("b: score 0 = cpu 1*0 + memory 0.5*0 + instances 0.2*0*10",
                                                        "refused: a: no Camera device; c: no Camera, Drive devices"))
    decision = place(pinned, hosts, W, params={"zone": "z"}, affinity={"a", "b"}, exclude={"a"})
    assert isinstance(decision, Unplaceable)
    assert decision.reason == ("no host can run Watch: a: excluded (a start there failed or timed out); "
                               "b: has 2 cores, the manifest pins core 3; c: outside its affinity (a, b)")


def test_preferred_hosts_get_a_bonus_and_ties_go_to_the_smaller_name() -> None:
    hosts = [hv("b", cpu=10), hv("a", cpu=10), hv("c", cpu=40)]
    assert place(WATCH, hosts, W, params={"zone": "z"}) == place(WATCH, hosts[::-1], W, params={"zone": "z"})
    decision = place(WATCH, hosts, W, params={"zone": "z"})
    assert isinstance(decision, Placed) and decision.host == "a"
    decision = place(WATCH, hosts, W, params={"zone": "z"}, prefer_hosts={"c"})
    assert isinstance(decision, Placed) and (decision.host, decision.score) == ("c", 40 - PREFER_BONUS)
    assert decision.reasons[0].endswith(f" - preferred {PREFER_BONUS:g}")


def test_down_hosts_do_not_count_towards_multiplicity() -> None:
    hosts = [hv("a", up=False, devices=("Camera",), running={"Camera": 1}), hv("b", devices=("Camera",))]
    assert running_count("Camera", hosts) == 0
    assert place(CAMERA, hosts, W) == Placed("b", 0.0, (
        "b: score 0 = cpu 1*0 + memory 0.5*0 + instances 0.2*0*10", "refused: a: down"))


def test_parameters_are_checked_before_any_host() -> None:
    assert check_params(WATCH, {"zone": "z", "duration": 2}) == []
    assert place(WATCH, [hv("a")], W, params={"duraton": 1, "zone": 3}) == Unplaceable(
        "Watch: unknown parameter duraton (did you mean duration?); parameter zone expects str, got int 3")
    assert place(WATCH, [hv("a")], W) == Unplaceable("Watch: parameter zone is required")
    assert place(CAMERA, [hv("a")], W, params={"x": True}) == Unplaceable("Camera: unknown parameter x (it has none)")
    assert place(CAMERA, [], W) == Unplaceable("Camera: no hosts known")


def test_odd_loads_are_clamped() -> None:
    assert score(hv("a", cpu=math.nan, memory=-5, instances=-2), W) == 100.0
    assert score(hv("a", cpu=250, memory=200, instances=1), Placement(1, 1, 1)) == 200 + INSTANCE_SCALE


def test_views_of_the_configured_hosts(catalog: Catalog) -> None:
    cluster = load_hosts(ROOT / "hosts.yaml", catalog)
    views = [view_of(h, cpu=20.0 if h.name == "controller" else 35.0, running={"Camera": 2} if h.name == "ranger1"
                     else None) for h in cluster.hosts]
    ranger1 = next(v for v in views if v.name == "ranger1")
    assert {"Camera", "Drive", "Launcher"} <= ranger1.devices and ranger1.instances == 2
    decision = place(catalog.components["Camera"], views, cluster.placement)
    assert isinstance(decision, Placed) and decision.host == "ranger1"
    decision = place(catalog.components["FollowCorridor"], views, cluster.placement)
    assert isinstance(decision, Placed) and decision.host == "controller"


# ---------------------------------------------------------------- properties

NAMES = ("controller", "ranger1", "ranger2", "scout", "sim", "w1", "w2")
DEVICES = ("Camera", "Drive", "RangeSensor")
percent = st.one_of(st.floats(0, 100, allow_nan=False), st.sampled_from([0.0, 50.0, 100.0]))
views = st.builds(
    HostView, st.sampled_from(NAMES), percent, percent, st.integers(0, 40), st.booleans(),
    st.frozensets(st.sampled_from(DEVICES)), st.dictionaries(st.sampled_from(["Camera", "Watch", "Ranger"]),
                                                             st.integers(0, 3)), st.none() | st.integers(1, 8),
    st.frozensets(st.sampled_from(["worker"])),
    st.none() | st.frozensets(st.sampled_from(["Camera", "Watch", "Ranger"])))
clusters = st.lists(views, max_size=6, unique_by=lambda h: h.name)
components = st.one_of(
    st.builds(lambda m: replace(CAMERA, multiplicity=m), st.none() | st.integers(1, 4)),
    st.builds(lambda m: replace(RANGER, multiplicity=m), st.none() | st.integers(1, 4)),
    st.builds(lambda m, c: ComponentType("Watch", Kind.BEHAVIOR, multiplicity=m, scheduling=Scheduling(cores=c)),
              st.none() | st.integers(1, 4), st.none() | st.tuples(st.integers(0, 7))),
)
weights = st.builds(Placement, *(st.floats(0, 5, allow_nan=False),) * 3)
subsets = st.frozensets(st.sampled_from(NAMES), max_size=3)


def eligible(c: ComponentType, h: HostView, hosts: list[HostView], exclude: frozenset[str],
             affinity: frozenset[str] | None) -> bool:
    """The policy's rules, written again independently of drd.placement."""
    needs = {Kind.RC: {c.name}, Kind.ARC: set(c.parts.values())}.get(c.kind, set())
    total = sum(x.running.get(c.name, 0) for x in hosts if x.up)
    cores_ok = not c.scheduling.cores or h.cores is None or max(c.scheduling.cores) < h.cores
    offered = h.offers is None or c.name in h.offers  # else its daemon would refuse the start
    return (h.up and h.name not in exclude and needs <= h.devices and cores_ok and offered
            and (affinity is None or h.name in affinity) and (c.multiplicity is None or total < c.multiplicity))


def formula(h: HostView, w: Placement, preferred: bool) -> float:
    return w.cpu * h.cpu + w.memory * h.memory + w.instances * h.instances * 10 - (50 if preferred else 0)


@settings(max_examples=300, deadline=None)
@given(components, clusters, weights, subsets, subsets, st.none() | subsets)
def test_the_choice_is_eligible_and_has_the_lowest_score(c: ComponentType, hosts: list[HostView], w: Placement,
                                                         prefer: frozenset[str], exclude: frozenset[str],
                                                         affinity: frozenset[str] | None) -> None:
    decision = place(c, hosts, w, prefer_hosts=prefer, exclude=exclude, affinity=affinity)
    ok = [h for h in hosts if eligible(c, h, hosts, exclude, affinity)]
    assert isinstance(decision, Unplaceable) == (not ok)
    if isinstance(decision, Placed):
        chosen = next(h for h in hosts if h.name == decision.host)
        assert chosen in ok
        assert decision.score == pytest.approx(formula(chosen, w, chosen.name in prefer))
        assert all(score(h, w, h.name in prefer) >= decision.score for h in ok)
        assert all(h.name > decision.host for h in ok if score(h, w, h.name in prefer) == decision.score
                   and h is not chosen)
    else:
        assert set(decision.refused) == {h.name for h in hosts}


@settings(max_examples=200, deadline=None)
@given(components, clusters, weights, subsets, st.randoms(use_true_random=False))
def test_deterministic_whatever_the_order_of_candidates(c: ComponentType, hosts: list[HostView], w: Placement,
                                                       prefer: frozenset[str], rnd: random.Random) -> None:
    shuffled = list(hosts)
    rnd.shuffle(shuffled)
    first = place(c, hosts, w, prefer_hosts=prefer)
    assert first == place(c, hosts, w, prefer_hosts=prefer)
    again = place(c, shuffled, w, prefer_hosts=prefer)
    assert type(again) is type(first)
    if isinstance(first, Placed):
        assert isinstance(again, Placed) and (again.host, again.score) == (first.host, first.score)
    else:
        assert isinstance(again, Unplaceable) and dict(again.refused) == dict(first.refused)


@settings(max_examples=200, deadline=None)
@given(components, clusters, weights)
def test_placing_repeatedly_never_exceeds_the_multiplicity(c: ComponentType, hosts: list[HostView],
                                                           w: Placement) -> None:
    before = running_count(c.name, hosts)
    placed = 0
    for _ in range(8):
        decision = place(c, hosts, w)
        if isinstance(decision, Unplaceable):
            break
        placed += 1
        hosts = [replace(h, instances=h.instances + 1, running={**h.running, c.name: h.running.get(c.name, 0) + 1})
                 if h.name == decision.host else h for h in hosts]
        assert c.multiplicity is None or running_count(c.name, hosts) <= c.multiplicity
    if c.multiplicity is not None and placed:
        assert placed <= c.multiplicity - before


@settings(max_examples=200, deadline=None)
@given(components, clusters, weights, st.frozensets(st.sampled_from(NAMES)))
def test_retrying_past_refusals_reaches_every_eligible_host_within_as_many_tries_as_hosts(
        c: ComponentType, hosts: list[HostView], w: Placement, refusing: frozenset[str]) -> None:
    """Fleet audit defect 2, as `RemoteComponent._place` drives the policy: each host that refuses the start is
    excluded, with why, and the policy asked again. It never picks an excluded host or one that does not offer
    the type, so the tries end within as many as there are hosts: on a host that does not refuse when an
    eligible one exists, else with every refusal named."""
    refused: dict[str, str] = {}
    decision = place(c, hosts, w, exclude=refused)
    while isinstance(decision, Placed) and decision.host in refusing:
        assert decision.host not in refused and len(refused) < len(hosts)
        chosen = next(h for h in hosts if h.name == decision.host)
        assert chosen.offers is None or c.name in chosen.offers
        refused[decision.host] = f"{decision.host} refused"
        decision = place(c, hosts, w, exclude=refused)
    ok = [h for h in hosts if eligible(c, h, hosts, frozenset(), None) and h.name not in refusing]
    assert isinstance(decision, Placed) == bool(ok)
    if isinstance(decision, Unplaceable):
        assert all(f"{h}: excluded (its start there failed: {h} refused)" in decision.reason for h in refused)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 5), st.integers(1, 5), st.data())
def test_a_recent_placement_counts_once_whether_or_not_its_host_announces_it(seen: int, placed: int,
                                                                              data: st.DataObject) -> None:
    """Fleet audit defect 3: k placements on a host that ran `seen` then: whatever share of them it announces
    now, the view counts seen + k instances of the type, never more."""
    announced = data.draw(st.integers(0, placed))
    view = HostView("b", instances=seen + announced + 1, running={"Watch": seen + announced, "Camera": 1})
    [counted] = with_recent([view], [Recent("b", "Watch", seen, float(i)) for i in range(placed)])
    assert counted.running["Watch"] == seen + placed and counted.instances == seen + placed + 1
