"""docs/cli.md names the commands that take `-C/--components`; each of them takes it, and no other command does
(fleet audit defect 5: the row said "every command that reads the catalog", and `missionctl run` and `components`,
whose catalog is the daemons', refused `-C`)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import typer.main

from drd.cli import drd, missionctl

ROOT = Path(__file__).resolve().parents[2]


def commands(app: typer.Typer, prefix: str) -> dict[str, Any]:
    """Every command of `app`, named as the docs name them (`world generate`); typer's own click's commands."""
    found: dict[str, Any] = {}
    group: Any = typer.main.get_command(app)
    for name, cmd in group.commands.items():
        if hasattr(cmd, "commands"):
            found.update({f"{prefix} {name} {sub}": c for sub, c in cmd.commands.items()})
        else:
            found[f"{prefix} {name}"] = cmd
    return found


def documented() -> set[str]:
    """The commands the `--components` row of docs/cli.md lists before "Not"."""
    row = next(line for line in (ROOT / "docs" / "cli.md").read_text().splitlines()
               if line.startswith("| `--components DIR`, `-C`"))
    listed = row.split(" | ")[2].split(". Not ")[0].split(": ", 1)[1]
    names: set[str] = set()
    for part in listed.split(";"):
        words = re.findall(r"`([^`]+)`", part)
        tool, first = words[0].split(" ", 1)
        names |= {f"{tool} {first}", *(f"{tool} {w}" for w in words[1:])}
    return names


def test_the_docs_name_exactly_the_commands_that_take_components() -> None:
    every = {**commands(missionctl.app, "missionctl"), **commands(drd.app, "drd")}
    taking = {name for name, cmd in every.items()
              if any("-C" in p.opts and "--components" in p.opts for p in cmd.params)}
    assert taking == documented()
    assert {"missionctl run", "missionctl components"} <= set(every) - taking
