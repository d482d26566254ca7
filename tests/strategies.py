"""Hypothesis strategies for well-formed mission ASTs (`dsl.ast` nodes, spans left at default).

Every strategy here builds only shapes the parser can produce, so `parse(pretty(x)) == x`
is expected to hold exactly. The shapes the parser normalizes are avoided:
- no negative numeric literals (`-1` parses as `Unary("-", Literal(1))`), no NaN/inf;
- no bool-valued ints (`Literal(True) == Literal(1)` in Python);
- an `Interp` has at least one expression, no empty string parts and no two adjacent
  string parts; expressions inside `{ }` hold no string (a `"` would end the outer string);
- a `Parallel` written without a policy (`explicit=False`) always has policy ALL;
- a mission has no params (the syntax has none);
- expressions stay well below `dsl.parser.MAX_EXPR_DEPTH`.
"""

from __future__ import annotations

from dataclasses import dataclass

from hypothesis import strategies as st

from dsl import ast
from dsl.parser import KEYWORDS

# ---------------------------------------------------------------- lexical

_IDENT_START = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ_"
_IDENT_REST = _IDENT_START + "0123456789"

#: Identifiers that are also keyword prefixes or otherwise interesting, mixed into generated names.
_TRICKY_NAMES = ("e", "E", "s", "ms", "min", "h", "x", "_", "__", "min_", "starts", "done_", "failed",
                 "important", "mission_", "Behavior", "TRUE", "False", "None", "if", "count", "len")

_raw_names = st.one_of(
    st.sampled_from(_TRICKY_NAMES),
    st.sampled_from(sorted(KEYWORDS)).map(lambda k: k + "_"),
    st.sampled_from(sorted(KEYWORDS)).map(lambda k: k.capitalize()),
    st.builds(lambda a, b: a + b, st.sampled_from(_IDENT_START), st.text(_IDENT_REST, max_size=8)),
)

#: A name the lexer reads as NAME (never a keyword).
names = _raw_names.filter(lambda n: n not in KEYWORDS)

#: CamelCase-ish names for types, behaviors and events (any non-keyword name is legal).
type_names = st.one_of(
    st.sampled_from(["Ranger", "Scout", "Camera", "RadioChannel", "OccupancyMap", "DoorLog", "int", "float",
                     "bool", "str", "duration"]),
    names,
)

# Within the language's literal limits (dsl.parser: MAX_INT_DIGITS, MAX_NUMBER, MAX_DURATION).
ints = st.integers(min_value=0, max_value=10**18 - 1)
floats = st.floats(min_value=0.0, max_value=1e15, allow_nan=False, allow_infinity=False)

#: Durations as written: `250ms 30s 5min 2h 1.5s`, with their value in seconds.
duration_texts = st.builds(
    lambda whole, frac, unit: f"{whole}{'.' + frac if frac else ''}{unit}",
    st.text("0123456789", min_size=1, max_size=3),  # 999h: below the 365-day limit
    st.one_of(st.none(), st.text("0123456789", min_size=1, max_size=3)),
    st.sampled_from(["ms", "s", "min", "h"]),
)


def _duration(text: str) -> ast.Duration:
    seconds = ast.parse_duration(text)
    assert seconds is not None, text
    return ast.Duration(seconds, text)


durations = duration_texts.map(_duration)

#: String contents: quotes, backslashes, braces, newlines, tabs, unicode.
string_values = st.one_of(
    st.text(max_size=20),
    st.text(alphabet=st.sampled_from('"\\{}\n\t\r #ab$é€😀\u2028'), max_size=12),
)

# ---------------------------------------------------------------- the grammar

BINARY_OPS = ("and", "or", "==", "!=", "<", "<=", ">", ">=", "+", "-", "*", "/", "%")
UNARY_OPS = ("not", "-")


