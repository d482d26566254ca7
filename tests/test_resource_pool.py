"""The Resource Pool's multiplicities and timing (issue #11, bugs 5 and 7), on the interpreter with a simulated
clock stepped in floating-point 0.1 s cycles, as the dry-run steps it."""

from __future__ import annotations

from drd.rcm import Aggregate, Unit
from drd.runtime import records as rec
from dsl import compile_text
from dsl.catalog import Catalog
from dsl.statechart import Statechart
from tests.runtime_support import Forever, Harness, Timed, ranger_world


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
    # at the first failure, 2 of the 3 can still succeed: fewer than the 3 it needs, and the reason counts right
    assert "only 2 of at least 3 instances of Lookout can succeed (0 succeeded, 2 running, 1 failed" in reason


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
