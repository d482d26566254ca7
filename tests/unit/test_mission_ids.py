"""Mission ids: `<name>-<number>`, a number after the last dash even when two start in the same millisecond."""

from __future__ import annotations

from drd.cli.cluster import mission_name
from drd.daemon.missions import mission_id


def test_an_id_is_the_name_and_the_time_in_milliseconds_modulo_ten_million() -> None:
    assert mission_id("HallSentry", 1_796_009_539.8284, set()) == "HallSentry-9539828"


def test_ids_taken_in_the_same_millisecond_get_the_next_numbers_and_keep_their_name() -> None:
    taken: set[str] = set()
    for _ in range(3):
        taken.add(mission_id("Hall-Sentry", 1_796_009_539.8284, taken))
    assert taken == {"Hall-Sentry-9539828", "Hall-Sentry-9539829", "Hall-Sentry-9539830"}
    assert {mission_name(mid) for mid in taken} == {"Hall-Sentry"}
