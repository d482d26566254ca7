"""What every command shares: consoles, exit codes, error rendering, the safety net.

No traceback reaches a user: `run_app` turns anything unexpected into one clear line and
exit code 2 (set `DRD_DEBUG=1` to see the traceback instead).
"""

from __future__ import annotations

import json
import os
import sys
import traceback
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import typer
from rich.console import Console
from rich.text import Text

if TYPE_CHECKING:  # the mission language loads only for the commands that use it
    from dsl.catalog import Catalog
    from dsl.errors import Diagnostic

#: Exit codes, the same for every command.
OK, MISSION_FAILED, INVALID = 0, 1, 2
#: The reader of our output went away (`missionctl status | head`): 128 + SIGPIPE, as a shell tool killed by it.
BROKEN_PIPE = 141


def _reader_gone() -> NoReturn:
    """Stop writing to a closed pipe, quietly (Python's own note on SIGPIPE): later writes go nowhere."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    sys.exit(BROKEN_PIPE)


class _Console(Console):
    """rich's Console, ending on a closed pipe with `BROKEN_PIPE`: rich's own exit code, 1, means a failed mission."""

    def on_broken_pipe(self) -> None:
        self.quiet = True
        _reader_gone()


out = _Console(highlight=False, soft_wrap=True)
err = _Console(stderr=True, highlight=False, soft_wrap=True)

ComponentsOption = typer.Option(
    None, "--components", "-C", help="Extra folder of component manifests (repeatable; also $DRD_COMPONENTS).",
    show_default=False)


def debug() -> bool:
    return os.environ.get("DRD_DEBUG", "") not in ("", "0")


def fail(message: str, code: int = INVALID, hint: str | None = None) -> NoReturn:
    """Print a one-line error (and a hint) to stderr and exit."""
    err.print(Text.assemble(("error: ", "bold red"), message))
    if hint:
        err.print(Text.assemble(("  hint: ", "cyan"), hint))
    raise typer.Exit(code)


def catalog(extra: Sequence[Path] | None) -> Catalog:
    """The component catalog, or a clear exit naming the bad manifest file and key."""
    from drd.manifests import ManifestError, default_dirs, load_catalog

    dirs = default_dirs() + [Path(p) for p in extra or ()]
    for d in extra or ():
        if not Path(d).is_dir():
            fail(f"--components {d}: no such folder")
    try:
        return load_catalog(dirs)
    except ManifestError as e:
        for p in e.problems:
            err.print(Text.assemble(("error: ", "bold red"), str(p)))
        raise typer.Exit(INVALID) from None


def print_json(data: Any, default: Callable[[Any], Any] | None = None) -> None:
    """Print `data` as indented JSON on stdout: highlighted on a terminal, else plain `json.dumps`.

    To a pipe or a file the text is exactly what rich's `print_json` writes there, without
    importing and running rich's JSON renderer (a tenth of a second for a cluster's status).
    """
    text = json.dumps(data, default=default)
    if out.is_terminal:
        out.print_json(text)
        return
    try:
        sys.stdout.write(json.dumps(json.loads(text), indent=2, ensure_ascii=False) + "\n")
        sys.stdout.flush()
    except BrokenPipeError:  # here, not in run_app: click would make it exit 1 first
        _reader_gone()


def render_diagnostic(d: Diagnostic, sources: Mapping[str, str], console: Console = err) -> None:
    """file:line:col, the message, the source line with a caret, notes and the hint."""
    from dsl.errors import Severity, caret, source_line

    colour = "red" if d.severity is Severity.ERROR else "yellow"
    console.print(Text.assemble((f"{d.span}: ", "bold"), (f"{d.severity.value}: ", f"bold {colour}"), d.message))
    line = source_line(d.span, sources)
    if line is not None:
        line = "".join(ch if ch.isprintable() else "\ufffd" for ch in line.expandtabs(1))
        start, width = caret(d.span, line)
        gutter = f"{d.span.line:>5} | "
        console.print(Text(gutter, style="dim") + Text(line))
        console.print(Text(" " * (len(gutter) - 2) + "| ", style="dim") + Text(" " * start + "^" * width,
                                                                                  style=f"bold {colour}"))
    for text, where in d.notes:
        console.print(Text.assemble(("  note: ", "dim"), f"{where}: {text}"))
    if d.hint:
        console.print(Text.assemble(("  hint: ", "cyan"), d.hint))


def version() -> str:
    """The installed distribution's version (the source tree's pyproject.toml says the same)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        return installed("drd")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown (not installed)"


def run_app(app: Callable[..., object], prog: str,
            fast: Callable[[Sequence[str]], Callable[[], object] | None] | None = None) -> NoReturn:
    """Run a typer app with the safety net: clean errors, documented exit codes.

    `fast(argv)` may return the call of a command it parsed itself (see `drd.cli.cluster.fast_command`):
    it then runs without typer building its parameters; otherwise (None) typer parses as usual.
    """
    if sys.argv[1:] == ["--version"]:  # before typer: a callback would cost every command its fast path
        out.print(f"{prog} (drd) {version()}", highlight=False)
        sys.exit(OK)
    try:
        call = fast(sys.argv[1:]) if fast is not None else None
        if call is not None:
            try:
                rc = call()
            except KeyboardInterrupt:  # as typer does for a command it runs
                rc = 130
        else:
            rc = app(prog_name=prog, standalone_mode=False)
    except typer.Exit as e:
        sys.exit(e.exit_code)
    except typer.Abort:
        err.print("aborted")
        sys.exit(130)
    except KeyboardInterrupt:
        err.print("interrupted")
        sys.exit(130)
    except BrokenPipeError:  # a plain print to a reader that went away
        _reader_gone()
    except Exception as e:  # the last line of defence: never a traceback for a user
        show = getattr(e, "show", None)
        if callable(show) and isinstance(getattr(e, "exit_code", None), int):
            show()  # a usage error or a bad value: click's (or typer's own click's) message and usage line
        elif debug():
            traceback.print_exc()
        else:
            err.print(Text.assemble(("error: ", "bold red"), f"{type(e).__name__}: {e}"))
            err.print(Text("  (set DRD_DEBUG=1 to see the traceback)", style="dim"))
        sys.exit(INVALID)
    sys.exit(rc if isinstance(rc, int) else OK)

