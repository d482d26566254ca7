"""A property typed with a robot type (`carrier: Ranger`) reads as that robot in an expression (users audit 12, D2:
`scout.carrier.id == "ranger1"` type-checked, then matched no Scout, and the mission failed "can never be
satisfied"). The repository's team (six Scouts carried by ranger1), the real executive (`drd.dryrun.run_many`)."""

from __future__ import annotations

from drd.dryrun import DryRun, Mission, run_many
from drd.hosts import load_hosts
from drd.sim.world import load_world
from dsl import compile_text
from dsl.catalog import Catalog
from tests.conftest import ROOT


def dry(catalog: Catalog, where: str) -> DryRun:
    text = f"mission Carried {{\n    needs scout: Scout where {where}\n    Observe(duration: 1s)\n}}\n"
    r = compile_text(text, catalog, "carried.mission")
    assert r.ok and r.statechart is not None, [d.message for d in r.diagnostics]
    (report,) = run_many([Mission(r.statechart)], load_hosts(ROOT / "hosts.yaml", catalog),
                         load_world(ROOT / "worlds" / "corridor.yaml"), catalog, until=30.0)
    return report


def test_the_carrier_reads_as_the_ranger(catalog: Catalog) -> None:
    assert dry(catalog, 'scout.carrier.id == "ranger1"').outcome == "success"
    assert dry(catalog, "scout.carrier.battery > 0.5").outcome == "success"  # the carrier's own property
    missing = dry(catalog, 'scout.carrier.id == "ranger9"')
    assert missing.outcome == "failure" and "can never be satisfied" in missing.reason


def test_the_catalog_names_the_properties_that_name_a_robot(catalog: Catalog) -> None:
    refs = catalog.references()
    assert "carrier" in refs["Scout"]
    assert "battery" not in refs["Scout"] and "id" not in refs["Scout"]
