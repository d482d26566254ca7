"""Text to AST: the LALR parser, its inline transformer, and syntax errors in the user's words.

The transformer runs inside the parser (lark's `transformer=` option), so AST nodes are
built at each reduction and no parse tree is ever materialised: this is both faster and
free of recursion, whatever the nesting depth of the input. Syntax errors are translated
through a table keyed by what came before the bad token (as lark does for its own
grammar language), and the parser recovers by inserting a missing token or skipping a
bad one, so several syntax errors of a file are reported in one run.
"""

from __future__ import annotations

import hashlib
import math
import os
import threading
from collections.abc import Callable, Sequence
from dataclasses import replace
from functools import cache
from importlib import resources
from typing import Any

from lark import Lark, Token, Transformer
from lark.exceptions import UnexpectedCharacters, UnexpectedInput, UnexpectedToken

from dsl import ast
from dsl.ast import KEYWORDS
from dsl.errors import NOWHERE, Diagnostic, OverBudget, Reporter, Span
from dsl.evaluate import INT_DIGITS
from dsl.layout import Layout
from dsl.unclosed import unclosed_block

#: Literals beyond these are errors: no robot mission means them, and Python's own limits (4,300 digits for an
#: int, inf for a float) would otherwise escape as an uncaught error or a silent infinity.
MAX_INT_DIGITS = INT_DIGITS  # the evaluator refuses results beyond them too
MAX_NUMBER = 1e15
MAX_DURATION = 365 * 86400.0

#: Expressions nested deeper than this are rejected (they would only come from a generator).
MAX_EXPR_DEPTH = 100
#: After this many syntax errors in one file the parser stops trying to recover.
MAX_SYNTAX_ERRORS = 10
#: ... and after this many errors met, reported or not (one line of garbage reports one): recovery is bounded.
MAX_RECOVERIES = 50


# Tokens that can start an item or a declaration: when one is acceptable we are between items.
ITEM_STARTS = frozenset({"NAME", "NEEDS", "SHARED", "VAR", "PARALLEL", "PLAN", "START", "MISSION",
                         "BEHAVIOR", "IMPORT", "CONSTRAINT"})

# Tokens that start a declaration at the top of a file: inside a block, one means a `}` is missing above.
DECLARATION_STARTS = frozenset({"MISSION", "BEHAVIOR", "IMPORT"})

_ESCAPES = {"n": "\n", "t": "\t", '"': '"', "\\": "\\", "{": "{", "}": "}"}

# What each terminal is called in a message.
_TERMINAL_WORDS = {
    "NAME": "a name", "INT": "an integer", "FLOAT": "a number", "DURATION": "a duration (e.g. 30s)",
    "STRING": 'a string ("...")', "_SEP": "a newline or ;", "$END": "the end of the file",
    "RBRACE": "`}`", "LBRACE": "`{`", "LPAR": "`(`", "RPAR": "`)`", "LSQB": "`[`", "RSQB": "`]`",
    "COMMA": "`,`", "COLON": "`:`", "EQUAL": "`=`", "DOT": "`.`", "ARROW": "`->`", "CMP": "a comparison",
    "LT": "`<`", "PLUS": "`+`", "MINUS": "`-`", "STAR": "`*`", "SLASH": "`/`", "PERCENT": "`%`",
    "ACTION_SLASH": "`/`", "ACTION_SEMI": "`;`", "__ANON_0": "`..`",
}

# Messages keyed by the token before the error: what the user was in the middle of writing.
AFTER_TOKEN = {
    "ARROW": "expected a state or done/fail after ->",
    "MISSION": "expected the mission's name after mission",
    "BEHAVIOR": "expected the behavior's name after behavior",
    "NEEDS": "expected `name: Type` after needs",
    "SHARED": "expected `name: Type` after shared",
    "VAR": "expected `name: type = value` after var",
    "FOR": "expected a duration after for (e.g. 5s)",
    "AFTER": "expected a duration after after (e.g. 2min)",
    "ON": "expected an event name or error after on",
    "WHEN": "expected a condition after when",
    "AS": "expected an alias name after as",
    "PRIORITY": "expected a priority number after priority (1 is the highest)",
    "IMPORT": 'expected a file name in quotes after import',
    "PLAN": "expected {, concurrent or preallocate after plan",
    "CONCURRENT": "expected { after plan concurrent",
    "PREALLOCATE": "expected a guard, actions or the end of the item after preallocate",
    "CONSTRAINT": "expected `name: condition` after constraint",
    "PARALLEL": "expected { or all/any/until after parallel",
    "UNTIL": "expected the name of the child that ends the parallel block after until",
    "LT": "expected a plan step after <",
    "ACTION_SLASH": "expected an action after / (set, emit, release or log)",
    "ACTION_SEMI": "expected an action after ; (set, emit, release or log)",
    "SET": "expected `variable = value` after set",
    "EMIT": "expected an event name after emit",
    "LOG": 'expected a message in quotes after log',
}


def _span(file: str, tok: Token) -> Span:
    return Span(file, tok.line or 1, tok.column or 1, tok.end_line or tok.line or 1,
                tok.end_column or (tok.column or 1) + 1)


