"""A controller killed and started again in a dry-run grants above every epoch the dead one gave (safety audit 25,
D1): its manager started at 0, so the resumed mission's grants reused epochs 1, 2... of the units, and a grant of
the new controller looked, in the trace and at a gate, like one of the old one's. Checked from the trace only:
every unit's epochs over the `granted` records strictly increase, across the restart."""

from __future__ import annotations

from dsl import compile_text
from dsl.catalog import Catalog
from tests.runtime_support import traced_dry_run

TURNS = """mission Turns {
    parallel all {
        Turn as left priority 2
        Turn as right priority 2
    }
}
behavior Turn {
    needs ranger: Ranger for 2s
    FollowCorridor(speed: 0.4)
    FollowCorridor -> done after 6s
}
"""


def test_a_restarted_controller_never_grants_an_epoch_the_dead_one_gave(catalog: Catalog) -> None:
    chart = compile_text(TURNS, catalog, "turns.mission").statechart
    assert chart is not None
    records = traced_dry_run(chart, catalog, ["kill controller at 3s", "restart controller at 5s"], 12.0)
    assert any(r["kind"] == "restored" for r in records)  # the restart happened and resumed the mission
    last: dict[str, int] = {}
    grants_after = 0
    for r in records:
        if r["kind"] != "granted":
            continue
        grants_after += r["at"] >= 5.0
        for unit, epoch in r["epochs"].items():
            assert epoch > last.get(unit, 0), (r, last)
            last[unit] = epoch
    assert grants_after >= 2  # the resumed holder and the next slice's were checked too
