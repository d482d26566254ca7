"""A `RemoteSimulation` whose simulator does not answer the flush of its queued commands (faults audit 23, #2: the
simulator's host frozen during a migrate): each command's owner is told, and nothing is raised to the handler that
flushed, which logged a traceback and made the controller blame that host's gates."""

from __future__ import annotations

from drd.bus.base import BusTimeout
from drd.sim.service import RemoteSimulation, SimReply, SimRequest
from tests.conftest import ROOT


def test_an_unanswered_flush_fails_each_queued_command_with_its_owner() -> None:
    asked: list[SimRequest] = []

    def silent(req: SimRequest) -> SimReply:
        asked.append(req)
        raise BusTimeout("no reply on 'drd/t/sim' within 1 s")

    sim = RemoteSimulation(silent, "corridor", root=ROOT)
    for owner in ("M/Drive", "M/Turn"):
        sim.owner = owner
        sim.set_velocity("ranger1", 0.5, 0.0)  # queued, as the Creator's drivers do
    refused = sim.flush()
    assert [r.op for r in asked] == ["multi"]
    why = "the simulator did not take the command: BusTimeout: no reply on 'drd/t/sim' within 1 s"
    assert refused == [("M/Drive", why), ("M/Turn", why)]
    assert sim.flush() == []  # nothing left queued

