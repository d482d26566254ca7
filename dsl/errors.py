"""Located diagnostics: every problem names file:line:column and can show its source line.

The compiler never prints; it returns `Diagnostic` records (or raises `MissionError`
carrying them). Rendering with colour is the CLI's job; `Diagnostic.render` gives the
plain-text form used everywhere else.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum

from drd.errors import MissionInputError
from dsl.limits import DEFAULT as DEFAULT_LIMITS
from dsl.limits import Limits


@dataclass(frozen=True, slots=True)
class Span:
    """A region of a source file. Lines and columns are 1-based; `end_column` is exclusive."""

    file: str
    line: int
    column: int
    end_line: int
    end_column: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.column}"

    def to(self, other: Span) -> Span:
        """The span from the start of `self` to the end of `other`."""
        return Span(self.file, self.line, self.column, other.end_line, other.end_column)


NOWHERE = Span("<unknown>", 1, 1, 1, 1)


class Severity(StrEnum):
    ERROR = "error"
    """The mission cannot run."""
    WARNING = "warning"
    """The mission runs, but probably not as its author meant."""


@dataclass(frozen=True, slots=True)
class Diagnostic:
    """One problem found in a mission, in the user's words, with a place and a hint."""

    code: str
    message: str
    span: Span
    hint: str | None = None
    notes: tuple[tuple[str, Span], ...] = ()
    severity: Severity = Severity.ERROR

    def render(self, sources: Mapping[str, str] | None = None) -> str:
        """Plain text: the location, the message, the source line with a caret, the hint."""
        out = [f"{self.span}: {self.severity.value}: {self.message}"]
        out.extend(_excerpt(self.span, sources))
        for text, where in self.notes:
            out.append(f"  note: {where}: {text}")
        if self.hint:
            out.append(f"  hint: {self.hint}")
        return "\n".join(out)

    def to_dict(self) -> dict[str, object]:
        """The JSON form used by `missionctl validate --json`."""
        return {
            "code": self.code,
            "severity": self.severity.value,
            "message": self.message,
            "file": self.span.file,
            "line": self.span.line,
            "column": self.span.column,
            "end_line": self.span.end_line,
            "end_column": self.span.end_column,
            "hint": self.hint,
            "notes": [{"message": t, "file": s.file, "line": s.line, "column": s.column} for t, s in self.notes],
        }


def source_line(span: Span, sources: Mapping[str, str] | None) -> str | None:
    """The text of the span's first line, if the source is known."""
    if not sources or span.file not in sources:
        return None
    lines = sources[span.file].split("\n")  # as the lexer counts lines: \n only (not \f, \u2028...)
    if 1 <= span.line <= len(lines):
        return lines[span.line - 1].removesuffix("\r")
    return "" if span.line == len(lines) + 1 else None


def caret(span: Span, line: str) -> tuple[int, int]:
    """Where the caret starts (0-based) and how wide it is, clipped to the line."""
    start = min(max(span.column - 1, 0), len(line))
    end = span.end_column - 1 if span.end_line == span.line else len(line)
    return start, max(1, min(end, len(line)) - start)


#: Source lines longer than this are shown as a window around the caret (a generated one-line file is megabytes).
EXCERPT_WIDTH = 100


@dataclass(frozen=True, slots=True)
class Excerpt:
    """The source line of a span as shown under its message: `gutter` (`   12 | `), the line's `text` (a window
    around the span when the line is long, cut ends marked `…`), and the caret under the span (`pad` spaces,
    then `width` carets)."""

    gutter: str
    text: str
    pad: int
    width: int

    def lines(self) -> list[str]:
        return [self.gutter + self.text, " " * (len(self.gutter) - 2) + "| " + " " * self.pad + "^" * self.width]


