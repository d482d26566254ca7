"""The text report folds runs of instances that say the same thing (`Wait(duration: 1s)[1000]` printed 1,000
timeline rows); instances that differ keep their rows, so the corridor mission's report is unchanged."""

from __future__ import annotations

from drd.cli.report import collapse_instances


def test_a_thousand_instances_that_say_the_same_are_one_row() -> None:
    rows = [("Thousand", "0.0", "1.0", "success"), ("Thousand/Wait", "0.0", "1.0", "success")]
    rows += [(f"Thousand/Wait[{i}]", "0.0", "1.0", "success") for i in range(1000)]
    assert collapse_instances(rows) == [*rows[:2], ("Thousand/Wait[0..999] (1,000)", "0.0", "1.0", "success")]


def test_instances_that_differ_keep_their_rows() -> None:
    rows = [(f"M/Room[{i}]", "0.0", f"{100 + 15 * i:.1f}", "success") for i in range(6)]
    assert collapse_instances(rows) == rows


def test_a_run_breaks_where_a_cell_an_index_or_the_rest_of_the_path_changes() -> None:
    same = [(f"M/W[{i}]/Leaf", "0.0", "1.0", "success") for i in range(5)]
    rows = [*same[:3], ("M/W[3]/Leaf", "0.0", "1.0", "failure"), *same[4:], ("M/W[7]/Leaf", "0.0", "1.0", "success"),
            ("M/W[8]/Other", "0.0", "1.0", "success")]
    assert collapse_instances(rows) == [("M/W[0..2]/Leaf (3)", "0.0", "1.0", "success"), *rows[3:]]


def test_two_short_runs_stay_as_they_are() -> None:
    rows = [("A[0]", "1"), ("A[1]", "1"), ("B", "1"), ("A[0]", "2")]
    assert collapse_instances(rows) == rows


def test_the_last_index_is_the_one_that_runs() -> None:
    rows = [(f"M/R[2]/W[{i}]", "x") for i in range(4)] + [(f"M/R[{i}]/W[0]", "y") for i in range(3, 6)]
    assert collapse_instances(rows) == [("M/R[2]/W[0..3] (4)", "x"), *rows[4:]]
