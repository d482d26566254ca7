"""The mission language: text -> AST -> checked program -> statechart.

Pure: nothing but `dsl.loader` touches the disk, and nothing prints. Errors come back as
located `Diagnostic`s (all of a file's in one run), never as a traceback.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from dsl.catalog import Catalog
from dsl.errors import Diagnostic, MissionError, OverBudget, Reporter, Severity
from dsl.limits import DEFAULT as DEFAULT_LIMITS
from dsl.limits import Limits
from dsl.statechart import Statechart

if TYPE_CHECKING:
    from dsl.checker import Program

# The parser (lark), the checker and builder (networkx) are imported when a mission is compiled, not when
# `dsl` is: a command that only reads manifests or talks to a cluster (`missionctl status`) starts in half
# the time.

__all__ = ["Compiled", "compile_file", "compile_text", "compile_program", "Diagnostic", "Limits", "MissionError",
           "Statechart"]


@dataclass
class Compiled:
    """The result of compiling one mission file: a statechart if there were no errors."""

    file: str
    statechart: Statechart | None
    diagnostics: list[Diagnostic] = field(default_factory=list)
    sources: dict[str, str] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not any(d.severity is Severity.ERROR for d in self.diagnostics)

    def raise_for_errors(self) -> Statechart | None:
        """The statechart (None for a library file with no mission), or MissionError."""
        if not self.ok:
            raise MissionError(self.diagnostics, self.sources)
        return self.statechart


#: The errors a file that could not be imported may explain: the behaviors it may have declared, the events they
#: emit and the outputs they offer, and what follows from not knowing them. Not types: a mission file declares none.
FROM_IMPORTS = frozenset({"unknown-behavior", "unknown-state", "unknown-event", "unknown-input-source",
                          "missing-input", "ambiguous-input"})


def _only_imports_missing(program: Program, report: Reporter) -> bool:
    """Whether every error so far is an import that could not be read, located in a file that was parsed."""
    return all(d.code in ("io", "import") and d.span.file in program.files
               for d in report.diagnostics if d.severity is Severity.ERROR)


def compile_program(program: Program, catalog: Catalog, report: Reporter) -> Statechart | None:
    """Check a parsed program and, if it has no errors and a mission, build its statechart."""
    from dsl.build import Builder
    from dsl.checker import Checker

    if report.failed and not _only_imports_missing(program, report):
        return None  # syntax errors (or the budget spent): semantic checks would only echo them
    if report.failed:  # the rest is checked, all but what the missing files may have declared (users audit 15, D7)
        report.quiet = FROM_IMPORTS
    try:
        checked = Checker(program, catalog, report).run()
        mission = program.mission
        # Bindings are checked even when the checker found errors (all of a file's errors in one run): the builder
        # then expands only what is sound and says nothing that only echoes an error already reported.
        builder = Builder(checked, catalog, report, diagnose=report.failed)
        if mission is None:  # a library: each behavior no other uses, as a mission's child that holds nothing
            builder.build_library()
            return None
        chart = builder.build(mission, program.main)
    except OverBudget as stop:
        report.over_budget(stop)
        return None
    return None if report.failed else chart


def _finish(program: Program, catalog: Catalog, report: Reporter) -> Compiled:
    chart = compile_program(program, catalog, report)
    diags = sorted(report.diagnostics, key=lambda d: (d.span.file != program.main, d.span.file,
                                                        d.span.line, d.span.column))
    return Compiled(program.main, chart, diags, program.sources)


def compile_file(path: str | Path, catalog: Catalog, limits: Limits = DEFAULT_LIMITS) -> Compiled:
    from dsl.loader import load_file

    report = Reporter(limits=limits)
    return _finish(load_file(path, report), catalog, report)


def compile_text(text: str, catalog: Catalog, file: str = "<string>", budget: float | None = None,
                 limits: Limits = DEFAULT_LIMITS, imports: Mapping[str, str] | None = None,
                 aliases: Mapping[str, str] | None = None) -> Compiled:
    """Compile a mission given as text; with `budget` (seconds), compiling stops past it with a located error.
    Imports are read from the disk (relative to the cwd) or, given `imports` (and the `aliases` of files sent once
    under two names), only from those texts (`dsl.loader.load_text`)."""
    from dsl.loader import load_text

    report = Reporter(budget=budget, limits=limits)
    return _finish(load_text(text, file, report, imports=imports, aliases=aliases), catalog, report)