def excerpt(span: Span, sources: Mapping[str, str] | None) -> Excerpt | None:
    """The excerpt every renderer shows (plain text, `missionctl`, the controller's replies), or None when the
    source is not known."""
    line = source_line(span, sources)
    if line is None:
        return None
    line = "".join(ch if ch.isprintable() else "\ufffd" for ch in line.expandtabs(1))
    start, width = caret(span, line)
    if len(line) > EXCERPT_WIDTH:
        width = min(width, EXCERPT_WIDTH // 2)
        begin = max(0, min(start - EXCERPT_WIDTH // 4, len(line) - EXCERPT_WIDTH))
        end = begin + EXCERPT_WIDTH
        head, tail = ("…" if begin else ""), ("…" if end < len(line) else "")
        line, start = head + line[begin:end] + tail, start - begin + len(head)
    return Excerpt(f"{span.line:>5} | ", line, start, width)


def _excerpt(span: Span, sources: Mapping[str, str] | None) -> list[str]:
    shown = excerpt(span, sources)
    return [] if shown is None else shown.lines()


class MissionError(MissionInputError):
    """A mission (or one of its imports) has errors. Carries every diagnostic found."""

    def __init__(self, diagnostics: Sequence[Diagnostic], sources: Mapping[str, str] | None = None):
        self.diagnostics = tuple(diagnostics)
        self.sources = dict(sources or {})
        super().__init__(self.render())

    def render(self) -> str:
        return "\n".join(d.render(self.sources) for d in self.diagnostics)


class OverBudget(Exception):  # noqa: N818 - a signal between the compiler's stages, never shown as such
    """Compiling went past its time budget (`Reporter.budget`): raised where it was, so the compiler stops there and
    reports it at that place (the file's name is filled in by whoever knows it)."""

    def __init__(self, span: Span) -> None:
        super().__init__(str(span))
        self.span = span


@dataclass
class Reporter:
    """Collects diagnostics during one compilation; the single place that records errors.

    `budget` (seconds, from the reporter's creation) bounds a compilation a controller does for someone else: the
    stages call `check_budget` as they go, and past it the compiler stops with one located error instead of
    holding a core for as long as the input makes it."""

    diagnostics: list[Diagnostic] = field(default_factory=list)
    budget: float | None = None
    limits: Limits = DEFAULT_LIMITS
    deadline: float = field(init=False, default=float("inf"))
    #: Error codes not reported (`dsl.compile_program`: what a file that could not be imported may have declared).
    quiet: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        if self.budget is not None:
            self.deadline = time.monotonic() + self.budget

    def check_budget(self, span: Span) -> None:
        """Raise `OverBudget` at `span` if the budget is spent."""
        if time.monotonic() > self.deadline:
            raise OverBudget(span)

    def over_budget(self, stop: OverBudget) -> None:
        """Report the stop `stop` (once)."""
        if not any(d.code == "budget" for d in self.diagnostics):
            self.error("budget", f"compiling stopped here: it took longer than its budget of {self.budget:g} s",
                       stop.span, "split the mission into smaller files, or run it with `missionctl dry-run`,"
                       " which has no budget")

    def error(self, code: str, message: str, span: Span, hint: str | None = None,
              notes: Iterable[tuple[str, Span]] = ()) -> None:
        if code not in self.quiet:
            self.diagnostics.append(Diagnostic(code, message, span, hint, tuple(notes)))

    def warning(self, code: str, message: str, span: Span, hint: str | None = None) -> None:
        """A warning, once: a behavior used twice is built twice, and its warnings would be said twice, at one place
        (users audit 25, D5)."""
        found = Diagnostic(code, message, span, hint, severity=Severity.WARNING)
        if found not in self.diagnostics:
            self.diagnostics.append(found)

    @property
    def failed(self) -> bool:
        return any(d.severity is Severity.ERROR for d in self.diagnostics)


#: How other languages spell the value types (`string` in a manifest written after a JSON schema): named for what
#: they are here, where no close spelling is.
OTHER_SPELLINGS = {"string": "str", "integer": "int", "boolean": "bool", "double": "float", "number": "float",
                   "real": "float", "time": "duration"}


def did_you_mean(name: str, candidates: Iterable[str], max_distance: int = 2) -> str | None:
    """`did you mean X?` for the closest candidate within `max_distance` edits (or a value type's other spelling,
    `OTHER_SPELLINGS`), else None."""
    candidates = set(candidates)
    other = OTHER_SPELLINGS.get(name.lower())
    if other is not None and other in candidates:
        return f"did you mean {other}?"
    best: tuple[int, str] | None = None
    for cand in sorted(candidates):
        if abs(len(cand) - len(name)) > max_distance:
            continue
        d = edit_distance(name.lower(), cand.lower()) if name.lower() != cand.lower() else 0
        if d <= max_distance and (best is None or d < best[0]):
            best = (d, cand)
    return f"did you mean {best[1]}?" if best and best[1] != name else None


def edit_distance(a: str, b: str) -> int:
    """Damerau-Levenshtein (optimal string alignment) distance."""
    prev2: list[int] = []
    prev = list(range(len(b) + 1))
    for i, ca in enumerate(a, 1):
        cur = [i] + [0] * len(b)
        for j, cb in enumerate(b, 1):
            cost = 0 if ca == cb else 1
            cur[j] = min(prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + cost)
            if i > 1 and j > 1 and ca == b[j - 2] and a[i - 2] == cb:
                cur[j] = min(cur[j], prev2[j - 2] + 1)
        prev2, prev = prev, cur
    return prev[-1]
