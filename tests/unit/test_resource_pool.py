"""The Resource Pool's multiplicities and timing (issue #11, bugs 5 and 7), on the interpreter with a simulated
clock stepped in floating-point 0.1 s cycles, as the dry-run steps it."""

from __future__ import annotations

from drd.rcm import Aggregate, Unit
from drd.runtime import records as rec
from dsl import compile_text
from dsl.catalog import Catalog
from dsl.statechart import Statechart
from tests.runtime_support import Fails, Forever, Harness, Timed, ranger_world


def compiled(text: str, catalog: Catalog) -> Statechart:
    r = compile_text(text, catalog, "t.mission")
    assert r.ok and r.statechart is not None, [d.message for d in r.diagnostics]
    return r.statechart


def scouts(n: int, battery: float = 1.0, host: str = "ranger1", first: int = 1) -> list[object]:
    out: list[object] = []
    for i in range(first, first + n):
        sid = f"s{i}"
        parts = {}
        for part, typ in (("wheels", "Drive"), ("foot", "Jump"), ("camera", "Camera")):
            out.append(Unit(f"{sid}.{part}", typ, host=host))
            parts[part] = f"{sid}.{part}"
        out.append(Aggregate(sid, "Scout", parts, {"carrier": "", "battery": battery}, host=host))
    return out


OPEN = """
mission M {
    Lookout[1..*]
}
behavior Lookout {
    needs scout: Scout where scout.battery > 0.5
    Watch(duration: 3s)
}
"""


def test_an_open_multiplicity_counts_only_the_resources_its_where_accepts(catalog: Catalog) -> None:
    h = Harness(compiled(OPEN, catalog), {"Watch": Timed}, [*scouts(1), *scouts(5, battery=0.2, first=2)])
    h.interp.start()
    instances = {r.path for r in h.of(rec.Entered) if r.path.startswith("M/Lookout[") and r.path.count("/") == 1}
    assert instances == {"M/Lookout[0]"}  # one eligible Scout, not one per Scout known
    assert h.run() == "success"


def test_an_open_multiplicity_grows_when_a_host_joins(catalog: Catalog) -> None:
    chart = compiled(OPEN.replace("3s", "30s"), catalog)
    h = Harness(chart, {"Watch": Timed}, scouts(1))
    h.interp.start()
    h.clock.advance(1.0)
    h.interp.step()
    h.interp.add_resources(scouts(2, first=2, host="ranger2"))
    grown = sorted({r.path for r in h.of(rec.Entered) if r.path.count("/") == 1 and "[" in r.path})
    assert grown == ["M/Lookout[0]", "M/Lookout[1]", "M/Lookout[2]"]
    assert h.run() == "success"


def test_a_failing_multiplicity_counts_what_can_still_succeed(catalog: Catalog) -> None:
    class FailsFast(Timed):
        def step(self, now: float) -> object:
            assert self.ctx is not None
            if "[0]" in self.ctx.path or "[1]" in self.ctx.path:
                from drd.runtime.component import Status
                return Status.FAILURE
            return super().step(now)

    text = "mission M {\n Lookout[3..3]\n}\nbehavior Lookout {\n needs scout: Scout\n Watch(duration: 50s)\n}"
    h = Harness(compiled(text, catalog), {"Watch": FailsFast}, scouts(3))
    assert h.run(dt=0.1) == "failure"
    reason = h.interp.reason
    # the first failure leaves fewer than the 3 it needs; the reason counts as of the multiplicity's own exit, after
    # the second instance that failed at the same instant (semantics audit 5: the trace shows both exits first)
    assert "only 1 of at least 3 instances of Lookout can succeed (0 succeeded, 1 running, 2 failed" in reason
    exits = [r.path for r in h.of(rec.Exited)]
    assert exits.index("M/Lookout[1]") < exits.index("M/Lookout"), exits


def test_a_multiplicity_short_of_instances_counts_the_one_that_succeeded_at_the_same_instant(
        catalog: Catalog) -> None:
    class OneFails(Timed):
        def step(self, now: float) -> object:
            from drd.runtime.component import Status

            assert self.ctx is not None
            return Status.FAILURE if "[0]" in self.ctx.path else Status.SUCCESS

    text = "mission M {\n Lookout[2..2]\n}\nbehavior Lookout {\n needs scout: Scout\n Watch(duration: 50s)\n}"
    h = Harness(compiled(text, catalog), {"Watch": OneFails}, scouts(2))
    assert h.run(dt=0.1) == "failure"
    assert h.interp.reason.startswith(
        "only 1 of at least 2 instances of Lookout can succeed (1 succeeded, 0 running, 1 failed"), h.interp.reason


def test_a_timeout_fires_in_the_cycle_it_falls_due(catalog: Catalog) -> None:
    text = "mission M {\n needs r: Ranger\n start -> Calibrate\n Calibrate -> done after 2s\n}"
    h = Harness(compiled(text, catalog), {"Calibrate": Forever}, ranger_world())
    assert h.run(dt=0.1) == "success"
    (taken,) = h.of(rec.Taken)
    assert abs(taken.at - 2.0) < 1e-6, taken.at  # not at 2.1: twenty 0.1 s cycles add up to 1.9999999999999996


