"""A `restored` record's times (records audit 18, #5): `since` is rounded to the microsecond as `at` is (it read
50.00000000000044), and a dry-run's `paused` is the sim seconds of the outage it models, kill to restart
(docs/trace.md: wall time on a cluster, whose world waits for its controller; sim time in a dry-run)."""

from __future__ import annotations

from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import ROOT
from tests.runtime_support import traced_dry_run


def test_a_restores_since_and_paused_are_rounded_sim_seconds_in_a_dry_run(catalog: Catalog) -> None:
    chart = compile_file(ROOT / "missions" / "corridor_surveillance.mission", catalog).statechart
    assert chart is not None
    records = traced_dry_run(chart, catalog, ["kill controller at 50s", "restart controller at 58s"], 120.0)
    [restored] = [r for r in records if r["kind"] == "restored"]
    assert (restored["at"], restored["since"], restored["paused"]) == (58.0, 50.0, 8.0), restored
