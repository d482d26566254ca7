"""The statechart runtime with the Resource Controller Manager, on a simulated clock."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from drd.rcm import Unit
from drd.runtime import records as rec
from drd.runtime.component import Status
from dsl import compile_text
from dsl.catalog import Catalog
from dsl.statechart import Statechart
from tests.conftest import shared_examples
from tests.runtime_support import Emits, Fails, Forever, Harness, Raises, Timed, ranger_world


def compiled(text: str, catalog: Catalog) -> Statechart:
    r = compile_text(text, catalog, "t.mission")
    assert r.ok and r.statechart is not None, "\n".join(d.render(r.sources) for d in r.diagnostics)
    return r.statechart


def grants_of(h: Harness, path_suffix: str) -> list[float]:
    return [r.at for r in h.of(rec.Granted) if r.path.endswith(path_suffix)]


def test_fig8_round_robin_then_lower_priority(catalog: Catalog) -> None:
    """Two priority-1 behaviors alternate 5 s slices on one camera; priority 2 starts after both."""
    path = shared_examples() / "shared_camera.mission"
    chart = compiled(path.read_text(), catalog)
    h = Harness(chart, {"Observe": Timed}, [Unit("ranger1.camera", "Camera")])
    assert h.run() == "success"
    holds = [(r.at, r.path.rsplit("/", 1)[-1]) for r in h.of(rec.Granted)]
    order = [who for _, who in holds]
    assert order[:4] == ["first", "second", "first", "second"], holds
    third = [t for t, who in holds if who == "third"]
    done = {r.path.rsplit("/", 1)[-1]: r.at for r in h.of(rec.Exited) if r.path.count("/") == 1}
    assert third and third[0] >= max(done["first"], done["second"])
    assert all(b - a >= 5.0 - 1e-9 for (a, _), (b, _) in zip(holds[:4], holds[1:5], strict=True))
    logs = [r.text for r in h.of(rec.Log)]
    assert {"inspection a finished", "inspection b finished", "inspection c finished"} <= set(logs)


def test_sequence_with_release_and_outputs(catalog: Catalog) -> None:
    text = """
mission M {
    needs ranger: Ranger
    var seen: int = 0
    start -> Calibrate
    Calibrate -> TurnToWatch / set seen = seen + 1
    TurnToWatch -> done [seen == 1] / release(ranger)
}"""
    h = Harness(compiled(text, catalog), {"Calibrate": Timed, "TurnToWatch": Timed}, ranger_world())
    assert h.run() == "success"
    taken = [(r.path.rsplit("/", 1)[-1], r.target.rsplit("/", 1)[-1]) for r in h.of(rec.Taken)]
    assert taken == [("Calibrate", "TurnToWatch"), ("TurnToWatch", "done")]
    assert h.of(rec.Released)[0].resources  # release(ranger) gave the units back before the exit


def test_a_composites_outputs_are_its_childrens_for_the_siblings_after_it(catalog: Catalog) -> None:
    """AlignRanger reads the door its own FindNewDoor found: a composite passes its children's outputs up."""
    seen: list[Any] = []

    class Finds(Timed):
        def step(self, now: float) -> Any:
            self.ctx.outputs["door"] = {"x": 4.0}
            return super().step(now)

    class Reads(Timed):
        def start(self) -> None:
            super().start()
            seen.append(self.input("door"))  # bound by the mission to Find's door (a sibling's output)

    text = """
mission M {
    needs r: Ranger
    start -> Find
    Find -> AlignRanger
}
behavior Find { DetectDoor(min_width: 0.5) }"""
    h = Harness(compiled(text, catalog), {"DetectDoor": Finds, "AlignRanger": Reads}, ranger_world())
    assert h.run() == "success" and seen == [{"x": 4.0}]


