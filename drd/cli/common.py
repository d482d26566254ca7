"""What every command shares: consoles, exit codes, error rendering, the safety net.

No traceback reaches a user: `run_app` turns anything unexpected into one clear line and
exit code 70 (2 for a file the system could not read or write; set `DRD_DEBUG=1` to see the
traceback instead). With `--json` on the command line every error is one JSON object on
stderr instead (`{"error": ..., "code": ...}`, docs/cli.md), so a script reads stdout as the
result and stderr as what went wrong, whatever happened.
"""

from __future__ import annotations

import io
import json
import os
import sys
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, NoReturn

import typer
from rich.console import Console
from rich.segment import Segment
from rich.text import Text

from drd import outputs
from drd.errors import DrdError, debugging
from drd.inert import escapes
from drd.runtime.trace import finite

if TYPE_CHECKING:  # the mission language loads only for the commands that use it
    from drd.record import Recorder
    from dsl import Compiled
    from dsl.catalog import Catalog
    from dsl.errors import Diagnostic

#: Exit codes, the same for every command.
OK, MISSION_FAILED, INVALID = 0, 1, 2
#: A bug of ours, not the user's input (sysexits' EX_SOFTWARE): the one-line error asks for DRD_DEBUG=1.
INTERNAL = 70
#: Ctrl-C before anything ran (128 + SIGINT, as a shell tool).
INTERRUPTED = 130
#: The reader of our output went away (`missionctl status | head`): 128 + SIGPIPE, as a shell tool killed by it.
BROKEN_PIPE = 141