def _merge_parts(raw: list[str | ast.Expr]) -> tuple[str | ast.Expr, ...]:
    """Join adjacent strings and drop empty ones, as the parser's string splitter does."""
    out: list[str | ast.Expr] = []
    for p in raw:
        if isinstance(p, str):
            if not p:
                continue
            if out and isinstance(out[-1], str):
                out[-1] = out[-1] + p
                continue
        out.append(p)
    return tuple(out)


@dataclass(frozen=True)
class Grammar:
    """Strategies for every node kind, over one vocabulary of names."""

    exprs: st.SearchStrategy[ast.Expr]
    interp_safe_exprs: st.SearchStrategy[ast.Expr]
    string_exprs: st.SearchStrategy[ast.Expr]
    children: st.SearchStrategy[ast.Child]
    items: st.SearchStrategy[ast.Item]
    behaviors: st.SearchStrategy[ast.Behavior]
    missions: st.SearchStrategy[ast.Behavior]
    imports: st.SearchStrategy[ast.Import]


def grammar(names: st.SearchStrategy[str], type_names: st.SearchStrategy[str],
            strings: st.SearchStrategy[str], max_leaves: int = 10, max_items: int = 5) -> Grammar:
    """Build every strategy from `names` (never keywords), `type_names` and string contents."""
    exprs, interp_safe, string_exprs = _expressions(names, type_names, strings, max_leaves)
    type_refs = type_names.map(ast.TypeRef)
    arg_tuples = st.lists(st.builds(ast.Arg, names, exprs), max_size=3).map(tuple)
    children, parallels = _children(names, exprs, arg_tuples)
    items: st.SearchStrategy[ast.Item] = st.one_of(
        st.builds(ast.Need, names, type_refs, st.none() | exprs, st.none() | exprs, st.none() | durations),
        st.builds(ast.Shared, names, type_refs),
        st.builds(ast.Var, names, type_refs, st.none() | exprs),
        children,
        parallels,
        _transitions(names, exprs, string_exprs, arg_tuples),
        _plans(names),
        st.builds(ast.Constraint, names, exprs),
    )
    bodies = st.lists(items, max_size=max_items).map(tuple)
    params = st.builds(ast.Param, names, type_refs, st.none() | exprs)
    behaviors = st.builds(lambda name, ps, body, prio: ast.Behavior(name, tuple(ps), body, prio, False),
                          names, st.lists(params, max_size=3), bodies, st.none() | priorities)
    missions = st.builds(lambda name, body, prio: ast.Behavior(name, (), body, prio, True), names, bodies,
                         st.one_of(st.none(), st.integers(1, 99)))
    return Grammar(exprs, interp_safe, string_exprs, children, items, behaviors, missions,
                   strings.map(ast.Import))