def test_error_propagates_unless_handled(catalog: Catalog) -> None:
    unhandled = "mission M {\n needs r: Ranger\n start -> Calibrate\n Calibrate -> ReturnToStart\n ReturnToStart\n}"
    h = Harness(compiled(unhandled, catalog), {"Calibrate": Fails, "ReturnToStart": Timed}, ranger_world())
    assert h.run() == "failure"
    handled = unhandled.replace(" ReturnToStart\n}", " ReturnToStart\n Calibrate -> ReturnToStart on error\n}")
    h = Harness(compiled(handled, catalog), {"Calibrate": Fails, "ReturnToStart": Timed}, ranger_world())
    assert h.run() == "success"


def test_component_that_raises_fails_its_state_not_the_executive(catalog: Catalog) -> None:
    text = "mission M {\n needs r: Ranger\n start -> Calibrate\n Calibrate -> ReturnToStart on error\n ReturnToStart\n}"
    h = Harness(compiled(text, catalog), {"Calibrate": Raises, "ReturnToStart": Timed}, ranger_world())
    assert h.run() == "success"
    assert any("RuntimeError: sensor on fire" in r.text for r in h.of(rec.Log))


def test_timeout_and_operator_event(catalog: Catalog) -> None:
    text = """
mission M {
    needs r: Ranger
    start -> Calibrate
    Calibrate -> fail after 2s
    Calibrate -> done on MotionDetected
}"""
    h = Harness(compiled(text, catalog), {"Calibrate": Forever}, ranger_world())
    assert h.run(until=10) == "failure"  # no event: the timeout fires
    assert [r.trigger for r in h.of(rec.Taken)] == ["timeout"]
    h = Harness(compiled(text, catalog), {"Calibrate": Forever}, ranger_world())
    h.interp.start()
    h.clock.advance(1.0)
    h.interp.emit("MotionDetected", area=1.0)
    h.interp.step()
    assert h.interp.outcome == "success"


def test_component_event_with_guard_and_action(catalog: Catalog) -> None:
    text = """
mission M {
    needs r: Ranger
    var area: float = 0.0
    parallel { Calibrate; Watch }
    Calibrate -> done on MotionDetected [event.area > 0.2] / set area = event.area
}"""
    h = Harness(compiled(text, catalog), {"Calibrate": Forever, "Watch": Emits}, ranger_world())
    assert h.run(until=10) == "success"
    assert [(r.name, r.path) for r in h.of(rec.Event)] == [("MotionDetected", "M/Watch")]
    assert h.interp.root is not None and h.interp.root.scope["area"] == 0.5


def test_multiplicity_graceful_degradation(catalog: Catalog) -> None:
    text = """
mission M { Room[1..count(Scout)] }
behavior Room { needs s: Scout
    Watch }"""
    calls = {"n": 0}

    class SometimesFails(Timed):
        def step(self, now: float):  # type: ignore[no-untyped-def]
            calls["n"] += 1
            assert self.ctx is not None
            return Fails().step(now) if self.ctx.path.endswith("[0]/Watch") else super().step(now)

    h = Harness(compiled(text, catalog), {"Watch": SometimesFails}, ranger_world(1, 3))
    assert h.run() == "success"  # one instance of three failed: still at least 1
    exits = {r.path: r.status for r in h.of(rec.Exited) if r.path.count("/") == 1 and "[" in r.path}
    assert exits == {"M/Room[0]": "failure", "M/Room[1]": "success", "M/Room[2]": "success"}
    h = Harness(compiled(text.replace("[1..", "[3.."), catalog), {"Watch": SometimesFails}, ranger_world(1, 3))
    assert h.run() == "failure"


