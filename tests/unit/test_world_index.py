"""World loading with spatial indexes gives exactly what the former scan of every room and wall gave.

The loader once asked, for each door, every room whether the door was on its side, every wall whether the door
was on it, and every pair of rooms whether they overlapped: quadratic, 5.6 minutes for the largest generated
building (scale audit D5). `drd.sim.geometry.GridIndex` now hands each question only the items near it, in file
order. The reference here is that scan: the same loader with `GridIndex.near` answering every item, in order,
for every question. Both must build equal worlds and report the same problems in the same order, on the shipped
worlds, generated buildings, the bad-file table and seeded random worlds full of overlaps. The cost is counted
(Python lines executed, no timing): four times the building may cost at most about four times the work.
"""

from __future__ import annotations

import random
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drd.sim import geometry
from drd.sim.building import Building, world
from drd.sim.world import World, WorldError, load_world, parse_world
from tests.conftest import lines_executed
from tests.unit.test_sim_world import BAD, base

ROOT = Path(__file__).resolve().parents[2]
WORLDS = sorted((ROOT / "worlds").glob("*.yaml"))
#: Four times the building may cost at most this many times the work (4, and slack for what does not grow).
LINEAR = 4.6


def every_item(index: geometry.GridIndex, box: geometry.Box) -> list[int]:
    """The former scan: every item, in file order, whatever the question."""
    return list(range(index.count))


def outcome(data: object) -> World | list[str]:
    """The world built, or the problems said, in order."""
    try:
        return parse_world(data, "worlds/w.yaml")
    except WorldError as e:
        return [str(p) for p in e.problems]


def both(data: object, monkeypatch: pytest.MonkeyPatch) -> tuple[World | list[str], World | list[str]]:
    """(indexed, scanned) outcomes of loading `data`."""
    indexed = outcome(data)
    with monkeypatch.context() as m:
        m.setattr(geometry.GridIndex, "near", every_item)
        scanned = outcome(data)
    return indexed, scanned


def random_world(seed: int) -> dict[str, Any]:
    """Rooms that overlap and touch, doors on shared sides, on no wall and overlapping each other, long and
    oblique walls, a room as large as the world, robots near walls: every question the indexes answer."""
    rnd = random.Random(seed)

    def pt(lo: float = -30, hi: float = 30) -> list[float]:
        return [rnd.choice([round(rnd.uniform(lo, hi), 1), rnd.randint(int(lo), int(hi))]) for _ in range(2)]

    rooms: list[dict[str, Any]] = []
    for i in range(60):
        x, y = rnd.randint(-30, 25), rnd.randint(-30, 25)
        rooms.append({"id": f"r{i}", "rect": [x, y, x + rnd.randint(1, 6), y + rnd.randint(1, 6)],
                      "walls": rnd.random() < 0.8})
    rooms.append({"id": "hall", "rect": [-40, -40, 40, 40], "walls": True})
    walls = [{"from": pt(), "to": pt()} for _ in range(15)] + [{"from": [-35, 0], "to": [35, 0]}]
    doors = []
    for i in range(80):
        r = rnd.choice(rooms)["rect"]
        at = rnd.choice([[r[0], rnd.randint(r[1], r[3])], [rnd.randint(r[0], r[2]), r[3]], pt()])
        doors.append({"id": f"d{i}", "at": at, "width": rnd.choice([0.5, 1.0, 2.0]),
                      "state": rnd.choice(["open", "closed", "blocked"])})
    rangers = [{"id": f"g{i}", "at": pt(), "magazine": [f"s{i}"]} for i in range(10)]
    scouts = [{"id": f"f{i}", "at": pt()} for i in range(10)]
    return {"name": f"random{seed}", "walls": walls, "rooms": rooms, "doors": doors, "rangers": rangers,
            "scouts": scouts}


def cases() -> Iterator[tuple[str, object]]:
    for path in WORLDS:
        yield path.name, __import__("yaml").safe_load(path.read_text(encoding="utf-8"))
    for wings, scouts in ((1, 1), (3, 7), (12, 5), (4, 99)):
        yield f"building_{wings}x{scouts}", world(Building(wings, scouts))
    for name, change, _ in BAD:
        yield f"bad: {name}", change(base())
    for seed in range(8):
        yield f"random{seed}", random_world(seed)


CASES = list(cases())


@pytest.mark.parametrize("data", [c[1] for c in CASES], ids=[c[0] for c in CASES])
def test_loading_is_what_the_scan_of_everything_gave(data: object, monkeypatch: pytest.MonkeyPatch) -> None:
    indexed, scanned = both(data, monkeypatch)
    assert indexed == scanned


def test_the_random_worlds_ask_the_hard_questions(monkeypatch: pytest.MonkeyPatch) -> None:
    """The comparison above means something: the random worlds have overlapping rooms, doors on no wall,
    overlapping doors and robots in walls, and doors of the building found their rooms."""
    said: list[str] = []
    for seed in range(8):
        found = outcome(random_world(seed))
        assert isinstance(found, list)
        said += found
    for kind in ("overlaps room", "is not on a wall", "overlaps door", "from a wall or closed door"):
        assert sum(kind in p for p in said) >= 3, kind
    built = outcome(world(Building(3, 7)))
    assert isinstance(built, World) and all(d.room for d in built.doors)
    assert [d.room for d in built.doors][:3] == ["w1_n1", "w1_s1", "w1_n2"]


def test_the_grid_finds_every_box_that_meets_the_question() -> None:
    rnd = random.Random(7)
    boxes = []
    for _ in range(300):
        x, y = rnd.uniform(-50, 50), rnd.uniform(-50, 50)
        boxes.append((x, y, x + rnd.choice([0.0, rnd.uniform(0, 3), rnd.uniform(0, 400)]), y + rnd.uniform(0, 3)))
    grid = geometry.GridIndex(boxes)
    assert grid.big  # the long ones are kept aside, and still found
    for _ in range(300):
        x, y = rnd.uniform(-60, 60), rnd.uniform(-60, 60)
        q = (x, y, x + rnd.uniform(0, 5), y + rnd.uniform(0, 5))
        meets = [i for i, b in enumerate(boxes) if b[0] <= q[2] and q[0] <= b[2] and b[1] <= q[3] and q[1] <= b[3]]
        near = grid.near(q)
        assert near == sorted(set(near)) and set(meets) <= set(near)


def work(data: object) -> int:
    """The Python lines executed to load `data`."""
    return lines_executed(lambda: parse_world(data, "cost.yaml"))


def test_loading_a_building_costs_in_proportion_to_its_size() -> None:
    small, large = work(world(Building(5, 19))), work(world(Building(20, 19)))
    assert large <= LINEAR * small, f"4x the wings cost {large / small:.2f}x the work"


def test_the_shipped_worlds_still_load() -> None:
    assert all(load_world(p).doors for p in WORLDS)
