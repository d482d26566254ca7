"""The Creator's worker processes, for real: components run in pre-started containers or dedicated processes,
their device calls come back to the fenced drivers in the Creator, a crashing component fails only its own
state, `tune` changes affinity and nice as psutil sees them, and nothing outlives the Creator.

The in-process tests share one `WorkerPool` (its fork server preloads this module, whose probe components
the test catalog names); the last test runs `missionctl tune` against real daemons (`cluster_support`).
Every process is ours and killed by pid; every wait is bounded.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil
import pytest

from drd.cluster.creator import Creator, CreatorError
from drd.cluster.gates import GateUpdate
from drd.cluster.remote import ComponentBatch, ComponentCall, ComponentReply
from drd.cluster.workers import Tune, WorkerPool
from drd.hosts import Cluster, load_hosts
from drd.hw.drivers import HostDrivers
from drd.hw.interfaces import Fence, HardwareError
from drd.manifests import load_catalog
from drd.runtime.component import Component, Status
from dsl.catalog import Catalog, ComponentType, Kind, NeedSpec, ParamSpec, Process, Scheduling

ROOT = Path(__file__).resolve().parents[2]
MISSION = "m1"


# -- probe components (imported by the workers: this module is their entry point) ------------------------


class Probe(Component):
    """Reports its pid; `mode` makes it drive, crash or emit."""

    def start(self) -> None:
        assert self.ctx is not None
        self.ctx.outputs["pid"] = os.getpid()

    def step(self, now: float) -> Status:
        ctx = self.ctx
        assert ctx is not None
        ctx.outputs["pid"] = os.getpid()
        mode = ctx.params.get("mode", "")
        if mode == "exit":
            os._exit(3)
        if mode == "sys.exit":
            sys.exit(3)
        if mode == "emit":
            ctx.emit("Seen", at=now)
        if mode == "huge":
            ctx.outputs["blob"] = "x" * 2_000_000
        if mode == "sleep":
            time.sleep(1e9)
        while mode == "spin":
            pass
        if mode == "shared":
            log = ctx.services.shared.setdefault("log", [])
            log.append(ctx.path)
        if mode == "drive":
            drive = self.device("drive")
            drive.set_velocity(0.5, 0.1)
            ctx.outputs["odometry"] = drive.odometry()
            ctx.outputs["max_speed"] = drive.max_speed
            try:
                drive.jam()
            except HardwareError as e:
                ctx.log(f"caught {type(e).__name__}: {e}")
        return Status.RUNNING

    def shutdown(self) -> None:
        """`mode: note:<file>` writes its path there (`hang:<file>`: then never returns)."""
        how, _, file = str(self.ctx.params.get("mode", "")).partition(":")
        if how in ("note", "hang"):
            with open(file, "a") as f:
                f.write(f"{self.ctx.path} {os.getpid()}\n")
        while how == "hang":
            time.sleep(1.0)


class Reader(Component):
    """Reads the Ranger's sensors each step (the readings the Creator reads ahead); `mode: launch` launches a
    Scout first, at its second step, and reads the magazine after it."""

    def step(self, now: float) -> Status:
        ctx = self.ctx
        assert ctx is not None
        launcher = self.device("launcher")
        if ctx.params.get("mode") == "launch" and now >= 2.0 and not ctx.outputs.get("landing"):
            ctx.outputs["landing"] = launcher.launch(launcher.loaded()[0], 0.0, 1.0) is not None
        ctx.outputs.update(odometry=self.device("drive").odometry(), scan=list(self.device("ranges").scan().ranges),
                           fov=self.device("camera").fov, loaded=launcher.loaded())
        return Status.RUNNING


class FakeDrive:
    """A fenced drive that records what reached it (in the Creator's process)."""

    READINGS = frozenset({"odometry", "max_speed", "jam"})
    SETPOINTS = ("set_velocity",)
    max_speed = 0.8

    def __init__(self) -> None:
        self.fence = Fence("fake.drive")
        self.commands: list[tuple[float, float, int | None, int]] = []

    def set_velocity(self, v: float, omega: float, epoch: int | None = None) -> None:
        self.fence.check(epoch)
        self.commands.append((v, omega, epoch, os.getpid()))

    def odometry(self) -> tuple[float, float, float]:
        return (1.0, 2.0, 0.5)

    def jam(self) -> None:
        raise HardwareError("the wheels are jammed")


def _type(name: str, process: Process = Process.CONTAINER, scheduling: Scheduling | None = None) -> ComponentType:
    return ComponentType(name, Kind.BEHAVIOR, entry_point=f"{__name__}:Probe", process=process,
                         scheduling=scheduling or Scheduling(), params=(ParamSpec("mode", "str"),),
                         needs=(NeedSpec("drive", "Drive"),))


READER = ComponentType("Reader", Kind.BEHAVIOR, entry_point=f"{__name__}:Reader", params=(ParamSpec("mode", "str"),),
                       needs=tuple(NeedSpec(n, t) for n, t in (("drive", "Drive"), ("ranges", "RangeSensor"),
                                                               ("camera", "Camera"), ("launcher", "Launcher"))))


@pytest.fixture(scope="module")
def catalog_() -> Catalog:
    base = load_catalog()
    return Catalog.of([*base.components.values(), _type("Probe"), _type("Alone", Process.DEDICATED),
                       _type("Niced", scheduling=Scheduling((0,), 3)), READER])


@pytest.fixture(scope="module")
def cluster_(tmp_path_factory: pytest.TempPathFactory, catalog_: Catalog) -> Cluster:
    from cluster_support import hosts_yaml

    path = tmp_path_factory.mktemp("workers") / "hosts.yaml"
    path.write_text(hosts_yaml("w", ["controller", "ranger1"], [7001, 7002]))
    return load_hosts(path, catalog_)


@pytest.fixture(scope="module")
def pool(catalog_: Catalog) -> Iterator[WorkerPool]:
    from drd.cluster.creator import behavior_modules

    p = WorkerPool(2, preload=behavior_modules(catalog_), call_timeout=10.0)  # generous: a loaded test machine
    try:
        assert p.wait_ready(60.0), "the pool did not start its workers"
        yield p
    finally:
        pids = p.pids()
        p.close()
        assert not [pid for pid in pids if _alive(pid)], "a worker outlived its pool"


@pytest.fixture
def creator(cluster_: Cluster, catalog_: Catalog, pool: WorkerPool) -> Iterator[Creator]:
    drive = FakeDrive()
    c = Creator(None, cluster_, "ranger1", catalog_, pool=pool,
                drivers=lambda world: HostDrivers({"ranger1.drive": drive}))
    c.fake_drive = drive  # type: ignore[attr-defined]
    try:
        yield c
    finally:
        pids = [w.pid for w in c._workers.values()]
        c.close()
        assert not [pid for pid in pids if _alive(pid)], "a worker outlived its Creator"


def _alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _all_gone(pids: list[int], within: float = 15.0) -> bool:
    """Whether every pid is gone (exited or killed, reaped) within a bounded wait."""
    deadline = time.monotonic() + within
    while any(_alive(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return not any(_alive(pid) for pid in pids)


def start(c: Creator, path: str, component: str = "Probe", mode: str = "", **kw: Any) -> ComponentReply:
    return c.handle(ComponentCall("start", MISSION, path, component=component, params={"mode": mode},
                                  bindings={"drive": ["ranger1.drive", "", ""]}, **kw))


def step(c: Creator, path: str, now: float = 1.0) -> ComponentReply:
    return c.handle(ComponentCall("step", MISSION, path, now=now))


# -- in process -------------------------------------------------------------------------------------------


def test_a_component_runs_in_a_worker_process_not_in_the_daemon(creator: Creator, pool: WorkerPool) -> None:
    r = start(creator, "M/A")
    assert r.error == ""
    pid = r.outputs["pid"] if r.outputs else None
    assert pid != os.getpid() and pid in pool.pids()
    assert step(creator, "M/A").status == "running"
    assert [(i.name, i.state, i.host) for i in creator.instance_infos()] == [("M/A", "running", "ranger1")]


def test_driver_calls_come_back_to_the_gated_driver_in_the_creator(creator: Creator) -> None:
    grant = [["grant", "ranger1.drive", f"{MISSION}/M", 7, 0.0]]  # the controller's word: M holds the drive
    start(creator, "M/D", mode="drive", epochs={"drive": 7}, gates=grant)
    r = step(creator, "M/D")
    assert r.error == "", r.error
    assert r.outputs is not None
    assert r.outputs["odometry"] == [1.0, 2.0, 0.5] and r.outputs["max_speed"] == 0.8
    assert creator.fake_drive.commands == [(0.5, 0.1, 7, os.getpid())]  # type: ignore[attr-defined]
    assert r.logs == ["caught HardwareError: the wheels are jammed"]
    assert r.records == [{"mission": MISSION, "kind": "command", "at": 1.0, "path": "M/D", "device": "ranger1.drive",
                          "method": "set_velocity", "epoch": 7, "accepted": True, "reason": ""}]


@pytest.mark.parametrize(("gates", "epoch", "why"), [
    (None, 7, "nobody holds the device"),
    ([["grant", "ranger1.drive", f"{MISSION}/Other", 7, 0.0]], 7, "not under the holder Other"),
    ([["grant", "ranger1.drive", "m2/M", 7, 0.0]], 7, "not under the holder M"),  # another mission's M
    ([["grant", "ranger1.drive", f"{MISSION}/M", 8, 0.0]], 7, "epoch 7 is not the grant's (8)"),
    ([["grant", "ranger1.drive", f"{MISSION}/M", 7, 0.0], ["clear", "ranger1.drive", f"{MISSION}/M", 0.5, "x"]],
     7, "nobody holds the device"),
])
def test_the_gate_in_the_creator_refuses_a_command_outside_the_current_grant(
        creator: Creator, gates: list[list[Any]] | None, epoch: int, why: str) -> None:
    start(creator, "M/D", mode="drive", epochs={"drive": epoch}, gates=gates)
    r = step(creator, "M/D")
    assert creator.fake_drive.commands == []  # type: ignore[attr-defined]
    assert r.records is not None and [(d["accepted"], d["reason"]) for d in r.records] == [(False, why)]


def test_dedicated_gets_a_process_of_its_own_containers_share_one(creator: Creator) -> None:
    pids = {p: (start(creator, p, comp).outputs or {})["pid"]
            for p, comp in (("M/A", "Probe"), ("M/B", "Probe"), ("M/X", "Alone"), ("M/Y", "Alone"))}
    assert pids["M/A"] == pids["M/B"]
    assert len({pids["M/A"], pids["M/X"], pids["M/Y"]}) == 3
    assert os.getpid() not in pids.values()


def test_a_component_that_exits_fails_its_state_and_the_creator_keeps_serving(creator: Creator,
                                                                              pool: WorkerPool) -> None:
    start(creator, "M/A")
    start(creator, "M/Crash", mode="exit")
    alone = (start(creator, "M/X", "Alone").outputs or {})["pid"]
    crashed = (start(creator, "M/A").outputs or {})["pid"]
    r = step(creator, "M/Crash")
    assert r.error == "component process of M/Crash died (exit code 3)"
    assert step(creator, "M/A").error == "component process of M/A died (exit code 3)"  # its container-mate
    assert {i.name: i.state for i in creator.instance_infos()} == {"M/A": "failed", "M/Crash": "failed",
                                                                   "M/X": "running"}
    assert step(creator, "M/X").status == "running"  # a dedicated process is not affected
    again = start(creator, "M/A")  # entering the state again places it afresh
    assert again.error == "" and (again.outputs or {})["pid"] not in (crashed, alone)
    assert not _alive(crashed)
    assert pool.wait_ready(60.0) and pool.idle() == 2  # refilled



@pytest.mark.parametrize("mode", ["sleep", "spin"])
def test_a_stuck_call_fails_its_instance_alone_and_its_container_goes_on(creator: Creator, mode: str) -> None:
    """Users audit 22, #1: a component blocked in its step had its container killed, failing its healthy
    container-mates with it, where the dry-run failed it alone. The worker now interrupts it (ComponentStuck) before
    the Creator's deadline; the pool here gives 10 s, so a kill would not have come by then anyway."""
    pid = (start(creator, "M/A").outputs or {})["pid"]
    assert (start(creator, "M/Stuck", mode=mode).outputs or {})["pid"] == pid  # one container
    r = step(creator, "M/Stuck")
    assert r.error.startswith("component raised ComponentStuck: step did not return within 0.6 s of wall time"), r
    assert "(at tests/e2e/test_workers.py" in r.error or "test_workers.py:" in r.error, r.error  # the line it was at
    ok = step(creator, "M/A")
    assert ok.error == "" and ok.status == "running" and (ok.outputs or {})["pid"] == pid  # the same process
    again = step(creator, "M/Stuck", now=2.0)  # it raised, as any component may: the controller ends its state
    assert again.error.startswith("component raised ComponentStuck"), again


def test_a_process_that_dies_in_a_batch_is_named_with_every_instance_of_that_call(creator: Creator) -> None:
    """Wedge audit D6: `Exit` died beside `Forward` in one container, and the reason said `Forward` died: which call
    of the round trip it died in is not known, so each is named."""
    start(creator, "M/A")
    start(creator, "M/Crash", mode="exit")
    calls = [ComponentCall("step", MISSION, p, now=2.0) for p in ("M/A", "M/Crash")]
    replies = creator.handle_batch(ComponentBatch(calls)).replies
    assert replies[0].error == "component process of M/A, M/Crash died (exit code 3)", replies


def test_a_reply_too_large_for_the_bus_fails_its_instance_alone(creator: Creator) -> None:
    """Wedge audit D5: a 2 MB output made the whole batch's reply unsendable ("handler returned a malformed reply:
    too large"), failing every instance stepped with it; now that instance's reply is the error, naming the size."""
    from drd.bus import encode

    for path, mode in (("M/A", ""), ("M/H", "huge"), ("M/B", "")):
        start(creator, path, mode=mode)
    calls = [ComponentCall("step", MISSION, p, now=2.0) for p in ("M/A", "M/H", "M/B")]
    batch = creator.handle_batch(ComponentBatch(calls))
    assert [r.error for r in batch.replies][0::2] == ["", ""], batch.replies
    assert batch.replies[1].error.startswith("the reply to step of M/H is too large for the bus (too large: 20"), \
        batch.replies[1].error
    assert len(encode(batch)) < 1 << 20  # the batch's reply goes out

def test_a_batch_runs_in_one_round_trip_per_process_and_stops_at_an_event(creator: Creator) -> None:
    for path, comp, mode in (("M/A", "Probe", "shared"), ("M/B", "Probe", "shared"), ("M/X", "Alone", "shared"),
                             ("M/C", "Probe", "emit"), ("M/D", "Probe", "")):
        start(creator, path, comp, mode)
    calls = [ComponentCall("step", MISSION, p, now=2.0, shared={"log": []}, shared_ids={"log": "s1"})
             for p in ("M/A", "M/B", "M/X", "M/C", "M/D")]
    replies = creator.handle_batch(ComponentBatch(calls)).replies
    assert len(replies) == 4  # stopped after M/C's event: M/D is stepped by a later call
    assert [(r.shared or {}).get("log") for r in replies[:3]] == [["M/A"], ["M/A", "M/B"], ["M/A", "M/B", "M/X"]]
    assert replies[3].events == [["Seen", {"at": 2.0}, "tests/e2e/test_workers.py:60, in step"]]  # with where it
    # was emitted, for a refusal on the controller to name (users audit 21, #3)


def test_after_losing_its_controller_a_host_answers_that_it_runs_no_such_instance(creator: Creator) -> None:
    """Its instances retired, the host's refusal of a later call says `lost` (alone and in a batch), so the
    controller places a movable one again instead of failing the mission; another refusal does not say it."""
    start(creator, "M/A")
    start(creator, "M/B")
    creator.controller_lost("frozen past the lease")
    alone = step(creator, "M/A")
    batch = creator.handle_batch(ComponentBatch([ComponentCall("step", MISSION, p, now=2.0)
                                                 for p in ("M/A", "M/B")])).replies
    for reply in (alone, batch[0]):
        assert reply.lost and reply.error == f"ranger1's Creator refused step of M/A: no instance M/A of mission" \
                                             f" {MISSION} on ranger1", reply
    assert len(batch) == 1  # the controller places it again before the next step is sent
    other = creator.handle_batch(ComponentBatch([ComponentCall("step", "m/1", "M/A")])).replies
    assert not other[0].lost and "names a mission (without '/')" in other[0].error


def test_sys_exit_in_a_worker_fails_the_state_and_the_worker_goes_on(creator: Creator, pool: WorkerPool) -> None:
    """Review of users audit 12, D4: the worker caught `Exception` around component code, so `sys.exit` ended the
    worker process (the dry-run failed the state)."""
    start(creator, "M/Quit", mode="sys.exit")
    pid = (start(creator, "M/Other").outputs or {})["pid"]
    r = step(creator, "M/Quit")
    assert r.error.startswith("component raised SystemExit: 3 (at "), r.error
    assert step(creator, "M/Other").outputs == {"pid": pid}  # the same worker, still serving


def test_manifest_scheduling_is_applied_to_the_process_it_is_placed_in(creator: Creator) -> None:
    pid = (start(creator, "M/N", "Niced").outputs or {})["pid"]
    other = (start(creator, "M/A").outputs or {})["pid"]
    assert pid != other  # a different scheduling never shares a container
    proc = psutil.Process(pid)
    assert proc.nice() == 3 and proc.cpu_affinity() == [0]


def test_tune_sets_affinity_and_nice_of_the_instance_process(creator: Creator) -> None:
    pid = (start(creator, "M/A").outputs or {})["pid"]
    start(creator, "M/B")
    cores = [psutil.cpu_count() - 1]
    tuned = creator.tune(Tune("M/A", cores, 5))
    assert (tuned.pid, tuned.process, tuned.cores, tuned.nice, tuned.shared_with) == (pid, "container", cores, 5,
                                                                                       ["M/B"])
    proc = psutil.Process(pid)
    assert proc.cpu_affinity() == cores and proc.nice() == 5
    assert creator.tune(Tune("M/A")).nice == 5  # neither: only reports
    with pytest.raises(CreatorError, match="core 4096 does not exist"):
        creator.tune(Tune("M/A", [4096]))
    with pytest.raises(CreatorError, match=r"nice must be in -20\.\.19"):
        creator.tune(Tune("M/A", None, 40))
    with pytest.raises(CreatorError, match="no instance 'M/Z' runs on ranger1"):
        creator.tune(Tune("M/Z", None, 1))
    if os.geteuid() != 0:
        with pytest.raises(CreatorError, match="permission denied"):
            creator.tune(Tune("M/A", None, -5))
    # a tuned container takes no new instance: the next one goes to another process
    assert (start(creator, "M/C").outputs or {})["pid"] != pid
    creator.handle(ComponentCall("terminate", MISSION, "M/B"))  # ended: it shares the process with nobody any more
    assert creator.tune(Tune("M/A")).shared_with == []


def test_missions_run_side_by_side_in_processes_of_their_own_until_retired(creator: Creator) -> None:
    pids = [(start(creator, p, c).outputs or {})["pid"] for p, c in (("M/A", "Probe"), ("M/X", "Alone"))]
    r = creator.handle(ComponentCall("start", "m2", "M/A", component="Probe", params={"mode": ""},
                                     bindings={"drive": ["ranger1.drive", "", ""]}))
    other = (r.outputs or {})["pid"]
    assert other not in pids and all(_alive(pid) for pid in [*pids, other])  # the same path, its own process
    assert sorted((i.mission, i.name) for i in creator.instance_infos()) == [
        ("m1", "M/A"), ("m1", "M/X"), ("m2", "M/A")]
    assert step(creator, "M/A").status == "running"  # m1's M/A is still m1's
    creator.handle(ComponentCall("retire", MISSION, ""))
    assert _all_gone(pids) and _alive(other)
    assert [(i.mission, i.name) for i in creator.instance_infos()] == [("m2", "M/A")]


def test_every_instance_dropped_gets_its_shutdown_once_before_its_process_goes(creator: Creator,
                                                                                tmp_path: Path) -> None:
    """docs/components.md: `shutdown` once, when the instance is dropped: at its mission's end (retire), in a
    container or a dedicated process, and when it moves away (it goes on elsewhere: this object is done)."""
    note = tmp_path / "shutdown.log"
    replies = [start(creator, p, c, mode=f"note:{note}") for p, c in (("M/A", "Probe"), ("M/B", "Probe"),
                                                                       ("M/X", "Alone"), ("M/V", "Probe"))]
    pids = sorted({(r.outputs or {})["pid"] for r in replies})
    assert len(pids) == 2  # A, B and V share a container; X has a process of its own
    creator.handle(ComponentCall("terminate", MISSION, "M/V", status="moved"))  # it goes on on another host
    creator.handle(ComponentCall("terminate", MISSION, "M/A", status="success"))  # ended, not dropped: kept
    step(creator, "M/B")
    creator.handle(ComponentCall("retire", MISSION, ""))
    assert _all_gone(pids)
    lines = sorted(note.read_text().splitlines())
    assert [line.split()[0] for line in lines] == ["M/A", "M/B", "M/V", "M/X"]  # each once
    assert {int(line.split()[1]) for line in lines} == set(pids)  # in its own process, before that went


def test_a_shutdown_that_hangs_does_not_keep_its_process(creator: Creator, tmp_path: Path) -> None:
    """`shutdown` is bounded (`SHUTDOWN_GRACE`): one that never returns is given up on and its process killed;
    the retire itself returns at once, and the Creator's other missions go on."""
    note = tmp_path / "shutdown.log"
    pid = (start(creator, "M/H", "Alone", mode=f"hang:{note}").outputs or {})["pid"]
    creator.handle(ComponentCall("retire", MISSION, ""))
    assert (start(creator, "M/N").outputs or {}).get("pid") not in (None, pid)  # the Creator still serves
    assert _all_gone([pid])
    assert note.read_text().split() == ["M/H", str(pid)]  # it was called, once


@pytest.fixture
def simulated(catalog_: Catalog, pool: WorkerPool) -> Iterator[tuple[Creator, Any, list[Any]]]:
    """A Creator whose `sim` drivers run on a simulation in this process (as on the simulator host), and the
    driver requests that come over the pipe (a spy on the Creator's side). The repository's hosts file: ranger1
    with its Scouts (a launch needs the Scout held, so bound, and so configured)."""
    from drd.sim.service import SimulationService

    corridor = load_hosts(ROOT / "hosts.yaml", catalog_)
    service = SimulationService(None, corridor.name)
    service.reset("corridor")
    c = Creator(None, corridor, "ranger1", catalog_, pool=pool, sim_service=service)
    asked: list[Any] = []
    serve = c._device_request

    def spy(worker: Any, req: Any, answer: bool = True) -> Exception | None:
        asked.append(req.name)
        return serve(worker, req, answer)
    c._device_request = spy  # type: ignore[method-assign]
    try:
        yield c, service, asked
    finally:
        c.close()


READER_BINDINGS = {n: [f"ranger1.{n}", "", ""] for n in ("drive", "ranges", "camera", "launcher")}


def test_readings_are_read_ahead_of_a_step_and_equal_those_asked(simulated: tuple[Creator, Any, list[Any]]) -> None:
    c, service, asked = simulated
    assert c.handle(ComponentCall("start", MISSION, "M/R", component="Reader", params={"mode": ""}, world="corridor",
                                  bindings=READER_BINDINGS)).error == ""
    first = c.handle(ComponentCall("step", MISSION, "M/R", now=1.0))
    assert first.error == "" and sorted(asked) == ["fov", "loaded", "odometry", "scan"]  # learnt over the pipe
    sim = service.sim
    sim.set_velocity("ranger1", 0.5, 0.2)
    for now in (2.0, 3.0):
        sim.step(0.1)
        asked.clear()
        r = c.handle(ComponentCall("step", MISSION, "M/R", now=now))
        assert r.error == "" and asked == [], "every reading came with the call"
        out = r.outputs or {}
        p = sim.odometry("ranger1")  # readings are a function of the instant: the same asked now
        assert out["odometry"] == [p.x, p.y, p.heading] and out["odometry"] != (first.outputs or {})["odometry"]
        assert out["scan"] == sim.ranges("ranger1", 181, 8.0, math.pi)
        assert out["fov"] == pytest.approx(math.radians(60.0)) and len(out["loaded"]) == 6


def test_a_launch_during_a_step_makes_the_readings_read_ahead_stale(
        simulated: tuple[Creator, Any, list[Any]]) -> None:
    c, service, asked = simulated
    grant = [["grant", "ranger1.launcher", f"{MISSION}/M", 3, 0.0]]
    holding = {**READER_BINDINGS, "scout": ["scout1", "", ""]}  # the launcher throws only a Scout it holds
    c.handle(ComponentCall("start", MISSION, "M/R", component="Reader", params={"mode": "launch"}, world="corridor",
                           bindings=holding, gates=grant, epochs={"launcher": 3}))
    before = (c.handle(ComponentCall("step", MISSION, "M/R", now=1.0)).outputs or {})["loaded"]
    service.sim.step(0.1)
    asked.clear()
    r = c.handle(ComponentCall("step", MISSION, "M/R", now=2.0))
    assert r.error == "" and (r.outputs or {})["landing"] is True
    assert asked == ["launch", "odometry", "scan", "fov", "loaded"]  # loaded() came ahead, the rest is asked
    assert (r.outputs or {})["loaded"] == before[1:], "the magazine as it is after the launch"
    asked.clear()
    c.handle(ComponentCall("step", MISSION, "M/R", now=3.0))
    assert "loaded" not in asked


# -- against real daemons ---------------------------------------------------------------------------------

TUNE_CLI = ("import typer\nfrom drd.cli.common import run_app\nfrom drd.cli.tune import register\n"
            "app = typer.Typer()\napp.callback()(lambda: None)\nregister(app)\nrun_app(app, 'missionctl')\n")


def corridor_hosts(c: Any) -> str:
    """The repository's hosts.yaml (controller, ranger1 + simulator) on our free ports, with the test lease."""
    text = (ROOT / "hosts.yaml").read_text()
    text = text.replace("name: corridor", f"name: {c.name}").replace("lease: 3s", "lease: 1000ms")
    return text.replace("127.0.0.1:7447", f"127.0.0.1:{c.ports[0]}").replace("127.0.0.1:7448",
                                                                             f"127.0.0.1:{c.ports[1]}")


def test_missionctl_tune_finds_the_instance_and_tunes_its_process(tmp_path: Path) -> None:
    import json

    from cluster_support import eventually, running_cluster

    with running_cluster(tmp_path, ["controller", "ranger1"]) as c:
        c.hosts_file.write_text(corridor_hosts(c))
        c.start_all()
        c.wait_ready()
        client = c.client()
        c.wait_up(client)
        r = c.missionctl("run", "missions/corridor_surveillance.mission", "--detach", "--speed", "1",
                         "--config", str(c.hosts_file))
        assert r.returncode == 0, r.stderr
        mission = r.stdout.strip()
        found: list[str] = []

        def announced() -> bool:
            found[:] = [i.name for i in client.components().instances if i.host == "ranger1"]
            return bool(found)

        eventually(announced, "an instance of ranger1 to be announced", 30.0, poll=0.1)
        name = found[0]
        daemon = psutil.Process(c.pid("ranger1"))
        children = {p.pid for p in daemon.children(recursive=True)}

        def tune(*args: str) -> subprocess.CompletedProcess[str]:
            return subprocess.run([sys.executable, "-c", TUNE_CLI, "tune", *args, "--config", str(c.hosts_file)],
                                  cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)

        r = tune(name, "--cores", "0", "--nice", "4", "--json")
        if r.returncode == 2 and "no running instance" in r.stderr:  # it finished in between: take the next one
            eventually(lambda: announced() and found[0] != name, "another instance", 30.0, poll=0.1)
            name = found[0]
            r = tune(name, "--cores", "0", "--nice", "4", "--json")
        assert r.returncode == 0, r.stderr
        got = json.loads(r.stdout)
        assert got["instance"] == name and got["host"] == "ranger1" and got["cores"] == [0] and got["nice"] == 4
        assert got["pid"] in children and got["pid"] != c.pid("ranger1")
        proc = psutil.Process(got["pid"])
        assert proc.cpu_affinity() == [0] and proc.nice() == 4

        for _ in range(5):  # a name one letter short of a running instance's
            r = tune(name[:-1], "--nice", "1")
            if "did you mean" in r.stderr or name in r.stderr:  # else it finished in between: the next one
                break
            ended = name
            eventually(lambda: announced() and found[0] != ended, "another instance", 30.0, poll=0.1)  # noqa: B023
            name = found[0]
        assert r.returncode == 2
        assert f"no running instance called {name[:-1]!r}" in r.stderr and "did you mean" in r.stderr

        r = tune(name, "--cores", "4096")
        assert r.returncode in (0, 2) and ("core 4096 does not exist" in r.stderr or "no running" in r.stderr)

        c.missionctl("stop", mission, "--config", str(c.hosts_file))
        os.kill(c.pid("ranger1"), signal.SIGTERM)  # a clean stop kills its workers
        c.procs["ranger1"].wait(20)
        eventually(lambda: not [pid for pid in children if _alive(pid)], "ranger1's processes to be gone", 10.0)


def test_an_action_is_answered_a_setpoint_is_not() -> None:
    """A hop (an action) changes what the sensors read within the step, so it is sent and answered (the answer
    says the world changed); a velocity (a setpoint) takes effect at the next step, so it goes without waiting.
    What is which is what each driver declares (`drd.hw.commands`)."""
    from drd.hw.commands import spec_of
    from drd.hw.drivers import drivers_for
    from drd.sim import Simulation, load_world

    catalog = load_catalog()
    sim = Simulation(load_world(ROOT / "worlds" / "corridor.yaml"))
    drivers = drivers_for(load_hosts(ROOT / "hosts.yaml", catalog), "ranger1", sim, catalog=catalog)
    foot, wheels = spec_of(drivers.robots["scout1"]["foot"]), spec_of(drivers.robots["scout1"]["wheels"])
    assert (foot.setpoints, foot.actions) == (frozenset(), {"jump"})
    assert (wheels.setpoints, wheels.actions, wheels.stop) == ({"set_velocity", "stop"}, frozenset(), "stop")


def test_a_host_refuses_the_calls_of_a_controller_older_than_one_it_heard(creator: Creator) -> None:
    """Issue #16: a controller frozen while another took over must not act when it wakes: each call carries the
    start time of its controller, and a host refuses one older than the newest it has heard."""
    newer, older = 2000.0, 1000.0
    grant = [["grant", "ranger1.drive", f"{MISSION}/M/A", 1, 0.0]]
    assert not start(creator, "M/A", term=newer, gates=grant).error
    refused = start(creator, "M/B", term=older)
    assert "refuses a call from an older controller" in refused.error, refused
    assert "M/B" not in {path for path, _ in creator.names()}
    stolen = GateUpdate([["grant", "ranger1.drive", "Old-1/M/X", 9, 1.0]], term=older)
    assert creator.update_gates(stolen).records == []
    gate = creator._gates.get("ranger1.drive")
    assert gate is not None and list(gate.holders) == [f"{MISSION}/M/A"], "the old controller's grant was ignored"
    again = creator.handle(ComponentCall("step", MISSION, "M/A", now=1.0, term=newer))
    assert not again.error, again  # the current controller goes on


def test_a_pool_keeps_idle_workers_only_while_the_host_has_work(catalog_: Catalog) -> None:
    """Issue #15 (lighter daemons): a cold pool starts nothing; a take or `warm()` makes it keep `size` idle
    workers, and `keep_warm` seconds after the last of them it stops them (by pid, reaped)."""
    from drd.cluster.creator import behavior_modules

    p = WorkerPool(2, preload=behavior_modules(catalog_), call_timeout=10.0, keep_warm=1.0, warm=False)
    try:
        time.sleep(0.3)
        assert p.pids() == [] and p.idle() == 0  # cold: not one process
        taken = p.take(60.0)
        assert p.wait_ready(60.0) and p.idle() == 2  # warm: ready for the next placements
        idle = [pid for pid in p.pids() if pid != taken.pid]
        deadline = time.monotonic() + 30.0
        # bounded: a hang guard, not a measure (an idle worker leaves the idle list, then is stopped and reaped)
        while (p.idle() or [pid for pid in idle if _alive(pid)]) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert p.idle() == 0 and not [pid for pid in idle if _alive(pid)]
        assert taken.alive and p.pids() == [taken.pid]  # a taken worker is its Creator's until released
        p.release(taken)
    finally:
        p.close()


class StoppableDrive(FakeDrive):
    """A fake drive with a safe stop, so a gate records a `halted` when it stops it."""

    SETPOINTS = ("set_velocity", "stop")
    STOP = "stop"

    def stop(self, epoch: int | None = None) -> None:
        self.commands.append((0.0, 0.0, epoch, os.getpid()))


def test_the_halts_on_losing_the_controller_are_at_the_last_time_it_said(cluster_: Cluster, catalog_: Catalog,
                                                                         pool: WorkerPool) -> None:
    """Cluster audit 14, D1: a retire (which says no time) set the host's clock to 0, and the halts it made when the
    controller was lost then came at -11 s in the resumed mission's trace: a "time backwards" breach."""
    drive = StoppableDrive()
    creator = Creator(None, cluster_, "ranger1", catalog_, pool=pool,
                      drivers=lambda world: HostDrivers({"ranger1.drive": drive}))
    try:
        grant = [["grant", "ranger1.drive", f"{MISSION}/M", 7, 0.0]]
        start(creator, "M/D", mode="drive", epochs={"drive": 7}, gates=grant)
        assert step(creator, "M/D", now=42.0).error == ""  # a setpoint in force, at 42 s
        creator.handle(ComponentCall("retire", "other-1", ""))  # another mission ended meanwhile
        creator.controller_lost("controller controller lost (test)")
        records = step(creator, "M/D", now=43.0).records or []
    finally:
        creator.close()
    halts = [r for r in records if r["kind"] == "halted"]
    assert [(h["device"], h["at"]) for h in halts] == [("ranger1.drive", 42.0)], records