@pytest.mark.parametrize("when", ["waiting", "running", "suspended", "twice"])
def test_stop_shuts_everything_down(catalog: Catalog, when: str) -> None:
    text = "mission M {\n parallel { A as a; A as b }\n}\nbehavior A { needs c: Camera for 1s\n Observe }"
    Forever.calls = []
    h = Harness(compiled(text, catalog), {"Observe": Forever}, [Unit("cam", "Camera")], slice_=1.0)
    h.interp.start()
    steps = {"waiting": 0, "running": 1, "suspended": 3, "twice": 2}[when]
    for _ in range(steps):
        h.clock.advance(0.75)
        h.interp.step()
    if when == "suspended":
        assert any(isinstance(r, rec.Suspended) for r in h.records)
    h.interp.stop()
    if when == "twice":
        h.interp.stop()
    assert h.interp.outcome == "stopped" and h.interp.active() == []
    starts = [p for c, p in Forever.calls if c == "start"]
    terminates = [p for c, p in Forever.calls if c == "terminate"]
    assert sorted(starts) == sorted(terminates)  # every started component was terminated, once
    assert h.rcm.holders("cam") == () and not h.rcm.queue()
    assert len(h.of(rec.Finished)) == 1


def test_trace_names_instances_and_resources(catalog: Catalog, tmp_path: Path) -> None:
    path = shared_examples() / "shared_camera.mission"
    h = Harness(compiled(path.read_text(), catalog), {"Observe": Timed}, [Unit("ranger1.camera", "Camera")])
    h.run()
    g = h.of(rec.Granted)[0]
    assert g.path == "SharedCamera/first" and g.resources == {"cam": "ranger1.camera"}
    assert g.to_dict()["kind"] == "granted"


def test_trace_writer_writes_one_json_line_per_record(catalog: Catalog, tmp_path: Path) -> None:
    import json

    from drd.runtime.trace import TraceWriter

    path = shared_examples() / "shared_camera.mission"
    h = Harness(compiled(path.read_text(), catalog), {"Observe": Timed}, [Unit("ranger1.camera", "Camera")])
    out = tmp_path / "trace.jsonl"
    with out.open("w") as fh:
        h.interp.attach(TraceWriter(fh))
        h.run()
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(lines) == len(h.records)
    assert lines[-1]["kind"] == "finished" and lines[-1]["outcome"] == "success"
    granted = [x for x in lines if x["kind"] == "granted"]
    assert granted[0]["path"] == "SharedCamera/first" and granted[0]["resources"] == {"cam": "ranger1.camera"}


ROOMS = """
mission M { Room[1..count(Scout)] }
behavior Room { needs s: Scout
    Watch }"""


def test_lost_host_fails_only_its_instances(catalog: Catalog) -> None:
    from tests.runtime_support import Forever

    h = Harness(compiled(ROOMS, catalog), {"Watch": Forever}, ranger_world(2, 1))
    h.interp.start()
    h.clock.advance(1.0)
    h.interp.step()
    assert sorted(r.path for r in h.of(rec.Granted)) == ["M/Room[0]", "M/Room[1]"]
    h.interp.remove_host("ranger2")
    exits = {r.path: r.status for r in h.of(rec.Exited)}
    lost = [p for p, st in exits.items() if st == "failure"]
    assert lost == ["M/Room[1]"] and h.interp.outcome is None  # the mission goes on with one Room
    released = h.of(rec.Released)
    assert released and released[0].reason == "host lost"


def test_a_behavior_holding_robots_on_two_hosts_fails_naming_the_one_lost(catalog: Catalog) -> None:
    """Users audit 15, D2: "lost crawler_a (host lost)" when the Hauler's host went: the reason and the `released`
    record named the grant's first robot, not the one on the lost host."""
    from tests.runtime_support import Forever

    text = ('mission M {\n needs a: Ranger where a.id == "ranger1"\n needs b: Ranger where b.id == "ranger2"\n'
            ' Wait(duration: 100s)\n}')
    h = Harness(compiled(text, catalog), {"Wait": Forever}, ranger_world(2, 1))
    h.interp.start()
    h.clock.advance(1.0)
    h.interp.step()
    h.interp.remove_host("ranger2")
    [released] = [r for r in h.of(rec.Released) if r.path == "M"]
    assert released.resources[0] == "ranger2" and released.reason == "host lost"
    assert h.interp.outcome == "failure" and h.interp.reason == "lost ranger2 (host lost)"


