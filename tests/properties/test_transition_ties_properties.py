"""Whatever the kinds, order and guards of a state's transitions all enabled at one instant, the first declared
enabled one is taken (spec audit D2); a failure is taken by a transition only when an `on error` is enabled."""

from __future__ import annotations

import functools
from typing import Any

from hypothesis import given, note, settings
from hypothesis import strategies as st

from drd.manifests import load_catalog
from drd.runtime import records as rec
from drd.runtime.component import Status
from dsl import compile_text
from tests.runtime_support import Harness, Timed, ranger_world

#: At t=2.0: Step's leaf ends (succeeds or fails) and launches scout1 (the `when` holds from then on), the sibling
#: emits Zap, and `after 2s` falls due. Every kind of trigger is enabled at that one instant.
TRIGGERS = {
    "completion": "",
    "error": " on error",
    "timeout": " after 2s",
    "event": " on Zap",
    "change": " when count(Scout where scout.carrier == r) < 2",
}
MISSION = """
mission M {{
    parallel all {{
        Zapper
        Target
    }}
}}
behavior Zapper {{ Wait(duration: 2s); Wait -> done / emit Zap(k: 1) }}
behavior Target {{
    needs r: Ranger
    start -> Step
{body}
}}
behavior Step {{ Wait(duration: 2s) }}
"""


catalog = functools.cache(load_catalog)  # not the fixture: hypothesis would print its 30 kB repr


def leaf(fails: bool) -> type:
    class StepWait(Timed):
        """Step's Wait ends at 2 s (a failure with `fails`) and launches scout1 as it does; any other Wait is Timed."""

        def step(self, now: float) -> Status:
            status = super().step(now)
            assert self.ctx is not None
            if status is Status.SUCCESS and self.ctx.path.endswith("/Step/Wait"):
                self.update_dependency("ranger1.scout1", "carrier", "")
                return Status.FAILURE if fails else status
            return status

    return StepWait


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(sorted(TRIGGERS)), st.booleans()), min_size=1, max_size=6),
       st.booleans())
def test_the_first_declared_enabled_transition_wins(transitions: list[tuple[str, bool]], fails: bool) -> None:
    names = [f"T{i}" for i in range(len(transitions))]
    body = [f"    Step -> {n}{TRIGGERS[kind]} [{'true' if ok else 'false'}]"
            for n, (kind, ok) in zip(names, transitions, strict=True)]
    body += [f'    {n} -> done / log "{n}"' for n in names]
    text = MISSION.format(body="\n".join(body)) + "".join(f"behavior {n} {{ Wait(duration: 1s) }}\n" for n in names)
    note(text)
    r = compile_text(text, catalog(), "t.mission")
    assert r.ok and r.statechart is not None, [d.message for d in r.diagnostics]
    registry: dict[str, Any] = {"Wait": leaf(fails)}
    h = Harness(r.statechart, registry, ranger_world(1, 2))
    outcome = h.run(until=20)
    finished = "error" if fails else "completion"
    enabled = [n for n, (kind, ok) in zip(names, transitions, strict=True)
               if ok and kind in ("timeout", "event", "change", finished)]
    caught = any(ok and kind == "error" for kind, ok in transitions)
    expected = enabled[0] if enabled and (caught or not fails) else None
    logs = [x.text for x in h.of(rec.Log) if x.text in names]
    assert logs == ([expected] if expected else [])
    assert outcome == ("failure" if fails and not caught else "success")
