"""A behavior's `start -> X after D` counts from the behavior's entry, its wait for its needs included, as every
`after` counts from its source's entry; one already overdue when the needs are granted fires at the grant
(reference.md *Children and multiplicity*; semantics audit 18, #3: it counted from the grant)."""

from __future__ import annotations

import pytest

from drd.runtime import records as rec
from dsl import compile_text
from dsl.catalog import Catalog
from tests.runtime_support import Harness, Timed, ranger_world

#: `Starter` is entered at 0 and waits for the camera `Hog` holds until 4 s.
MISSION = """
mission M {{ parallel all {{ Hog; Starter }} }}
behavior Hog {{ needs c: Camera; Wait(duration: 4s) }}
behavior Starter priority 2 {{
    needs c: Camera
    start -> Go after {delay} / log "go"
    Wait(duration: 1s) as Go
}}
"""


@pytest.mark.parametrize(("delay", "at"), [("6s", 6.0), ("3s", 4.0), ("4s", 4.0)])
def test_start_after_counts_from_entry(catalog: Catalog, delay: str, at: float) -> None:
    result = compile_text(MISSION.format(delay=delay), catalog, "t.mission")
    assert result.ok and result.statechart is not None
    h = Harness(result.statechart, {"Wait": Timed}, ranger_world(1, 0))
    assert h.run(until=30) == "success"
    assert [(r.path, r.at) for r in h.of(rec.Entered) if r.path == "M/Starter"] == [("M/Starter", 0.0)]
    assert [(r.path, r.at) for r in h.of(rec.Granted)] == [("M/Hog", 0.0), ("M/Starter", 4.0)]
    assert [(r.text, r.at) for r in h.of(rec.Log)] == [("go", at)]