def test_new_scout_grows_a_running_multiplicity(catalog: Catalog) -> None:
    from tests.runtime_support import Forever

    world = ranger_world(1, 2)
    h = Harness(compiled(ROOMS, catalog), {"Watch": Forever}, world)
    h.interp.start()
    assert h.interp.root is not None
    extra = [r for r in ranger_world(2, 1) if r.id.startswith("ranger2")]
    h.interp.add_resources(extra)
    rooms = [n.path for n in h.interp.active() if n.path.startswith("M/Room[") and "/Watch" not in n.path]
    assert rooms == ["M/Room[0]", "M/Room[1]", "M/Room[2]"]


def test_two_missions_share_one_manager_by_priority(catalog: Catalog) -> None:
    from drd.rcm import ResourceManager
    from drd.runtime.clock import SimClock
    from drd.runtime.interpreter import Interpreter
    from drd.runtime.pool import ResourcePool

    low = compiled("mission Low { needs c: Camera\n Observe(duration: 2s) }", catalog)
    high = compiled("mission High { A priority 1 }\nbehavior A { needs c: Camera\n Observe(duration: 2s) }",
                    catalog)
    low_prio = compiled("mission Low { A priority 2 }\nbehavior A { needs c: Camera\n Observe(duration: 12s) }",
                        catalog)
    del low
    clock, rcm = SimClock(), ResourceManager()
    pool = ResourcePool(rcm)
    pool.add([Unit("cam", "Camera")], 0.0)
    log: list[rec.Record] = []
    runs = [Interpreter(chart, {"Observe": Timed}, rcm, clock, pool=pool) for chart in (low_prio, high)]
    for r in runs:
        r.attach(log.append)
    runs[0].start()
    runs[1].start()
    while not all(r.finished for r in runs) and clock.now() < 60:
        clock.advance(0.5)
        for r in runs:
            r.step()
    assert [r.outcome for r in runs] == ["success", "success"]
    granted = [(g.at, g.path) for g in log if isinstance(g, rec.Granted)]
    assert granted[0][1] == "Low/A"  # first come, while the camera was free
    finished = {f.path: f.at for f in log if isinstance(f, rec.Finished)}
    assert finished["High"] < finished["Low"]  # priority 1 took the camera at the slice boundary
    revoked = [r for r in log if isinstance(r, rec.Revoked)]
    assert [(r.path, r.at) for r in revoked] == [("Low/A", 5.0)]
    # fleet audit defect 6: an ended mission's `time` is its own end, not the clock its world's missions share
    assert [r.snapshot()["time"] for r in runs] == [finished["Low"], finished["High"]]
    clock.advance(30.0)
    assert [r.snapshot()["time"] for r in runs] == [finished["Low"], finished["High"]]


class StopsOnStart(Forever):
    """Calls stop from inside its own start(): a stop during entry."""

    interp: Any = None

    def start(self) -> None:
        super().start()
        StopsOnStart.interp.stop("stopped during entry")


def test_stop_during_entry(catalog: Catalog) -> None:
    Forever.calls = []
    text = "mission M {\n needs r: Ranger\n parallel { Calibrate; TurnToWatch; ReturnToStart }\n}"
    h = Harness(compiled(text, catalog), {"Calibrate": Forever, "TurnToWatch": StopsOnStart,
                                         "ReturnToStart": Forever}, ranger_world())
    StopsOnStart.interp = h.interp
    h.interp.start()
    assert h.interp.outcome == "stopped" and h.interp.active() == []
    started = [p for c, p in Forever.calls if c == "start"]
    assert started == ["M/Calibrate", "M/TurnToWatch"]  # ReturnToStart was never entered
    assert sorted(p for c, p in Forever.calls if c == "terminate") == sorted(started)
    assert h.rcm.holders("ranger1.drive") == ()


