"""Reading mission files and their imports: the only module of `dsl` that touches the disk."""

from __future__ import annotations

import codecs
import os
import stat
from collections.abc import Collection, Mapping
from pathlib import Path

from dsl.checker import Program
from dsl.errors import Reporter, Span
from dsl.parser import parse

#: Larger files are refused before parsing (a mission is text a person writes; compiling costs about 4 us a byte,
#: so 1 MiB is about 4 s of a controller's time).
MAX_FILE_BYTES = 1024 * 1024


def _not_regular(mode: int) -> str:
    """What a file that is not a regular file is ('' for a regular file)."""
    kinds = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
             (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))
    return next((name for test, name in kinds if test(mode)), "" if stat.S_ISREG(mode) else "not a file")


def decode(data: bytes, file: str, report: Reporter) -> str:
    """UTF-8 text (without the byte order mark some editors write first: lines and columns are counted after it,
    as the editor shows them), or a located error at the first bad byte (and the text with replacements)."""
    if data.startswith(codecs.BOM_UTF8):  # stripped here, not by the `utf-8-sig` codec: its errors' positions
        data = data[len(codecs.BOM_UTF8):]  # would be relative to the text after it, this function's to `data`
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        line_start = data.rfind(b"\n", 0, e.start) + 1
        col = len(data[line_start:e.start].decode("utf-8", "replace")) + 1  # in characters, like every column
        report.error("encoding", f"not valid UTF-8: byte 0x{data[e.start]:02x} cannot start or continue a character",
                     Span(file, line, col, line, col + 1), "save the file as UTF-8")
        return data.decode("utf-8", errors="replace")


def load_text(text: str, file: str, report: Reporter, base: Path | None = None,
              imports: Mapping[str, str] | None = None, aliases: Mapping[str, str] | None = None) -> Program:
    """Parse `text` as the main file. Its imports are read from the disk relative to `base` (default: the cwd) or,
    given `imports` (file name -> text, named as `load_file` names them: `imported_texts`), from there only: the
    controller compiles what a client sent, relative to the main file's name, and never reads a file of its own
    disk for it (users audit 12, D1: imports were read from the controller's working directory); `aliases` (name ->
    name, `import_aliases`) are the other names the client's disk gave a file it sent once."""
    program = Program(file, {}, {})
    if imports is None:
        _add(program, text, file, base or Path.cwd(), report)
    else:
        _add(program, text, file, Path(file).parent, report, sent=imports, aliases=aliases or {})
    return program


def imported_texts(program: Program) -> dict[str, str]:
    """The texts of the files a loaded program imports, by the names `load_text(imports=...)` looks them up by (a file
    that could not be read is there as "": its error is the loader's report's)."""
    return {name: text for name, text in program.sources.items() if name != program.main}


def import_aliases(program: Program) -> dict[str, str]:
    """The other names an import statement gives a file already read under one (`../app/sub/b.mission` for
    `sub/b.mission`, a symlink): name -> the name it was read under, for `load_text(aliases=...)`, so a controller
    compiles it once (reverify audit 14, D1: the second name was "not sent with the mission")."""
    out: dict[str, str] = {}
    for name, tree in program.files.items():
        for imp in tree.imports:
            key = str(Path(name).parent / imp.path)
            if key not in program.sources:
                same = _same_file(program, Path(key))
                if same is not None:
                    out[key] = same
    return out


def load_file(path: str | Path, report: Reporter) -> Program:
    """Read and parse a mission file and, recursively, the files it imports."""
    path = Path(path)
    name = str(path)
    program = Program(name, {}, {})
    text = _read(path, name, report, None)
    if text is not None:
        _add(program, text, name, path.parent, report)
    return program


