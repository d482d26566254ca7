"""`missionctl hosts`: how a host that stopped reporting is shown (issue #16: a frozen peer is named, not hidden)."""

from __future__ import annotations

from typing import Any

from drd.cli.cluster import SILENT_AFTER, _hosts_table
from drd.cli.common import as_text


def host(name: str, age: float | None, state: str = "up") -> dict[str, Any]:
    return {"name": name, "state": state, "since": 100.0, "reason": "joined", "roles": ["worker"], "cpu": 10.0,
            "memory": 5.0, "load1": 0.5, "instances": 2, "report_age": age}


def render(rows: list[dict[str, Any]]) -> str:
    return as_text(_hosts_table(rows, 110.0), width=140)


def test_a_host_that_stopped_reporting_shows_as_silent_with_how_long() -> None:
    text = render([host("ranger1", SILENT_AFTER + 0.6), host("ranger2", 0.2)])
    frozen = next(line for line in text.splitlines() if "ranger1" in line)
    fine = next(line for line in text.splitlines() if "ranger2" in line)
    assert "silent" in frozen and f"no load report for {SILENT_AFTER + 0.6:.1f} s" in frozen, frozen
    assert "silent" not in fine and " up " in fine, fine


def test_a_down_host_is_down_however_old_its_last_report() -> None:
    text = render([host("ranger1", 30.0, state="down")])
    assert "silent" not in text and "down" in text


def test_a_query_table_shows_a_live_float_to_three_decimals() -> None:
    """A live pose is a physics float (`x=6.482061619805352`): the table shows 3 decimals; other values as they are."""
    from drd.cli.cluster import shown_property

    assert [shown_property(v) for v in (6.482061619805352, 0.97, 1.0, -0.0001, "ranger1", 3, True)] == [
        "6.482", "0.97", "1", "0", "ranger1", "3", "True"]
