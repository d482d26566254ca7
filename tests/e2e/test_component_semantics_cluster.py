"""A dry-run and a cluster agree on what a component author relies on (component audit D1, D2, D4): the same
missions run once in process and once with every component in a real Creator's worker processes (its proxies,
`RemoteComponent`, talk to it over an in-process bus), and give the same outcome, the same failure reason and
the same lifecycle order. The components are this module's (the workers import it); they note their lifecycle
calls in a file, as the workers are other processes. Every process is the pool's, closed by the fixture."""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil
import pytest

from drd.bus import Message, Query
from drd.bus.local import LocalBus
from drd.cluster.creator import Creator, behavior_modules
from drd.cluster.remote import ComponentBatch, ComponentCall, ComponentRouter
from drd.cluster.workers import WorkerPool
from drd.hosts import Cluster, load_hosts
from drd.hw.drivers import HostDrivers
from drd.manifests import load_catalog
from drd.runtime import records as rec
from drd.runtime.component import Component
from dsl import compile_text
from dsl.catalog import Catalog, ComponentType, Kind, NeedSpec, ParamSpec
from tests.runtime_support import DOOR, INSIDE, LEAF, DoorFacer, DoorFinder, Harness, Idle, ranger_world

NOTES = "DRD_TEST_LIFECYCLE_NOTES"  # the file the components note their calls in (set before the workers fork)


def note(text: str) -> None:
    with open(os.environ[NOTES], "a") as f:
        f.write(text + "\n")


class Finder(DoorFinder):
    sink = staticmethod(note)


class Facer(DoorFacer):
    sink = staticmethod(note)


class Returns(Component):
    """Returns what its `value` says: `none` is None, `raise` raises ValueError, anything else that string."""

    def step(self, now: float) -> Any:
        assert self.ctx is not None
        value = self.ctx.params.get("value")
        if value == "raise":
            raise ValueError("boom")
        return None if value == "none" else value


STANDING_IN = {"DetectDoor": Finder, "AlignRanger": Facer, "FollowCorridor": Idle}
RETURNS = ComponentType("Returns", Kind.BEHAVIOR, entry_point=f"{__name__}:Returns",
                        params=(ParamSpec("value", "str", "none"),), needs=(NeedSpec("drive", "Drive"),))


@pytest.fixture(scope="module")
def catalog_() -> Catalog:
    base = load_catalog()
    stand_ins = [dataclasses.replace(base.components[name], entry_point=f"{__name__}:{cls.__name__}")
                 for name, cls in STANDING_IN.items()]
    return Catalog.of([*(c for c in base.components.values() if c.name not in STANDING_IN), *stand_ins, RETURNS])


