"""A component's emits are checked against its manifest at run time (component audit D6): an undeclared event,
a field missing, unknown or of the wrong type fails the emitting state with a reason naming the component, the
event and the field, instead of a guard that silently misfires. The check (`drd.runtime.emits`) sits in the
component host, which the dry-run and the cluster's replayed replies both go through."""

from __future__ import annotations

from typing import Any

import pytest

from drd.bus import LocalNetwork
from drd.executive import EntryPoints, Executive
from drd.rcm import Unit
from drd.runtime.clock import SimClock
from drd.runtime.component import Component, Status
from drd.runtime.emits import EmitError, check_emit
from dsl import compile_text
from dsl.catalog import Catalog, ComponentType, Kind, RecordSpec

FIB = RecordSpec("Fib", {"size": "float", "n": "int"})
LIAR = ComponentType("Liar", Kind.BEHAVIOR, "emits what its params say", entry_point="x:Liar", events=(FIB,))


MISSION = """\
mission M {
    var got: float = 0.0
    start -> l
    Liar as l
    l -> done on Fib [event.size > 1.0] / set got = event.size
}
"""


def run(emit: tuple[str, dict[str, Any]]) -> tuple[str | None, str]:
    cat = Catalog.of([LIAR])
    chart = compile_text(MISSION, cat, "m.mission").statechart
    assert chart is not None
    clock = SimClock()
    ex = Executive(LocalNetwork().session("c"), clock, EntryPoints(cat, {"Liar": lambda: _With(emit)}),
                   resources=[Unit("r.ranges", "RangeSensor")])
    mid = ex.submit(chart)
    ex.run(lambda: clock.advance(0.5), until=10)
    return ex.missions[mid].outcome, ex.missions[mid].reason


class _With(Component):
    """Liar: emits what it is told, then succeeds."""

    def __init__(self, emit: tuple[str, dict[str, Any]]) -> None:
        self.emit = emit

    def step(self, now: float) -> Status:
        name, fields = self.emit
        self.ctx.emit(name, **fields)
        return Status.SUCCESS


@pytest.mark.parametrize(("emit", "says"), [
    (("Fib", {"size": "huge", "n": 1}), "Liar emits Fib with size='huge' (str) where its manifest declares size"),
    (("Fib", {"size": 2.0, "n": 1, "extra": 1}), "Liar emits Fib with field extra, which its manifest does not"),
    (("Fib", {"size": 2.0}), "Liar emits Fib without field n"),
    (("Fib", {"size": 2.0, "n": True}), "Liar emits Fib with n=True (bool) where its manifest declares n: int"),
    (("NeverDeclared", {}), "Liar emits NeverDeclared, which its manifest does not declare (its events: Fib)"),
])
def test_an_emit_its_manifest_does_not_allow_fails_the_state_naming_it(emit: tuple[str, dict[str, Any]],
                                                                      says: str) -> None:
    outcome, reason = run(emit)
    assert outcome == "failure" and "EmitError" in reason and says in reason, reason


def test_a_declared_emit_goes_through_and_its_guard_reads_it() -> None:
    assert run(("Fib", {"size": 2, "n": 3})) == ("success", "")  # an int is a float


def test_the_check_is_pure_and_reads_only_the_declaration() -> None:
    check_emit("Liar", (FIB,), "Fib", {"size": 1.5, "n": 0})
    with pytest.raises(EmitError, match="declares size: float"):
        check_emit("Liar", (FIB,), "Fib", {"size": float("nan"), "n": 0})
    check_emit("Door", (RecordSpec("Seen", {"door": "Door"}),), "Seen", {"door": {"x": 1}})  # not a scalar: present


def test_numpy_scalars_are_emitted_as_the_python_values_they_hold() -> None:
    """What computing on a sensor's arrays gives (re-verification audit N2: np.float32 was refused as not a float,
    and on a cluster, sent as its string, refused as a str)."""
    import numpy as np

    from drd.runtime.records import plain

    sizes = np.array([1.5, 2.5], dtype=np.float32)
    fields = check_emit("Liar", (FIB,), "Fib", {"size": sizes.max(), "n": np.int64(3)})
    assert fields == {"size": 2.5, "n": 3} and type(fields["size"]) is float and type(fields["n"]) is int
    flag = check_emit("Flag", (RecordSpec("Up", {"on": "bool"}),), "Up", {"on": np.bool_(True)})
    assert flag == {"on": True} and type(flag["on"]) is bool
    assert plain({"size": np.float32(2.5), "n": np.int64(3)}) == {"size": 2.5, "n": 3}  # what a worker sends
    assert run(("Fib", {"size": np.float64(2.0), "n": np.int32(3)})) == ("success", "")