def _expressions(names: st.SearchStrategy[str], type_names: st.SearchStrategy[str],
                 strings: st.SearchStrategy[str], max_leaves: int
                 ) -> tuple[st.SearchStrategy[ast.Expr], st.SearchStrategy[ast.Expr], st.SearchStrategy[ast.Expr]]:
    """Expressions, those safe inside `{ }` of a string, and string expressions: built together because an
    interpolated string holds expressions and an expression may be a string."""
    name_exprs = st.one_of(names.map(ast.Name), st.just(ast.Name("event")))
    plain_leaves = st.one_of(ints.map(ast.Literal), floats.map(ast.Literal), st.booleans().map(ast.Literal),
                             durations, name_exprs)

    def extend(kids: st.SearchStrategy[ast.Expr]) -> st.SearchStrategy[ast.Expr]:
        where_call = st.builds(
            lambda f, first, rest, cond: ast.Call(f, (first, *rest), cond),
            st.sampled_from(["count", "min", "max", "len", "abs"]) | names,
            st.one_of(type_names.map(ast.Name), kids),
            st.lists(kids, max_size=2),
            kids,
        )
        return st.one_of(
            st.builds(ast.Attr, kids, names),
            st.builds(ast.Call, names, st.lists(kids, max_size=3).map(tuple)),
            where_call,
            st.builds(ast.Unary, st.sampled_from(UNARY_OPS), kids),
            st.builds(ast.Binary, st.sampled_from(BINARY_OPS), kids, kids),
        )

    # Inside `{ }` of a string: no string at all (its `"` would end the outer string).
    interp_safe = st.recursive(plain_leaves, extend, max_leaves=max(2, max_leaves // 2))
    interps = st.lists(st.one_of(strings, interp_safe), min_size=1, max_size=5).map(_merge_parts).filter(
        lambda parts: any(isinstance(p, ast.Expr) for p in parts)).map(ast.Interp)
    string_exprs = st.one_of(strings.map(ast.Literal), interps)
    exprs = st.recursive(st.one_of(plain_leaves, string_exprs), extend, max_leaves=max_leaves)
    return exprs, interp_safe, string_exprs


def _children(names: st.SearchStrategy[str], exprs: st.SearchStrategy[ast.Expr],
              arg_tuples: st.SearchStrategy[tuple[ast.Arg, ...]]
              ) -> tuple[st.SearchStrategy[ast.Child], st.SearchStrategy[ast.Parallel]]:
    """Child declarations and the parallel blocks that group them (a policy-less block is always ALL, as
    parsed)."""
    multiplicities = st.one_of(
        st.builds(ast.Multiplicity, exprs),
        st.builds(ast.Multiplicity, exprs, exprs),
        st.builds(lambda low: ast.Multiplicity(low, None, True), exprs),
    )
    children = st.builds(ast.Child, names, st.none() | arg_tuples, st.none() | multiplicities,
                         st.none() | names, st.none() | priorities)
    kids = st.lists(children, max_size=3).map(tuple)
    parallels = st.one_of(
        kids.map(lambda k: ast.Parallel(ast.Policy.ALL, k, None, False)),
        st.builds(lambda p, k: ast.Parallel(p, k, None, True), st.sampled_from([ast.Policy.ALL, ast.Policy.ANY]),
                  kids),
        st.builds(lambda u, k: ast.Parallel(ast.Policy.UNTIL, k, u, True), names, kids),
    )
    return children, parallels


def _transitions(names: st.SearchStrategy[str], exprs: st.SearchStrategy[ast.Expr],
                 string_exprs: st.SearchStrategy[ast.Expr], arg_tuples: st.SearchStrategy[tuple[ast.Arg, ...]]
                 ) -> st.SearchStrategy[ast.Transition]:
    """Transitions with every trigger kind and action kind (kept apart: the largest item shape)."""
    actions = st.one_of(
        st.builds(ast.SetAction, names, exprs),
        st.builds(ast.EmitAction, names, st.none() | arg_tuples),
        st.builds(ast.ReleaseAction, names),
        st.builds(ast.LogAction, string_exprs),
    )
    triggers = st.one_of(
        st.just({"kind": ast.TriggerKind.COMPLETION}),
        exprs.map(lambda c: {"kind": ast.TriggerKind.CHANGE, "condition": c}),
        names.map(lambda e: {"kind": ast.TriggerKind.EVENT, "event": e}),
        st.just({"kind": ast.TriggerKind.ERROR}),
        durations.map(lambda d: {"kind": ast.TriggerKind.TIMEOUT, "delay": d}),
    )
    return st.builds(
        lambda src, dst, trig, guard, acts, pre: ast.Transition(src, dst, guard=guard, actions=tuple(acts),
                                                                preallocate=pre, **trig),
        st.just("start") | names,
        st.sampled_from(["done", "fail"]) | names,
        triggers,
        st.none() | exprs,
        st.lists(actions, max_size=3),
        st.booleans(),
    )


def _plans(names: st.SearchStrategy[str]) -> st.SearchStrategy[ast.Plan]:
    """Plans: chains of named steps, run in order or concurrently."""
    return st.builds(
        lambda concurrent, chains, pre: ast.Plan(concurrent, tuple(tuple(c) for c in chains), preallocate=pre),
        st.booleans(),
        st.lists(st.lists(names.map(ast.PlanStep), min_size=1, max_size=4), max_size=4),
        st.booleans(),
    )


priorities = st.integers(min_value=0, max_value=10**6)

#: The default grammar: any names, any strings.
G = grammar(names, type_names, string_values)
exprs = G.exprs
interp_safe_exprs = G.interp_safe_exprs
string_exprs = G.string_exprs
items = G.items

#: A small vocabulary of catalog and local names, so that generated programs reach the
#: checker's and the builder's interesting paths (known children, parameters, recursion...).
VOCABULARY = ("FollowCorridor", "AvoidObstacles", "DetectDoor", "Watch", "Calibrate", "Observe", "LaunchScout",
              "A", "B", "M", "speed", "min_width", "duration", "margin", "ranger", "scout", "cam", "laps", "x",
              "door", "MotionDetected", "area", "Ranger", "Scout", "Camera", "RadioChannel", "OccupancyMap",
              "count", "min", "len")
SEMANTIC = grammar(
    st.sampled_from(VOCABULARY),
    st.sampled_from(["int", "float", "bool", "str", "duration", "Ranger", "Scout", "Camera", "RadioChannel",
                     "OccupancyMap", "DoorLog", "Drive", "Thing"]),
    st.sampled_from(["", "a", "{x}", "ranger1.camera"]),
    max_leaves=5, max_items=5,
)


def _files(g: Grammar, max_behaviors: int, max_imports: int = 2) -> st.SearchStrategy[ast.MissionFile]:
    @st.composite
    def build(draw: st.DrawFn) -> ast.MissionFile:
        decls = draw(st.lists(g.behaviors, max_size=max_behaviors))
        if draw(st.booleans()):
            decls.insert(draw(st.integers(0, len(decls))), draw(g.missions))
        return ast.MissionFile(tuple(draw(st.lists(g.imports, max_size=max_imports))), tuple(decls))

    return build()


def mission_files(max_behaviors: int = 3) -> st.SearchStrategy[ast.MissionFile]:
    """A file: imports, behaviors, and at most one mission anywhere among them."""
    return _files(G, max_behaviors)


def semantic_mission_files(max_behaviors: int = 3) -> st.SearchStrategy[ast.MissionFile]:
    """Like `mission_files`, over `VOCABULARY`, without imports (they would read the disk)."""
    return _files(SEMANTIC, max_behaviors, max_imports=0)


def wrap_expr(e: ast.Expr, name: str = "M") -> ast.MissionFile:
    """A tiny mission holding `e` as a var's initial value."""
    body = (ast.Var("x", ast.TypeRef("int"), e),)
    return ast.MissionFile((), (ast.Behavior(name, (), body, None, True),))


# ---------------------------------------------------------------- plans as graphs


@st.composite
def acyclic_chains(draw: st.DrawFn, max_steps: int = 8) -> list[list[str]]:
    """Plan chains over steps S0..Sn whose precedence graph is a DAG.

    A hidden rank orders the steps; each chain lists distinct steps in increasing rank, so
    every edge goes up the rank and no cycle is possible. Declaration order (first
    appearance) is independent of the hidden rank.
    """
    n = draw(st.integers(1, max_steps))
    steps = [f"S{i}" for i in range(n)]
    hidden = draw(st.permutations(steps))
    rank = {s: i for i, s in enumerate(hidden)}
    chains = draw(st.lists(st.lists(st.sampled_from(steps), min_size=1, max_size=5, unique=True),
                           min_size=1, max_size=8))
    chains = [sorted(c, key=rank.__getitem__) for c in chains]
    # every step appears somewhere, at a random place among the chains
    seen = {s for c in chains for s in c}
    for s in steps:
        if s not in seen:
            chains.insert(draw(st.integers(0, len(chains))), [s])
    return chains


def plan_of(chains: list[list[str]], concurrent: bool = False) -> ast.Plan:
    return ast.Plan(concurrent, tuple(tuple(ast.PlanStep(s) for s in c) for c in chains))
