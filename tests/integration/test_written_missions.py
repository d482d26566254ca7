"""Missions a user wrote that the examples never tried (users audit 25), run in the dry-run as `missionctl dry-run`
runs them: what they say must be what happens."""

from __future__ import annotations

import pytest

from drd.dryrun import DryRun, run
from drd.hosts import load_hosts
from drd.sim.world import load_world
from dsl import compile_text
from dsl.catalog import Catalog
from tests.conftest import ROOT


def dry_run(catalog: Catalog, text: str, until: float = 30.0) -> DryRun:
    compiled = compile_text(text, catalog, "mine.mission")
    assert compiled.ok and compiled.statechart is not None, compiled.diagnostics
    cluster, world = load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" / "corridor.yaml")
    return run(compiled.statechart, cluster, world, catalog, until=until)


def test_a_wait_of_one_second_says_it_waited_one_second(catalog: Catalog) -> None:
    """D1: the dry-run's clock adds 0.1 s a cycle, and `waited.seconds` read 0.9999999999999999: the guard failed
    the mission in a dry-run and not on a cluster."""
    report = dry_run(catalog, "mission ExactWait {\n    Wait(duration: 1s) as a\n    Wait(duration: 2s) as b\n"
                              "    start -> a\n    a -> b [a.waited.seconds >= 1.0]\n    a -> fail\n"
                              "    b -> done [b.waited.seconds == 2.0]\n    b -> fail\n}\n")
    assert report.outcome == "success", report.reason


@pytest.mark.parametrize("body", ["parallel all { }", "parallel any { }", "plan concurrent { }"])
def test_an_empty_parallel_block_is_done_at_once(catalog: Catalog, body: str) -> None:
    """D2: docs/reference.md, "a body with no child is done at once"; an empty parallel block ran until --until."""
    report = dry_run(catalog, f"behavior Nothing {{ {body} }}\nmission Seq {{\n    Nothing\n"
                              "    Wait(duration: 1s)\n    start -> Nothing\n    Nothing -> Wait\n}\n")
    assert report.outcome == "success" and report.sim_time < 2.0, (report.outcome, report.reason, report.sim_time)


def test_a_condition_that_cannot_be_read_is_logged_once_not_every_cycle(catalog: Catalog) -> None:
    """D3: a `when` reading its own source's output (published only when it exits) logged its error 10 times a
    second; it is said once, until the condition reads again."""
    report = dry_run(catalog, "mission EarlyExit {\n    Wait(duration: 10s) as a\n"
                              "    a -> done when a.waited.seconds > 5.0\n}\n", until=20.0)
    errors = [line for line in report.logs() if "condition error" in line["text"]]
    assert report.outcome == "success" and len(errors) == 1, errors[:3]
    assert errors[0]["text"] == "condition error: a has no value here"