def _reader_gone() -> NoReturn:
    """Stop writing to a closed pipe, quietly (Python's own note on SIGPIPE): later writes go nowhere."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    sys.exit(BROKEN_PIPE)


#: The control characters a terminal acts on (C0 but newline and tab, DEL, C1), each shown as its escape instead.
_INERT = escapes(keep="\n\t")


class InertConsole(Console):
    """rich's Console, ending on a closed pipe with `BROKEN_PIPE` (rich's own exit code, 1, means a failed mission),
    and printing text as inert: a control character in what it prints shows as `\x1b`, so a name, a reason or an
    event field from the wire cannot clear the operator's screen, paint over a report or set the clipboard (wire
    audit 25, D2). rich's own control segments (a live display's cursor moves) and styles pass as they are."""

    def on_broken_pipe(self) -> None:
        self.quiet = True
        _reader_gone()

    def _render_buffer(self, buffer: Iterable[Segment]) -> str:
        return super()._render_buffer(
            Segment(text.translate(_INERT), style, control) if control is None else Segment(text, style, control)
            for text, style, control in buffer)


out = InertConsole(highlight=False, soft_wrap=True)
err = InertConsole(stderr=True, highlight=False, soft_wrap=True)



def debug() -> bool:
    return debugging()


class _Mode:
    """How errors are written: set once per command by `run_app` (from `--json` on its command line)."""

    json = False


def json_errors(on: bool = True) -> None:
    """Write errors as JSON objects on stderr (`--json` commands), or as text (the default)."""
    _Mode.json = on


def wants_json(argv: Sequence[str]) -> bool:
    """Does this command line ask for JSON (`--json` before any `--`)? Then its errors are JSON too."""
    for word in argv:
        if word == "--":
            return False
        if word == "--json":
            return True
    return False


def error_json(data: Mapping[str, Any]) -> None:
    """One error as one JSON line on stderr (what `fail` writes under `--json`)."""
    sys.stderr.write(json.dumps(dict(data), ensure_ascii=False, default=str) + "\n")
    sys.stderr.flush()


def fail(message: str, code: int = INVALID, hint: str | None = None, **extra: Any) -> NoReturn:
    """Print a one-line error (and a hint) to stderr and exit; under `--json` the same as one JSON object,
    `{"error": message, "code": code, "hint": hint, ...extra}`."""
    if _Mode.json:
        error_json({"error": message, "code": code, **({"hint": hint} if hint else {}), **extra})
        raise typer.Exit(code)
    err.print(Text.assemble(("error: ", "bold red"), message))
    if hint:
        err.print(Text.assemble(("  hint: ", "cyan"), hint))
    raise typer.Exit(code)


def fail_all(problems: Sequence[object], code: int = INVALID, hint: str | None = None) -> NoReturn:
    """Several problems found at once (a hosts file's, a world's): each on its line, or one JSON object whose
    `errors` lists them."""
    lines = [line for p in problems for line in str(p).splitlines()] or ["invalid input"]
    if _Mode.json:
        fail(lines[0] if len(lines) == 1 else f"{len(lines)} problems: {lines[0]}", code, hint, errors=lines)
    for line in lines[:-1]:
        err.print(Text.assemble(("error: ", "bold red"), line))
    fail(lines[-1], code, hint)


def show_diagnostics(results: Sequence[Compiled]) -> bool:
    """Show what the compiler found in each file (errors and warnings): rendered with the source line, or under
    `--json` as one JSON error with every diagnostic when one is an error (warnings alone say nothing there, as
    `validate --json` has them). True when every file is valid."""
    ok = all(r.ok for r in results)
    if _Mode.json:
        if not ok:
            diagnostics = [d.to_dict() for r in results for d in r.diagnostics]
            bad = [r.file for r in results if not r.ok]
            first = next(d for r in results for d in r.diagnostics if d.severity.value == "error")
            error_json({"error": f"{', '.join(bad)}: invalid: {first.span}: {first.message}", "code": INVALID,
                        "diagnostics": diagnostics})
        return ok
    for r in results:
        render_diagnostics(r.diagnostics, r.sources)
    return ok


def fail_diagnostics(diagnostics: Sequence[Diagnostic], sources: Mapping[str, str]) -> NoReturn:
    """Errors found in a mission before it could be compiled (not a mission, empty, unreadable): rendered, or one
    JSON error under `--json`; exit 2."""
    if _Mode.json:
        first = diagnostics[0]
        fail(f"{first.span}: {first.message}", INVALID, first.hint, diagnostics=[d.to_dict() for d in diagnostics])
    render_diagnostics(diagnostics, sources)
    raise typer.Exit(INVALID)


def as_text(renderable: object, width: int = 120) -> str:
    """What a renderable prints as, in plain text (for a test, or a log)."""
    console = Console(width=width, color_system=None, record=True, file=io.StringIO())
    console.print(renderable)
    return console.export_text()


def duration_text(seconds: float) -> str:
    """Seconds as the mission language writes them: `90s`, `2min`, `1h`, `500ms`."""
    for unit, size in (("h", 3600), ("min", 60), ("s", 1)):
        if seconds >= size and seconds % size == 0:
            return f"{int(seconds // size)}{unit}"
    return f"{seconds * 1000:g}ms" if 0 < seconds < 1 else f"{seconds:g}s"


def wrap_cut(text: str, width: int, lines: int) -> list[str]:
    """`text` wrapped at spaces to lines of at most `width`, at most `lines` of them, the last cut with `…` when
    more is left: a long reason reads whole in a few lines, and a very long one still says it was cut."""
    import textwrap

    # only what the lines can show is wrapped: textwrap splits a long word in time quadratic in its length (a 10 MB
    # log line took 45 s to print: records audit 26, D6)
    limit = lines * (max(2, width) + 1) + 1
    wrapped = textwrap.wrap(text[:limit], max(2, width), break_on_hyphens=False) or [""]
    if len(wrapped) <= lines and len(text) <= limit:
        return wrapped
    last = " ".join(wrapped[lines - 1:])
    return wrapped[:lines - 1] + [last[:max(1, width - 1)].rstrip() + "…"]


def shorten(path: str, width: int) -> str:
    """A path in at most `width` characters, cut from the middle: its first step, `…`, and as many of its last
    steps as fit (`RoomSurveillance[0]/…/FollowCorridor`), else the start of the first step
    (`CorridorSurveillance/RoomSurveillance[2]/HideInCorner/Watch` -> `Corridor…/Watch`). The leaf is what a
    reader looks for, the start says which mission or instance."""
    if len(path) <= width:
        return path
    steps = path.split("/")
    if len(steps) > 2:
        keep = 0
        while keep < len(steps) - 2 and len(steps[0]) + 3 + len("/".join(steps[-keep - 1:])) <= width:
            keep += 1
        if keep:
            return steps[0] + "/…/" + "/".join(steps[-keep:])
    tail = steps[-1]
    room = width - len(tail) - 2
    if len(steps) > 1 and room >= 3:
        return path[:room] + "…/" + tail
    if len(steps) > 1 and room >= 0:
        return "…/" + tail
    if width < 3:
        return path[:width]
    half = (width - 1) // 2
    return path[:width - 1 - half] + "…" + path[len(path) - half:]


class OutputFile(io.TextIOWrapper):
    """A file a run writes as it goes (`--trace`): a write error after it opened (a full disk, EIO) stops the file
    there, not the run, and leaves one line naming the file that the command says after its report (`unwritten`)."""

    def __init__(self, path: Path, what: str) -> None:
        super().__init__(path.open("wb"), encoding="utf-8")
        self.path, self.what, self.error = path, what, ""

    def write(self, text: str) -> int:
        if not self.error:
            try:
                return super().write(text)
            except OSError as e:
                self.failed(e)
        return len(text)

    def flush(self) -> None:
        if not self.error and not self.closed:
            try:
                super().flush()
            except OSError as e:
                self.failed(e)

    def close(self) -> None:
        try:
            super().close()  # the buffer's file is closed even when its last flush fails
        except OSError as e:
            self.failed(e)

    def failed(self, e: OSError) -> None:
        if not self.error:
            self.error = f"{self.path}: cannot write the {self.what}: {e.strerror or e}; it stops there"
            outputs.failed(self.error)


def open_trace(trace: Path | None) -> IO[str] | None:
    """The `--trace` file opened for writing (`OutputFile`), or a clear exit when it cannot be (None when not
    asked)."""
    try:
        return OutputFile(trace, "trace") if trace is not None else None
    except OSError as e:
        fail(f"{trace}: cannot write the trace: {e.strerror or e}")


def distinct_files(inputs: Mapping[str, Sequence[Path | None]], outputs: Mapping[str, Path | None]) -> None:
    """Refuse, before anything runs (exit 2), an output file that is one of the command's inputs or another of its
    outputs: writing it would destroy the input (a `--trace` over the mission file, a `replay --trace` over the
    recording) or mix two outputs in one file that is neither (cli audit 24, #2). Paths are compared as the
    system resolves them (links, `..`)."""
    seen: dict[str | tuple[int, int], str] = {}  # resolved path, and (device, inode) if it exists -> what it is
    for what, paths in inputs.items():
        for path in paths:
            if path is not None:
                for key in _file_keys(path):
                    seen.setdefault(key, what)
    for option, path in outputs.items():
        if path is None:
            continue
        keys = _file_keys(path)
        if (same := next((seen[k] for k in keys if k in seen), None)) is not None:
            fail(f"{option} {path}: it is {same}; writing it there would destroy it", hint="give another path")
        for key in keys:
            seen[key] = f"the {option} file"


def _file_keys(path: Path) -> list[str | tuple[int, int]]:
    """What names one file: its resolved path (links, `..`), and, if it exists, its device and inode (a hard
    link to it has another path)."""
    try:
        st = os.stat(path)
    except OSError:
        return [os.path.realpath(path)]
    return [os.path.realpath(path), (st.st_dev, st.st_ino)]


def write_file(path: Path, text: str, what: str) -> None:
    """Write `text` to `path` (`plan -o`), or a clear exit naming the file (a missing folder, a full disk)."""
    try:
        with path.open("w", encoding="utf-8") as fh:
            fh.write(text)
    except OSError as e:
        fail(f"{path}: cannot write the {what}: {e.strerror or e}")


def open_recorder(path: Path | None) -> Recorder | None:
    """The `--record` file's writer (`drd.record`), or a clear exit when it cannot be written (None when not
    asked)."""
    if path is None:
        return None
    from drd.record import Recorder, RecordingError

    try:
        return Recorder(path)
    except RecordingError as e:
        fail(str(e))


def catalog(extra: Sequence[Path] | None) -> Catalog:
    """The component catalog, or a clear exit naming the bad manifest file and key."""
    from drd.manifests import ManifestError, default_dirs, load_catalog

    dirs = default_dirs() + [Path(p) for p in extra or ()]
    for d in extra or ():
        if not Path(d).is_dir():
            fail(f"--components {d}: " + ("not a folder (a folder of component manifests is expected)"
                                          if Path(d).exists() else "no such folder"))
    try:
        return load_catalog(dirs)
    except ManifestError as e:
        fail_all(e.problems)


def utf8_json(data: Any, default: Callable[[Any], Any] | None = None) -> str:
    """`data` as indented JSON, text as it is (not `\\u` escapes), unless some string holds bytes that are not UTF-8
    (a file name, `caf\\xe9.mission`, as the system passes it): then escaped, so the output stays UTF-8 JSON that a
    strict reader takes, as the errors on stderr are (cli audit 24, #5)."""
    text = json.dumps(data, indent=2, ensure_ascii=False, default=default)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return json.dumps(data, indent=2, default=default)
    return text


def print_json(data: Any, default: Callable[[Any], Any] | None = None) -> None:
    """Print `data` as indented JSON on stdout: highlighted on a terminal, else plain `json.dumps`.

    To a pipe or a file the text is exactly what rich's `print_json` writes there, without
    importing and running rich's JSON renderer (a tenth of a second for a cluster's status).
    """
    try:
        text = json.dumps(data, default=default, allow_nan=False)
    except ValueError:  # an inf or a NaN somewhere: JSON has neither, and a strict reader refuses the file
        text = json.dumps(finite(data), default=default, allow_nan=False)
    if out.is_terminal:
        out.print_json(text)
        return
    try:
        sys.stdout.write(utf8_json(json.loads(text)) + "\n")
        sys.stdout.flush()
    except BrokenPipeError:  # here, not in run_app: click would make it exit 1 first
        _reader_gone()


#: Diagnostics shown per file (the rest are counted; `--json` has them all).
SHOWN_ERRORS = 20


def render_diagnostics(diagnostics: Sequence[Diagnostic], sources: Mapping[str, str], console: Console = err,
                       limit: int = SHOWN_ERRORS) -> None:
    """The first `limit` diagnostics rendered, then how many more there are."""
    for d in diagnostics[:limit]:
        render_diagnostic(d, sources, console)
    if len(diagnostics) > limit:
        console.print(Text(f"… and {len(diagnostics) - limit} more (validate --json lists them all)", style="dim"))


def render_diagnostic(d: Diagnostic, sources: Mapping[str, str], console: Console = err) -> None:
    """file:line:col, the message, the source line with a caret (`dsl.errors.excerpt`), notes and the hint."""
    from dsl.errors import Severity, excerpt

    colour = "red" if d.severity is Severity.ERROR else "yellow"
    console.print(Text.assemble((f"{d.span}: ", "bold"), (f"{d.severity.value}: ", f"bold {colour}"), d.message))
    shown = excerpt(d.span, sources)
    if shown is not None:
        console.print(Text(shown.gutter, style="dim") + Text(shown.text))
        console.print(Text(" " * (len(shown.gutter) - 2) + "| ", style="dim")
                      + Text(" " * shown.pad + "^" * shown.width, style=f"bold {colour}"))
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


#: The tools' `--version` callbacks: a command's own options never reach them (typer reads a callback's options
#: before the command's name), so the fast path (`drd.cli.cluster.fast_command`) may run the command without them.
VERSION_CALLBACKS: set[Callable[..., object]] = set()


def version_option(app: typer.Typer, prog: str) -> None:
    """`--version` in the tool's `--help` (docs/cli.md lists it for both tools). `run_app` answers a bare
    `--version` before typer parses anything, so no command pays for it; this option is parsed only among other
    words (`missionctl --version validate x.mission` prints the version, as `git` does)."""

    def show(value: bool) -> None:
        if value:
            out.print(f"{prog} (drd) {version()}", highlight=False)
            raise typer.Exit(OK)

    @app.callback()
    def tool(version_flag: bool = typer.Option(False, "--version", is_eager=True, expose_value=False,
                                               callback=show,
                                               help="Print the installed drd's version and exit (with --json: as "
                                                    "JSON).")) -> None:
        pass

    VERSION_CALLBACKS.add(tool)


def run_app(app: Callable[..., object], prog: str,
            fast: Callable[[Sequence[str]], Callable[[], object] | None] | None = None) -> NoReturn:
    """Run a typer app with the safety net: clean errors, documented exit codes.

    `fast(argv)` may return the call of a command it parsed itself (see `drd.cli.cluster.fast_command`):
    it then runs without typer building its parameters; otherwise (None) typer parses as usual.
    """
    try:
        _run_app(app, prog, fast)
    except SystemExit as e:
        zenoh_bus = sys.modules.get("drd.bus.zenoh_bus")
        if zenoh_bus is not None and zenoh_bus.still_closing():  # see drd.bus.zenoh_bus.still_closing
            end_now(e.code)
        raise


def end_now(code: object) -> NoReturn:
    """End the process without the interpreter's shutdown: a session's close that still runs in zenoh (it waits on
    a peer) would be torn down by it mid-call, and the process would abort ("FATAL: exception not rethrown", exit
    -6) after its output. What the command wrote is flushed first; its files are closed by then."""
    import logging

    logging.shutdown()
    if code is not None and not isinstance(code, int):  # sys.exit("message"), as the interpreter would print it
        print(code, file=sys.stderr)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code if isinstance(code, int) else (0 if code is None else 1))


