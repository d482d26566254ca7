"""An event emitted by a start action while a `parallel` is entered reaches every sibling listening at that instant,
whatever their declaration order and whether the block is the mission's first entry (semantics audit 18, #1: at
t=0 it was dispatched before the siblings declared after the emitter were entered, and they never heard it)."""

from __future__ import annotations

import pytest

from drd.runtime import records as rec
from dsl import compile_text
from dsl.catalog import Catalog
from tests.runtime_support import Harness, Timed, ranger_world

EMITTER = """
behavior Emitter {
    start -> W / emit Ready(k: 1)
    Wait(duration: 1s) as W
}
"""

#: A listener in a state entered by the start, and one waiting in its `start` state.
WAITERS = {
    "in_state": """
behavior Waiter {
    start -> Listen
    Wait(duration: 5s) as Listen
    Listen -> Go on Ready / log "heard Ready"
    Listen -> done / log "never heard"
    Wait(duration: 1s) as Go
}
""",
    "at_start": """
behavior Waiter {
    start -> Go on Ready / log "heard Ready"
    start -> Go after 5s / log "never heard"
    Wait(duration: 1s) as Go
}
""",
}

AT_ONCE = "mission M {{ parallel all {{ {children} }} }}\n"
LATER = """
mission M {{
    start -> Pre
    Wait(duration: 1s) as Pre
    Pre -> Block
}}
behavior Block {{ parallel all {{ {children} }} }}
"""


@pytest.mark.parametrize("waiter", sorted(WAITERS))
@pytest.mark.parametrize("children", ["Emitter; Waiter", "Waiter; Emitter"])
@pytest.mark.parametrize(("mission", "at"), [(AT_ONCE, 0.0), (LATER, 1.0)], ids=["first_instant", "later"])
def test_sibling_hears_event_of_start_action(catalog: Catalog, mission: str, at: float, children: str,
                                             waiter: str) -> None:
    text = mission.format(children=children) + EMITTER + WAITERS[waiter]
    result = compile_text(text, catalog, "t.mission")
    assert result.ok and result.statechart is not None
    h = Harness(result.statechart, {"Wait": Timed}, ranger_world(1, 0))
    assert h.run(until=20) == "success"
    assert [(r.text, r.at) for r in h.of(rec.Log)] == [("heard Ready", at)]


#: `Block` enters its parallel when it is granted the camera at Hog's slice boundary (3 s): a grant made by the
#: manager's tick, outside a run to completion, as the mission's start is.
AT_GRANT = """
mission M {{ parallel all {{ Hog; Block }} }}
behavior Hog {{ needs c: Camera; Wait(duration: 8s) }}
behavior Block {{
    needs c: Camera
    parallel all {{ {children} }}
}}
"""


@pytest.mark.parametrize("children", ["Emitter; Waiter", "Waiter; Emitter"])
def test_sibling_hears_event_of_start_action_at_grant(catalog: Catalog, children: str) -> None:
    result = compile_text(AT_GRANT.format(children=children) + EMITTER + WAITERS["in_state"], catalog, "t.mission")
    assert result.ok and result.statechart is not None
    h = Harness(result.statechart, {"Wait": Timed}, ranger_world(1, 0), slice_=3.0)
    assert h.run(until=40) == "success"
    assert [(r.path, r.at) for r in h.of(rec.Granted)][:2] == [("M/Hog", 0.0), ("M/Block", 3.0)]
    assert [(r.text, r.at) for r in h.of(rec.Log)] == [("heard Ready", 3.0)]