def test_stop_during_a_transition(catalog: Catalog) -> None:
    Forever.calls = []
    text = "mission M {\n needs r: Ranger\n start -> Calibrate\n Calibrate -> ReturnToStart\n ReturnToStart\n}"
    h = Harness(compiled(text, catalog), {"Calibrate": Timed, "ReturnToStart": Forever}, ranger_world())
    h.interp.attach(lambda r: h.interp.stop("stopped mid-transition") if isinstance(r, rec.Taken) else None)
    assert h.run(until=5) == "stopped"
    assert Forever.calls == []  # the target was never entered
    assert h.interp.active() == [] and h.rcm.holders("ranger1.drive") == ()


#: Counts the Scouts its Ranger carries when Calibrate is done.
ABOARD = """
mission M {
    needs r: Ranger
    var aboard: int = 0
    start -> Calibrate
    Calibrate -> done / set aboard = count(Scout where scout.carrier == r)
}"""


def test_static_dependencies_change_at_run_time(catalog: Catalog) -> None:
    h = Harness(compiled(ABOARD, catalog), {"Calibrate": Timed}, ranger_world(1, 3))
    h.interp.start()
    h.interp.set_property("ranger1.scout2", "carrier", "")  # launched: it left the magazine
    h.run()
    assert h.interp.root is not None and h.interp.root.scope["aboard"] == 2


PREALLOC = """
mission M {
    needs r: Ranger
    start -> Calibrate
    Calibrate -> Look
}
behavior Look { needs cam: Camera where cam.id == "cam"
    Observe(duration: 1s) }"""


@pytest.mark.parametrize("preallocate", [False, True])
def test_preallocation_reserves_the_next_states_needs(catalog: Catalog, preallocate: bool) -> None:
    from drd.rcm import ResourceManager
    from drd.runtime.clock import SimClock
    from drd.runtime.interpreter import Interpreter
    from drd.runtime.pool import ResourcePool

    clock, rcm = SimClock(), ResourceManager()
    pool = ResourcePool(rcm)
    pool.add([*ranger_world(1, 0), Unit("cam", "Camera")], 0.0)
    log: list[rec.Record] = []
    mine = Interpreter(compiled(PREALLOC, catalog), {"Calibrate": Timed, "Observe": Timed}, rcm, clock, pool=pool,
                       preallocate=preallocate)
    other = Interpreter(compiled("mission Other { needs c: Camera\n Observe(duration: 20s) }", catalog),
                        {"Observe": Timed}, rcm, clock, pool=pool)
    mine.attach(log.append)
    mine.start()
    clock.advance(0.5)
    other.start()  # asks for the camera while Calibrate is running
    while not mine.finished and clock.now() < 60:
        clock.advance(0.5)
        mine.step()
        other.step()
    assert mine.outcome == "success"
    entered = next(r.at for r in log if isinstance(r, rec.Entered) and r.path == "M/Look")
    granted = next(r.at for r in log if isinstance(r, rec.Granted) and r.path == "M/Look")
    if preallocate:
        assert granted < entered  # reserved while Calibrate ran: Look started at once
        assert next(r.at for r in log if isinstance(r, rec.Entered) and r.path == "M/Look/Observe") == entered
    else:
        assert granted >= 5.0  # waited for the other mission's slice to end
    assert rcm.holders("cam") != ("M/M/Look",)


def test_preallocation_is_cancelled_when_the_mission_goes_elsewhere(catalog: Catalog) -> None:
    text = PREALLOC.replace("    Calibrate -> Look\n", "    Calibrate -> Look\n    Calibrate -> fail on error\n")
    from drd.rcm import ResourceManager
    from drd.runtime.clock import SimClock
    from drd.runtime.interpreter import Interpreter
    from drd.runtime.pool import ResourcePool

    clock, rcm = SimClock(), ResourceManager()
    pool = ResourcePool(rcm)
    pool.add([*ranger_world(1, 0), Unit("cam", "Camera")], 0.0)
    mine = Interpreter(compiled(text, catalog), {"Calibrate": Fails, "Observe": Timed}, rcm, clock, pool=pool,
                       preallocate=True)
    mine.start()
    assert rcm.holders("cam") == ("M/M/Look",)  # reserved and granted ahead of need
    clock.advance(0.5)
    mine.step()
    assert mine.outcome == "failure"
    assert rcm.holders("cam") == () and not rcm.queue()