class _Builder(Transformer):  # type: ignore[type-arg]
    """Builds AST nodes at each reduction. One instance per Lark object; state is per parse."""

    def __init__(self) -> None:
        super().__init__()
        self.file = "<string>"
        self.errors: list[Diagnostic] = []
        self.depth: dict[int, int] = {}
        self.line_offset = 0
        self.column_offset = 0
        self.subparse: Callable[[str, Token], ast.Expr | None] | None = None

    def say(self, found: Diagnostic) -> None:
        """Report a syntax error once: error recovery may transform one token again, and a string's parts are split
        for its text and for its expressions (users audit 25, D7: one unclosed `{` said twice)."""
        if found not in self.errors:
            self.errors.append(found)

    # -- positions
    def tspan(self, tok: Token) -> Span:
        s = _span(self.file, tok)
        if self.line_offset or self.column_offset:
            return Span(s.file, s.line + self.line_offset, s.column + self.column_offset,
                        s.end_line + self.line_offset, s.end_column + self.column_offset)
        return s

    def pos(self, x: Any) -> Span | None:
        if isinstance(x, Token):
            return self.tspan(x)
        return getattr(x, "span", None)

    def cover(self, first: Any, last: Any) -> Span:
        a, b = self.pos(first), self.pos(last)
        assert a is not None and b is not None
        return a.to(b)

    def expr(self, node: ast.Expr, *subs: ast.Expr) -> ast.Expr:
        depth = 1 + max((self.depth.get(id(s), 1) for s in subs), default=0)
        if depth > MAX_EXPR_DEPTH:
            if not any(d.code == "nesting" for d in self.errors):
                self.errors.append(Diagnostic(
                    "nesting", f"expression nested too deeply (more than {MAX_EXPR_DEPTH} levels)",
                    node.span, "split it with var or shorten it"))
            return ast.Literal(0, span=node.span)
        if depth > 1:
            self.depth[id(node)] = depth
        return node

    # -- declarations
    def start(self, c: list[Any]) -> ast.MissionFile:
        imports = tuple(x for x in c if isinstance(x, ast.Import))
        behaviors = tuple(x for x in c if isinstance(x, ast.Behavior))
        return ast.MissionFile(imports, behaviors, path=self.file)

    def import_decl(self, c: list[Any]) -> ast.Import:
        return ast.Import(self.text(c[1]), span=self.cover(c[0], c[1]))

    def mission(self, c: list[Any]) -> ast.Behavior:
        items, end = c[3]
        return ast.Behavior(str(c[1]), (), items, c[2], True, span=self.cover(c[0], end),
                            name_span=self.tspan(c[1]))

    def behavior(self, c: list[Any]) -> ast.Behavior:
        items, end = c[4]
        return ast.Behavior(str(c[1]), c[2] or (), items, c[3], False, span=self.cover(c[0], end),
                            name_span=self.tspan(c[1]))

    def param_list(self, c: list[Any]) -> tuple[ast.Param, ...]:
        return tuple(p for p in c if p is not None)

    def param(self, c: list[Any]) -> ast.Param:
        last = c[2] if c[2] is not None else c[1]
        return ast.Param(str(c[0]), self.typeref(c[1]), c[2], span=self.cover(c[0], last))

    def priority(self, c: list[Any]) -> int:
        return self._int(c[0])

    def block(self, c: list[Any]) -> tuple[tuple[ast.Item, ...], Token]:
        return tuple(c[:-1]), c[-1]

    def typeref(self, tok: Token) -> ast.TypeRef:
        return ast.TypeRef(str(tok), span=self.tspan(tok))

    # -- body items
    def needs(self, c: list[Any]) -> ast.Need:
        kw, name, typ, where, quantity, slice_ = c
        last = next(x for x in (slice_, quantity, where, typ) if x is not None)
        return ast.Need(str(name), self.typeref(typ), where, quantity, slice_, span=self.cover(kw, last))

    def where(self, c: list[Any]) -> ast.Expr:
        return c[0]  # type: ignore[no-any-return]

    quantity = where

    def slice(self, c: list[Any]) -> ast.Duration:
        return self.duration([c[1]])  # type: ignore[return-value]

    def shared(self, c: list[Any]) -> ast.Shared:
        return ast.Shared(str(c[1]), self.typeref(c[2]), span=self.cover(c[0], c[2]))

    def var(self, c: list[Any]) -> ast.Var:
        last = c[3] if c[3] is not None else c[2]
        return ast.Var(str(c[1]), self.typeref(c[2]), c[3], span=self.cover(c[0], last))

    def child(self, c: list[Any]) -> ast.Child:
        name, args, mult, alias, prio = c
        end: Any = name
        for part in (args and args[1], mult, alias):
            if part is not None:
                end = part
        span = self.cover(name, end)
        return ast.Child(str(name), args[0] if args else None, mult, alias and str(alias), prio, span=span)

    def args(self, c: list[Any]) -> tuple[tuple[ast.Arg, ...], Token]:
        return tuple(a for a in c[:-1] if a is not None), c[-1]

    def arg(self, c: list[Any]) -> ast.Arg:
        return ast.Arg(str(c[0]), c[1], span=self.cover(c[0], c[1]))

    def mult_exact(self, c: list[Any]) -> ast.Multiplicity:
        return ast.Multiplicity(c[1], span=self.cover(c[0], c[-1]))

    def mult_range(self, c: list[Any]) -> ast.Multiplicity:
        return ast.Multiplicity(c[1], c[2], span=self.cover(c[0], c[-1]))

    def mult_open(self, c: list[Any]) -> ast.Multiplicity:
        return ast.Multiplicity(c[1], None, True, span=self.cover(c[0], c[-1]))

    def alias(self, c: list[Any]) -> Token:
        return c[0]  # type: ignore[no-any-return]

    def parallel(self, c: list[Any]) -> ast.Parallel:
        policy = c[1]
        children = tuple(x for x in c[2:-1] if x is not None)
        span = self.cover(c[0], c[-1])
        if policy is None:
            return ast.Parallel(ast.Policy.ALL, children, None, False, span=span)
        return ast.Parallel(ast.Policy(str(policy[0])), children, policy[1] and str(policy[1]), span=span)

    def policy(self, c: list[Any]) -> tuple[Token, Token | None]:
        return c[0], (c[1] if len(c) > 1 else None)

    def transition(self, c: list[Any]) -> ast.Transition:
        src, _, dst, pre, trig, guard, actions = c
        kind, event, cond, delay, event_tok, *rest = trig or (ast.TriggerKind.COMPLETION, None, None, None, None)
        end: Any = dst
        for part in (pre, cond or delay or event_tok, guard and guard[1], actions and actions[-1]):
            if part is not None:
                end = part
        sender, name_tok, sender_tok = rest or (None, None, None)
        return ast.Transition(str(src), str(dst), kind, event, cond, delay, guard and guard[0],
                              tuple(actions or ()), preallocate=pre is not None, sender=sender,
                              span=self.cover(src, end), source_span=self.tspan(src), target_span=self.tspan(dst),
                              event_span=self.tspan(name_tok) if name_tok is not None else NOWHERE,
                              sender_span=self.tspan(sender_tok) if sender_tok is not None else NOWHERE)

    def constraint(self, c: list[Any]) -> ast.Constraint:
        return ast.Constraint(str(c[1]), c[2], span=self.cover(c[0], c[2]))

    def source(self, c: list[Any]) -> Token:
        return c[0]  # type: ignore[no-any-return]

    target = source

    def when(self, c: list[Any]) -> tuple[Any, ...]:
        return ast.TriggerKind.CHANGE, None, c[0], None, None

    def on_error(self, c: list[Any]) -> tuple[Any, ...]:
        return ast.TriggerKind.ERROR, None, None, None, None

    def on_event(self, c: list[Any]) -> tuple[Any, ...]:
        name, _, sender = c
        return (ast.TriggerKind.EVENT, str(name), None, None, sender or name, str(sender) if sender else None, name,
                sender)

    def after(self, c: list[Any]) -> tuple[Any, ...]:
        return ast.TriggerKind.TIMEOUT, None, None, c[0], None

    def guard(self, c: list[Any]) -> tuple[ast.Expr, Token]:
        return c[0], c[1]

    def actions(self, c: list[Any]) -> list[ast.Action]:
        return [a for a in c if not isinstance(a, Token)]

    def set_action(self, c: list[Any]) -> ast.SetAction:
        return ast.SetAction(str(c[1]), c[2], span=self.cover(c[0], c[2]))

    def emit_action(self, c: list[Any]) -> ast.EmitAction:
        args = c[2]
        return ast.EmitAction(str(c[1]), args[0] if args else None,
                              span=self.cover(c[0], args[1] if args else c[1]))

    def release_action(self, c: list[Any]) -> ast.ReleaseAction:
        return ast.ReleaseAction(str(c[1]), span=self.cover(c[0], c[2]))

    def log_action(self, c: list[Any]) -> ast.LogAction:
        return ast.LogAction(self.string([c[1]]), span=self.cover(c[0], c[1]))

    def plan(self, c: list[Any]) -> ast.Plan:
        chains = tuple(x for x in c[3:-1] if x is not None)
        return ast.Plan(c[1] is not None, chains, preallocate=c[2] is not None, span=self.cover(c[0], c[-1]))

    def chain(self, c: list[Any]) -> tuple[ast.PlanStep, ...]:
        return tuple(x for x in c if isinstance(x, ast.PlanStep))

    def step(self, c: list[Any]) -> ast.PlanStep:
        return ast.PlanStep(str(c[0]), span=self.tspan(c[0]))

    # -- expressions
    def or_op(self, c: list[Any]) -> ast.Expr:
        return self.expr(ast.Binary("or", c[0], c[1], span=self.cover(c[0], c[1])), c[0], c[1])

    def and_op(self, c: list[Any]) -> ast.Expr:
        return self.expr(ast.Binary("and", c[0], c[1], span=self.cover(c[0], c[1])), c[0], c[1])

    def not_op(self, c: list[Any]) -> ast.Expr:
        return self.expr(ast.Unary("not", c[0], span=c[0].span), c[0])

    def compare(self, c: list[Any]) -> ast.Expr:
        return self.expr(ast.Binary(str(c[1]), c[0], c[2], span=self.cover(c[0], c[2])), c[0], c[2])

    binary = compare

    def neg(self, c: list[Any]) -> ast.Expr:
        return self.expr(ast.Unary("-", c[1], span=self.cover(c[0], c[1])), c[1])

    def attr(self, c: list[Any]) -> ast.Expr:
        return self.expr(ast.Attr(c[0], str(c[1]), span=self.cover(c[0], c[1])), c[0])

    def int_lit(self, c: list[Any]) -> ast.Expr:
        return ast.Literal(self._int(c[0]), span=self.tspan(c[0]))

    def float_lit(self, c: list[Any]) -> ast.Expr:
        value = float(c[0])
        if not math.isfinite(value) or abs(value) > MAX_NUMBER:
            self._too_large(c[0], f"number {_cut(str(c[0]))} is too large (at most {MAX_NUMBER:g})")
            value = 0.0
        return ast.Literal(value, span=self.tspan(c[0]))

    def _int(self, tok: Token) -> int:
        """An integer literal's value, or 0 and a located error for one too long to mean anything."""
        if len(tok.value.lstrip("0")) > MAX_INT_DIGITS:
            self._too_large(tok, f"integer {_cut(tok.value)} is too large ({len(tok.value)} digits, at most "
                                 f"{MAX_INT_DIGITS})")
            return 0
        return int(tok.value)

    def _too_large(self, tok: Token, message: str) -> None:
        found = Diagnostic("literal", message, self.tspan(tok))
        self.say(found)

    def true_lit(self, c: list[Any]) -> ast.Expr:
        return ast.Literal(True, span=self.tspan(c[0]))

    def false_lit(self, c: list[Any]) -> ast.Expr:
        return ast.Literal(False, span=self.tspan(c[0]))

    def duration(self, c: list[Any]) -> ast.Expr:
        text = str(c[0])
        seconds = ast.parse_duration(text)
        if seconds is not None and not seconds <= MAX_DURATION:
            self._too_large(c[0], f"duration {_cut(text)} is too long (at most {MAX_DURATION // 86400:g} days)")
            seconds = 0.0
        return ast.Duration(seconds if seconds is not None else 0.0, text, span=self.tspan(c[0]))

    def name(self, c: list[Any]) -> ast.Expr:
        return ast.Name(str(c[0]), span=self.tspan(c[0]))

    def call(self, c: list[Any]) -> ast.Expr:
        args, where = c[1] if c[1] is not None else ((), None)
        node = ast.Call(str(c[0]), args, where, span=self.cover(c[0], c[2]))
        return self.expr(node, *ast.children_of(node))

    def call_args(self, c: list[Any]) -> tuple[tuple[ast.Expr, ...], ast.Expr | None]:
        return (c[0], *c[2:]), c[1]

    def string(self, c: list[Any]) -> ast.Expr:
        tok: Token = c[0]
        span = self.tspan(tok)
        parts = self.split_string(tok)
        if all(isinstance(p, str) for p in parts):
            return ast.Literal("".join(p for p in parts if isinstance(p, str)), span=span)
        return self.expr(ast.Interp(tuple(parts), span=span), *(p for p in parts if isinstance(p, ast.Expr)))

    def text(self, tok: Token) -> str:
        return "".join(p for p in self.split_string(tok) if isinstance(p, str))

    def split_string(self, tok: Token) -> list[str | ast.Expr]:
        """Unescape a string literal and cut out its `{expr}` parts."""
        raw = str(tok)[1:-1]
        parts: list[str | ast.Expr] = []
        buf: list[str] = []
        i = 0
        while i < len(raw):
            ch = raw[i]
            if ch == "\\" and i + 1 < len(raw):
                esc = raw[i + 1]
                if esc not in _ESCAPES:
                    self.say(Diagnostic(
                        "syntax", f"unknown escape \\{esc} in string", self._inner(tok, i, i + 2),
                        'write \\\\ for a backslash; known escapes: \\n \\t \\" \\\\ \\{ \\}'))
                buf.append(_ESCAPES.get(esc, esc))
                i += 2
            elif ch == "{":
                close = raw.find("}", i)
                if close < 0:
                    self.say(Diagnostic("syntax", "unclosed { in string", self._inner(tok, i, i + 1),
                                                  "close it with } or write \\{ for a brace"))
                    break
                if buf:
                    parts.append("".join(buf))
                    buf = []
                inner = self.subparse(raw[i + 1:close].replace('\\"', '"'),  # a string in it: {x == \"a\"}
                                      self._at(tok, i + 1)) if self.subparse else None
                if inner is not None:
                    parts.append(inner)
                i = close + 1
            elif ch == "}":
                self.say(Diagnostic("syntax", "unmatched } in string", self._inner(tok, i, i + 1),
                                              "write \\} for a literal brace"))
                i += 1
            else:
                buf.append(ch)
                i += 1
        if buf or not parts:
            parts.append("".join(buf))
        return parts

    def _at(self, tok: Token, offset: int) -> Token:
        col = (tok.column or 1) + 1 + offset
        return Token("STRING", "", 0, tok.line, col, tok.line, col + 1)

    def _inner(self, tok: Token, start: int, end: int) -> Span:
        s = self.tspan(tok)
        return Span(s.file, s.line, s.column + 1 + start, s.line, s.column + 1 + end)


