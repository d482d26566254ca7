"""docs/trace.md's order, checked by `drd.tracecheck.check` (safety audit 2): nothing of a mission after its
`finished`, and its `at` never goes back except where a restore opens."""

from __future__ import annotations

from typing import Any

from drd.tracecheck import check


def r(kind: str, at: float, mission: str = "M-1", **fields: Any) -> dict[str, Any]:
    return {"kind": kind, "at": at, "path": "M", "mission": mission, **fields}


def kinds(records: list[dict[str, Any]]) -> list[str]:
    return [b.kind for b in check(records).breaches]


def test_a_halt_after_its_mission_finished_is_refused() -> None:
    """The audit's s3br trace: `halted` at 4.43 s as the last line, after `finished` at 10.19 s."""
    trace = [r("entered", 0.0, state="M"), r("finished", 10.19, outcome="failure", reason="expired"),
             r("halted", 4.43, device="ranger1.drive", method="stop", reason="controller lost", error="")]
    assert kinds(trace) == ["after finished", "time backwards"]


def test_a_record_after_finished_at_the_same_time_is_still_refused() -> None:
    trace = [r("finished", 5.0, outcome="success", reason=""), r("log", 5.0, text="late")]
    assert kinds(trace) == ["after finished"]


def test_time_going_back_within_a_mission_is_refused_but_not_across_missions() -> None:
    assert kinds([r("entered", 3.0, state="M"), r("log", 2.0, text="x")]) == ["time backwards"]
    assert kinds([r("entered", 3.0, state="M"), r("entered", 2.0, "N-2", state="N")]) == []


def test_a_restore_may_start_before_the_last_records_and_goes_on_from_there() -> None:
    """A restored mission's clock goes on from its journal's last save: the `released` (`controller lost`) and
    `restored` that open it may be earlier than the records the lost controller sent after that save."""
    trace = [r("entered", 0.0, state="M"), r("log", 4.4, text="after the last save"),
             r("released", 4.3, resources=["ranger1"], reason="controller lost"),
             r("restored", 4.3, since=4.2, paused=2.0), r("entered", 4.3, state="M")]
    assert kinds(trace) == []
    assert kinds([*trace, r("log", 4.0, text="back again")]) == ["time backwards"]


def test_only_a_restore_opens_a_new_clock() -> None:
    trace = [r("entered", 5.0, state="M"), r("released", 4.0, resources=["ranger1"], reason="exit")]
    assert kinds(trace) == ["time backwards"]


def test_a_restore_enters_a_finished_mission_again_but_nothing_else_does() -> None:
    ended = [r("entered", 0.0, state="M"), r("finished", 1.0, outcome="stopped", reason="the executive closed")]
    again = [r("released", 1.0, resources=["ranger1"], reason="controller lost"), r("restored", 1.0, since=0.5,
                                                                                     paused=1.0)]
    assert kinds([*ended, *again, r("entered", 1.0, state="M")]) == []
    assert kinds([*ended, r("released", 1.0, resources=["ranger1"], reason="exit")]) == ["after finished"]


def test_an_exclusive_units_epoch_must_grow_from_grant_to_grant_but_a_shares_need_not() -> None:
    """Safety audit 25, D1: a restarted controller granted ranger1.drive at epoch 1 again."""
    def grant(at: float, path: str, epoch: int, shares: dict[str, str] | None = None) -> dict[str, Any]:
        unit = "ranger1.radio" if shares else "ranger1.drive"
        return {**r("granted", at, resources={"r": unit}, epochs={unit: epoch}, shares=shares or {}), "path": path}

    released = {**r("released", 2.0, resources=["ranger1.drive"], reason="done"), "path": "M/a"}
    assert kinds([grant(0.0, "M/a", 1), released, grant(3.0, "M/b", 1)]) == ["epoch reused"]
    assert kinds([grant(0.0, "M/a", 1), released, grant(3.0, "M/b", 100_002)]) == []
    radio = {"r": "ranger1.radio"}
    assert kinds([grant(0.0, "M/a", 2, radio), grant(0.0, "M/b", 1, radio)]) == []  # shares, in any order
