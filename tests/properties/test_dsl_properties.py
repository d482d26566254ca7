"""Property tests of the mission language front end.

- the printer and the parser are inverse: `parse(pretty(ast)) == ast` for generated ASTs;
- the compiler never raises, whatever the input: it returns located diagnostics;
- deep, long, huge, binary and oddly encoded inputs give diagnostics, not crashes;
- plan linearization respects precedence, breaks ties by declaration order, and finds
  real cycles, both in `dsl.linearize` and in the statechart the compiler builds.
"""

from __future__ import annotations

import dataclasses
import os
import re
from pathlib import Path

import networkx as nx
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from drd.manifests import load_catalog
from dsl import ast, compile_file, compile_text
from dsl.catalog import Catalog
from dsl.errors import Diagnostic, MissionError, Reporter
from dsl.linearize import find_cycle, plan_graph, predecessors, respects, total_order
from dsl.loader import decode
from dsl.parser import KEYWORDS, MAX_EXPR_DEPTH, Parser, parse
from dsl.printer import expr, pretty
from dsl.statechart import Statechart

try:  # run as `python -m pytest` (the repo root on sys.path) or as plain `pytest` (tests/ on sys.path)
    from tests import strategies as S
except ImportError:
    import strategies as S  # type: ignore[no-redef]

EXAMPLES = Path("/work/shared/examples")
EXAMPLE_FILES = sorted(EXAMPLES.glob("*.mission")) if EXAMPLES.is_dir() else []
needs_examples = pytest.mark.skipif(not EXAMPLE_FILES, reason=f"normative examples not found in {EXAMPLES}")

SLOW = [HealthCheck.too_slow, HealthCheck.data_too_large]
#: `DRD_FUZZ_SCALE=20 pytest tests/properties/test_dsl_properties.py` runs every property 20 times longer.
SCALE = max(1, int(os.environ.get("DRD_FUZZ_SCALE", "1")))


def n(examples: int) -> int:
    return examples * SCALE


@pytest.fixture(scope="module")
def catalog() -> Catalog:
    return load_catalog()


# ---------------------------------------------------------------- helpers