@cache
def _grammar() -> str:
    return resources.files("dsl").joinpath("mission.lark").read_text(encoding="utf-8")


#: The directory where parsers keep their LALR tables between processes, or None to build them in every
#: process (0.15 s). dsl reads and writes no file of its own accord: the application chooses (`cache_tables`).
_tables_dir: str | None = None


def cache_tables(directory: str | None) -> None:
    """Keep the parser's LALR tables in `directory` (which must exist and belong to the user: lark unpickles
    what it finds there), so that a new process loads them in 15 ms instead of building them. A file that
    is missing, stale or unreadable is rebuilt and written again; one that cannot be written is skipped."""
    global _tables_dir
    _tables_dir = directory


def _tables_file() -> str | bool:
    """The cache file of this grammar (named by its hash: checkouts with different grammars keep apart)."""
    if _tables_dir is None:
        return False
    digest = hashlib.sha256(_grammar().encode()).hexdigest()[:16]
    return os.path.join(_tables_dir, f"mission-grammar-{digest}.lark")


class Parser:
    """A reusable mission parser. Thread-safe: one parse at a time per instance."""

    def __init__(self) -> None:
        self.builder = _Builder()
        self.layout = Layout()
        self.lark = Lark(_grammar(), parser="lalr", lexer="basic", postlex=self.layout,
                         transformer=self.builder, start=["start", "expr"], maybe_placeholders=True,
                         cache=_tables_file())
        self.builder.subparse = self._subexpr
        self.lock = threading.Lock()

    def parse(self, text: str, file: str = "<string>", report: Reporter | None = None,
              ) -> tuple[ast.MissionFile | None, list[Diagnostic]]:
        """Parse one file's text. Returns the AST (None if unrecoverable) and syntax diagnostics; past the budget of
        `report` (if any), None and the place it stopped."""
        with self.lock:
            b = self.builder
            b.file, b.errors, b.depth = file, [], {}
            b.line_offset = b.column_offset = 0
            self.layout.reset(report.deadline if report is not None else float("inf"))
            recovery = _Recovery(self, file, text)
            try:
                tree = self.lark.parse(text, start="start", on_error=recovery)
            except UnexpectedInput as e:
                recovery.report(e)
                tree = None
            except OverBudget as stop:
                assert report is not None  # only a budget raises it
                report.over_budget(OverBudget(replace(stop.span, file=file)))
                tree = None
            errors = recovery.diagnostics + b.errors
            errors.sort(key=lambda d: (d.span.line, d.span.column))
            b.depth = {}
            return (tree if isinstance(tree, ast.MissionFile) else None), errors

    def expression(self, text: str, file: str = "<expression>") -> ast.Expr | None:
        """One expression on its own (a constraint's condition, sent to a device's host as the printer wrote
        it), or None if it does not parse."""
        with self.lock:
            b = self.builder
            b.file, b.errors, b.depth = file, [], {}
            b.line_offset = b.column_offset = 0
            self.layout.reset()
            try:
                result = self.lark.parse(text, start="expr")
            except UnexpectedInput:
                result = None
            b.depth = {}
            return result if isinstance(result, ast.Expr) and not b.errors else None

    def _subexpr(self, text: str, at: Token) -> ast.Expr | None:
        """Parse an interpolated `{expr}` with positions relative to the string token."""
        b = self.builder
        saved, layout = (b.line_offset, b.column_offset), self.layout.save()
        self.layout.reset()
        b.line_offset, b.column_offset = (at.line or 1) - 1, (at.column or 1) - 1
        try:
            result = self.lark.parse(text, start="expr")
        except UnexpectedInput as e:
            result = None
            char = e.char if isinstance(e, UnexpectedCharacters) else None
            what = f"unexpected character `{char}`" if char is not None else \
                _describe_token_error(e).replace("the end of the file", "the end of the expression")
            hint = ('a string in an interpolation is written in escaped double quotes: "lane {x == \\"east\\"}"'
                    if char in ("'", "\\") else "write \\{ for a literal brace")
            b.errors.append(Diagnostic(
                "syntax", "bad expression in string interpolation: " + what,
                Span(b.file, at.line or 1, (at.column or 1) + e.column - 1,
                     at.line or 1, (at.column or 1) + e.column), hint))
        finally:
            b.line_offset, b.column_offset = saved
            self.layout.restore(layout)
        return result if isinstance(result, ast.Expr) else None


