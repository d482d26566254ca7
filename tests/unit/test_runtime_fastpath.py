"""The runtime's fast paths (issue #3) change nothing a mission or a listener can observe.

Records are built only when someone listens, per-state plans replace per-entry work, and a node is
still made per entry: a run without a listener must drive its components exactly as a run with
one, and a node that exited stays exited when its state is entered again.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import pytest

from drd.rcm import ResourceManager
from drd.runtime import records as rec
from drd.runtime.clock import SimClock
from drd.runtime.component import Component, Status
from drd.runtime.interpreter import Interpreter, Phase
from drd.runtime.pool import ResourcePool
from dsl import compile_file, compile_text
from dsl.catalog import Catalog
from dsl.statechart import Statechart
from tests.conftest import ROOT, SHARED_EXAMPLES
from tests.runtime_support import Forever, Harness, ranger_world

MISSIONS = sorted([*(ROOT / "tests" / "missions").glob("*.mission"), *(ROOT / "missions").glob("*.mission"),
                   *SHARED_EXAMPLES.glob("*.mission")])


def random_run(chart: Statechart, seed: int, listen: bool) -> list[Any]:
    """Drive `chart` with seeded random components, events and time; everything observable, in order."""
    seen: list[Any] = []
    events = sorted({t.event for t in chart.transitions() if t.event}) or ["Nothing"]
    drive = random.Random(seed)
    clock = SimClock()
    rcm = ResourceManager(lease=120.0, default_slice=drive.choice([1.0, 5.0]))  # leases outlive 40 s steps
    pool = ResourcePool(rcm)
    pool.add(ranger_world(2, 2), 0.0)
    component = dice(seed, events, seen)
    registry = {leaf.component or "": component for leaf in chart.leaves()}
    interp = Interpreter(chart, registry, rcm, clock, pool=pool, preallocate=drive.random() < 0.3, lease=120.0)
    if listen:
        interp.attach(lambda r: None)
    interp.start()
    shake(interp, clock, drive, events)
    seen.append((interp.outcome, interp.reason, interp.snapshot(), rcm.snapshot()))
    return seen


def dice(seed: int, events: list[str], seen: list[Any]) -> type[Component]:
    """A component class whose every call is recorded in `seen`: what the two runs compare."""

    class Dice(Component):
        """Succeeds, fails, raises, emits or keeps running, by a die seeded per path and entry."""

        def start(self) -> None:
            assert self.ctx is not None
            seen.append(("start", self.ctx.path, self.ctx.now(), sorted(self.ctx.params)))
            self.die = random.Random(f"{seed}/{self.ctx.path}/{len(seen)}")

        def step(self, now: float) -> Status:
            assert self.ctx is not None
            x = self.die.random()
            seen.append(("step", self.ctx.path, now))
            if x < 0.01:
                raise RuntimeError("dice")
            if x < 0.08:
                self.ctx.emit(self.die.choice(events), area=x)
            if x < 0.12:
                self.ctx.outputs["goal"] = x
            return Status.SUCCESS if x < 0.15 else Status.FAILURE if x < 0.17 else Status.RUNNING

        def terminate(self, status: Status) -> None:
            assert self.ctx is not None
            seen.append(("terminate", self.ctx.path, status))

        def suspend(self) -> None:
            assert self.ctx is not None
            seen.append(("suspend", self.ctx.path))

        def resume(self) -> None:
            assert self.ctx is not None
            seen.append(("resume", self.ctx.path))

    return Dice


def shake(interp: Interpreter, clock: SimClock, drive: random.Random, events: list[str]) -> None:
    """Up to 300 random moves (time, events, steps, a host lost) from `drive`: the same moves for both runs."""
    for _ in range(300):
        if interp.finished:
            break
        x = drive.random()
        if x < 0.6:
            clock.advance(drive.choice([0.1, 0.5, 1.0, 3.0, 40.0]))
            interp.step()
        elif x < 0.9:
            interp.emit(drive.choice(events), area=drive.random())
        elif x < 0.99:
            interp.step()
        else:
            interp.remove_host("ranger2")


@pytest.mark.parametrize("path", MISSIONS, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_a_run_without_listeners_is_the_run_with_one(path: Path, catalog: Catalog) -> None:
    result = compile_file(path, catalog)
    assert result.ok and result.statechart is not None, [d.message for d in result.diagnostics]
    for seed in range(8):
        with_listener = random_run(result.statechart, seed, listen=True)
        assert random_run(result.statechart, seed, listen=False) == with_listener, seed
        assert any(call[0] == "step" for call in with_listener[:-1]), "the components were never stepped"


TOGGLE = """
mission Toggle {
    needs ranger: Ranger
    Watch as a
    Watch as b
    start -> a
    a -> b on MotionDetected
    b -> a on MotionDetected
}"""


def test_reentering_a_state_makes_a_new_node_and_the_old_one_stays_done(catalog: Catalog) -> None:
    r = compile_text(TOGGLE, catalog, "t.mission")
    assert r.ok and r.statechart is not None
    h = Harness(r.statechart, {"Watch": Forever}, ranger_world())
    h.interp.start()
    (first,) = [n for n in h.interp.active() if n.path == "Toggle/a"]
    fields: dict[str, Any] = {"area": 0.5}
    h.interp.emit("MotionDetected", **fields)
    h.interp.emit("MotionDetected", **fields)
    fields["area"] = 9.0  # the caller's dict is not the record's
    (again,) = [n for n in h.interp.active() if n.path == "Toggle/a"]
    assert again is not first and first.phase is Phase.DONE and again.phase is Phase.ACTIVE
    assert [e.fields for e in h.of(rec.Event)] == [{"area": 0.5}, {"area": 0.5}]
    assert [(t.path, t.target) for t in h.of(rec.Taken)] == [("Toggle/a", "Toggle/b"), ("Toggle/b", "Toggle/a")]
