"""Only the holder drives: the ownership bugs of issue #11, each checked from outside (the trace and the robot).

Every mission here runs in the real dry-run (executive, manager, gates, `sim` drivers, pymunk) with test
components. What is asserted is what a user or a robot sees: the `command` records of the trace (checked with
`drd.tracecheck`, the invariant of `docs/trace.md`), and the velocity the simulated robot was commanded.
"""

from __future__ import annotations

import io
import json
from collections.abc import Callable
from typing import Any

import pytest

from drd.dryrun import DryRun, Mission, run_many
from drd.executive import EntryPoints
from drd.hosts import load_hosts
from drd.runtime.component import Component, Status
from drd.sim.physics import Simulation
from drd.sim.world import load_world
from drd.tracecheck import check
from dsl import compile_text
from dsl.catalog import Catalog, ComponentType, Kind, NeedSpec, ParamSpec
from tests.conftest import ROOT


class Push(Component):
    """Drives its Drive forward at `v` m/s every cycle, for `duration` seconds of running time."""

    def start(self) -> None:
        assert self.ctx is not None
        self.left = float(self.ctx.params["duration"])
        self.last = self.ctx.now()

    def step(self, now: float) -> Status:
        assert self.ctx is not None
        self.left -= now - self.last
        self.last = now
        self.device("drive").set_velocity(float(self.ctx.params["v"]), 0.0)
        return Status.SUCCESS if self.left <= 1e-9 else Status.RUNNING

    def resume(self) -> None:
        assert self.ctx is not None
        self.last = self.ctx.now()


class Idle(Component):
    """Needs a Drive and never reads it: runs until stopped (a component binds a need when it first reads it)."""

    def step(self, now: float) -> Status:
        return Status.RUNNING


IDLE = ComponentType("Idle", Kind.BEHAVIOR, "never reads its drive", entry_point="tests.test_ownership:Idle",
                     needs=(NeedSpec("drive", "Drive", ("Ranger",)),), interfaces=("Drive",))
PUSH = ComponentType("Push", Kind.BEHAVIOR, "drives forward", entry_point="tests.test_ownership:Push",
                     params=(ParamSpec("v", "float", 0.2), ParamSpec("duration", "duration", 5.0)),
                     needs=(NeedSpec("drive", "Drive", ("Ranger",)),), interfaces=("Drive",))


@pytest.fixture(scope="module")
def cat(catalog: Catalog) -> Catalog:
    return Catalog.of([*catalog.components.values(), PUSH, IDLE])


def dry(cat: Catalog, *texts: str, until: float = 60.0, priorities: tuple[int | None, ...] = (),
        sample: Callable[[Simulation], Any] | None = None, **kw: Any
        ) -> tuple[list[DryRun], list[dict[str, Any]], list[tuple[float, Any]]]:
    """Dry-run the missions together; their reports, the trace's records, and `sample(sim)` every cycle."""
    charts = []
    for i, text in enumerate(texts):
        r = compile_text(text, cat, f"m{i}.mission")
        assert r.ok and r.statechart is not None, [d.message for d in r.diagnostics]
        charts.append(Mission(r.statechart, priorities[i] if i < len(priorities) else None))
    trace = io.StringIO()
    seen: list[tuple[float, Any]] = []
    progress = (lambda sim, _ex: seen.append((round(sim.time, 3), sample(sim)))) if sample else None
    reports = run_many(charts, load_hosts(ROOT / "hosts.yaml", cat), load_world(ROOT / "worlds" / "corridor.yaml"),
                       cat, until=until, trace=trace, registry=EntryPoints(cat, {"Push": Push, "Idle": Idle}),
                       progress=progress, progress_every=0.1, **kw)
    return reports, [json.loads(line) for line in trace.getvalue().splitlines()], seen


def commands(records: list[dict[str, Any]], suffix: str) -> list[dict[str, Any]]:
    return [r for r in records if r["kind"] == "command" and r["path"].endswith(suffix)]


def assert_owned(records: list[dict[str, Any]]) -> None:
    report = check(records, sharable={"ranger1.radio"})
    assert report.ok, report.breaches[:5]
    assert report.accepted > 0, "nothing was commanded: the test proves nothing"


SUSPENDED_CHILD = """
mission Bug1 {
    parallel all { P; R; Q }
}
behavior P {
    needs cam: Camera where cam.id == "ranger1.camera" for 2s
    C
}
behavior C {
    needs drv: Drive where drv.id == "ranger1.drive" for 3s
    Push(v: 0.3, duration: 8s)
}
behavior R {
    Wait(duration: 0.5s)
    Back
    plan { Wait < Back }                       # asks for the drive at 0.5 s, once C holds it
}
behavior Back {
    needs drv: Drive where drv.id == "ranger1.drive" for 3s
    Push(v: -0.3, duration: 8s)
}
behavior Q {
    needs cam: Camera where cam.id == "ranger1.camera" for 2s
    Observe(duration: 6s)
}
"""