class _Recovery:
    """lark's on_error hook: record a located error, then repair by insertion or skipping."""

    def __init__(self, parser: Parser, file: str, text: str = "") -> None:
        self.parser = parser
        self.file = file
        self.text = text
        self.diagnostics: list[Diagnostic] = []
        self.lines: set[int] = set()
        self.seen = 0
        self.skipped_at = -1  # the token (`Layout.emitted`) of the last error the parser went on past unrepaired
        self.closed_early = 0  # `}` inserted by a repair: the user's own `}` for that block comes later, stray

    def __call__(self, e: UnexpectedInput) -> bool:
        at = self.parser.layout.emitted
        # the token right after one skipped is the same mistake (`parallel any {` in a parallel block: each of its
        # tokens); a `}` where none can be is the one a repair put in earlier: neither is a mistake of its own
        echo = at == self.skipped_at + 1 and isinstance(e, UnexpectedToken)
        if not echo and not self._stray_close(e):
            self.report(e)
        self.seen += 1  # every error, also those not reported (one per line): garbage on one line stops too
        if len(self.diagnostics) >= MAX_SYNTAX_ERRORS or self.seen >= MAX_RECOVERIES:
            return False
        repaired = isinstance(e, UnexpectedToken) and e.interactive_parser is not None and self._repair(e)
        self.skipped_at = -1 if repaired else at
        return True

    def _stray_close(self, e: UnexpectedInput) -> bool:
        """A `}` where no block is open, after a repair closed one early: the user's own `}` of that block (an
        error at it and at each `}` after it said nothing new: users audit 22, #4)."""
        if not (isinstance(e, UnexpectedToken) and e.token.type == "RBRACE" and "RBRACE" not in e.expected
                and self.closed_early):
            return False
        self.closed_early -= 1
        return True

    def report(self, e: UnexpectedInput) -> None:
        layout = self.parser.layout
        d = syntax_diagnostic(e, layout.history, self.file, self.text, layout.openers)
        if d.span.line not in self.lines:  # one error per line: the rest are usually echoes
            self.lines.add(d.span.line)
            self.diagnostics.append(d)

    def _repair(self, e: UnexpectedToken) -> bool:
        """Insert the one missing token that lets the parser accept the bad one, if any (or close the bracket
        left open before it, see `left_open`); whether it did."""
        ip = e.interactive_parser
        if self._close(e):
            return True
        for name in sorted(ip.accepts() - {"$END"}, key=_repair_order):  # type: ignore[no-untyped-call]
            if self._takes(e, [name]):
                self._insert(e, [name])
                if name == "RBRACE":
                    self.closed_early += 1
                return True
        return False

    def _close(self, e: UnexpectedToken) -> bool:
        """Brackets left open before the bad token (`left_open`): close the fewest of them, innermost first, end
        the item there if needed, and go on with the bad token, if the parser takes it so. Whether it did."""
        layout = self.parser.layout
        if left_open(e.token, layout.history, layout.openers) is None:
            return False
        closers = ["RPAR" if o.type == "LPAR" else "RSQB" for o in reversed(layout.openers)]
        for count in range(1, len(closers) + 1):
            for inserted in (closers[:count], [*closers[:count], "_SEP"]):
                if self._takes(e, inserted):
                    self._insert(e, inserted)
                    del layout.openers[-count:]  # closed: the newlines after them end items again
                    return True
        return False

    def _takes(self, e: UnexpectedToken, inserted: list[str]) -> bool:
        """Whether the parser takes the bad token (at the end of the file: anything) after the `inserted`
        terminals, tried on a copy (a deep copy would cost the AST so far)."""
        trial = e.interactive_parser.copy(deepcopy_values=False)  # type: ignore[no-untyped-call]
        try:
            for name in inserted:
                trial.feed_token(self._dummy(name, e.token))
        except UnexpectedInput:
            return False
        return e.token.type == "$END" or e.token.type in trial.accepts()

    def _insert(self, e: UnexpectedToken, inserted: list[str]) -> None:
        """Feed the `inserted` terminals, then the bad token (`_takes` said the parser takes it)."""
        for name in inserted:
            e.interactive_parser.feed_token(self._dummy(name, e.token))
        if e.token.type != "$END":
            e.interactive_parser.feed_token(e.token)

    def _dummy(self, name: str, at: Token) -> Token:
        values = {"NAME": "_", "INT": "0", "FLOAT": "0.0", "DURATION": "0s", "STRING": '""', "_SEP": "\n",
                  "ACTION_SLASH": "/", "ACTION_SEMI": ";"}  # declared terminals have no pattern
        if name not in values:
            term = self.parser.lark.get_terminal(name)
            values[name] = str(term.pattern.value)
        return Token.new_borrow_pos(name, values[name], at)


