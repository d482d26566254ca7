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