def _run_app(app: Callable[..., object], prog: str,
             fast: Callable[[Sequence[str]], Callable[[], object] | None] | None) -> NoReturn:
    argv = sys.argv[1:]
    if argv in (["--version"], ["--version", "--json"], ["--json", "--version"]):  # before typer: a callback
        if "--json" in argv:                                                      # would cost every command its
            print_json({"program": prog, "version": version()})                   # fast path
        else:
            out.print(f"{prog} (drd) {version()}", highlight=False)
        sys.exit(OK)
    json_errors(wants_json(argv))
    try:
        call = fast(argv) if fast is not None else None
        if call is not None:
            try:
                rc = call()
            except KeyboardInterrupt:  # as typer does for a command it runs
                rc = INTERRUPTED
        else:
            rc = app(prog_name=prog, standalone_mode=False)
    except typer.Exit as e:
        _said_unwritten(e.exit_code)
        sys.exit(e.exit_code)
    except (typer.Abort, KeyboardInterrupt) as e:
        _error("aborted" if isinstance(e, typer.Abort) else "interrupted", INTERRUPTED)
    except BrokenPipeError:  # a plain print to a reader that went away
        _reader_gone()
    except DrdError as e:  # ours, on purpose: the input or the cluster is wrong, not the code
        if debug():
            traceback.print_exc()
        where = f"{e.where}: " if e.where else ""
        _error(f"{where}{e}", INVALID, f"hint: {e.hint}" if e.hint else "")
    except Exception as e:  # the last line of defence: never a traceback for a user
        show = getattr(e, "show", None)
        code = getattr(e, "exit_code", None)
        if callable(show) and isinstance(code, int):  # a usage error or a bad value: click's message (and usage)
            if _Mode.json:
                error_json({"error": e.format_message() if hasattr(e, "format_message") else str(e), "code": code})
            else:
                show()
            sys.exit(code)
        if debug():
            traceback.print_exc()
            sys.exit(INTERNAL if not isinstance(e, OSError) else INVALID)
        if isinstance(e, OSError):  # a file or folder of the user's that cannot be read or written
            where = f"{e.filename}: " if e.filename else ""
            _error(f"{where}{e.strerror or type(e).__name__ + ': ' + str(e)}", INVALID,
                   "(set DRD_DEBUG=1 to see the traceback)")
        _error(f"internal error: {type(e).__name__}: {e}", INTERNAL,
               "(set DRD_DEBUG=1 to see the traceback, and report it)")
    rc = rc if isinstance(rc, int) else OK
    if rc == INTERRUPTED:  # typer's answer to a Ctrl-C in a command (exit 130, and not a word): said as the others
        _error("interrupted", INTERRUPTED)
    _said_unwritten(rc)
    sys.exit(rc)


def _said_unwritten(code: int) -> None:
    """After the command's own output (its report), the files it could not finish writing, one line each: exit 2
    then (a file the system could not write, as for one it could not open), unless the command already failed."""
    lines = outputs.failures()
    if not lines or code not in (OK, MISSION_FAILED):
        return
    if _Mode.json:
        error_json({"error": lines[0] if len(lines) == 1 else f"{len(lines)} files unwritten: {lines[0]}",
                    "code": INVALID, **({"errors": lines} if len(lines) > 1 else {})})
        sys.exit(INVALID)
    for line in lines:
        err.print(Text.assemble(("error: ", "bold red"), line))
    sys.exit(INVALID)


def _error(message: str, code: int, note: str = "") -> NoReturn:
    """The safety net's own last word: one line (or one JSON object), then exit `code`."""
    if _Mode.json:
        error_json({"error": message, "code": code})
    else:
        err.print(Text.assemble(("error: ", "bold red"), message) if code != INTERRUPTED else Text(message))
        if note:
            err.print(Text(f"  {note}", style="dim"))
    sys.exit(code)