def _repair_order(name: str) -> tuple[int, str]:
    preferred = ["_SEP", "RPAR", "RSQB", "RBRACE", "NAME", "INT"]
    return (preferred.index(name) if name in preferred else len(preferred), name)


def left_open(tok: Token, history: Sequence[Token], openers: Sequence[Token]) -> Token | None:
    """The `(` or `[` still open when `tok`, a new item's start or a block's `}`, came on a line of its own (or
    `tok` is `as` or `priority` after a value, which only follow a call), if any: newlines inside brackets are not
    separators (`Layout`), so a `)` left out at a line's end reads as if the next item went on the argument list;
    the bracket is what the user forgot, not a separator."""
    earlier = [t for t in history if t is not tok]
    if not openers or not earlier:
        return None
    if tok.type in CALL_SUFFIXES and earlier[-1].type not in OPENS_A_VALUE:  # `as`, `priority` after a value:
        return openers[-1]  # only a call's `)` may come between (after `,` it is a reserved word as a name)
    if tok.type not in ITEM_STARTS | {"RBRACE"} or (tok.line or 0) <= (earlier[-1].end_line or 0):
        return None
    return openers[-1]


#: What follows a call's `)` and never comes inside its arguments (`Wait(duration: 1s as a`: the `)` is missing).
CALL_SUFFIXES = frozenset({"AS", "PRIORITY"})
#: Tokens after which a value or a name is due, not a call's end.
OPENS_A_VALUE = frozenset({"COMMA", "LPAR", "LSQB", "COLON"})


