"""The Component Database's trader (seed: the CORBA trader): select offers by type, constraint and preference.

    TYPE [where EXPR] [prefer min(EXPR) | prefer max(EXPR) | prefer random | prefer first]

`Camera where resolution >= 640 prefer min(host.load)`. TYPE matches offers of that type and of every type that
extends it (`Robot` matches Rangers and Scouts: `extends` in their manifests). EXPR is the mission language's
expression, parsed by dsl's `expr` rule and evaluated by `dsl.evaluate` (never Python's eval); an offer's
properties are names, with `id` and `host` (a mapping: name, load, cpu, memory, up). As in CORBA, an
offer whose constraint cannot be evaluated does not match, and one whose preference cannot be (or is
not a number) comes after the others. Pure: no I/O, no clock; `random` is seeded. See docs/placement.md.
"""

from __future__ import annotations

import math
import random
import re
import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, NoReturn

from drd.errors import MissionInputError
from dsl import ast
from dsl.catalog import SCALAR_TYPES, Catalog, Kind, RecordSpec
from dsl.errors import Reporter, did_you_mean
from dsl.evaluate import EvalError, evaluate, truthy
from dsl.exprtypes import ANY, NUMBERS, Scope, Type, Typer, show

#: What `host` is inside an expression: the offer's host, as the Load Reporter last saw it.
HOST_FIELDS: Mapping[str, str] = {"name": "str", "load": "float", "cpu": "float", "memory": "float", "up": "bool"}
_HOST = RecordSpec("host", HOST_FIELDS)
_ORDERS = ("min", "max", "random", "first")
# Strings, words and brackets: enough to find the top-level `where` and `prefer` of a query.
_TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"?|[A-Za-z_][A-Za-z0-9_]*|\d[\w.]*|\S')
_OPERANDS = frozenset({"NAME", "INT", "FLOAT", "DURATION", "STRING", "TRUE", "FALSE"})
_FUNCTIONS = ("abs", "len", "min", "max")
_OPERATORS = frozenset({"CMP", "LT", "PLUS", "MINUS", "STAR", "SLASH", "PERCENT", "AND", "OR", "DOT"})


class TraderError(MissionInputError):
    """A query that cannot run: a syntax error, an unknown type or property, a type mismatch.

    `column` is 1-based in the query's text, for a caret under it (`render`).
    """

    def __init__(self, message: str, column: int) -> None:
        super().__init__(f"column {column}: {message}")
        self.message = message
        self.column = column

    def render(self, text: str) -> str:
        """The query, and a caret under the column followed by the message."""
        line = " ".join(text.splitlines())
        return f"{line}\n{' ' * (self.column - 1)}^ {self.message}"


@dataclass(frozen=True, slots=True)
class Offer:
    """A resource or component instance the Component Database knows of, with its host's latest view.

    `live`: the properties that are the cluster's live state rather than hosts.yaml's (`carrier` after a launch, a
    robot's `x`, `y`, `heading`, `battery`), each with its age in seconds."""

    id: str
    type: str
    properties: Mapping[str, object] = field(default_factory=dict, hash=False)
    host: Mapping[str, object] = field(default_factory=dict, hash=False)
    live: Mapping[str, float] = field(default_factory=dict, hash=False)

    def names(self) -> dict[str, object]:
        """The names an expression sees: the properties, then `id` and `host` (which win)."""
        return {**self.properties, "id": self.id, "host": self.host}


class Order(StrEnum):
    FIRST = "first"
    """The offers' own order (the default)."""
    RANDOM = "random"
    """A shuffle seeded by the caller."""
    MIN = "min"
    """Ascending by the key; ties keep the offers' order."""
    MAX = "max"
    """Descending by the key; ties keep the offers' order."""


@dataclass(frozen=True, slots=True)
class Query:
    """A parsed and checked query; `run` it against offers as often as needed. `types`: the queried type and its
    subtypes (just the type when compiled without a catalog)."""

    type: str
    where: ast.Expr | None = None
    order: Order = Order.FIRST
    key: ast.Expr | None = None
    types: frozenset[str] = frozenset()

    def matches(self, offer: Offer) -> bool:
        """Of the type (or a subtype) and satisfying the constraint; an evaluation error means no match."""
        if offer.type != self.type and offer.type not in self.types:
            return False
        try:
            return truthy(self.where, offer.names())
        except EvalError:
            return False

    def key_of(self, offer: Offer) -> float | None:
        """The preference value of an offer: a number, or None (it cannot be evaluated, or is not a number)."""
        if self.key is None:
            return None
        try:
            value = evaluate(self.key, offer.names())
        except EvalError:
            return None
        if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
            return None
        return value

    def run(self, offers: Iterable[Offer], seed: int = 0) -> list[Offer]:
        """The matching offers, best first."""
        found = [o for o in offers if self.matches(o)]
        if self.order is Order.RANDOM:
            random.Random(seed).shuffle(found)
        elif self.order in (Order.MIN, Order.MAX):
            sign = 1 if self.order is Order.MIN else -1
            keyed = [(self.key_of(o), o) for o in found]
            keyed.sort(key=lambda pair: (1, 0.0) if pair[0] is None else (0, sign * pair[0]))
            found = [o for _, o in keyed]
        return found


