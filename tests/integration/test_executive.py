"""The embedded executor over the local bus: records published, operator commands served."""

from __future__ import annotations

import pytest

from drd.bus import Bus, LocalNetwork, RemoteError
from drd.executive import EntryPoints, Executive, MissionCommand, MissionRecord, MissionStatus
from drd.hosts import load_hosts
from drd.rcm import Unit
from drd.runtime.clock import SimClock
from dsl import compile_file, compile_text
from dsl.catalog import Catalog
from tests.conftest import ROOT, shared_examples
from tests.runtime_support import Forever, Timed


def test_shared_camera_over_the_local_bus(catalog: Catalog) -> None:
    net = LocalNetwork()
    controller, operator = net.session("controller"), net.session("operator")
    seen: list[MissionRecord] = []
    operator.subscribe("drd/local/mission/*/record", lambda s: seen.append(s.payload))  # type: ignore[arg-type]
    clock = SimClock()
    ex = Executive(controller, clock, {"Observe": Timed}, resources=[Unit("ranger1.camera", "Camera")])
    chart = compile_file(shared_examples() / "shared_camera.mission", catalog).statechart
    assert chart is not None
    mid = ex.submit(chart)
    ex.run(lambda: clock.advance(0.5), until=120)
    assert ex.missions[mid].outcome == "success"
    grants = [r.path.rsplit("/", 1)[-1] for r in seen if r.kind == "granted"]
    assert grants[:4] == ["first", "second", "first", "second"] and grants[-1] == "third"
    assert seen[-1].kind == "finished" and seen[-1].data["outcome"] == "success"
    status = operator.call("drd/local/executive", MissionCommand("status"))
    assert isinstance(status, MissionStatus) and status.missions[0]["outcome"] == "success"


def two_waiting_missions(catalog: Catalog) -> tuple[Executive, Bus, str, str]:
    """An executive on a local bus, an operator's session, and two missions waiting for a `MotionDetected` of
    `area` > 0.5, a second into their run."""
    net = LocalNetwork()
    controller, operator = net.session("controller"), net.session("operator")
    clock = SimClock()
    ex = Executive(controller, clock, {"Calibrate": Forever}, resources=[Unit("r.ranges", "RangeSensor")])
    text = "mission M {\n start -> Calibrate\n Calibrate -> done on MotionDetected [event.area > 0.5]\n}"
    chart = compile_text(text, catalog, "m.mission").statechart
    assert chart is not None
    first, second = ex.submit(chart), ex.submit(chart)
    clock.advance(1.0)
    ex.step()
    return ex, operator, first, second


def test_operator_stops_and_emits_over_the_bus(catalog: Catalog) -> None:
    ex, operator, first, second = two_waiting_missions(catalog)
    operator.call("drd/local/executive", MissionCommand("emit", first, "MotionDetected", {"area": 0.9}))
    assert ex.missions[first].outcome == "success" and ex.missions[second].outcome is None
    reply = operator.call("drd/local/executive", MissionCommand("stop", second))
    assert isinstance(reply, MissionStatus)
    assert {m["id"]: m["outcome"] for m in reply.missions} == {second: "stopped"}  # the one it stopped (a page)
    status = operator.call("drd/local/executive", MissionCommand("status"))
    assert isinstance(status, MissionStatus) and status.next == 0
    assert {m["id"]: m["outcome"] for m in status.missions} == {first: "success", second: "stopped"}
    with pytest.raises(RemoteError, match="no mission nope"):
        operator.call("drd/local/executive", MissionCommand("stop", "nope"))


def test_resources_come_from_hosts_yaml(catalog: Catalog) -> None:
    cluster = load_hosts(ROOT / "hosts.yaml", catalog)
    net = LocalNetwork()
    clock = SimClock()
    ex = Executive(net.session(), clock, {}, resources=cluster.resources())
    assert ex.pool.count("Scout", None) == 6
    assert ex.pool.count("Scout", lambda s: s["carrier"] == "ranger1") == 6  # type: ignore[index]


def test_missing_implementation_fails_the_state_clearly(catalog: Catalog) -> None:
    net = LocalNetwork()
    clock = SimClock()
    import dataclasses

    broken = Catalog({**catalog.components, "Calibrate": dataclasses.replace(
        catalog.components["Calibrate"], entry_point="components.nowhere:Calibrate")})
    ex = Executive(net.session(), clock, EntryPoints(broken), resources=[Unit("r.ranges", "RangeSensor")])
    chart = compile_text("mission M { Calibrate }", catalog, "m.mission").statechart
    assert chart is not None
    mid = ex.submit(chart)
    ex.run(lambda: clock.advance(0.5), until=5)
    assert ex.missions[mid].outcome == "failure"
    assert "no implementation of component Calibrate" in ex.missions[mid].reason


def test_the_executive_keeps_a_bounded_history_of_finished_missions() -> None:
    """Issue #16: 3,800 finished missions once made a status reply outgrow the transport; the oldest finished go,
    a running one never does."""
    from drd.manifests import load_catalog

    cat = load_catalog()
    clock = SimClock()
    ex = Executive(LocalNetwork().session("c"), clock, EntryPoints(cat), history=3)
    quick = compile_text("mission Quick {\n    Wait(duration: 1s)\n}\n", cat, "q.mission").statechart
    slow = compile_text("mission Slow {\n    Wait(duration: 1h)\n}\n", cat, "s.mission").statechart
    assert quick is not None and slow is not None
    ex.submit(slow, "Slow-1")
    for n in range(1, 8):
        ex.submit(quick, f"Quick-{n}")
        for _ in range(15):
            clock.advance(0.1)
            ex.step()
    assert ex.missions["Quick-7"].finished
    assert list(ex.missions) == ["Slow-1", "Quick-5", "Quick-6", "Quick-7"]  # 3 finished kept, the running one too


def test_an_operators_event_may_have_any_field_name_and_one_it_cannot_record_is_refused_whole(
        catalog: Catalog) -> None:
    """Wire audit 25, D4: a field called `name` or `source` was a TypeError sent back to the client with a
    traceback in the log, and a field of 2**70 (which the decoder takes, the encoder refuses) was kept among the
    mission's records, so every later `records` query of that mission failed."""
    from drd.bus import encode

    ex, operator, first, second = two_waiting_missions(catalog)
    fields = {"area": 0.9, "name": "x", "source": "me"}
    operator.call("drd/local/executive", MissionCommand("emit", first, "MotionDetected", fields))
    assert ex.missions[first].outcome == "success", ex.missions[first].reason
    raw = encode(MissionCommand("emit", second, "MotionDetected", {"area": 1})).replace(b'"area":1',
                                                                                      b'"area":%d' % 2**70)
    [reply] = operator.request_raw("drd/local/executive", raw)
    assert reply.error is not None and "its fields cannot be recorded" in reply.error, reply
    records = operator.call("drd/local/executive", MissionCommand("records", second))
    assert not [r for r in records.records if r.kind == "event"]  # type: ignore[attr-defined]  # nobody heard it
    assert ex.missions[second].outcome is None
