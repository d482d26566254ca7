"""Which `{` was never closed: the block a "missing `}`" error should name.

The parser only learns that a `}` is missing where the next declaration starts or the file ends, often far
below the block the user forgot to close. Indentation says which one it was: a block whose `}` is less indented
than the line that opened it was probably closed by its parent's brace, and a line as little indented as a
block's opening line, inside that block, should have come after its `}`. Pure text scanning; strings and
comments are skipped.
"""

from __future__ import annotations

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class Opener:
    """A `{` (1-based line and column), the start of its line (`mission Patrol`, `parallel all`), and the line its
    `}` should have come before, when indentation says (else 0)."""

    line: int
    column: int
    header: str
    close_before: int = 0


def unclosed_block(text: str, before_line: int) -> Opener | None:
    """The block most likely left open by the line `before_line` (where the parser noticed), or None if every
    `{` before it is closed."""
    lines = [line.removesuffix("\r") for line in text.split("\n")]  # as the lexer counts lines: \n only
    stack: list[tuple[Opener, int]] = []  # the open blocks, innermost last, with their line's indentation
    suspects: list[Opener] = []
    for number, raw in enumerate(lines[:max(0, before_line - 1)], start=1):
        code = _code(raw)
        stripped = code.strip()
        if not stripped:
            continue
        indent = len(code) - len(code.lstrip())
        if not stripped.startswith("}"):
            for opener, own in reversed(stack):  # a sibling of a block, written inside it
                if number > opener.line and indent <= own:
                    suspects.append(replace(opener, close_before=number))
                    break
        for column, ch in enumerate(code, start=1):
            if ch == "{":
                stack.append((Opener(number, column, code[:column - 1].strip() or "{"), indent))
            elif ch == "}" and stack:
                opener, own = stack.pop()
                if code[:column - 1].strip() == "" and indent < own:  # closed by a brace less indented than it
                    suspects.append(replace(opener, close_before=number))
    if not stack:
        return None
    return suspects[0] if suspects else stack[-1][0]


def _code(line: str) -> str:
    """The line without its comment and with each string's contents blanked (braces inside them are text)."""
    out: list[str] = []
    quoted = escaped = False
    for ch in line:
        if quoted:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                quoted = False
            out.append(" " if quoted else ch)
            continue
        if ch == "#":
            break
        if ch == '"':
            quoted = True
        out.append(ch)
    return "".join(out)