def syntax_diagnostic(e: UnexpectedInput, history: Sequence[Token], file: str, text: str = "",
                      openers: Sequence[Token] = ()) -> Diagnostic:
    """Translate a lark error into a located message in the user's words (`text`, the whole source, lets a
    missing `}` name the block that was never closed; `openers`, the brackets still open, a missing `)`)."""
    if isinstance(e, UnexpectedCharacters):
        ch = e.char if hasattr(e, "char") else "?"
        span = Span(file, e.line, e.column, e.line, e.column + 1)
        if ch == '"':  # no STRING matched from here: no closing quote on this line (or a `\` ending it)
            return Diagnostic("syntax", "syntax: unterminated string", span,
                              'a string ends with " on the same line; write \\" for a quote inside it')
        hint = "strings use double quotes" if ch == "'" else None
        return Diagnostic("syntax", f"syntax: unexpected character {ch!r}", span, hint)
    assert isinstance(e, UnexpectedToken)
    tok = e.token
    earlier = [t for t in history if t is not tok]
    prev = earlier[-1] if earlier else None
    # what is missing goes before a line's end, the file's or a `}` on the same line; a `}` on a line of its own is
    # what the message is about (it pointed past the line before)
    at_end = tok.type in ("_SEP", "$END") or (tok.type == "RBRACE" and prev is not None and prev.type != "_SEP"
                                              and prev.end_line == tok.line)
    span = _after(file, prev) if (at_end and prev is not None) else _span(file, tok)
    if "RBRACE" in e.expected and tok.type in ("$END", *DECLARATION_STARTS) and text:
        unclosed = _unclosed(file, text, tok)
        if unclosed is not None:
            return unclosed
    unit = _unknown_unit(file, prev, tok)
    if unit is not None:
        return unit
    spaced = _spaced_unit(prev, tok) if prev is not None else None
    if spaced is not None and prev is not None:  # wherever a duration was written `2 s` (reverify audit 14, D3)
        return Diagnostic("syntax", f"syntax: a duration's unit follows its number with no space: "
                                    f"`{prev.value} {tok.value}`", _span(file, tok), spaced)
    opener = left_open(tok, history, openers)
    if opener is not None and prev is not None:
        closer = "`)`" if opener.type == "LPAR" else "`]`"
        where = (f"before {_show(tok)}" if tok.line == prev.end_line else f"at the end of line {prev.end_line}")
        return Diagnostic("syntax", f"syntax: expected {closer} after {_show(prev)}: the {_show(opener)} on line"
                                    f" {opener.line} is never closed", _after(file, prev), f"add {closer} {where}")
    hint = _keyword_hint(tok, e.expected, prev)
    if prev is not None and tok.type == "LPAR" and len(earlier) >= 2 and earlier[-2].type == "ARROW":
        return Diagnostic("syntax", f"syntax: a transition's target is a state's name, not a call: "
                                    f"`-> {prev.value}(`", _span(file, tok),
                          f"give the arguments where the state is declared (`{prev.value}(...)`, or "
                          f"`Type(...) as {prev.value}`) and write `-> {prev.value}`")
    if prev is not None and prev.type == "NAME" and tok.type == "COLON" and "ARROW" in e.expected:
        return Diagnostic("syntax", f"syntax: `{prev.value}:` is not how a child is named", _span(file, tok),
                          f"name a child with as: `Type(...) as {prev.value}`")
    if prev is not None and prev.type in AFTER_TOKEN and tok.type != "$END":
        return Diagnostic("syntax", f"syntax: {AFTER_TOKEN[prev.type]}", span, hint)
    if tok.type == "$END":
        closing = "RBRACE" in e.expected
        missing = "`}`" if closing else _describe(e.expected)
        return Diagnostic("syntax", f"syntax: the file ends too early: expected {missing}", span,
                          "every { needs a matching }" if closing else None)
    if "_SEP" in e.expected and not (e.expected & ITEM_STARTS) and prev is not None and tok.type != "_SEP":
        return Diagnostic("syntax", f"syntax: expected a newline or ; after {_show(prev)}", _after(file, prev),
                          hint or f"{_show(tok)} starts a new item: put it on its own line")
    return Diagnostic("syntax", f"syntax: {_describe_token_error(e)}", span, hint)


