"""`token_slots`: the keys of the instances' liveliness tokens come from a bounded set (zenoh keeps state for
every token key it ever saw), and two overlapping runs of one mission never share a key."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from drd.cluster.creator import token_slots

PATH = "Corridor/Room[1]/Follow"


def test_one_mission_after_another_reuses_slot_0() -> None:
    keys: set[tuple[str, int]] = set()
    held: dict[str, tuple[str, int]] = {}
    for n in range(50):  # 50 missions in turn: one key for ever, not one per mission id
        running = {f"Corridor-{n}/{PATH}": PATH}
        held = token_slots(running, {k: v for k, v in held.items() if k in running})
        keys |= set(held.values())
    assert keys == {(PATH, 0)}


def test_overlapping_runs_take_distinct_slots_and_a_held_one_keeps_its_own() -> None:
    first = token_slots({f"A-1/{PATH}": PATH}, {})
    both = token_slots({f"A-1/{PATH}": PATH, f"A-2/{PATH}": PATH}, first)
    assert both == {f"A-1/{PATH}": (PATH, 0), f"A-2/{PATH}": (PATH, 1)}
    later = token_slots({f"A-2/{PATH}": PATH, f"A-3/{PATH}": PATH}, {f"A-2/{PATH}": (PATH, 1)})
    assert later == {f"A-2/{PATH}": (PATH, 1), f"A-3/{PATH}": (PATH, 0)}, "the freed slot 0 is taken again"


@given(st.lists(st.sets(st.sampled_from(["m1", "m2", "m3", "m4"]), max_size=4), max_size=20))
def test_slots_are_unique_per_path_stable_while_held_and_bounded(steps: list[set[str]]) -> None:
    held: dict[str, tuple[str, int]] = {}
    most = 0
    for missions in steps:
        most = max(most, len(missions))
        running = {f"{m}/{PATH}": PATH for m in missions}
        before = {k: v for k, v in held.items() if k in running}
        held = token_slots(running, before)
        assert set(held) == set(running)
        assert len(set(held.values())) == len(held), "no two running instances share a key"
        assert all(held[k] == v for k, v in before.items()), "a held token keeps its key"
        assert all(slot < most for _, slot in held.values()), "slots stay below the most runs at once so far"