def strict_equal(a: object, b: object) -> bool:
    """AST equality that also tells `1` from `1.0` and `True` (spans still ignored)."""
    if type(a) is not type(b):
        return False
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return all(strict_equal(getattr(a, f.name), getattr(b, f.name))
                   for f in dataclasses.fields(a) if f.compare)
    if isinstance(a, tuple):
        assert isinstance(b, tuple)
        return len(a) == len(b) and all(strict_equal(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def roundtrip(f: ast.MissionFile) -> tuple[str, ast.MissionFile]:
    text = pretty(f)
    back, diags = parse(text, "<printed>")
    assert not diags, text + "\n" + "\n".join(d.render({"<printed>": text}) for d in diags)
    assert back is not None
    return text, back


def check_diagnostics(diags: list[Diagnostic], sources: dict[str, str]) -> None:
    """Every diagnostic is located inside its source and renders without a traceback."""
    for d in diags:
        for span in (d.span, *(s for _, s in d.notes)):
            assert span.line >= 1 and span.column >= 1, d
            assert (span.end_line, span.end_column) >= (span.line, span.column), d
            source = sources.get(span.file)
            if source is not None:
                lines = source.split("\n")  # the lexer counts lines by \n only
                assert span.line <= len(lines), (d, len(lines))
                assert span.column <= len(lines[span.line - 1]) + 1, (d, lines[span.line - 1])
        rendered = d.render(sources)
        assert "Traceback" not in rendered
        assert rendered.startswith(f"{d.span.file}:{d.span.line}:{d.span.column}: ")
    if diags:
        assert "Traceback" not in MissionError(diags, sources).render()


def compile_checked(text: str, catalog: Catalog, file: str = "<fuzz>") -> list[Diagnostic]:
    c = compile_text(text, catalog, file)
    check_diagnostics(c.diagnostics, c.sources)
    if not c.ok:
        assert c.statechart is None
    return c.diagnostics


def mission_with(line: str) -> str:
    return "mission M {\n    " + line + "\n    FollowCorridor\n}\n"


# ---------------------------------------------------------------- round trip


@settings(max_examples=n(100), deadline=None, suppress_health_check=SLOW)
@given(S.mission_files())
def test_pretty_then_parse_gives_the_same_ast(f: ast.MissionFile) -> None:
    _, back = roundtrip(f)
    assert back == f
    assert strict_equal(back, f)


@settings(max_examples=n(200), deadline=None, suppress_health_check=SLOW)
@given(S.exprs)
def test_expression_round_trip(e: ast.Expr) -> None:
    _, back = roundtrip(S.wrap_expr(e))
    mission = back.mission
    assert mission is not None
    (var,) = mission.body
    assert isinstance(var, ast.Var)
    assert var.value == e
    assert strict_equal(var.value, e)
    assert expr(var.value) == expr(e)


@settings(max_examples=n(30), deadline=None, suppress_health_check=SLOW)
@given(S.mission_files())
def test_printing_is_idempotent(f: ast.MissionFile) -> None:
    text, back = roundtrip(f)
    assert pretty(back) == text


@settings(max_examples=n(100), deadline=None, suppress_health_check=SLOW)
@given(S.string_exprs)
def test_strings_round_trip_in_every_string_position(s: ast.Expr) -> None:
    """Log messages (plain or interpolated) and import paths (plain only)."""
    t = ast.Transition("A", "done", actions=(ast.LogAction(s),))
    f = ast.MissionFile((ast.Import(s.value),) if isinstance(s, ast.Literal) else (),
                        (ast.Behavior("M", (), (t,), None, True),))
    _, back = roundtrip(f)
    assert back == f


@needs_examples
@pytest.mark.parametrize("path", EXAMPLE_FILES, ids=lambda p: p.name)
def test_examples_round_trip(path: Path, catalog: Catalog) -> None:
    """The normative examples survive pretty-printing: same AST, same statechart."""
    text = path.read_text(encoding="utf-8")
    f, diags = parse(text, path.name)
    assert not diags and f is not None
    printed, back = roundtrip(f)
    assert back == f
    a, b = compile_text(text, catalog, "x"), compile_text(printed, catalog, "x")
    assert a.ok and b.ok
    assert a.statechart == b.statechart


def test_keywords_match_the_grammar() -> None:
    """`KEYWORDS` (what the strategies avoid as names) is exactly the grammar's reserved words."""
    grammar_words = {t.pattern.value for t in Parser().lark.terminals
                     if t.pattern.type == "str" and re.fullmatch(r"[A-Za-z_]\w*", t.pattern.value)}
    assert grammar_words == set(KEYWORDS)


# ---------------------------------------------------------------- robustness

_TOKENS = [*sorted(KEYWORDS), "{", "}", "(", ")", "[", "]", ":", ",", ".", "..", "->", "<", "<=", "==", "!=",
           ">", ">=", "+", "-", "*", "/", "%", "=", ";", "\n", "\r\n", "#", '"', '"a{x}b"', '"\\q"', '"{"', "1",
           "0.5", "30s", "2min", "1e5", "Ranger", "Scout", "FollowCorridor", "DetectDoor", "speed", "x",
           "count", "Camera", "MotionDetected", "M", "A", "B", "\t", "\x00", "é", "\ufeff", "\u2028"]

token_soup = st.lists(st.tuples(st.sampled_from(_TOKENS), st.sampled_from(["", " ", "\n"])), max_size=60).map(
    lambda toks: "".join(t + sep for t, sep in toks))


@settings(max_examples=n(150), deadline=None, suppress_health_check=SLOW)
@given(st.one_of(st.text(), token_soup))
def test_random_text_gives_located_diagnostics(catalog: Catalog, text: str) -> None:
    compile_checked(text, catalog)


@settings(max_examples=n(100), deadline=None, suppress_health_check=SLOW)
@given(st.one_of(st.binary(max_size=4096), st.binary(max_size=64).map(lambda b: b"\xef\xbb\xbf" + b),
                 token_soup.map(lambda s: s.encode("utf-8")).flatmap(
    lambda b: st.tuples(st.just(b), st.binary(max_size=4), st.integers(0, len(b))).map(
        lambda t: t[0][:t[2]] + t[1] + t[0][t[2]:]))))
def test_random_bytes_give_located_diagnostics(catalog: Catalog, data: bytes) -> None:
    report = Reporter()
    text = decode(data, "<bytes>", report)
    check_diagnostics(report.diagnostics, {"<bytes>": text})
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as e:
        (d,) = report.diagnostics
        assert d.code == "encoding"
        assert d.span.line == data.count(b"\n", 0, e.start) + 1
    else:
        assert not report.diagnostics
    compile_checked(text, catalog, "<bytes>")


@st.composite
def mutated_examples(draw: st.DrawFn) -> str:
    """A normative example with a few random edits: characters, lines, keywords."""
    text = draw(st.sampled_from(EXAMPLE_FILES)).read_text(encoding="utf-8")
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(["delete", "insert", "duplicate", "swap", "line_delete", "line_dup",
                                     "line_swap", "keyword"]))
        size = len(text)
        i = draw(st.integers(0, max(size - 1, 0)))
        if kind == "delete" and size:
            j = draw(st.integers(i + 1, min(size, i + 8)))
            text = text[:i] + text[j:]
        elif kind == "insert":
            text = text[:i] + draw(st.one_of(st.sampled_from(_TOKENS), st.text(max_size=3))) + text[i:]
        elif kind == "duplicate":
            j = draw(st.integers(i, min(size, i + 20)))
            text = text[:j] + text[i:j] + text[j:]
        elif kind == "swap" and size:
            j = draw(st.integers(0, size - 1))
            a, b = sorted((i, j))
            if a != b:
                text = text[:a] + text[b] + text[a + 1:b] + text[a] + text[b + 1:]
        elif kind.startswith("line"):
            lines = text.split("\n")
            k = draw(st.integers(0, len(lines) - 1))
            if kind == "line_delete":
                del lines[k]
            elif kind == "line_dup":
                lines.insert(k, lines[k])
            else:
                m = draw(st.integers(0, len(lines) - 1))
                lines[k], lines[m] = lines[m], lines[k]
            text = "\n".join(lines)
        elif kind == "keyword":
            kw = draw(st.sampled_from(sorted(KEYWORDS)))
            pad = draw(st.sampled_from(["", " ", "\n"]))
            text = text[:i] + pad + kw + draw(st.sampled_from(["", " ", "\n"])) + text[i:]
    return text


@needs_examples
@settings(max_examples=n(100), deadline=None, suppress_health_check=SLOW)
@given(mutated_examples())
def test_mutated_examples_give_located_diagnostics(catalog: Catalog, text: str) -> None:
    compile_checked(text, catalog, "<mutated>")


@settings(max_examples=n(60), deadline=None, suppress_health_check=SLOW)
@given(S.semantic_mission_files())
def test_generated_programs_compile_without_crashing(catalog: Catalog, f: ast.MissionFile) -> None:
    """Well-formed but mostly meaningless programs over a small vocabulary reach the checker
    and the builder (recursion, duplicates, cycles, unknown names...): diagnostics only."""
    compile_checked(pretty(f), catalog, "<generated>")


# ---------------------------------------------------------------- edge cases


@pytest.mark.parametrize("line", ["A -> B 1", 'A -> done "x"', "A -> B / set x = 1 2"])
def test_syntax_recovery_never_inserts_a_declared_terminal(catalog: Catalog, line: str) -> None:
    c = compile_text("mission M {\n    " + line + "\n}\n", catalog)
    assert [d.code for d in c.diagnostics] == ["syntax"]
    assert c.diagnostics[0].span.line == 2


def _assert_nesting_error(diags: list[Diagnostic]) -> None:
    assert [d.code for d in diags] == ["nesting"], diags
    assert str(MAX_EXPR_DEPTH) in diags[0].message


def test_deep_parentheses_are_fine(catalog: Catalog) -> None:
    """Parentheses add no AST depth: 1000 of them around a literal compile."""
    assert compile_checked(mission_with("var x: int = " + "(" * 1000 + "1" + ")" * 1000), catalog) == []


def test_deep_not_chain(catalog: Catalog) -> None:
    _assert_nesting_error(compile_checked(mission_with("var x: bool = " + "not " * 1000 + "true"), catalog))


@pytest.mark.parametrize("sep", ["", " "])
def test_deep_unary_minus(catalog: Catalog, sep: str) -> None:
    _assert_nesting_error(compile_checked(mission_with("var x: int = " + ("-" + sep) * 1000 + "1"), catalog))


def test_long_sum_chain(catalog: Catalog) -> None:
    _assert_nesting_error(compile_checked(mission_with("var x: int = " + " + ".join(["1"] * 5000)), catalog))


@pytest.mark.parametrize("closed", [False, True])
def test_deeply_nested_parallel_blocks(catalog: Catalog, closed: bool) -> None:
    text = "mission M {\n" + "parallel {\n" * 1000 + "FollowCorridor\n" + ("}\n" * 1001 if closed else "")
    diags = compile_checked(text, catalog)
    assert diags and all(d.code == "syntax" for d in diags)


def test_one_megabyte_mission(catalog: Catalog) -> None:
    head = "mission Big {\n    needs ranger: Ranger\n    plan { B0 < B1 < B2 }\n}\n"
    parts, size, i = [head], len(head), 0
    while size < 1_000_000:
        p = (f"behavior B{i}(speed: float = 0.5) priority 2 {{\n    var laps: int = {i} + 1  # comment\n"
             f"    FollowCorridor(speed: speed)\n}}\n\n")
        parts.append(p)
        size, i = size + len(p), i + 1
    c = compile_text("".join(parts), catalog, "big.mission")
    assert c.ok, c.diagnostics[:3]
    assert c.statechart is not None


def test_binary_garbage_with_nul_bytes(catalog: Catalog) -> None:
    data = bytes(range(256)) * 4 + b"\x00mission\x00M {\x00}\x00\xff\xfe"
    report = Reporter()
    text = decode(data, "<bin>", report)
    assert [d.code for d in report.diagnostics] == ["encoding"]
    diags = compile_checked(text, catalog, "<bin>")
    assert diags and all(d.code == "syntax" for d in diags)


def test_invalid_utf8_file_names_line_and_column(catalog: Catalog, tmp_path: Path) -> None:
    path = tmp_path / "bad.mission"
    path.write_bytes(b'mission M {\n    Watch\n    Watch -> done / log "a\xff"\n}\n')
    c = compile_file(path, catalog)
    check_diagnostics(c.diagnostics, c.sources)
    enc = [d for d in c.diagnostics if d.code == "encoding"]
    assert len(enc) == 1
    assert (enc[0].span.line, enc[0].span.column) == (3, 27)
    assert f"{path}:3:27:" in enc[0].render(c.sources)


def test_invalid_utf8_column_counts_characters(tmp_path: Path) -> None:
    path = tmp_path / "bad.mission"
    path.write_bytes('mission M {\n    var s: str = "éé'.encode() + b'\xff"\n}\n')
    report = Reporter()
    text = decode(path.read_bytes(), "bad.mission", report)
    (d,) = report.diagnostics
    line = text.splitlines()[d.span.line - 1]
    assert line[d.span.column - 1] == "\ufffd", (d.span, line)


@pytest.mark.parametrize("text", [
    "# note\u2028more\nmission M {\n    Foo\n}\n",   # a line separator in a comment
    "mission M {\x0c\n    Foo\n}\n",               # a form feed, which the grammar treats as blank
    "mission M {  # a\rb\n    Foo\n}\n",           # a lone carriage return in a comment
])
def test_excerpt_shows_the_line_of_the_error(catalog: Catalog, text: str) -> None:
    c = compile_text(text, catalog, "f.mission")
    (d,) = c.diagnostics
    assert d.code == "unknown-behavior" and d.span.line == text.split("\n").index("    Foo") + 1
    assert d.render(c.sources).splitlines()[1].endswith("|     Foo")


@pytest.mark.parametrize("text", ["", "\n\n", "   \t", "# only a comment", "# one\n# two\n\n#three",
                                  "#\r\n#\r\n", ";;\n;"])
def test_empty_and_comment_only_files(catalog: Catalog, text: str) -> None:
    """Nothing to run is an error that says so (issue #12: it used to pass as valid)."""
    c = compile_text(text, catalog)
    [d] = c.diagnostics
    assert not c.ok and d.code == "empty" and "declares no mission" in d.message and c.statechart is None


@needs_examples
@pytest.mark.parametrize("path", EXAMPLE_FILES, ids=lambda p: p.name)
def test_crlf_line_endings(path: Path, catalog: Catalog) -> None:
    text = path.read_text(encoding="utf-8")
    crlf = text.replace("\n", "\r\n")
    assert parse(crlf)[0] == parse(text)[0]
    a, b = compile_text(text, catalog, "x"), compile_text(crlf, catalog, "x")
    assert b.ok, [d.render(b.sources) for d in b.diagnostics]
    assert a.statechart == b.statechart


@pytest.mark.parametrize("text", [
    "missionpatrol M {}\n",
    "behaviorX {}\n",
    "missionM {\n    FollowCorridor\n}\n",
    "behaviorB(speed: float) {\n    FollowCorridor\n}\n",
    'importx "x.mission"\n',
])
def test_keyword_glued_to_name_is_rejected(catalog: Catalog, text: str) -> None:
    diags = compile_checked(text, catalog)
    assert diags and diags[0].code == "syntax", text
    assert diags[0].span.line == 1 and diags[0].span.column == 1
    assert diags[0].hint is not None and diags[0].hint.startswith("put a space between"), diags[0]


def test_empty_parameter_list_is_no_parameters() -> None:
    a, b = parse("behavior B() {\n    FollowCorridor\n}\n")[0], parse("behavior B {\n    FollowCorridor\n}\n")[0]
    assert a is not None and a == b and a.behaviors[0].params == ()


@settings(max_examples=n(60), deadline=None)
@given(st.sampled_from([
    ("mission", "{mission} M {{\n    FollowCorridor\n}}\n"),
    ("behavior", "{behavior} B {{\n    FollowCorridor\n}}\n"),
    ("needs", "mission M {{\n    {needs} r: Ranger\n    FollowCorridor\n}}\n"),
    ("shared", "mission M {{\n    {shared} m: OccupancyMap\n    FollowCorridor\n}}\n"),
    ("var", "mission M {{\n    {var} x: int = 1\n    FollowCorridor\n}}\n"),
    ("parallel", "mission M {{\n    {parallel} all {{\n        FollowCorridor\n    }}\n}}\n"),
    ("plan", "mission M {{\n    {plan} {{ FollowCorridor < DetectDoor }}\n}}\n"),
]), st.text(S._IDENT_REST, min_size=1, max_size=6))
def test_any_glued_keyword_is_rejected(catalog: Catalog, case: tuple[str, str], suffix: str) -> None:
    kw, template = case
    assert compile_checked(template.format(**{kw: kw}), catalog) == []  # the unglued text is valid
    diags = compile_checked(template.format(**{kw: kw + suffix}), catalog)
    assert any(d.code == "syntax" for d in diags)


# ---------------------------------------------------------------- linearizer


def _rank(chains: list[list[str]]) -> dict[str, int]:
    out: dict[str, int] = {}
    for c in chains:
        for s in c:
            out.setdefault(s, len(out))
    return out


def _edges(chains: list[list[str]]) -> set[tuple[str, str]]:
    return {(a, b) for c in chains for a, b in zip(c, c[1:], strict=False)}


def _reference_order(chains: list[list[str]]) -> list[str]:
    """Kahn's algorithm, always taking the earliest-declared ready step."""
    rank, edges = _rank(chains), _edges(chains)
    left, out = set(rank), []
    while left:
        ready = [s for s in left if not any(a in left and b == s for a, b in edges)]
        nxt = min(ready, key=rank.__getitem__)
        out.append(nxt)
        left.remove(nxt)
    return out


@settings(max_examples=n(100), deadline=None)
@given(S.acyclic_chains())
def test_total_order_respects_precedence_and_declaration_order(chains: list[list[str]]) -> None:
    g = plan_graph(S.plan_of(chains))
    order = total_order(g)
    assert sorted(order) == sorted(_rank(chains))
    assert respects(order, g)
    assert set(g.edges) == _edges(chains)
    rank = _rank(chains)
    first_free = min((s for s in rank if not any(b == s for _, b in _edges(chains))), key=rank.__getitem__)
    assert order[0] == first_free
    assert order == _reference_order(chains)
    assert find_cycle(g) is None


@settings(max_examples=n(100), deadline=None)
@given(S.acyclic_chains())
def test_respects_rejects_a_violated_precedence(chains: list[list[str]]) -> None:
    g = plan_graph(S.plan_of(chains))
    order = total_order(g)
    assume(g.number_of_edges() > 0)
    for a, b in g.edges:
        bad = list(order)
        i, j = bad.index(a), bad.index(b)
        bad[i], bad[j] = bad[j], bad[i]
        assert not respects(bad, g)


@settings(max_examples=n(100), deadline=None)
@given(S.acyclic_chains())
def test_predecessors_are_the_direct_ones_in_declaration_order(chains: list[list[str]]) -> None:
    preds = predecessors(plan_graph(S.plan_of(chains)))
    rank, edges = _rank(chains), _edges(chains)
    assert set(preds) == set(rank)
    for step, ps in preds.items():
        assert list(ps) == sorted({a for a, b in edges if b == step}, key=rank.__getitem__)


@st.composite
def cyclic_chains(draw: st.DrawFn) -> list[list[str]]:
    """Acyclic chains plus one back edge (or a self-loop) somewhere among them."""
    chains = draw(S.acyclic_chains())
    g = plan_graph(S.plan_of(chains))
    u = draw(st.sampled_from(sorted(g.nodes)))
    v = draw(st.sampled_from(sorted(nx.descendants(g, u) | {u})))  # v reachable from u: v < u closes a cycle
    chains.insert(draw(st.integers(0, len(chains))), [v, u])
    return chains


def _is_cycle(cycle: list[str], g: nx.DiGraph) -> bool:
    return len(set(cycle)) == len(cycle) and all(
        g.has_edge(a, b) for a, b in zip(cycle, [*cycle[1:], cycle[0]], strict=True))


@settings(max_examples=n(100), deadline=None)
@given(cyclic_chains())
def test_find_cycle_returns_a_real_cycle_from_its_earliest_step(chains: list[list[str]]) -> None:
    g = plan_graph(S.plan_of(chains))
    cycle = find_cycle(g)
    assert cycle is not None
    assert _is_cycle(cycle, g)
    rank = _rank(chains)
    assert rank[cycle[0]] == min(rank[s] for s in cycle)


def _plan_mission(chains: list[list[str]], concurrent: bool) -> str:
    steps = list(_rank(chains))
    head = "plan concurrent {" if concurrent else "plan {"
    lines = ["mission M {", "    needs ranger: Ranger", "    " + head,
             *("        " + " < ".join(c) for c in chains), "    }", "}", ""]
    for s in steps:
        lines += [f"behavior {s} {{", "    FollowCorridor(speed: 0.5)", "}", ""]
    return "\n".join(lines)


def _compile_plan(chains: list[list[str]], concurrent: bool, catalog: Catalog) -> Statechart:
    c = compile_text(_plan_mission(chains, concurrent), catalog, "plan.mission")
    assert c.ok, [d.render(c.sources) for d in c.diagnostics]
    assert c.statechart is not None
    return c.statechart


@settings(max_examples=n(40), deadline=None, suppress_health_check=SLOW)
@given(S.acyclic_chains(max_steps=6))
def test_compiled_concurrent_plan_waits_for_direct_predecessors(catalog: Catalog, chains: list[list[str]]) -> None:
    chart = _compile_plan(chains, True, catalog)
    rank, edges = _rank(chains), _edges(chains)
    root = chart[chart.root]
    assert root.policy is ast.Policy.ALL
    for s in rank:
        state = chart[f"M/{s}"]
        expected = sorted({a for a, b in edges if b == s}, key=rank.__getitem__)
        assert state.after == tuple(f"M/{p}" for p in expected)
        assert not any(t.generated for t in state.transitions)


@settings(max_examples=n(40), deadline=None, suppress_health_check=SLOW)
@given(S.acyclic_chains(max_steps=6))
def test_compiled_sequential_plan_follows_total_order(catalog: Catalog, chains: list[list[str]]) -> None:
    chart = _compile_plan(chains, False, catalog)
    order = total_order(plan_graph(S.plan_of(chains)))
    assert order == _reference_order(chains)
    root = chart[chart.root]
    walked, state = [], root.initial
    while state is not None and state != "M/done":
        walked.append(state)
        generated = [t for t in chart[state].transitions if t.generated]
        assert len(generated) == 1, chart[state].transitions
        state = generated[0].target
    assert walked == [f"M/{s}" for s in order]
    assert state == "M/done"


@settings(max_examples=n(40), deadline=None, suppress_health_check=SLOW)
@given(cyclic_chains(), st.booleans())
def test_compiled_plan_cycle_names_a_real_cycle(catalog: Catalog, chains: list[list[str]], concurrent: bool) -> None:
    c = compile_text(_plan_mission(chains, concurrent), catalog, "plan.mission")
    check_diagnostics(c.diagnostics, c.sources)
    cycles = [d for d in c.diagnostics if d.code == "plan-cycle"]
    assert len(cycles) == 1, c.diagnostics
    m = re.fullmatch(r"plan cycle: (.*)", cycles[0].message)
    assert m is not None
    named = m.group(1).split(" < ")
    assert named[0] == named[-1]
    g = plan_graph(S.plan_of(chains))
    assert _is_cycle(named[:-1], g)
    rank = _rank(chains)
    assert rank[named[0]] == min(rank[s] for s in named)
    assert len(cycles[0].notes) == len(named) - 1
