"""Text that came from elsewhere (a peer, a file), shown without the control characters a terminal or a log reader
would act on: each is written as its escape (`\\x1b`, `\\n`), so it reads as what it was and does nothing. One table
for every place that shows such text: the CLI's consoles and the daemon's log."""

from __future__ import annotations

#: Newline, carriage return and tab as a string literal writes them; any other control character as `\xNN`.
_NAMED = {0x0A: "\\n", 0x0D: "\\r", 0x09: "\\t"}


def escapes(keep: str = "") -> dict[int, str]:
    """A `str.translate` table that escapes C0, DEL and C1, but the characters of `keep` (a console keeps its own
    newlines and tabs; a log line keeps none)."""
    table = {c: _NAMED.get(c, f"\\x{c:02x}") for c in (*range(0x00, 0x20), *range(0x7F, 0xA0))}
    for ch in keep:
        table.pop(ord(ch), None)
    return table