#: Units people write that the language spells otherwise, with the seconds each is worth (`3days` -> `72h`).
_UNIT_WORDS = {**dict.fromkeys(("sec", "secs", "second", "seconds"), 1.0),
               **dict.fromkeys(("m", "mn", "mins", "minute", "minutes"), 60.0),
               **dict.fromkeys(("hr", "hrs", "hour", "hours"), 3600.0),
               **dict.fromkeys(("d", "day", "days"), 86400.0),
               **dict.fromkeys(("msec", "msecs", "millis", "millisecond", "milliseconds"), 0.001)}


def _unknown_unit(file: str, prev: Token | None, tok: Token) -> Diagnostic | None:
    """A number with a name glued to it (`5parsecs`, `3days`) is a duration with a unit the language lacks: say so,
    rather than that the name starts a new item (which only a duration can mean there)."""
    if (prev is None or prev.type not in ("INT", "FLOAT") or tok.type != "NAME" or prev.end_line != tok.line
            or prev.end_column != tok.column):
        return None
    word = str(tok.value)
    span = Span(file, prev.line or 1, prev.column or 1, tok.end_line or 1, tok.end_column or 1)
    if word in _OWN_UNITS and prev.type == "FLOAT" and "e" in str(prev.value).lower():
        return _exponent_duration(str(prev.value), word, span)
    hint = None
    size = _UNIT_WORDS.get(word.lower())
    if size is not None:
        from dsl.catalog import duration_text

        seconds = float(prev.value) * size
        hint = (f"did you mean {duration_text(seconds)}?" if seconds <= MAX_DURATION else
                f"a duration is at most {MAX_DURATION // 86400:g} days ({duration_text(MAX_DURATION)})")
    return Diagnostic("syntax", f"syntax: unknown duration unit {word} in `{prev.value}{word}`: write 250ms, 30s,"
                      " 5min or 2h", span, hint)


def _spaced_unit(prev: Token, tok: Token) -> str | None:
    """The hint for a duration written with a space before its unit (`2 s`, `5 minutes`): `write 2s` (users audit
    12, D9: it said "`s` starts a new item")."""
    word = str(tok.value)
    # not `m` or `d` apart: `<= 6 m` is a distance in metres, `2 d` a name (review: "write 6min")
    size = _OWN_UNITS.get(word) or (_UNIT_WORDS.get(word.lower()) if len(word) > 2 else None)
    if prev.type not in ("INT", "FLOAT") or tok.type != "NAME" or prev.end_line != tok.line or size is None:
        return None
    from dsl.catalog import duration_text

    seconds = float(prev.value) * size
    written = f"{prev.value}{word}" if word in _OWN_UNITS else duration_text(seconds)
    return f"write {written}" if seconds <= MAX_DURATION else None