def test_slices_last_their_length_in_floating_point_cycles(catalog: Catalog) -> None:
    text = """
mission M {
    parallel all { A; B }
}
behavior A { needs cam: Camera for 5s; Observe(duration: 12s) }
behavior B { needs cam: Camera for 5s; Observe(duration: 12s) }
"""
    h = Harness(compiled(text, catalog), {"Observe": Timed}, [Unit("ranger1.camera", "Camera")])
    assert h.run(dt=0.1) == "success"
    grants = [r.at for r in h.of(rec.Granted)]
    assert [round(b - a, 6) for a, b in zip(grants[:3], grants[1:4], strict=True)] == [5.0, 5.0, 5.0]


PREALLOCATED = """
mission M {
    needs r: Ranger
    start -> Prep
    Prep -> Look preallocate
}
behavior Prep { Calibrate(samples: 3) }
behavior Look { needs cam: Camera where cam.id == "cam"
    Observe(duration: 1s) }"""


def _against_a_rival(catalog: Catalog, text: str, prep: type = Timed) -> tuple[list[rec.Record], str | None]:
    """Run `text` while another mission asks for the camera half a second in: does `Look` wait for it?"""
    from drd.rcm import ResourceManager
    from drd.runtime.clock import SimClock
    from drd.runtime.interpreter import Interpreter
    from drd.runtime.pool import ResourcePool

    clock, rcm = SimClock(), ResourceManager()
    pool = ResourcePool(rcm)
    pool.add([*ranger_world(1, 0), Unit("cam", "Camera")], 0.0)
    log: list[rec.Record] = []
    mine = Interpreter(compiled(text, catalog), {"Calibrate": prep, "Observe": Timed}, rcm, clock, pool=pool,
                       mission="mine")
    other = Interpreter(compiled("mission Other { needs c: Camera\n Observe(duration: 20s) }", catalog),
                        {"Observe": Timed}, rcm, clock, pool=pool, mission="other")
    mine.attach(log.append)
    mine.start()
    clock.advance(0.5)
    other.start()
    while not mine.finished and clock.now() < 60:
        clock.advance(0.5)
        mine.step()
        other.step()
    return log, mine.outcome


def test_preallocate_reserves_the_next_states_needs_after_a_composite_predecessor(catalog: Catalog) -> None:
    """`Prep -> Look preallocate`: Look's camera is reserved when Prep (a behavior, not a leaf) is entered and
    survives Prep's exit, so Look starts at once although another mission asked for the camera meanwhile."""
    log, outcome = _against_a_rival(catalog, PREALLOCATED)
    assert outcome == "success"
    reserved = [r for r in log if isinstance(r, rec.Reserved)]
    assert [(r.path, r.by) for r in reserved] == [("M/Look", "M/Prep")] and reserved[0].at == 0.0
    granted = next(r.at for r in log if isinstance(r, rec.Granted) and r.path == "M/Look")
    entered = next(r.at for r in log if isinstance(r, rec.Entered) and r.path == "M/Look")
    assert granted == 0.0 and entered >= 1.0  # held ahead of need, not waited for
    assert not [r for r in log if isinstance(r, rec.Waiting) and r.path == "M/Look"]


def test_without_preallocate_the_next_state_waits(catalog: Catalog) -> None:
    log, outcome = _against_a_rival(catalog, PREALLOCATED.replace(" preallocate", ""))
    assert outcome == "success"
    assert next(r.at for r in log if isinstance(r, rec.Granted) and r.path == "M/Look") >= 5.0  # the rival's slice


def test_a_sequential_plan_can_preallocate(catalog: Catalog) -> None:
    text = PREALLOCATED.replace("    start -> Prep\n    Prep -> Look preallocate\n",
                                "    plan preallocate { Prep < Look }\n")
    log, outcome = _against_a_rival(catalog, text)
    assert outcome == "success"
    assert [(r.path, r.by) for r in log if isinstance(r, rec.Reserved)] == [("M/Look", "M/Prep")]


def test_a_preallocation_not_used_is_released_and_recorded(catalog: Catalog) -> None:
    text = PREALLOCATED.replace("Prep -> Look preallocate", "Prep -> Look preallocate\n    Prep -> done on error")
    log, outcome = _against_a_rival(catalog, text, prep=Fails)
    assert outcome == "success"
    ends = [r for r in log if isinstance(r, rec.Released) and r.path == "M/Look"]
    assert [(r.reason, r.resources) for r in ends] == [("cancelled", ("cam",))]
    assert not [r for r in log if isinstance(r, rec.Entered) and r.path == "M/Look"]


def test_preallocate_is_checked(catalog: Catalog) -> None:
    def errors(text: str) -> list[str]:
        return [d.message for d in compile_text(text, catalog, "t.mission").diagnostics]

    assert any("only a completion transition preallocates" in m
               for m in errors(PREALLOCATED.replace("Look preallocate", "Look preallocate on error")))
    assert any("plan concurrent preallocate" in m
               for m in errors(PREALLOCATED.replace("    start -> Prep\n    Prep -> Look preallocate\n",
                                                    "    plan concurrent preallocate { Prep < Look }\n")))
    warned = compile_text(PREALLOCATED.replace("behavior Look { needs cam: Camera where cam.id == \"cam\"",
                                               "behavior Look {"), catalog, "t.mission").diagnostics
    assert [d.severity.value for d in warned] == ["warning"] and "nothing to preallocate" in warned[0].message
