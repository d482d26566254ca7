"""Docs are tests: every ```mission block in docs/ compiles, every ```mission-invalid block fails, every complete
mission runs to the outcome the text states, and every command output shown (a ```text block that starts with
`$ missionctl`) is what the real command prints, run on the docs' own named mission files."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from dsl import compile_text
from dsl.catalog import Catalog

DOCS = Path(__file__).resolve().parents[2] / "docs"
BLOCK = re.compile(r"```(mission(?:-invalid)?)(?: [\w.-]+)?\n(.*?)```", re.S)


def _blocks() -> list[tuple[str, str, str]]:
    out = []
    for path in sorted(DOCS.glob("*.md")):
        for i, m in enumerate(BLOCK.finditer(path.read_text(encoding="utf-8"))):
            out.append((f"{path.name}#{i}", m[1], m[2]))
    return out


def test_the_tutorial_has_examples() -> None:
    kinds = {kind for _, kind, _ in _blocks()}
    assert kinds == {"mission", "mission-invalid"}


@pytest.mark.parametrize(("where", "kind", "text"), _blocks(), ids=[b[0] for b in _blocks()])
def test_doc_snippet(where: str, kind: str, text: str, catalog: Catalog) -> None:
    result = compile_text(text, catalog, where)
    if kind == "mission":
        assert result.ok, "\n".join(d.render(result.sources) for d in result.diagnostics)
    else:
        assert not result.ok and result.diagnostics


# ---------------------------------------------------------------- every docs mission runs to its stated outcome

RUN = re.compile(r"<!-- dry-run: (success|failure|stopped) -->\n```mission(?: [\w.-]+)?\n(.*?)```", re.S)
COMPLETE = re.compile(r"^mission \w+", re.M)


def _missions() -> list[tuple[str, str, str]]:
    out = []
    for path in sorted(DOCS.glob("*.md")):
        text = path.read_text(encoding="utf-8")
        for m in RUN.finditer(text):
            out.append((f"{path.name}:{text.count(chr(10), 0, m.start()) + 2}", m[1], m[2]))
    return out


def test_every_complete_mission_in_the_docs_states_its_dry_run_outcome() -> None:
    stated = {text for _, _, text in _missions()}
    missing = [where for where, kind, text in _blocks() if kind == "mission" and COMPLETE.search(text)
               and text not in stated]
    assert not missing, f"complete missions without a `<!-- dry-run: OUTCOME -->` line before them: {missing}"


@pytest.mark.parametrize(("where", "outcome", "text"), _missions(), ids=[m[0] for m in _missions()])
def test_docs_mission_runs_to_its_stated_outcome(where: str, outcome: str, text: str, catalog: Catalog) -> None:
    """The dry-run a reader would do (`missionctl dry-run` with the repository's hosts.yaml and corridor world);
    a mission said to run to its time limit is given 300 s of sim time."""
    from drd.dryrun import run
    from drd.hosts import load_hosts
    from drd.sim.world import load_world

    result = compile_text(text, catalog, where)
    assert result.ok and result.statechart is not None
    root = DOCS.parent
    report = run(result.statechart, load_hosts(root / "hosts.yaml", catalog), load_world(root / "worlds" /
                 "corridor.yaml"), catalog, until=300.0 if outcome == "stopped" else 1800.0)
    assert report.outcome == outcome, f"{where}: {report.outcome} ({report.reason})"


# ---------------------------------------------------------------- every output shown in the docs is real

#: A mission block that names its file (```` ```mission hello.mission ````): the docs' commands run on these.
NAMED = re.compile(r"```mission(?:-invalid)? ([\w.-]+\.mission)\n(.*?)```", re.S)
SHOWN = re.compile(r"```text\n(\$ missionctl .*?)```", re.S)
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]


def _shown() -> list[tuple[str, str, str]]:
    out = []
    for path in sorted(DOCS.glob("*.md")):
        text = path.read_text(encoding="utf-8")
        for m in SHOWN.finditer(text):
            out.append((f"{path.name}:{text.count(chr(10), 0, m.start()) + 1}", path.name, m[1]))
    return out


def matches(expected: list[str], got: list[str]) -> bool:
    """Line by line, where a line `...` in the docs stands for any lines (none included)."""
    if not expected:
        return not got
    if expected[0] == "...":
        return any(matches(expected[1:], got[i:]) for i in range(len(got) + 1))
    return bool(got) and expected[0] == got[0] and matches(expected[1:], got[1:])


@pytest.mark.parametrize(("where", "doc", "block"), _shown(), ids=[s[0] for s in _shown()])
def test_an_output_shown_in_the_docs_is_the_real_commands(where: str, doc: str, block: str, tmp_path: Path) -> None:
    text = (DOCS / doc).read_text(encoding="utf-8")
    for name, source in NAMED.findall(text):
        (tmp_path / name).write_text(source, encoding="utf-8")
    shutil.copy(DOCS.parent / "hosts.yaml", tmp_path / "hosts.yaml")
    lines = block.rstrip("\n").split("\n")
    commands = [shlex.split(line[2:]) for line in lines if line.startswith("$ ")]
    expected = [line.rstrip() for line in lines if not line.startswith("$ ")]
    if any(a.endswith((".svg", ".png", ".pdf")) for c in commands for a in c) and not shutil.which("dot"):
        pytest.skip("Graphviz's dot is not installed (the docs show a drawing)")
    env = {**os.environ, "COLUMNS": "100", "NO_COLOR": "1", "TERM": "dumb"}
    for command in commands:
        assert command[0] == "missionctl", where
        done = subprocess.run([*MISSIONCTL, *command[1:]], cwd=tmp_path, capture_output=True, text=True,
                              timeout=300, env=env, check=False)
    got = [line.rstrip() for line in (done.stdout + done.stderr).rstrip("\n").split("\n")] if commands else []
    assert matches(expected, got), f"{where}: the docs show\n" + "\n".join(expected) + "\nthe command printed\n" \
        + "\n".join(got)
