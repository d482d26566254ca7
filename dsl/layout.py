"""The post-lexer: where newlines count, and which `/` and `;` start or separate actions.

Newlines end items, except inside `( )` and `[ ]`, so long argument lists may wrap.
`;` is an item separator too, except inside a transition's action list:
`A -> B / set x = 1; log "y"`. An action list starts at a `/` followed by an action
keyword (`set emit release log` are reserved, so `x / set` can never be a division) and
its `;` are those followed by an action keyword. One token of look-ahead decides both.

The state lives on the instance, not in the generator, because lark starts a fresh
`process()` when it resumes after a syntax error: a token already pulled for look-ahead
must not be lost, or one error would cascade into the next line.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from itertools import chain

from lark import Token
from lark.lark import PostLex

from dsl.errors import OverBudget, Span

OPENERS = {"LPAR", "LSQB"}
CLOSERS = {"RPAR", "RSQB"}
#: The budget is looked at every this many tokens (a clock read per token would cost more than the check is worth).
BUDGET_EVERY = 1024
ACTION_KEYWORDS = {"SET", "EMIT", "RELEASE", "LOG"}


class Layout(PostLex):
    """Drops, folds and retypes separator tokens; remembers the last tokens for errors."""

    always_accept = ("_SEP", "SLASH")

    def __init__(self) -> None:
        self.reset()

    def reset(self, deadline: float = float("inf")) -> None:
        """Forget everything: called before each parse. Past `deadline` (`time.monotonic`), `OverBudget` is raised
        at the token reached."""
        self.history: list[Token] = []
        self.pending: list[Token] = []  # pulled from the lexer, not yet given to the parser
        self.openers: list[Token] = []  # the `(` and `[` not closed yet, innermost last (where one was left open)
        self.deadline = deadline
        self.count = 0
        self.emitted = 0  # tokens given to the parser: which one an error is at (`dsl.parser._Recovery`)

    def save(self) -> tuple[list[Token], list[Token], list[Token]]:
        return self.history, self.pending, self.openers

    def restore(self, state: tuple[list[Token], list[Token], list[Token]]) -> None:
        self.history, self.pending, self.openers = state

    def process(self, stream: Iterator[Token]) -> Iterator[Token]:
        replay, self.pending = self.pending, []
        held: Token | None = None  # a _SEP or SLASH waiting for the next token
        for tok in chain(replay, stream):
            kind = tok.type
            self.count += 1
            if not self.count % BUDGET_EVERY and time.monotonic() > self.deadline:
                line, column = tok.line or 1, tok.column or 1
                raise OverBudget(Span("", line, column, line, column + max(1, len(tok.value))))
            if kind == "_SEP":
                if self.openers:
                    continue
                if held is not None and held.type == "_SEP":  # fold a run into one
                    held = Token.new_borrow_pos("_SEP", held.value + tok.value, held)
                    continue
            if held is not None:
                self.pending = [tok]
                yield self._emit(_resolve(held, tok))
                self.pending = []
                held = None
            if kind in OPENERS:
                self.openers.append(tok)
            elif kind in CLOSERS and self.openers:
                self.openers.pop()
            if kind in ("_SEP", "SLASH"):
                held = tok
                continue
            yield self._emit(tok)
        if held is not None:
            yield self._emit(held)

    def _emit(self, tok: Token) -> Token:
        self.emitted += 1
        self.history.append(tok)
        if len(self.history) > 4:
            del self.history[0]
        return tok


def _resolve(held: Token, nxt: Token) -> Token:
    """Retype a held `/` or `;` by the token that follows it."""
    if nxt.type not in ACTION_KEYWORDS:
        return held
    if held.type == "SLASH":
        return Token.new_borrow_pos("ACTION_SLASH", held.value, held)
    if "\n" not in held.value:
        return Token.new_borrow_pos("ACTION_SEMI", held.value, held)
    return held