def _read(path: Path, name: str, report: Reporter, at: Span | None) -> str | None:
    """A mission file's text: a regular file only (a FIFO would block, a device never end), read up to the size
    limit whatever its size says (it may grow while read)."""
    where = at or Span(name, 1, 1, 1, 1)
    try:
        kind = _not_regular(path.stat().st_mode)
        if kind:
            report.error("io", f"{name} is {kind}, not a regular file", where, "give the path of a .mission file")
            return None
        with path.open("rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
        if len(data) > MAX_FILE_BYTES:
            report.error("io", f"{name} is larger than {MAX_FILE_BYTES // 2**20} MiB (a mission is text a person "
                               "writes; split a generated one into imports)", where)
            return None
    except (OSError, ValueError) as e:  # ValueError: a NUL byte in the path
        what = "cannot read imported file" if at else "cannot read"
        reason = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
        report.error("io", f"{what} {name!r}: {reason}" if "\x00" in name else f"{what} {name}: {reason}", where)
        return None
    return decode(data, name, report)


#: What a file that is not a mission usually is, by its suffix (a user passing hosts.yaml or a README).
_NOT_MISSIONS = {".yaml": "a YAML file", ".yml": "a YAML file", ".json": "a JSON file", ".md": "a Markdown file",
                 ".txt": "a text file", ".py": "a Python file"}


def _not_a_mission(name: str, report: Reporter) -> bool:
    """A main file of a known other format (by its suffix) gets one clear error instead of a syntax error at its
    first line."""
    kind = _NOT_MISSIONS.get(Path(name).suffix.lower())
    if kind is not None:
        report.error("not-a-mission", f"{name} is {kind}, not a mission", Span(name, 1, 1, 1, 1),
                     "give a .mission file (`mission Name { ... }`); a hosts file goes to --config")
    return kind is not None


#: Files deep in one chain of imports, at most (each level is a Python frame of `_add`).
MAX_IMPORT_DEPTH = 64


def _same_file(program: Program, target: Path, on_disk: bool = True,
               aliases: Mapping[str, str] | None = None) -> str | None:
    """The name under which `target` was read already, if it was: compared as paths the system resolves, so
    `sub/../sub/a.mission` is `sub/a.mission` (users audit 9, D2: never recognised, such a cycle recursed until
    the interpreter's stack or the system's file name length gave out); as names only (`normpath`) when the files
    were sent rather than read."""
    if not on_disk:
        alias = (aliases or {}).get(str(target))
        if alias is not None and alias in program.sources:
            return alias
        return _named(program.sources, str(target))
    real = target.resolve()
    return next((name for name in program.sources if Path(name).resolve() == real), None)


def _named(names: Collection[str], key: str) -> str | None:
    """The one of `names` that is `key` as a name (`normpath`: `sub/../a.mission` is `a.mission`), or None."""
    if key in names:
        return key
    plain = os.path.normpath(key)
    return next((name for name in names if os.path.normpath(name) == plain), None)


def _sent(sent: Mapping[str, str], key: str, report: Reporter, at: Span) -> str | None:
    """An imported file's text from those a client sent with the mission, or a located error."""
    name = _named(sent, key)
    text = None if name is None else sent[name]
    if text is None:
        report.error("io", f"cannot read imported file {key}: it was not sent with the mission", at,
                     "missionctl run sends the files a mission imports, read relative to the importing file; "
                     "check that the file is there")
    return text


def _add(program: Program, text: str, name: str, base: Path, report: Reporter, main: bool = True,
         depth: int = 0, sent: Mapping[str, str] | None = None, aliases: Mapping[str, str] | None = None) -> None:
    program.sources[name] = text
    if main and _not_a_mission(name, report):
        return
    tree, errors = parse(text, name, report if report.budget is not None else None)
    report.diagnostics.extend(errors)
    if tree is None:
        return
    if main and not errors and not tree.imports and not tree.behaviors:
        report.error("empty", f"{name} declares no mission: it is empty or only comments", Span(name, 1, 1, 1, 1),
                     "write `mission Name { ... }` (docs/language.md, section 1)")
        return
    program.files[name] = tree
    for imp in tree.imports:
        target = base / imp.path
        key = str(target)
        if key in program.sources or _same_file(program, target, sent is None, aliases) is not None:
            continue
        if depth >= MAX_IMPORT_DEPTH:
            report.error("import", f"imports nest more than {MAX_IMPORT_DEPTH} files deep", imp.span,
                         "import the shared files from the main mission instead of through a chain")
            return
        sub = _read(target, key, report, imp.span) if sent is None else _sent(sent, key, report, imp.span)
        if sub is None:
            program.sources[key] = ""
            continue
        _add(program, sub, key, target.parent, report, main=False, depth=depth + 1, sent=sent, aliases=aliases)