def test_a_resumed_parent_does_not_resume_a_child_whose_own_grant_was_revoked(cat: Catalog) -> None:
    """Bug 1: P (camera) is resumed at 4 s while its child C lost the drive to R at 3 s; C must stay suspended,
    and from 2 s (P suspended) the drive obeys nobody but its holder."""
    (report,), records, seen = dry(cat, SUSPENDED_CHILD, sample=lambda sim: sim.command("ranger1"))
    assert report.outcome == "success", report.reason
    assert_owned(records)
    c_cmds = [r["at"] for r in commands(records, "P/C/Push") if r["accepted"]]
    r_cmds = [r["at"] for r in commands(records, "R/Back/Push") if r["accepted"]]
    assert c_cmds and r_cmds
    assert not [t for t in c_cmds if 2.0 - 1e-6 < t < 6.0 - 1e-6], "C drove while suspended"
    # the robot's side: stopped as soon as C's subtree froze, pushed backwards only while R held the drive
    stopped = [cmd for t, cmd in seen if 2.05 < t < 2.95]
    assert stopped and all(cmd == (0.0, 0.0) for cmd in stopped)
    backwards = [t for t, cmd in seen if cmd[0] + cmd[1] < 0]
    assert backwards and min(backwards) >= 3.0 - 1e-6


RELEASE = """
mission Rel {
    parallel all { A; B }
}
behavior A {
    needs drv: Drive where drv.id == "ranger1.drive"
    start -> first
    Push(v: 0.3, duration: 2s) as first
    Push(v: 0.3, duration: 5s) as second
    first -> second / release(drv)
    second -> done on error
}
behavior B priority 2 {
    needs drv: Drive where drv.id == "ranger1.drive"
    Push(v: -0.3, duration: 3s)
}
"""


def test_release_unbinds_the_need_at_once(cat: Catalog) -> None:
    """Bug 2: after `release(drv)` nothing below A commands the drive; B gets it, and `second`, which needs the
    released drive, fails saying so instead of driving with the old epoch."""
    (report,), records, _ = dry(cat, RELEASE)
    assert_owned(records)
    assert not commands(records, "A/second"), "second commanded the released drive"
    assert [r for r in commands(records, "B/Push") if r["accepted"]], "B never got the drive"
    released = [r for r in records if r["kind"] == "released" and r["path"] == "Rel/A"]
    assert released and released[0]["reason"] == "release" and "ranger1.drive" in released[0]["resources"]
    failure = [r for r in records if r["kind"] == "exited" and r["path"] == "Rel/A/second"]
    assert failure and failure[0]["status"] == "failure"
    taken = [r for r in records if r["kind"] == "taken" and r["path"] == "Rel/A/second"]
    assert taken and taken[0]["trigger"] == "error"
    assert report.outcome == "success", report.reason


RELEASED_BEFORE = """
mission Unused {
    needs drv: Drive where drv.id == "ranger1.drive"
    start -> first
    Push(v: 0.3, duration: 1s) as first
    first -> later / release(drv)
    Idle as later
}
"""


def test_a_leaf_entered_after_its_need_was_released_fails_at_entry_naming_the_release(cat: Catalog) -> None:
    """Semantics audit 2, 3: `later` never reads its drive, so it ran (until --until) with a need nothing could
    bind; one that read it failed later, with `component raised BindingError (at drd/runtime/...)`."""
    (report,), records, _ = dry(cat, RELEASED_BEFORE, until=10.0)
    why = "need drive (Drive) is bound to drv of Unused, but Unused released it"
    assert (report.outcome, report.reason) == ("failure", why)
    [exited] = [r for r in records if r["kind"] == "exited" and r["path"] == "Unused/later"]
    assert exited["status"] == "failure" and exited["at"] == pytest.approx(1.0, abs=0.11), exited
    assert not [r for r in records if r["kind"] == "log" and "component raised" in r.get("text", "")]


RELEASED_BESIDE = """
mission Beside {
    needs drv: Drive where drv.id == "ranger1.drive"
    parallel all {
        Push(v: 0.3, duration: 100s) as cruise
        Wait(duration: 1s) as tick
    }
    tick -> tick / release(drv)
}
"""


def test_a_running_leaf_whose_need_is_released_beside_it_fails_naming_the_release(cat: Catalog) -> None:
    """Semantics audit 4: `cruise` went on being stepped for the rest of the run, every command refused, `running`
    in the report; it fails when the release takes its drive, and the robot stops then."""
    (report,), records, seen = dry(cat, RELEASED_BESIDE, until=10.0, sample=lambda sim: sim.command("ranger1"))
    assert_owned(records)
    why = "need drive (Drive) is bound to drv of Beside, but Beside released it"
    [exited] = [r for r in records if r["kind"] == "exited" and r["path"] == "Beside/cruise"]
    assert (exited["status"], exited["reason"]) == ("failure", why), exited
    assert exited["at"] == pytest.approx(1.0, abs=0.11), exited
    assert report.outcome == "failure" and report.sim_time < 2.0, (report.outcome, report.reason, report.sim_time)
    assert not [r for r in commands(records, "Beside/cruise") if r["at"] > exited["at"]], "stepped after failing"
    halted = [r for r in records if r["kind"] == "halted" and r.get("device") == "ranger1.drive"]
    assert halted and halted[0]["at"] <= exited["at"] + 1e-9, halted
    assert seen and seen[-1][1] == (0.0, 0.0), seen[-3:]


