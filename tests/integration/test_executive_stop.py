"""`stop` at the executive: an unknown id is answered with the missions still running, and a mission that had
already ended is not reported stopped (the audit's `missionctl stop` of a finished mission said it stopped it)."""

from __future__ import annotations

import pytest

from drd.bus import LocalNetwork, RemoteError
from drd.executive import EntryPoints, Executive, MissionCommand, MissionStatus
from drd.manifests import load_catalog
from drd.runtime.clock import SimClock
from dsl import compile_text


def test_stop_names_only_running_missions_and_does_not_stop_an_ended_one() -> None:
    cat = load_catalog()
    clock = SimClock()
    net = LocalNetwork()
    ex = Executive(net.session("c"), clock, EntryPoints(cat))
    operator = net.session("operator")
    quick = compile_text("mission Quick {\n    Wait(duration: 1s)\n}\n", cat, "q.mission").statechart
    slow = compile_text("mission Slow {\n    Wait(duration: 1h)\n}\n", cat, "s.mission").statechart
    assert quick is not None and slow is not None
    ex.submit(quick, "Quick-1")
    ex.submit(slow, "Slow-1")
    for _ in range(20):
        clock.advance(0.1)
        ex.step()
    assert ex.missions["Quick-1"].outcome == "success" and ex.missions["Slow-1"].outcome is None

    with pytest.raises(RemoteError) as e:
        operator.call("drd/local/executive", MissionCommand("stop", "NoSuch-1"))
    assert "no mission NoSuch-1; running: Slow-1; 1 ended mission known" in str(e.value)
    assert "Quick-1" not in str(e.value), "an ended mission is not listed as running"

    ended = operator.call("drd/local/executive", MissionCommand("stop", "Quick-1"))
    assert isinstance(ended, MissionStatus)
    [quick_status] = ended.missions
    assert quick_status["already_ended"] is True and quick_status["outcome"] == "success"

    stopped = operator.call("drd/local/executive", MissionCommand("stop", "Slow-1"))
    assert isinstance(stopped, MissionStatus)
    [slow_status] = stopped.missions
    assert "already_ended" not in slow_status and slow_status["outcome"] == "stopped"
    again = operator.call("drd/local/executive", MissionCommand("stop", "Slow-1"))
    assert isinstance(again, MissionStatus) and again.missions[0]["already_ended"] is True

    with pytest.raises(RemoteError, match=r"running: none; 2 ended missions known"):
        operator.call("drd/local/executive", MissionCommand("stop", "NoSuch-1"))
