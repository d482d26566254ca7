"""A dry-run keeps the collector's full passes off what it holds (`gc.freeze` while it runs) and gives the heap
back as it found it: thawed after the run, even when the run fails, and left alone when someone else froze it
or turned the collector off.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator

import pytest

from drd.dryrun import Mission, run_many
from drd.hosts import load_hosts
from drd.sim.world import load_world
from dsl import compile_text
from dsl.catalog import Catalog
from tests.conftest import ROOT

WAIT = """
mission Idle {
    needs ranger: Ranger
    FollowCorridor(speed: 0.3)
}
"""


@pytest.fixture(autouse=True)
def thawed() -> Iterator[None]:
    gc.unfreeze()
    was = gc.isenabled()
    yield
    gc.unfreeze()
    if was:
        gc.enable()


def frozen_counts(catalog: Catalog, until: float = 3.0) -> list[int]:
    """The frozen object count seen at each progress call of a short corridor run."""
    r = compile_text(WAIT, catalog, "idle.mission")
    assert r.ok and r.statechart is not None
    seen: list[int] = []
    run_many([Mission(r.statechart)], load_hosts(ROOT / "hosts.yaml", catalog),
             load_world(ROOT / "worlds" / "corridor.yaml"), catalog, until=until,
             progress=lambda sim, ex: seen.append(gc.get_freeze_count()), progress_every=0.5)
    return seen


def test_the_heap_is_frozen_while_the_run_steps_and_thawed_after(catalog: Catalog) -> None:
    seen = frozen_counts(catalog)
    assert len(seen) >= 5 and all(n > 0 for n in seen)
    assert seen[-1] > seen[0], "frozen again on the way, with what the run made since"
    assert gc.get_freeze_count() == 0


def test_a_heap_frozen_by_someone_else_or_a_collector_off_is_left_alone(catalog: Catalog) -> None:
    gc.freeze()
    before = gc.get_freeze_count()
    seen = frozen_counts(catalog)
    assert seen and max(seen) <= before, "nothing more frozen (what was frozen may die)"
    assert 0 < gc.get_freeze_count() <= before, "still frozen: the run did not thaw someone else's heap"
    gc.unfreeze()
    gc.disable()
    assert set(frozen_counts(catalog)) == {0}
    assert not gc.isenabled()


def test_a_failing_run_thaws_the_heap(catalog: Catalog, monkeypatch: pytest.MonkeyPatch) -> None:
    from drd.sim.physics import Simulation

    def broken(self: Simulation, dt: float) -> None:
        raise RuntimeError("the simulator broke")

    monkeypatch.setattr(Simulation, "step", broken)
    with pytest.raises(RuntimeError, match="simulator broke"):
        frozen_counts(catalog)
    assert gc.get_freeze_count() == 0
