"""The manager's wait queue index (claim groups and their atoms) against a scan of every waiter (hypothesis).

Waiters join, leave, change their claims (to a set shared with others, an equal copy of it, or their own) and
units disappear, in random order; after each step every question the manager asks of the index (the best-placed
claimant of a unit, all claimants, the heads of a claim set's atoms) must have the answer a scan gives.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from drd.rcm.model import NeedRequest, Request
from drd.rcm.state import Key, Wait, WaitQueue

UNITS = [f"u{i}" for i in range(8)]
HOLDERS = [f"w{i}" for i in range(10)]

#: (operation, holder, claim set as unit indexes, copy: an equal frozenset rather than the shared one, priority)
steps = st.lists(
    st.tuples(
        st.sampled_from(["add", "reclaim", "remove", "drop"]),
        st.sampled_from(HOLDERS),
        st.sampled_from([(0, 1, 2, 3), (2, 3, 4), (4, 5, 6, 7), (0,), (), tuple(range(8)), (1, 5)]),
        st.booleans(),
        st.integers(1, 3),
    ),
    max_size=60,
)


def check(queue: WaitQueue, dropped: set[str]) -> None:
    for unit in UNITS:
        claimants = [(w.key, h) for h, w in queue.waits.items() if unit in w.claims]
        assert queue.head(unit) == min(claimants, default=None), unit
        assert queue.claimants(unit) == {h for _, h in claimants}
    for wait in queue.waits.values():
        group = queue.group(wait.claims)
        if not wait.claims:
            assert group is None
            continue
        assert group is not None and wait.holder in group.members
        atoms = queue.atoms(group)
        assert sorted(u for atom, _ in atoms for u in atom) == sorted(wait.claims - dropped)
        for atom, groups in atoms:
            assert {queue.head(u) for u in atom} == {queue.best(groups)}


@settings(max_examples=300, deadline=None)
@given(steps)
def test_index_answers_as_a_scan(ops: list[tuple[str, str, tuple[int, ...], bool, int]]) -> None:
    queue = WaitQueue()
    shared: dict[frozenset[str], frozenset[str]] = {}
    dropped: set[str] = set()
    order = 0

    def claim_set(indexes: tuple[int, ...], copy: bool) -> frozenset[str]:
        units = frozenset(UNITS[i] for i in indexes) - dropped
        return frozenset(set(units)) if copy else shared.setdefault(units, units)

    for op, holder, indexes, copy, priority in ops:
        wait = queue.get(holder)
        if op == "add" and wait is None:
            order += 1
            key: Key = (1, priority, 1, 0.0, order)
            request = Request(holder, priority, (NeedRequest("r", "R"),))
            queue.add(Wait(request, key, order, False, {}), claim_set(indexes, copy), set())
        elif op == "reclaim" and wait is not None:
            queue.reclaim(wait, claim_set(indexes, copy))
        elif op == "remove" and wait is not None:
            queue.remove(wait)
        elif op == "drop" and indexes:
            unit = UNITS[indexes[0]]
            claimants = sorted(queue.claimants(unit))
            queue.drop_unit(unit)
            dropped.add(unit)
            for h in claimants:  # as the manager does: every claimant of a lost unit is reconsidered
                w = queue.waits[h]
                queue.reclaim(w, claim_set(tuple(UNITS.index(u) for u in w.claims), copy))
        check(queue, dropped)
