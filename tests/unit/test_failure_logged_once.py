"""A component whose host died fails its step and its terminate with the same words: the trace logs them once
(cluster audit 20, #6: every failed leaf had its "host ranger2 is down: ..." line twice on a cluster)."""

from __future__ import annotations

from drd.errors import ComponentFailure, host_down_reason
from drd.runtime import records as rec
from drd.runtime.component import Component, Status
from dsl import compile_text
from dsl.catalog import Catalog
from tests.runtime_support import Harness, ranger_world


class HostGone(ComponentFailure):
    said = True  # as `drd.cluster.remote.HostDown`: the reason, said as it is


class OnDeadHost(Component):
    """What a remote component of a dead host does: every call fails with the host's loss."""

    def step(self, now: float) -> Status:
        if now >= 1.0:
            raise HostGone(host_down_reason("ranger1"))
        return Status.RUNNING

    def terminate(self, status: Status) -> None:
        raise HostGone(host_down_reason("ranger1"))


class SaysOther(OnDeadHost):
    def terminate(self, status: Status) -> None:
        raise HostGone("something else on the way out")


def run(catalog: Catalog, component: type[Component]) -> list[str]:
    result = compile_text("mission M {\n    needs r: Ranger\n    Observe(duration: 5s)\n}\n", catalog, "m.mission")
    assert result.ok and result.statechart is not None
    h = Harness(result.statechart, {"Observe": component}, ranger_world(1, 0))
    assert h.run(until=3) == "failure"
    return [r.text for r in h.of(rec.Log)]


def test_the_same_words_from_step_and_terminate_are_logged_once(catalog: Catalog) -> None:
    assert run(catalog, OnDeadHost) == ["host ranger1 is down: the component cannot run there"]


def test_other_words_on_the_way_out_are_still_logged(catalog: Catalog) -> None:
    assert run(catalog, SaysOther) == ["host ranger1 is down: the component cannot run there",
                                       "something else on the way out"]
