"""A cluster run's pace leaves out the time its controller was away (a restart, a failover): the report said
"the cluster could not keep up" for a mission that kept its pace except while it had no controller."""

from __future__ import annotations

import io

import pytest
from rich.console import Console  # noqa: TID251 - rendering the report at a chosen width

from drd.cli.report import print_report
from drd.dryrun import DryRun


def report(away: float) -> DryRun:
    return DryRun("Patrol", "success", "", 100.0, 30.0, speed=5.0, on_cluster=True, mission_id="Patrol-1", away=away)


def test_the_time_without_a_controller_is_not_the_clusters_pace() -> None:
    assert not report(0.0).kept_up  # 100 s in 30 s: 3.3x of the 5x asked
    assert report(10.0).kept_up  # 100 s in the 20 s it had a controller: 5x
    assert report(10.0).to_dict()["controller_away"] == 10.0 and "controller_away" not in report(0.0).to_dict()


def test_the_report_says_how_long_it_was_without_a_controller() -> None:
    sink = io.StringIO()
    print_report(report(10.0), console=Console(file=sink, width=120))
    text = sink.getvalue()
    assert "wall time 30.00 s (10.0 s of it without a controller)" in text and "could not keep up" not in text


def test_a_report_with_no_wall_time_is_strict_json() -> None:
    """A replay of a recording cut before its end has no wall time (clients audit: `Infinity` in --json)."""
    import json

    cut = DryRun("Patrol", "unfinished", "", 53.2, 0.0)
    data = json.loads(json.dumps(cut.to_dict(), allow_nan=False))
    assert data["real_time_factor"] is None
    sink = io.StringIO()
    print_report(cut, console=Console(file=sink, width=120))
    assert "inf" not in sink.getvalue()


def test_a_list_of_facts_cut_at_20_says_how_many_more() -> None:
    """Newcomer audit 8: `intruders detected: 35` listed 20 rows and said nothing of the other 15."""
    run = DryRun("Patrol", "success", "", 100.0, 30.0)
    run.detections = [{"at": float(i), "by": "Patrol/Watch", "area": 0.1} for i in range(35)]
    sink = io.StringIO()
    print_report(run, console=Console(file=sink, width=120))
    text = sink.getvalue()
    assert "intruders detected: 35" in text and text.count("by=Watch") == 20
    assert "… and 15 more (--json has them all)" in text


def test_a_log_lines_further_lines_are_shown_whole() -> None:
    """With DRD_DEBUG=1 a component's log line carries its traceback: the report's wrap-and-cut of a log line
    flattened it into three cut lines; the lines after the first now come whole, below it."""
    from drd.runtime import records as rec

    run = DryRun("Patrol", "failure", "x", 1.0, 1.0)
    tb = 'Traceback (most recent call last):\n  File "kit/bad.py", line 6, in step\n    raise ValueError("boom")'
    run.records = [rec.Log(0.1, "Patrol/b", f"component raised ValueError: boom\n{tb}\nValueError: boom")]
    sink = io.StringIO()
    print_report(run, console=Console(file=sink, width=80))
    lines = [line.strip() for line in sink.getvalue().splitlines()]
    assert 'File "kit/bad.py", line 6, in step' in lines and 'raise ValueError("boom")' in lines, lines


def test_a_mission_that_ended_at_once_has_no_pace() -> None:
    """Recovery audit D4: a mission refused at 0.0 s read `0x real time (2x asked: the cluster could not keep
    up)`. Under a second of sim time, the report gives the times and judges no pace."""
    at_once = DryRun("Drive2", "failure", "no Ranger is known", 0.0, 0.4, speed=2.0, on_cluster=True, mission_id="D-1")
    assert at_once.kept_up and not at_once.paced
    sink = io.StringIO()
    print_report(at_once, console=Console(file=sink, width=120))
    text = sink.getvalue()
    assert "sim time 0.0 s · wall time 0.40 s" in text and "real time" not in text and "keep up" not in text


def test_the_pace_leaves_out_the_time_without_a_controller_and_is_given_to_a_tenth_below_10x() -> None:
    """Cluster audit 17, D4: a run at 3.65x with a 10 s outage read "1.59x real time"; and 3.5x, rounded, read
    "4x real time (4x asked: the cluster could not keep up)"."""
    resumed = DryRun("Hold", "success", "", 36.5, 20.0, speed=4.0, on_cluster=True, mission_id="H-1", away=10.0)
    assert resumed.real_time_factor == pytest.approx(3.65) and resumed.kept_up
    slow = DryRun("Hold", "success", "", 35.0, 10.0, speed=4.0, on_cluster=True, mission_id="H-2")
    sink = io.StringIO()
    for run in (resumed, slow):
        print_report(run, console=Console(file=sink, width=120))
    text = sink.getvalue()
    assert "wall time 20.00 s (10.0 s of it without a controller) · 3.6x real time\n" in text, text
    assert "3.5x real time (4x asked: the cluster could not keep up)" in text