@pytest.mark.parametrize("other", ["Calibrate -> Observe after 290ms", "Calibrate -> Observe on MotionDetected"])
def test_an_after_due_between_two_cycles_wins_over_what_is_enabled_only_at_the_next(catalog: Catalog,
                                                                                    other: str) -> None:
    """Semantics audit 24, D4: `after 250ms` was due alone at 0.25 s, but at the 0.3 s cycle the first declared of
    the two timers won (`after 290ms`); so did an event declared first and emitted at 0.3 s."""
    text = f"""
mission M {{
    needs r: Ranger
    start -> Calibrate
    {other}
    Calibrate -> TurnToWatch after 250ms
    TurnToWatch -> done after 1s
    Observe -> fail after 1s
}}"""
    fakes = {"Calibrate": Forever, "TurnToWatch": Forever, "Observe": Forever}
    h = Harness(compiled(text, catalog), fakes, ranger_world())
    h.interp.start()
    for _ in range(3):  # the control cycles at 0.1, 0.2 and 0.3 s
        h.clock.advance(0.1)
        if " on " in other and h.clock.now() > 0.25:
            h.interp.emit("MotionDetected", area=1.0)
        h.interp.step()
    taken = [(r.target.rsplit("/", 1)[-1], r.trigger) for r in h.of(rec.Taken) if r.path.endswith("Calibrate")]
    assert taken == [("TurnToWatch", "timeout")], taken


def test_a_timeout_can_be_a_parameter(catalog: Catalog) -> None:
    text = """
mission M { Patient(limit: 3s) }
behavior Patient(limit: duration = 10s) {
    needs r: Ranger
    start -> Calibrate
    Calibrate -> fail after limit * 2
}"""
    h = Harness(compiled(text, catalog), {"Calibrate": Forever}, ranger_world())
    assert h.run(until=60) == "failure"
    assert [(r.trigger, r.at) for r in h.of(rec.Taken)] == [("timeout", 6.0)]


def test_a_livelock_fails_the_mission_instead_of_hanging(catalog: Catalog) -> None:
    text = "mission M {\n needs r: Ranger\n start -> Calibrate\n Calibrate -> Calibrate when true\n}"
    h = Harness(compiled(text, catalog), {"Calibrate": Forever}, ranger_world())
    assert h.run(until=5) == "failure"
    assert "livelock" in h.interp.reason
    assert [r.outcome for r in h.of(rec.Finished)] == ["failure"]
    assert h.interp.active() == [] and h.rcm.holders("ranger1.drive") == ()



def test_a_zero_time_loop_is_a_livelock_after_a_hundred_turns(catalog: Catalog) -> None:
    """Wedge audit D1: `A -> A after 0s` took 10,000 turns before the livelock limit; on a cluster each restarts a
    remote component, and the controller's mission loop was held for 20 s. One transition taken MAX_REPEATS times
    by one node in one instant is a loop."""
    from drd.runtime.interpreter import MAX_REPEATS

    text = "mission M {\n needs r: Ranger\n start -> Calibrate\n Calibrate -> Calibrate after 0s\n}"
    h = Harness(compiled(text, catalog), {"Calibrate": Forever}, ranger_world())
    assert h.run(until=5) == "failure"
    assert h.interp.reason == ("livelock: M/Calibrate -> M/Calibrate taken 100 times without time passing (a loop of"
                               " zero-time transitions)")
    assert len(h.of(rec.Taken)) == MAX_REPEATS and {r.at for r in h.of(rec.Taken)} == {0.0}  # not a 101st


class Storm(Forever):
    """Emits 10,001 DoorDetected in its first step, heard by nobody, and runs on."""

    stormed = False

    def step(self, now: float) -> Status:
        assert self.ctx is not None
        if not self.stormed:
            self.stormed = True
            for i in range(10_001):
                self.ctx.emit("DoorDetected", width=0.9, x=float(i), y=0.0)
        return Status.RUNNING


