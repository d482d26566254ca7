"""Small shapes of what the CLI prints (docs audit 2, item 9): `query`'s header in the singular for one offer,
`stop --json`'s statuses shaped as `run --json` reports (`mission` the name, `id` the id, times rounded by
`report_time`), and `drd.record.read` taking a str path as docs/recording.md calls it."""

from __future__ import annotations

from pathlib import Path

import pytest

from drd import record
from drd.cli.cluster import mission_json, offers_title, status_json


def test_query_header_counts_offers_in_the_singular_for_one() -> None:
    assert offers_title(1, "Camera") == "1 offer for Camera"
    assert offers_title(7, "Camera where fov > 1") == "7 offers for Camera where fov > 1"
    assert offers_title(0, "Camera") == "0 offers for Camera"


def test_mission_json_names_the_mission_and_rounds_its_times_as_run_does() -> None:
    status = {"id": "CorridorSurveillance-9900205", "mission": "CorridorSurveillance-9900205",
              "outcome": "stopped", "time": 34.50000000000022, "started": 0.30000000000000004, "already_ended": True}
    shown = mission_json(status)
    assert shown["mission"] == "CorridorSurveillance" and shown["id"] == "CorridorSurveillance-9900205"
    assert shown["time"] == 34.5 and shown["started"] == 0.3
    assert shown["outcome"] == "stopped" and shown["already_ended"] is True
    assert status["time"] == 34.50000000000022  # the reply itself is left as it came


def test_status_json_shapes_each_mission_as_run_and_stop_do() -> None:
    """Re-verification audit: `status --json` times were unrounded (768.3999999999763) while `stop --json`'s were."""
    data = {"hosts": [], "missions": [{"id": "Hold-4242", "mission": "Hold-4242", "outcome": None,
                                       "time": 768.3999999999763, "started": 0.30000000000000004}]}
    [shown] = status_json(data)["missions"]
    assert (shown["mission"], shown["id"], shown["time"], shown["started"]) == ("Hold", "Hold-4242", 768.4, 0.3)
    assert status_json({"hosts": [], "missions": None})["missions"] is None  # the controller did not answer


def test_mission_json_keeps_an_id_that_is_not_name_dash_number() -> None:
    assert mission_json({"id": "adhoc", "time": None})["mission"] == "adhoc"


def test_read_takes_a_str_path_and_names_the_file_it_cannot_read(tmp_path: Path) -> None:
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file")
    with pytest.raises(record.RecordingError, match="junk.mcap: cannot read it as a drd recording"):
        record.read(str(junk))
    with pytest.raises(record.RecordingError, match="nowhere.mcap"):
        record.read(str(tmp_path / "nowhere.mcap"))
