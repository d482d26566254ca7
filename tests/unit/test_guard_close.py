"""A world's guard ends with its world (soak audit, defect 1: each mission left a `drd-telemetry` thread in every
worker daemon, and with it the old world's guard, pool, gates and drivers, forever). `BackgroundRead.close` ends
its thread; `HostGuard.close` lets the guard be collected; the Creator closes the last world's guard when it
builds the next one and when it closes."""

from __future__ import annotations

import gc
import threading
import weakref
from pathlib import Path
from typing import Any

import pytest

from drd.cluster.creator import Creator
from drd.cluster.gates import GateUpdate
from drd.cluster.guard import BackgroundRead, HostGuard
from drd.hosts import Cluster, load_hosts
from drd.runtime.ownership import LocalGates
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parents[2]


#: The threads alive when the running test began: other tests of this process may leave guards unclosed, and their
#: threads are not this test's.
BEFORE: set[threading.Thread] = set()


@pytest.fixture(autouse=True)
def others_threads() -> None:
    BEFORE.clear()
    BEFORE.update(threading.enumerate())


def telemetry_threads() -> list[threading.Thread]:
    """The telemetry threads this test started that still run."""
    return [t for t in threading.enumerate() if t.name == "drd-telemetry" and t.is_alive() and t not in BEFORE]


class Drive:
    """A Ranger's drive standing still (what the guard's telemetry reads)."""

    READINGS = frozenset({"odometry", "battery", "max_speed"})
    SETPOINTS = ("set_velocity", "stop")
    STOP = "stop"
    max_speed = 0.8

    def set_velocity(self, v: float, omega: float, epoch: int | None = None) -> None:
        pass

    def stop(self, epoch: int | None = None) -> None:
        pass

    def odometry(self) -> tuple[float, float, float]:
        return (1.0, 2.0, 0.0)

    def battery(self) -> float:
        return 0.75


class Drivers:
    """`drd.hw.HostDrivers` of ranger1 with only its drive."""

    def __init__(self) -> None:
        self.drive = Drive()
        self.devices = {"ranger1.drive": self.drive}
        self.robots = {"ranger1": {"drive": self.drive}}


class Pool:
    """The Creator's worker processes, none needed here: gate updates place nothing."""

    def warm(self) -> None:
        pass

    def close(self) -> None:
        pass


@pytest.fixture
def cluster(catalog: Catalog) -> Cluster:
    return load_hosts(ROOT / "hosts.yaml", catalog)


def test_close_ends_the_thread_and_a_closed_read_starts_none() -> None:
    reads = BackgroundRead(lambda: 7)
    assert reads.get(5.0) == 7
    thread = telemetry_threads()
    assert len(thread) == 1
    assert reads.close(5.0)
    assert not thread[0].is_alive()
    assert reads.get(0.01) == 7 and not telemetry_threads()  # the last value, and no thread started again
    assert BackgroundRead(lambda: 1).close(0.01)  # never started: nothing to end


def test_a_read_hanging_in_its_driver_ends_its_thread_when_it_returns() -> None:
    release, entered = threading.Event(), threading.Event()

    def read() -> int:
        entered.set()
        release.wait(10)
        return 1

    reads = BackgroundRead(read)
    reads.get(0.0)
    assert entered.wait(5.0)
    assert not reads.close(0.01)  # still in the driver: not ended yet, and close did not wait for it
    release.set()
    for thread in telemetry_threads():
        thread.join(5.0)
    assert not telemetry_threads()


def test_a_closed_guard_ends_its_thread_and_is_collected(cluster: Cluster) -> None:
    drivers = Drivers()
    gates = LocalGates.of(drivers.devices, drivers.robots)
    guard = HostGuard(cluster, "ranger1", drivers, gates, lambda: 1.0, lambda _: None)
    guard.apply(["watch", ["ranger1"], 1.0])
    telemetry = guard.telemetry()
    assert telemetry is not None and telemetry["robots"]["ranger1"]["x"] == 1.0
    assert len(telemetry_threads()) == 1
    gone, drivers_gone = weakref.ref(guard), weakref.ref(drivers)
    guard.close()
    assert not telemetry_threads()
    del guard, gates, drivers, telemetry
    gc.collect()
    assert gone() is None and drivers_gone() is None


def watch(generation: int) -> GateUpdate:
    return GateUpdate([["watch", ["ranger1"], 1.0]], world="corridor", generation=generation)


def test_a_new_world_closes_the_last_worlds_guard_and_keeps_nothing_of_it(cluster: Cluster, catalog: Catalog) -> None:
    built: list[weakref.ref[Drivers]] = []

    def make(world: str) -> Drivers:
        drivers = Drivers()
        built.append(weakref.ref(drivers))
        return drivers

    pool: Any = Pool()
    creator = Creator(None, cluster, "ranger1", catalog, pool=pool, drivers=make)
    try:
        for generation in range(1, 5):
            reply = creator.update_gates(watch(generation))
            assert any(r["kind"] == "telemetry" for r in reply.records), reply.records
            assert len(telemetry_threads()) == 1, telemetry_threads()
        gc.collect()
        assert [ref() is None for ref in built] == [True, True, True, False]  # only the current world's drivers
    finally:
        creator.close()
    assert not telemetry_threads()
    del creator
    gc.collect()
    assert built[-1]() is None  # no thread kept the closed Creator's world


def test_gate_operations_of_a_world_no_longer_run_are_dropped_with_one_line(cluster: Cluster, catalog: Catalog,
                                                                          caplog: pytest.LogCaptureFixture) -> None:
    """Faults audit 21, #5: the simulator's host restarted (no world runs there); the controller's gate operations
    of the ended world raised in the Creator's handler (its drivers cannot be built), a traceback each time, and the
    controller logged them not delivered. They are moot: dropped, said in one line."""
    from drd.hw.drivers import DriverError

    def make(world: str) -> Drivers:
        raise DriverError("no simulation is running (the controller resets it when a mission starts)")

    pool: Any = Pool()
    creator = Creator(None, cluster, "ranger1", catalog, pool=pool, drivers=make)
    try:
        with caplog.at_level("WARNING", logger="drd.cluster.creator"):
            reply = creator.update_gates(watch(1))
        assert reply.records == []
        assert [r.getMessage() for r in caplog.records] == [
            "creator ranger1: 1 gate operations of world corridor (generation 1) not applied: no simulation is running"
            " (the controller resets it when a mission starts)"]
    finally:
        creator.close()