def query(text: str, offers: Iterable[Offer], *, catalog: Catalog | None = None, seed: int = 0) -> list[Offer]:
    """Run one query text against offers (see `compile_query` for the checks and errors)."""
    return compile_query(text, catalog).run(offers, seed)


def compile_query(text: str, catalog: Catalog | None = None) -> Query:
    """Parse and check a query. With a catalog, the type and (for RC/ARC types) its properties are known, and the
    query matches the type's subtypes too; the properties are the queried type's (`Robot where magazine > 0` is an
    error: only a Ranger has a magazine).

    Raises:
        TraderError: with a message in the user's words and the column of the problem.
    """
    flat = re.sub(r"\s", " ", text)  # one line: columns stay those of the text
    words = _top_level_words(flat)
    if not words or not _is_name(words[0][0]):
        _fail("expected a component type, such as Camera", words[0][1] if words else len(flat) + 1)
    type_name, type_col = words[0]
    if type_name in ("where", "prefer"):
        _fail(f"expected a component type before {type_name}", type_col)
    after = _TOKEN.search(flat, type_col - 1 + len(type_name))
    if after is not None and after.group() not in ("where", "prefer"):
        _fail(f"expected where or prefer after {type_name}, got `{after.group()}`", after.start() + 1)
    where_at = prefer_at = None
    for word, col in words[1:]:
        if word == "where":
            if where_at is not None or prefer_at is not None:
                _fail("where must come before prefer" if prefer_at is not None else "where is given twice", col)
            where_at = col
        elif word == "prefer":
            if prefer_at is not None:
                _fail("prefer is given twice", col)
            prefer_at = col
    end = len(flat) + 1
    where = _clause(flat, where_at, "where", prefer_at or end, "a condition") if where_at else None
    prefer = _clause(flat, prefer_at, "prefer", end, "min(...), max(...), random or first") if prefer_at else None
    order, key = _preference(prefer) if prefer is not None else (Order.FIRST, None)
    _check(type_name, type_col, where, key, catalog)
    types = frozenset(catalog.subtypes(type_name)) if catalog is not None else frozenset({type_name})
    return Query(type_name, where, order, key, types)


# ---------------------------------------------------------------- parsing


def _fail(message: str, column: int) -> NoReturn:
    raise TraderError(message, column)


def _is_name(word: str) -> bool:
    return re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", word) is not None and word not in ast.KEYWORDS - {"where"}


def _top_level_words(text: str) -> list[tuple[str, int]]:
    """The first token and every word outside brackets and strings, with 1-based columns."""
    out: list[tuple[str, int]] = []
    depth = 0
    for m in _TOKEN.finditer(text):
        tok = m.group()
        if tok in ("(", "["):
            depth += 1
        elif tok in (")", "]"):
            depth = max(0, depth - 1)
        if not out or (depth == 0 and _is_name(tok)):
            out.append((tok, m.start() + 1))
    return out


def _clause(text: str, at: int, keyword: str, end: int, wanted: str) -> ast.Expr:
    """Parse the expression after `keyword` (at column `at`) up to column `end`, keeping columns."""
    start = at - 1 + len(keyword)
    body = text[start:end - 1]
    if not body.strip():
        _fail(f"expected {wanted} after {keyword}", at + len(keyword) + 1)
    return _parse_expr(" " * start + body, f"the {'condition' if keyword == 'where' else 'preference'} after {keyword}")


if TYPE_CHECKING:  # the parser (lark) is loaded by the first query, not by importing the trader
    from lark.exceptions import UnexpectedInput

    from dsl.parser import Parser

_lock = threading.Lock()
_parser: Parser | None = None


def _parse_expr(padded: str, what: str) -> ast.Expr:
    """dsl's `expr` rule on a space-padded text (so columns are the query's); errors as TraderError."""
    from lark.exceptions import UnexpectedInput

    from dsl.parser import Parser

    global _parser
    with _lock:
        p = _parser = _parser or Parser()  # our own instance: its builder state is ours while locked
        b = p.builder
        b.file, b.errors, b.depth, b.line_offset, b.column_offset = "<query>", [], {}, 0, 0
        p.layout.reset()
        try:
            result = p.lark.parse(padded, start="expr")
        except UnexpectedInput as e:
            raise _syntax_error(e, padded, p.layout.history[-1:], what) from None
        finally:
            b.depth = {}
        if b.errors:
            d = b.errors[0]
            raise TraderError(d.message + (f" ({d.hint})" if d.hint else ""), d.span.column)
    if not isinstance(result, ast.Expr):
        raise TraderError(f"{what} is not an expression", len(padded) - len(padded.lstrip()) + 1)
    return result


