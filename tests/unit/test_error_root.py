"""One error root (issue #14): every error drd raises on purpose is a `DrdError` of a kind, and the CLI's safety
net tells them (exit 2, one line) from a bug of ours (exit 70, one line, `DRD_DEBUG=1` for the traceback)."""

from __future__ import annotations

import importlib
import json
import pkgutil
import sys
from collections.abc import Iterator
from typing import NoReturn

import pytest

import components
import drd
import dsl
from drd.cli import common
from drd.errors import DrdError

#: Exceptions that never leave their module: control flow, caught where they are raised (each with why).
INTERNAL = {
    "drd.bus.schema.Mismatch": "a schema check's inner signal, turned into MalformedMessage by its caller",
    "drd.bus.messages.MalformedMessage": "a wire payload refused; the server logs it and answers an error",
    "dsl.evaluate.EvalError": "an expression's failure at run time; the interpreter fails the state with it",
    "drd.cluster.pipe.ProtocolError": "a worker's message refused by the Creator, which kills that worker",
    "dsl.errors.OverBudget": "a compile stage's signal past its budget; the compiler reports it as a located error",
}


def our_modules() -> Iterator[str]:
    for package in (drd, dsl, components):
        yield package.__name__
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            yield info.name


def our_exceptions() -> list[type[BaseException]]:
    for name in our_modules():
        try:
            importlib.import_module(name)
        except ImportError:  # an optional module whose library is absent
            continue
    seen: list[type[BaseException]] = []
    todo: list[type[BaseException]] = [Exception]
    while todo:
        cls = todo.pop()
        for sub in cls.__subclasses__():
            if sub not in seen:
                seen.append(sub)
                todo.append(sub)
    return [c for c in seen if c.__module__.split(".")[0] in ("drd", "dsl", "components")]


def test_every_error_we_raise_on_purpose_has_the_root() -> None:
    found = our_exceptions()
    assert len(found) > 20
    stray = [f"{c.__module__}.{c.__qualname__}" for c in found
             if not issubclass(c, DrdError) and f"{c.__module__}.{c.__qualname__}" not in INTERNAL]
    assert stray == []


@pytest.mark.parametrize(("path", "kind"), [
    ("drd.hosts.HostsError", "configuration"), ("drd.manifests.ManifestError", "configuration"),
    ("dsl.errors.MissionError", "mission"), ("dsl.params.ParamError", "mission"),
    ("drd.cluster.remote.HostDown", "component"), ("drd.bus.base.BusTimeout", "bus"),
    ("drd.daemon.client.NoDaemon", "bus"), ("drd.hw.interfaces.StaleCommand", "hardware"),
])
def test_each_error_says_what_it_is_about(path: str, kind: str) -> None:
    module, name = path.rsplit(".", 1)
    cls = getattr(importlib.import_module(module), name)
    assert issubclass(cls, DrdError) and cls.kind == kind


def run(fn: object, argv: list[str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        debug: bool = False) -> tuple[int, str]:
    monkeypatch.setattr(sys, "argv", ["missionctl", *argv])
    monkeypatch.setenv("DRD_DEBUG", "1" if debug else "")
    with pytest.raises(SystemExit) as stopped:
        common.run_app(fn, "missionctl")  # type: ignore[arg-type]
    common.json_errors(False)
    return int(stopped.value.code or 0), capsys.readouterr().err


def crash(**_: object) -> NoReturn:
    raise KeyError("a bug of ours")


def refuse(**_: object) -> NoReturn:
    raise DrdError("the daemon refused", where="hosts.yaml: cluster.name", hint="check the name")


def test_a_bug_exits_70_in_one_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    code, err = run(crash, ["status"], monkeypatch, capsys)
    assert code == 70
    assert "internal error: KeyError" in err and "DRD_DEBUG=1" in err and "Traceback" not in err


def test_a_bug_shows_its_traceback_with_drd_debug(monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    code, err = run(crash, ["status"], monkeypatch, capsys, debug=True)
    assert code == 70 and "Traceback" in err and "a bug of ours" in err


def test_our_error_exits_2_naming_where_and_the_hint(monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    code, err = run(refuse, ["status"], monkeypatch, capsys)
    assert code == 2
    assert "hosts.yaml: cluster.name: the daemon refused" in err and "check the name" in err
    assert "internal error" not in err


def test_under_json_both_are_one_json_object(monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    code, err = run(refuse, ["status", "--json"], monkeypatch, capsys)
    assert code == 2 and json.loads(err)["code"] == 2 and "the daemon refused" in json.loads(err)["error"]
    code, err = run(crash, ["status", "--json"], monkeypatch, capsys)
    assert code == 70 and json.loads(err)["code"] == 70
