"""A call the controller timed out because it was itself frozen (SIGSTOP, a suspended machine) fails with that true
reason, and the host it called is neither marked gone nor avoided: it did nothing wrong (bus audit defect 5, where
a controller woken from a 10 s freeze failed its mission with "host ranger1 is down")."""

from __future__ import annotations

import pytest

from drd.bus import LocalNetwork
from drd.cluster.remote import ComponentCall, ComponentRouter, ControllerFrozen, HostDown


def router(frozen: float) -> ComponentRouter:
    bus = LocalNetwork().session("controller")  # nobody serves ranger1's Creator: every call gets no answer
    return ComponentRouter(bus, "lab", {}, "controller", local={}, mission="M-1", world="corridor", timeout=0.05,
                           frozen=lambda since: frozen)


def test_a_call_timed_out_by_the_controllers_own_freeze_blames_the_freeze() -> None:
    r = router(frozen=10.4)
    with pytest.raises(ControllerFrozen, match="this controller was frozen for 10.4 s"):
        r.call("ranger1", ComponentCall("step", "M-1", "M/Watch"))
    assert not r.is_down("ranger1")  # not gone: its next call is made, and its components are not placed around it


def test_a_call_that_times_out_otherwise_marks_the_host_gone() -> None:
    r = router(frozen=0.0)
    with pytest.raises(HostDown, match="ranger1 did not answer step"):
        r.call("ranger1", ComponentCall("step", "M-1", "M/Watch"))
    assert r.is_down("ranger1")