@pytest.fixture(scope="module")
def notes(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    path = tmp_path_factory.mktemp("notes") / "lifecycle.log"
    old = os.environ.get(NOTES)
    os.environ[NOTES] = str(path)  # before the pool forks its workers: they inherit it
    yield path
    if old is None:
        del os.environ[NOTES]
    else:
        os.environ[NOTES] = old


@pytest.fixture(scope="module")
def creator(tmp_path_factory: pytest.TempPathFactory, catalog_: Catalog, notes: Path) -> Iterator[Creator]:
    from cluster_support import hosts_yaml

    hosts = tmp_path_factory.mktemp("hosts") / "hosts.yaml"
    hosts.write_text(hosts_yaml("t", ["controller", "ranger1"], [7001, 7002]))
    cluster: Cluster = load_hosts(hosts, catalog_)
    pool = WorkerPool(1, preload=behavior_modules(catalog_), call_timeout=10.0)
    c = Creator(None, cluster, "ranger1", catalog_, pool=pool, drivers=lambda world: HostDrivers({}))
    try:
        assert pool.wait_ready(60.0), "the pool did not start its worker"
        yield c
    finally:
        pids = pool.pids()
        c.close()
        pool.close()
        assert not [pid for pid in pids if psutil.pid_exists(pid) and
                    psutil.Process(pid).status() != psutil.STATUS_ZOMBIE], "a worker outlived its pool"


def run(source: str, catalog: Catalog, notes: Path, creator: Creator | None) -> tuple[Harness, list[str]]:
    """`source` run in process (`creator` None) or with its components in `creator`'s workers."""
    result = compile_text(source, catalog, "t.mission")
    assert result.ok and result.statechart is not None, [d.message for d in result.diagnostics]
    notes.write_text("")
    world = ranger_world(1, 1)
    if creator is None:
        h = Harness(result.statechart, {**STANDING_IN, "Returns": Returns}, world)
    else:
        bus = LocalBus()

        def serve(query: Query) -> Message:
            msg = query.payload
            return creator.handle_batch(msg) if isinstance(msg, ComponentBatch) else creator.handle(msg)

        bus.serve("drd/t/host/ranger1/creator", serve)
        hosts = {r.id: "ranger1" for r in world if r.id.startswith("ranger1.") and "scout" not in r.id}
        router = ComponentRouter(bus, "t", hosts, "controller", local={**STANDING_IN, "Returns": Returns},
                                 mission="m", world="corridor", timeout=10.0, catalog=catalog)
        h = Harness(result.statechart, router.registry(), world)
        router.active = h.interp.host.active
    h.run(until=20.0, dt=0.1)
    if creator is not None:
        ran = {inst.path: inst.name for inst in creator.instances.values() if inst.mission == "m"}
        assert ran and set(ran) <= {r.path for r in h.of(rec.Entered)}, "they ran in the Creator's worker"
        creator.handle(ComponentCall("retire", "m", ""))  # the next run starts afresh there
    return h, notes.read_text().splitlines()


@pytest.mark.parametrize("source", [LEAF, INSIDE], ids=["leaf", "inside a parallel"])
def test_an_output_and_the_order_around_an_emit_are_the_same_in_a_dry_run_and_on_a_cluster(
        source: str, catalog_: Catalog, notes: Path, creator: Creator) -> None:
    """D1, D4: the door its producer set before the event that exited it reaches `face` in both modes, and the
    emitting step ends before its `terminate` and the next start in both."""
    here, here_notes = run(source, catalog_, notes, None)
    there, there_notes = run(source, catalog_, notes, creator)
    assert here.interp.outcome == there.interp.outcome == "success", (here.interp.reason, there.interp.reason)
    assert here_notes == there_notes
    assert here_notes[-3:] == ["after emit", "terminate running", f"face start {DOOR}"]


@pytest.mark.parametrize(("value", "outcome"), [("none", "failure"), ("ok", "failure"), ("success", "success"),
                                                ("failure", "failure"), ("raise", "failure")])
def test_a_steps_return_value_means_the_same_in_a_dry_run_and_on_a_cluster(
        value: str, outcome: str, catalog_: Catalog, notes: Path, creator: Creator) -> None:
    """D2: None and "ok" fail the state with the same reason naming the component and the value (the dry-run
    ran them for ever; the cluster said `'None' is not a valid Status`); "success" succeeds in both."""
    source = f'mission M {{\n    start -> w\n    Returns(value: "{value}") as w\n}}\n'
    results = []
    for where in (None, creator):
        h, _ = run(source, catalog_, notes, where)
        [exited] = [r for r in h.of(rec.Exited) if r.path == "M/w"]
        results.append((h.interp.outcome, exited.status, exited.reason))
    assert results[0] == results[1]
    assert results[0][0] == outcome
    if value in ("none", "ok"):
        shown = "None" if value == "none" else value
        assert results[0][2] == (f"Returns.step returned {shown}, not a Status "
                                 "(return Status.RUNNING, Status.SUCCESS or Status.FAILURE)")
    if value == "raise":  # said once on the cluster too (it was `component raised ComponentError: component ...`)
        # and where it was raised, the same in both modes (newcomer audit 2: the file and line were lost)
        assert re.fullmatch(r"component raised ValueError: boom \(at \S*test_component_semantics_cluster\.py:\d+,"
                            r" in step\)", results[0][2]), results[0][2]