def test_events_nobody_hears_are_no_livelock(catalog: Catalog) -> None:
    """Wedge audit D2: each event counted as a transition, so 10,001 events in one step failed the mission as a
    livelock though no transition was taken."""
    text = "mission M {\n needs bot: Ranger\n DetectDoor\n}"
    h = Harness(compiled(text, catalog), {"DetectDoor": Storm}, ranger_world())
    assert h.run(until=3) is None, h.interp.reason
    assert len(h.of(rec.Event)) == 10_001 and not h.of(rec.Taken)

class RecordingDrive:
    """A driver that records what reaches the hardware."""

    READINGS = frozenset({"odometry"})
    SETPOINTS = ("set_velocity",)

    def __init__(self) -> None:
        self.calls: list[tuple[float, float, int | None]] = []

    def set_velocity(self, v: float, omega: float, epoch: int | None = None) -> None:
        self.calls.append((v, omega, epoch))

    def odometry(self) -> tuple[float, float, float]:
        return (0.0, 0.0, 0.0)


def _commands(v: float) -> type:
    class Commands(Forever):
        def step(self, now: float) -> Any:
            self.device("drive").set_velocity(v, 0.0)
            self.device("drive").odometry()  # a query goes straight through
            return super().step(now)
    return Commands


@pytest.mark.parametrize(("layers", "winner"), [
    ("FollowCorridor; AvoidObstacles", 2.0),  # equal priorities: the one declared last wins
    ("AvoidObstacles; FollowCorridor", 1.0),
    ("FollowCorridor priority 1; AvoidObstacles priority 2", 1.0),  # a higher priority beats the later layer
])
def test_commands_to_one_actuator_are_multiplexed(catalog: Catalog, layers: str, winner: float) -> None:
    from types import SimpleNamespace

    from drd.rcm import ResourceManager
    from drd.runtime.clock import SimClock
    from drd.runtime.interpreter import Interpreter
    from drd.runtime.pool import ResourcePool

    drive = RecordingDrive()
    drivers = SimpleNamespace(devices={"ranger1.drive": drive}, robots={"ranger1": {"drive": drive}})
    clock, rcm = SimClock(), ResourceManager()
    pool = ResourcePool(rcm)
    pool.add(ranger_world(1, 0), 0.0)
    chart = compiled(f"mission M {{\n needs ranger: Ranger\n parallel {{ {layers} }}\n}}", catalog)
    interp = Interpreter(chart, {"FollowCorridor": _commands(1.0), "AvoidObstacles": _commands(2.0)}, rcm, clock,
                         pool=pool, services={"drivers": drivers})
    interp.start()
    for _ in range(3):
        clock.advance(0.1)
        interp.step()
    assert [v for v, _, _ in drive.calls] == [winner] * 3  # one command per cycle reached the drive
    assert {e for _, _, e in drive.calls} == {1}  # fenced with the grant's epoch


def test_a_component_updates_the_static_dependency_database(catalog: Catalog) -> None:
    class Launches(Timed):
        def start(self) -> None:
            super().start()
            self.update_dependency("ranger1.scout1", "carrier", "")  # the Scout left the magazine

    text = """
mission M {
    needs r: Ranger
    var aboard: int = 0
    start -> LaunchScout
    LaunchScout -> done / set aboard = count(Scout where scout.carrier == r)
}"""
    h = Harness(compiled(text, catalog), {"LaunchScout": Launches}, ranger_world(1, 3))
    assert h.run() == "success"
    assert h.interp.root is not None and h.interp.root.scope["aboard"] == 2


class Counted(Timed):
    """Counts its lifecycle calls in a list shared by the test."""

    calls: list[str] = []

    def start(self) -> None:
        super().start()
        Counted.calls.append("start")

    def terminate(self, status: Any) -> None:
        Counted.calls.append("terminate")

    def shutdown(self) -> None:
        Counted.calls.append("shutdown")


