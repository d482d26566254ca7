"""Placement as filters then scores (drd.placement): the invariants of the framework and its `Decision` record,
under hypothesis, with roles, preferences, exclusions and device affinity."""

from __future__ import annotations

import random
from dataclasses import replace
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from drd.hosts import Placement
from drd.placement import FILTERS, Context, HostView, Placed, Unplaceable, filtered, place, running_count, total
from dsl.catalog import ComponentType, Kind, Scheduling

NAMES = ("controller", "ranger1", "ranger2", "scout", "sim", "w1", "w2")
DEVICES = ("Camera", "Drive", "RangeSensor")
percent = st.one_of(st.floats(0, 100, allow_nan=False), st.sampled_from([0.0, 50.0, 100.0]))
views = st.builds(
    HostView, st.sampled_from(NAMES), percent, percent, st.integers(0, 40), st.booleans(),
    st.frozensets(st.sampled_from(DEVICES)),
    st.dictionaries(st.sampled_from(["Camera", "Watch", "Ranger"]), st.integers(0, 3)), st.none() | st.integers(1, 8),
    st.frozensets(st.sampled_from(["worker", "controller", "simulator"])))
clusters = st.lists(views, max_size=6, unique_by=lambda h: h.name)
components = st.one_of(
    st.builds(lambda m: ComponentType("Camera", Kind.RC, multiplicity=m), st.none() | st.integers(1, 4)),
    st.builds(lambda m: ComponentType("Ranger", Kind.ARC, parts={"d": "Drive", "c": "Camera"}, multiplicity=m),
              st.none() | st.integers(1, 4)),
    st.builds(lambda m, c: ComponentType("Watch", Kind.BEHAVIOR, multiplicity=m, scheduling=Scheduling(cores=c)),
              st.none() | st.integers(1, 4), st.none() | st.tuples(st.integers(0, 7))),
)
weights = st.builds(Placement, *(st.sampled_from([0.0, 0.2, 1.0]) | st.floats(0, 5, allow_nan=False),) * 4)
subsets = st.frozensets(st.sampled_from(NAMES), max_size=3)
near = st.dictionaries(st.sampled_from(NAMES), st.floats(0, 1, allow_nan=False), max_size=3)
asks = st.fixed_dictionaries({"prefer_hosts": subsets, "exclude": subsets, "affinity": st.none() | subsets,
                              "role": st.none() | st.just("worker"), "near": near})


def context(c: ComponentType, hosts: list[HostView], w: Placement, ask: dict[str, Any]) -> Context:
    """The context `place` builds, for checking each filter on its own."""
    role = ask["role"] if any("worker" in h.roles for h in hosts) else None
    affinity = ask["affinity"]
    return Context(c, w, running_count(c.name, hosts), frozenset(ask["exclude"]),
                   None if affinity is None else frozenset(affinity), role, frozenset(ask["prefer_hosts"]),
                   dict(ask["near"]))


@settings(max_examples=300, deadline=None)
@given(components, clusters, weights, asks)
def test_the_winner_passes_every_filter_and_has_the_lowest_total(c: ComponentType, hosts: list[HostView],
                                                                  w: Placement, ask: dict[str, Any]) -> None:
    outcome = place(c, hosts, w, **ask)
    record = outcome.decision
    assert record is not None
    ctx = context(c, hosts, w, ask)
    assert record.candidates == tuple(sorted(h.name for h in hosts))
    assert set(record.filtered) | {s.host for s in record.scored} == set(record.candidates)
    assert not set(record.filtered) & {s.host for s in record.scored}
    for h in hosts:  # a host is filtered exactly when some filter refuses it
        refused = [f.name for f in FILTERS if f.check(h, ctx) is not None]
        assert (h.name in record.filtered) == bool(refused)
        assert tuple(record.filtered.get(h.name, ())) == filtered(h, ctx)
    for s in record.scored:
        assert s.total == total(s.parts)
    if isinstance(outcome, Placed):
        best = record.scored[0]
        assert outcome.host == record.winner == best.host and outcome.score == best.total
        assert outcome.host not in record.filtered
        winner = next(h for h in hosts if h.name == outcome.host)
        assert all(f.check(winner, ctx) is None for f in FILTERS)
        assert all(s.total > best.total or (s.total == best.total and s.host > best.host)
                   for s in record.scored[1:]), "the lowest total wins, ties to the smaller name"
    else:
        assert isinstance(outcome, Unplaceable) and record.winner is None and not record.scored
        assert set(outcome.refused) == set(record.filtered) == set(record.candidates)


@settings(max_examples=200, deadline=None)
@given(components, clusters, weights, asks, st.randoms(use_true_random=False))
def test_the_record_does_not_depend_on_the_order_of_candidates(c: ComponentType, hosts: list[HostView],
                                                               w: Placement, ask: dict[str, Any],
                                                               rnd: random.Random) -> None:
    shuffled = list(hosts)
    rnd.shuffle(shuffled)
    first, again = place(c, hosts, w, **ask), place(c, shuffled, w, **ask)
    assert first == again
    assert first.decision is not None and again.decision is not None
    assert first.decision.as_dict() == again.decision.as_dict()


@settings(max_examples=200, deadline=None)
@given(components, clusters, weights, asks)
def test_scores_never_change_who_is_filtered_and_no_devices_change_nothing(c: ComponentType, hosts: list[HostView],
                                                                           w: Placement,
                                                                           ask: dict[str, Any]) -> None:
    with_near = place(c, hosts, w, **ask)
    without = place(c, hosts, replace(w, affinity=0.0), **{**ask, "near": {}})
    assert with_near.decision is not None and without.decision is not None
    assert dict(with_near.decision.filtered) == dict(without.decision.filtered)
    no_devices = place(c, hosts, w, **{**ask, "near": {}})
    assert no_devices == without, "without devices near it, the affinity weight changes nothing"


@settings(max_examples=150, deadline=None)
@given(weights, st.floats(0, 1, allow_nan=False), st.floats(0, 1, allow_nan=False))
def test_a_larger_share_of_the_devices_never_scores_worse(w: Placement, more: float, less: float) -> None:
    """Two hosts alike in every way but their share of the devices: the one with more never totals more, and
    with a positive affinity weight and a real difference it comes first."""
    more, less = max(more, less), min(more, less)
    twin = HostView("zz-twin", 30.0, 30.0, 2, True, frozenset(), {}, None, frozenset({"worker"}))
    base = replace(twin, name="aa-base")
    outcome = place(ComponentType("Watch", Kind.BEHAVIOR), [twin, base], w, near={"zz-twin": more, "aa-base": less})
    assert outcome.decision is not None
    totals = {s.host: s.total for s in outcome.decision.scored}
    assert totals["zz-twin"] <= totals["aa-base"]
    if w.affinity >= 0.01 and more - less >= 0.01:
        assert isinstance(outcome, Placed) and outcome.host == "zz-twin"