SHORT = "mission Short {\n    Wait(duration: 2s)\n}\n"
LONG = "mission Long {\n    Wait(duration: 5s)\n}\n"


def test_each_report_of_a_run_of_several_missions_gives_that_missions_own_time(cat: Catalog) -> None:
    """Semantics audit 1: every report said the whole run's sim time (Short: 5.0 s, its real-time factor from it);
    a cluster run reports a mission's own time."""
    short, long = dry(cat, SHORT, LONG)[0]
    assert (short.outcome, long.outcome) == ("success", "success")
    assert short.sim_time == pytest.approx(2.0, abs=0.11) and long.sim_time == pytest.approx(5.0, abs=0.11)
    assert short.sim_time < long.sim_time and short.wall_time <= long.wall_time
    assert short.to_dict()["sim_time"] == pytest.approx(2.0, abs=0.11)


STOPPING = """
mission Stopping {
    parallel all { A; B }
}
behavior A {
    needs drv: Drive where drv.id == "ranger1.drive" for 60s
    Push(v: 0.3, duration: 100s)
}
behavior B {
    needs drv: Drive where drv.id == "ranger1.drive"
    Push(v: -0.3, duration: 100s)
}
"""


def test_a_stopping_mission_grants_nothing_to_its_waiters(cat: Catalog) -> None:
    """Bug 3: when the mission stops (its time limit), A's drive is released while B waits for it; B must not
    be granted, started, or moved."""
    (report,), records, _ = dry(cat, STOPPING, until=3.0)
    assert report.outcome == "stopped"
    assert_owned(records)
    b = [r for r in records if r["path"].startswith("Stopping/B")]
    assert [r["kind"] for r in b if r["kind"] in ("granted", "resumed", "entered")] == ["entered"]  # B itself only
    assert not commands(records, "B/Push")


REDECLARED = """
mission Chain {
    needs ranger: Ranger
    Inner
}
behavior Inner {
    needs ranger: Ranger WHERE
    Observe(duration: 2s)
}
"""


def test_a_need_redeclared_by_a_child_binds_to_the_ancestors_grant(cat: Catalog) -> None:
    """Bug 4: `Inner` re-declares `ranger`; Observe's camera is the ancestor's Ranger's camera."""
    (report,), records, _ = dry(cat, REDECLARED.replace(" WHERE", ""))
    assert report.outcome == "success", report.reason
    granted = [r for r in records if r["kind"] == "granted"]
    assert [(r["path"], r["resources"]["ranger"]) for r in granted] == [("Chain", "ranger1")]


def test_a_redeclared_need_whose_where_the_ancestors_grant_fails_is_a_clear_failure(cat: Catalog) -> None:
    (report,), _, _ = dry(cat, REDECLARED.replace("WHERE", 'where ranger.id == "ranger9"'))
    assert report.outcome == "failure"
    assert "ranger" in report.reason and "where" in report.reason and "ranger1" in report.reason


def test_an_orphaned_gate_stops_its_device_and_refuses_everyone_until_granted_again() -> None:
    """What a host does when its controller is lost (`LocalGates.orphan_all`), seen on the driver and the records."""
    from drd.hw.interfaces import Fence
    from drd.runtime import records as rec
    from drd.runtime.ownership import LocalGates, NotHolder

    class Wheels:
        SETPOINTS = ("set_velocity", "stop")
        STOP = "stop"

        def __init__(self) -> None:
            self.fence = Fence("wheels")
            self.v = 0.0

        def set_velocity(self, v: float, epoch: int | None = None) -> None:
            self.v = v

        def stop(self, epoch: int | None = None) -> None:
            self.v = 0.0

    records: list[tuple[str, rec.Record]] = []
    wheels = Wheels()
    gates = LocalGates.of({"r1.drive": wheels}, sink=lambda mission, record: records.append((mission, record)))
    gates.grant("r1.drive", "M-1/M/Go", 3, 0.0)
    gate = gates.get("r1.drive")
    assert gate is not None
    gate.execute(wheels, "M-1/M/Go/Drive", 3, "set_velocity", (0.5,), {}, 1.0)
    assert wheels.v == 0.5
    gates.orphan_all(2.0, "controller lost")
    assert wheels.v == 0.0
    assert any(isinstance(r, rec.Halted) and r.reason == "controller lost" for _, r in records)
    with pytest.raises(NotHolder, match="nobody holds the device"):
        gate.execute(wheels, "M-1/M/Go/Drive", 3, "set_velocity", (0.5,), {}, 3.0)
    assert wheels.v == 0.0
    gates.grant("r1.drive", "M-1/M/Go", 4, 4.0)  # a controller grants it again
    gate.execute(wheels, "M-1/M/Go/Drive", 4, "set_velocity", (0.2,), {}, 5.0)
    assert wheels.v == 0.2