def test_shutdown_ends_an_instance_once_after_its_last_entry(catalog: Catalog) -> None:
    """Issue #14: a state entered twice reuses its component (`terminate` ends each entry); when the mission ends,
    `shutdown` is called once, last."""
    text = """
mission M {
    needs ranger: Ranger
    var laps: int = 0
    start -> Calibrate
    Calibrate -> Calibrate [laps < 1] / set laps = laps + 1
    Calibrate -> done [laps >= 1]
}"""
    Counted.calls = []
    h = Harness(compiled(text, catalog), {"Calibrate": Counted}, ranger_world())
    assert h.run() == "success"
    assert Counted.calls == ["start", "terminate", "start", "terminate", "shutdown"], Counted.calls


class DiesOnTerminate(Forever):
    """Its process is gone by the time it is told to terminate: the remote stand-in says so, in words."""

    def terminate(self, status: Status) -> None:
        from drd.cluster.remote import ComponentError

        raise ComponentError("component process of M/Calibrate did not answer within 0.8 s (killed)")


def test_a_reason_already_said_is_logged_as_it_is_not_as_a_component_exception(catalog: Catalog) -> None:
    """Wedge audit D6: a worker killed after 0.8 s was logged again as `component raised ComponentError: ... (at
    drd/cluster/remote.py:683, in _call)`: the component raised nothing, and the line was drd's."""
    text = "mission M {\n needs r: Ranger\n start -> Calibrate\n Calibrate -> done after 1s\n}"
    h = Harness(compiled(text, catalog), {"Calibrate": DiesOnTerminate}, ranger_world())
    h.run(until=5)
    logs = [r.text for r in h.of(rec.Log) if r.path == "M/Calibrate"]
    assert logs == ["component process of M/Calibrate did not answer within 0.8 s (killed)"], logs


def test_a_zero_time_ring_through_many_states_is_a_livelock_after_a_thousand_transitions(catalog: Catalog) -> None:
    """Reverify audit 7, D-a: a ring of 100 states took each transition 99 times (under MAX_REPEATS), 9,900 remote
    starts and stops that held a cluster's controller for 16 s. MAX_BEHAVIOR_TURNS transitions between the states
    of one behavior in one instant are a loop."""
    from drd.runtime.interpreter import MAX_BEHAVIOR_TURNS

    names = [f"S{i}" for i in range(100)]
    body = "\n".join(f" Calibrate as {n}" for n in names)
    ring = "\n".join(f" {a} -> {b} after 0s" for a, b in zip(names, names[1:] + names[:1], strict=True))
    text = f"mission M {{\n needs r: Ranger\n start -> S0\n{body}\n{ring}\n}}"
    h = Harness(compiled(text, catalog), {"Calibrate": Forever}, ranger_world())
    assert h.run(until=5) == "failure"
    assert h.interp.reason.startswith(f"livelock: {MAX_BEHAVIOR_TURNS:,} transitions between the states of M without"
                                      " time passing"), h.interp.reason
    assert len(h.of(rec.Taken)) == MAX_BEHAVIOR_TURNS and {r.at for r in h.of(rec.Taken)} == {0.0}


def test_count_where_passes_over_a_resource_without_the_property(catalog: Catalog) -> None:
    """New-user audit 8, D1: a Scout on the floor has no `carrier`, and `count(Scout where scout.carrier == r)` failed
    the whole mission (`scout3 has no carrier`) where `needs s: Scout where s.carrier == r` passed over it."""
    from drd.rcm import Aggregate

    floor = [Unit("floor.wheels", "Drive", host="ranger1"),
             Aggregate("floor", "Scout", {"wheels": "floor.wheels"}, {"battery": 1.0}, host="ranger1")]
    h = Harness(compiled(ABOARD, catalog), {"Calibrate": Timed}, [*ranger_world(1, 2), *floor])
    assert h.run() == "success", h.interp.reason
    assert h.interp.root is not None and h.interp.root.scope["aboard"] == 2
