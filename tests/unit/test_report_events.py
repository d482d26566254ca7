"""The report's `events`: every event a run emitted, whatever its components are called (own-world audit D1: a team's
own `Spotted` event was nowhere in the report, which said `intruders detected: 0`, `doors found: 0`, `Scouts placed:
0`, counting only the standard components' event names)."""

from __future__ import annotations

import io

from rich.console import Console  # noqa: TID251 - rendering the report at a chosen width

from drd.cli.report import print_report
from drd.dryrun import DryRun, facts
from drd.runtime import records as rec


def run_of(events: list[rec.Event]) -> DryRun:
    run = DryRun("GateRound", "success", "", 60.0, 1.0)
    for r in events:
        run.records.append(r)
        facts(run, r)
    return run


def text_of(run: DryRun) -> str:
    sink = io.StringIO()
    print_report(run, console=Console(file=sink, width=120))
    return sink.getvalue()


def test_a_missions_own_events_are_counted_by_name_with_their_first() -> None:
    run = run_of([rec.Event(36.3, "GateRound/Glance", "Spotted", {"label": "night_porter"}),
                  rec.Event(40.0, "GateRound/Tally", "Counted", {}),
                  rec.Event(41.5, "GateRound/Glance", "Spotted", {"label": "cat"})])
    assert run.to_dict()["events"] == [
        {"name": "Spotted", "count": 2, "at": 36.3, "by": "GateRound/Glance", "fields": {"label": "night_porter"}},
        {"name": "Counted", "count": 1, "at": 40.0, "by": "GateRound/Tally", "fields": {}}]
    text = text_of(run)
    assert "events: 3 (2 kinds)" in text
    assert "Spotted x2, first at 36.3 s by Glance: label=night_porter" in text
    assert "Counted x1, first at 40.0 s by Tally\n" in text
    for shipped in ("doors found", "robots launched", "intruders detected"):
        assert shipped not in text, f"{shipped!r}: a count of events this mission cannot emit"


def test_the_standard_components_facts_are_shown_when_the_run_had_them() -> None:
    run = run_of([rec.Event(5.0, "Corridor/Watch", "MotionDetected", {"area": 0.2})])
    text = text_of(run)
    assert "intruders detected: 1" in text and "MotionDetected x1" in text and "doors found" not in text
    assert "events" not in run_of([]).to_dict() or run_of([]).to_dict()["events"] == []
    assert "events:" not in text_of(run_of([]))
