"""Output files that stopped on a write error while a command ran (a `--trace` or a `--record` file on a full
disk): the run goes on without them, and the command says so after its report, one line per file naming it. One
registry for every kind of output file, so the CLI asks one place (pure: no I/O)."""

from __future__ import annotations

_FAILED: list[str] = []


def failed(line: str) -> None:
    """An output file stopped: `line` names it and says why."""
    _FAILED.append(line)


def failures() -> list[str]:
    """The output files that stopped since the last call, one line each (then forgotten)."""
    said = list(_FAILED)
    _FAILED.clear()
    return said
