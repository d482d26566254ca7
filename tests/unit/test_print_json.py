"""Every `--json` output is strict JSON: an inf or a NaN in what a command prints (a report with no wall time had
`Infinity`) is written as null, which every JSON reader takes."""

from __future__ import annotations

import json
import math

import pytest

from drd.cli.common import print_json


def test_non_finite_floats_are_written_as_null(capsys: pytest.CaptureFixture[str]) -> None:
    print_json({"factor": math.inf, "rows": [1.5, -math.inf, {"nan": math.nan}], "ok": True})
    text = capsys.readouterr().out
    data = json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} is not JSON"))
    assert data == {"factor": None, "rows": [1.5, None, {"nan": None}], "ok": True}


def test_finite_data_is_written_as_it_is(capsys: pytest.CaptureFixture[str]) -> None:
    print_json({"a": 1, "b": [0.1, "x"]})
    assert json.loads(capsys.readouterr().out) == {"a": 1, "b": [0.1, "x"]}
