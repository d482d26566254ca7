"""Missions as fixture files (tests/missions): each header names its components and expected run.

Header lines: `# expect: success|failure`, `# components: Name=TestComponent ...`,
optionally `# world: rangers=N scouts=M`, `# taken: Src>Dst ...` (the exact sequence of
transitions by state name) and `# order: A,B<C` (A and B started before C started).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from drd.runtime import records as rec
from dsl import compile_file
from dsl.catalog import Catalog
from tests.runtime_support import COMPONENTS, Harness, ranger_world

MISSIONS = sorted((Path(__file__).parents[1] / "missions").glob("*.mission"))


def header(path: Path) -> dict[str, str]:
    out = {}
    for line in path.read_text().splitlines():
        if not line.startswith("# ") or ":" not in line:
            break
        key, _, value = line[2:].partition(":")
        out[key.strip()] = value.strip()
    return out


@pytest.mark.parametrize("path", MISSIONS, ids=lambda p: p.stem)
def test_mission_runs_as_its_header_says(path: Path, catalog: Catalog) -> None:
    h = header(path)
    result = compile_file(path, catalog)
    assert result.ok and result.statechart is not None, [d.message for d in result.diagnostics]
    registry = {name: COMPONENTS[impl] for name, impl in (x.split("=") for x in h["components"].split())}
    world = dict(x.split("=") for x in h.get("world", "rangers=1 scouts=1").split())
    run = Harness(result.statechart, registry, ranger_world(int(world["rangers"]), int(world["scouts"])))
    assert run.run(until=120) == h["expect"], run.interp.reason
    if "taken" in h:
        taken = [f"{r.path.rsplit('/', 1)[-1]}>{r.target.rsplit('/', 1)[-1]}" for r in run.of(rec.Taken)]
        assert taken == h["taken"].split()
    if "order" in h:
        before, after = h["order"].split("<")
        entered = {r.path.rsplit("/", 1)[-1]: r.at for r in run.of(rec.Entered)}
        assert all(entered[b] <= entered[after] for b in before.split(","))
        assert entered[after] > 0
