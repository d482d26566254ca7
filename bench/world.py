"""World loading benchmark: a generated building loaded with the grid index against the former scan of every item.

Run `python bench/world.py [--wings 50,200] [--scouts 19] [--cpu]` (never by pytest). The peer is measured in the
same run: the same loader with `GridIndex.near` answering every item for every question, which is what the loader
did before (every door asked every room and wall, every room every earlier room). Both must build the same world.
Goals (scale audit D5): the index at least 10x faster than the scan at the largest size, and 4x the wings cost at
most 6x the time with the index (linear, with slack).
"""

from __future__ import annotations

import argparse
import functools
import time
from collections.abc import Callable

from drd.sim import geometry
from drd.sim.building import Building, world
from drd.sim.model import World
from drd.sim.world import parse_world


def best(load: Callable[[], World], repeat: int, clock: Callable[[], float]) -> tuple[float, World]:
    """The best of `repeat` runs of `load`, and what it built."""
    times, built = [], None
    for _ in range(repeat):
        t = clock()
        built = load()
        times.append(clock() - t)
    assert built is not None
    return min(times), built


def scanning(data: object) -> World:
    """The former loader: every question looks at every item, in order."""
    near = geometry.GridIndex.near
    geometry.GridIndex.near = lambda self, box: list(range(self.count))  # type: ignore[method-assign]
    try:
        return parse_world(data, "bench.yaml")
    finally:
        geometry.GridIndex.near = near  # type: ignore[method-assign]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--wings", default="50,200", help="two or more sizes, comma separated (default 50,200)")
    parser.add_argument("--scouts", type=int, default=19)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cpu", action="store_true", help="process CPU time rather than wall time")
    args = parser.parse_args()
    clock = time.process_time if args.cpu else time.perf_counter
    sizes = [int(w) for w in args.wings.split(",")]
    rows: list[tuple[int, float, float]] = []
    print(f"{'wings':>6} {'rooms':>7} {'indexed s':>10} {'scan s':>9} {'scan/indexed':>13}")
    for wings in sizes:
        data = world(Building(wings, args.scouts))
        fast, built = best(functools.partial(parse_world, data, "bench.yaml"), args.repeat, clock)
        slow, peer = best(functools.partial(scanning, data), 1, clock)
        assert built == peer, "the index built another world than the scan"
        rows.append((wings, fast, slow))
        print(f"{wings:>6} {len(built.rooms):>7} {fast:>10.3f} {slow:>9.3f} {slow / fast:>12.1f}x")
    (w0, f0, _), (w1, f1, s1) = rows[0], rows[-1]
    growth = f1 / f0
    print(f"{w1 / w0:g}x the wings: indexed {growth:.2f}x the time (goal <= {1.5 * w1 / w0:g}x): "
          f"{'PASS' if growth <= 1.5 * w1 / w0 else 'MISS'}; scan {s1 / f1:.1f}x the indexed time at {w1} wings "
          f"(goal >= 10x): {'PASS' if s1 / f1 >= 10 else 'MISS'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