def _syntax_error(e: UnexpectedInput, text: str, last: Sequence[object], what: str) -> TraderError:
    from lark.exceptions import UnexpectedCharacters, UnexpectedToken

    if isinstance(e, UnexpectedCharacters):
        ch = e.char
        hint = " (strings use double quotes)" if ch == "'" else ""
        return TraderError(f"unexpected character {ch!r}{hint}", e.column)
    if not isinstance(e, UnexpectedToken):  # pragma: no cover - lalr with a basic lexer raises only these two
        return TraderError(str(e).splitlines()[0], getattr(e, "column", 1))
    tok = e.token
    column = tok.column or 1
    opened = sum(+1 if t in "([" else -1 if t in ")]" else 0 for t in _TOKEN.findall(text[:column - 1]))
    exp = set(e.expected)
    if exp == {"NAME"}:
        wanted = "a field name"
    elif exp & _OPERANDS:
        wanted = "a value (a property, a number, a string, true or false)"
    else:
        wanted = " or ".join(w for w, ok in (("an operator", exp & _OPERATORS), ("`)`", opened > 0)) if ok)
    if tok.type == "$END":
        end = getattr(last[0], "end_column", None) if last else None
        return TraderError(f"{what} ends too early" + (f": expected {wanted}" if wanted else ""), end or column)
    got = "`;`" if tok.type == "_SEP" else f"`{tok.value}`"
    return TraderError(f"expected {wanted}, got {got}" if wanted else f"unexpected {got}", column)


def _preference(expr: ast.Expr) -> tuple[Order, ast.Expr | None]:
    """`min(EXPR)`, `max(EXPR)`, `random` or `first`, read from the parsed clause."""
    col = expr.span.column
    match expr:
        case ast.Name(id="random" | "first" as word):
            return Order(word), None
        case ast.Call(func="min" | "max" as func, args=(key,), where=None):
            return Order(func), key
        case ast.Call(func="min" | "max" as func):
            _fail(f"prefer {func}(...) takes one expression", col)
        case ast.Name(id="min" | "max" as func):
            _fail(f"prefer {func} needs an expression: prefer {func}(EXPR)", col)
        case ast.Call(func=func) | ast.Name(id=func):
            hint = did_you_mean(func, _ORDERS)
            _fail(f"unknown preference {func}" + (f" ({hint})" if hint else f" (expected one of {', '.join(_ORDERS)})"),
                  col)
    _fail("expected min(...), max(...), random or first after prefer", col)


# ---------------------------------------------------------------- static checks


def _check(type_name: str, type_col: int, where: ast.Expr | None, key: ast.Expr | None,
           catalog: Catalog | None) -> None:
    """Known type, known properties (RC and ARC types), no count(...), a bool constraint, a numeric key."""
    exprs = [e for e in (where, key) if e is not None]
    for node in (n for e in exprs for n in ast.walk(e)):
        if isinstance(node, ast.Call) and node.func == "count":
            _fail("count(...) is not available in trader queries", node.span.column)
        if isinstance(node, ast.Call) and node.func not in _FUNCTIONS:
            close = did_you_mean(node.func, _FUNCTIONS) or f"functions: {', '.join(_FUNCTIONS)}"
            _fail(f"unknown function {node.func} ({close})", node.span.column)
    names: dict[str, Type] = {"id": "str", "host": _HOST}
    closed = False
    if catalog is not None:
        t = catalog.get(type_name)
        if t is None:
            kinds = ", ".join(sorted(n for n, c in catalog.components.items() if c.kind in (Kind.RC, Kind.ARC)))
            hint = did_you_mean(type_name, catalog.names()) or (f"resource types: {kinds}" if kinds else None)
            _fail(f"unknown type {type_name}" + (f" ({hint})" if hint else ""), type_col)
        elif t.kind in (Kind.RC, Kind.ARC):  # abstract ones too: `Robot where battery > 0.5`
            closed = True
            names = {n: _trader_type(ty, catalog) for n, ty in catalog.properties(type_name).items()} | names
    if closed:
        for node in (n for e in exprs for n in ast.walk(e)):
            if isinstance(node, ast.Name) and node.id not in names:
                hint = did_you_mean(node.id, names) or f"{type_name} has {', '.join(sorted(names))}"
                _fail(f"unknown property {node.id} ({hint})", node.span.column)
    report = Reporter()
    typer, scope = Typer(catalog or Catalog({}), report), Scope(names, open=not closed)
    if where is not None:
        typer.expect(where, "bool", scope, "where")
    if key is not None and not report.failed:
        kt = typer.infer(key, scope)
        if not report.failed and kt not in (*NUMBERS, "duration", ANY):
            report.error("type", f"prefer needs a number, got {show(kt)}", key.span)
    if report.diagnostics:
        d = report.diagnostics[0]
        _fail(d.message + (f" ({d.hint})" if d.hint else ""), d.span.column)


def _trader_type(t: str, catalog: Catalog) -> Type:
    """A property's type as an offer carries it: scalars as declared, references to resources as ids."""
    if t in SCALAR_TYPES:
        return t
    return "str" if catalog.get(t) is not None else ANY


__all__ = ["HOST_FIELDS", "Offer", "Order", "Query", "TraderError", "compile_query", "query"]