#: The language's own duration units, with the seconds each is worth.
_OWN_UNITS = {"ms": 0.001, "s": 1.0, "min": 60.0, "h": 3600.0}


def _exponent_duration(number: str, unit: str, span: Span) -> Diagnostic:
    """`1e3s`: a known unit after a number with an exponent, which durations do not take (say so, and the plain
    spelling when it is one the language accepts)."""
    from dsl.catalog import duration_text

    seconds = float(number) * _OWN_UNITS[unit]
    hint = (f"write {duration_text(seconds)}" if math.isfinite(seconds) and 0 < seconds <= MAX_DURATION else
            f"write the number in full: 250ms, 30s, 5min or 2h, at most {MAX_DURATION // 86400:g} days")
    return Diagnostic("syntax", f"syntax: a duration takes no exponent: `{number}{unit}`", span, hint)


def _unclosed(file: str, text: str, tok: Token) -> Diagnostic | None:
    """A declaration (or the end of the file) where a `}` was expected: name the block that was never closed,
    at its own `{`."""
    at_end = tok.type == "$END"
    line = text.count("\n") + 2 if at_end else (tok.line or 1)  # at the end: every line is before it
    opener = unclosed_block(text, line)
    if opener is None:
        return None
    where = "the file ends" if at_end else f"`{tok.value}` starts a new declaration on line {line}"
    before = opener.close_before or (0 if at_end else line)
    return Diagnostic("syntax", f"syntax: this `{{` of `{opener.header}` is never closed ({where})",
                      Span(file, opener.line, opener.column, opener.line, opener.column + 1),
                      "add the `}` that ends this block" + (f" before line {before}" if before else ""))


def _cut(text: str, width: int = 24) -> str:
    """A long literal, shortened for a message (its length is said there)."""
    return text if len(text) <= width else text[:width - 1] + "…"


def _describe_token_error(e: UnexpectedInput) -> str:
    if isinstance(e, UnexpectedToken):
        return f"expected {_describe(e.expected)}, got {_show(e.token)}"
    return str(e).splitlines()[0]


def _after(file: str, tok: Token) -> Span:
    line, col = tok.end_line or tok.line or 1, tok.end_column or (tok.column or 1) + len(tok)
    if tok.type == "_SEP":
        line, col = tok.line or 1, tok.column or 1
    return Span(file, line, col, line, col + 1)


def _show(tok: Token) -> str:
    if tok.type == "$END":
        return "the end of the file"
    if tok.type == "_SEP":
        return "the end of the line" if "\n" in tok.value else ";"
    return f"`{tok.value}`"


def _describe(expected: set[str] | frozenset[str]) -> str:
    shown = {t for t in expected if not t.startswith("__")}
    if shown - {"_SEP", "$END"}:
        shown -= {"_SEP", "$END"}  # optional separators only clutter the list
    words = sorted({_TERMINAL_WORDS.get(t, t.lower() if t.isupper() else t) for t in shown}
                   or {"something else"})
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " or " + words[-1]


#: Keywords a misspelled word is compared with (the short ones, `as`, `on`, `or`, would match too many names).
_SPELLED = sorted(k for k in KEYWORDS if len(k) >= 4)


def _misspelled(*tokens: Token | None) -> str | None:
    """`did you mean needs?` when one of `tokens` (the word before the error, or at it) is a name one or two edits
    from a keyword: `need rig: Ranger` was told "`rig` starts a new item" (users audit 9, D8)."""
    from dsl.errors import did_you_mean

    for tok in tokens:
        if tok is not None and tok.type == "NAME" and str(tok.value) not in KEYWORDS and len(str(tok.value)) >= 3:
            hint = did_you_mean(str(tok.value).lower(), _SPELLED)
            if hint is not None:
                return hint.replace("did you mean ", f"`{tok.value}` is no keyword: did you mean ")
    return None


def _keyword_hint(tok: Token, expected: set[str] | frozenset[str], prev: Token | None = None) -> str | None:
    """Explain the usual causes: a misspelled keyword, a keyword where a name belongs, or glued to a name."""
    if tok.type in ("SET", "EMIT", "RELEASE", "LOG") and tok.type not in expected:
        return f"actions such as {tok.value} follow a / at the end of a transition: A -> B / {tok.value} ..."
    if tok.type == "PARALLEL" and "NAME" in expected:
        return ("a parallel block holds behaviors, not another parallel block: declare the inner one in a behavior"
                " (`behavior Both { parallel all { ... } }`) and name that behavior here")
    if tok.type != "NAME" and tok.value in KEYWORDS and "NAME" in expected:
        return f"{tok.value} is a reserved word: choose another name"
    if tok.type == "NAME":
        for kw in sorted(KEYWORDS, key=len, reverse=True):
            if kw.upper() in expected and tok.value.startswith(kw) and len(tok.value) > len(kw):
                return f"put a space between {kw} and {tok.value[len(kw):]}"
    return _misspelled(prev, tok)


_default: Parser | None = None


def _shared() -> Parser:
    """The shared parser instance (building the LALR tables once per process)."""
    global _default
    if _default is None:
        _default = Parser()
    return _default


def parse(text: str, file: str = "<string>", report: Reporter | None = None,
          ) -> tuple[ast.MissionFile | None, list[Diagnostic]]:
    """Parse with the shared parser instance (within the budget of `report`, if it has one)."""
    return _shared().parse(text, file, report)


def parse_expression(text: str) -> ast.Expr | None:
    """Parse one expression with the shared parser instance (None if it does not parse)."""
    return _shared().expression(text)
