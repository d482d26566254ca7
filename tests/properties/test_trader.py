"""The trader (drd.trader): queries and their order, exact errors with columns, and properties under hypothesis."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drd.trader import Offer, Order, TraderError, compile_query, query
from dsl.catalog import Catalog


def host(name: str, load: float, up: bool = True) -> dict[str, object]:
    return {"name": name, "load": load, "cpu": load * 100, "memory": 30.0, "up": up}


OFFERS = [
    Offer("ranger1.camera", "Camera", {"resolution": 640, "fov": 60.0}, host("ranger1", 0.7)),
    Offer("scout1.camera", "Camera", {"resolution": 320, "fov": 90.0}, host("ranger1", 0.7)),
    Offer("ranger2.camera", "Camera", {"resolution": 1280, "fov": 60.0}, host("ranger2", 0.2)),
    Offer("sim.camera", "Camera", {"fov": 45.0}, host("controller", 0.1)),  # no resolution: never matches on it
    Offer("scout1", "Scout", {"carrier": "ranger1", "battery": 0.9, "camera": "scout1.camera"}, host("ranger1", 0.7)),
    Offer("scout2", "Scout", {"carrier": "ranger1", "battery": 0.3}, host("ranger1", 0.7)),
    Offer("scout3", "Scout", {"carrier": "ranger2", "battery": 1.0}, host("ranger2", 0.2)),
    Offer("ranger1", "Ranger", {"battery": 1.0, "magazine": 2}, host("ranger1", 0.7)),
    Offer("ranger2", "Ranger", {"battery": 0.5, "magazine": 0}, host("ranger2", 0.2)),
    Offer("ranger1.drive", "Drive", {"max_speed": 0.8}, host("ranger1", 0.7)),
    Offer("ranger2.drive", "Drive", {"max_speed": 0.8}, host("ranger2", 0.2)),
    Offer("scout1.wheels", "Drive", {"max_speed": 0.3}, host("ranger1", 0.7)),
]


@pytest.mark.parametrize(("text", "ids"), [
    ("Camera where resolution >= 640 prefer min(host.load)", ["ranger2.camera", "ranger1.camera"]),
    ('Scout where carrier == "ranger1" and battery > 0.5', ["scout1"]),
    ("Ranger", ["ranger1", "ranger2"]),
    ("Camera prefer max(resolution)", ["ranger2.camera", "ranger1.camera", "scout1.camera", "sim.camera"]),
    ("Camera prefer min(resolution)", ["scout1.camera", "ranger1.camera", "ranger2.camera", "sim.camera"]),
    ("Camera prefer min(fov)", ["sim.camera", "ranger1.camera", "ranger2.camera", "scout1.camera"]),
    ("Camera prefer first", ["ranger1.camera", "scout1.camera", "ranger2.camera", "sim.camera"]),
    ("Ranger prefer max(battery * magazine)", ["ranger1", "ranger2"]),
    ('Scout where host.name == "ranger1" prefer max(battery)', ["scout1", "scout2"]),
    ('Scout where id != "scout1" and not (battery < 0.5)', ["scout3"]),
    ('Drive where host.up and max_speed > 0.5 prefer max(host.load)', ["ranger1.drive", "ranger2.drive"]),
    ("Camera where resolution > 5000", []),
    ("Jump", []),
    ("  Ranger\n  where magazine > 0  ", ["ranger1"]),
])
def test_queries(text: str, ids: list[str], catalog: Catalog) -> None:
    assert [o.id for o in query(text, OFFERS, catalog=catalog)] == ids


def test_random_is_seeded(catalog: Catalog) -> None:
    text = 'Drive where host.name != "ranger2" prefer random'
    runs = {seed: [o.id for o in query(text, OFFERS, catalog=catalog, seed=seed)] for seed in range(20)}
    assert all(sorted(ids) == ["ranger1.drive", "scout1.wheels"] for ids in runs.values())
    assert len({tuple(ids) for ids in runs.values()}) == 2  # both orders happen...
    assert runs[7] == [o.id for o in query(text, OFFERS, catalog=catalog, seed=7)]  # ...and a seed repeats its own


@pytest.mark.parametrize(("text", "message", "column"), [
    ("", "expected a component type, such as Camera", 1),
    ("Camra", "unknown type Camra (did you mean Camera?)", 1),
    ("  Zeppelin", "unknown type Zeppelin (resource types: Camera, Drive, Jump, Launcher, RadioChannel, RangeSensor, "
                "Ranger, Robot, Scout, Sensor)", 3),
    ("Camera where resolutin >= 640", "unknown property resolutin (did you mean resolution?)", 14),
    ("Camera where colour", "unknown property colour (Camera has driver, fov, host, id, resolution)", 14),
    ("Camera where host.lod > 1", "host has no field lod (did you mean load?)", 14),
    ("Camera where resolution", "where expects bool, got int", 14),
    ('Camera where resolution > "640"', "cannot order int and str with >", 14),
    ("Camera prefer min(id)", "prefer needs a number, got str", 19),
    ("Camera where", "expected a condition after where", 14),
    ("Camera where resolution >= prefer max(fov)",
     "the condition after where ends too early: expected a value (a property, a number, a string, true or false)",
     27),
    ("Camera where (resolution > 1", "the condition after where ends too early: expected `)`", 29),
    ("Camera where resolution > 1 fov", "expected an operator, got `fov`", 29),
    ("Camera where id == 'a'", "unexpected character \"'\" (strings use double quotes)", 20),
    ("Camera where host.", "the condition after where ends too early: expected a field name", 19),
    ("Camera x", "expected where or prefer after Camera, got `x`", 8),
    ("where x", "expected a component type before where", 1),
    ("Camera prefer", "expected min(...), max(...), random or first after prefer", 15),
    ("Camera prefer randon", "unknown preference randon (did you mean random?)", 15),
    ("Camera prefer min", "prefer min needs an expression: prefer min(EXPR)", 15),
    ("Camera prefer min(fov, resolution)", "prefer min(...) takes one expression", 15),
    ("Camera prefer 3", "expected min(...), max(...), random or first after prefer", 15),
    ("Camera prefer max(fov) where fov > 1", "where must come before prefer", 24),
    ("Camera where fov > 1 where fov < 2", "where is given twice", 22),
    ("Camera prefer random prefer first", "prefer is given twice", 22),
    ("Scout where count(Scout) > 1", "count(...) is not available in trader queries", 13),
    ('Scout where carrier == "r\\q1"', "unknown escape \\q in string (write \\\\ for a backslash; known escapes: "
                                       '\\n \\t \\" \\\\ \\{ \\})', 26),
    ("Scout where sqrt(battery) > 1", "unknown function sqrt (functions: abs, len, min, max)", 13),
])
def test_bad_queries(text: str, message: str, column: int, catalog: Catalog) -> None:
    with pytest.raises(TraderError) as info:
        compile_query(text, catalog)
    assert (info.value.message, info.value.column) == (message, column)


def test_the_error_renders_a_caret(catalog: Catalog) -> None:
    with pytest.raises(TraderError) as info:
        query("Camera where resolutin >= 640", OFFERS, catalog=catalog)
    assert info.value.render("Camera where resolutin >= 640") == (
        "Camera where resolutin >= 640\n"
        "             ^ unknown property resolutin (did you mean resolution?)")
    assert str(info.value) == "column 14: unknown property resolutin (did you mean resolution?)"


def test_without_a_catalog_only_syntax_and_types_are_checked() -> None:
    assert [o.id for o in query("Camra where x > 1", OFFERS)] == []
    assert [o.id for o in query("Camera where resolution > 400", OFFERS)] == ["ranger1.camera", "ranger2.camera"]
    with pytest.raises(TraderError, match="cannot compare int with str"):
        compile_query('Camera where 1 == "a"')


def test_offers_that_cannot_be_evaluated() -> None:
    odd = [Offer("a", "T", {"k": "text"}), Offer("b", "T", {"k": 2}), Offer("c", "T", {"k": math.nan}),
           Offer("d", "T", {"k": True}), Offer("e", "T", {}), Offer("f", "T", {"k": 1.5})]
    assert [o.id for o in query("T prefer min(k)", odd)] == ["f", "b", "a", "c", "d", "e"]
    assert [o.id for o in query("T prefer max(k)", odd)] == ["b", "f", "a", "c", "d", "e"]
    assert [o.id for o in query("T where k > 1", odd)] == ["b", "f"]  # "text" > 1 and a missing k do not match
    assert [o.id for o in query("T where k", odd)] == ["d"]  # a non-bool condition does not match
    assert compile_query("T").order is Order.FIRST


# ---------------------------------------------------------------- properties

OPS = {"<": float.__lt__, "<=": float.__le__, ">": float.__gt__, ">=": float.__ge__, "==": float.__eq__,
       "!=": float.__ne__}
values = st.one_of(st.integers(-5, 5), st.floats(-5, 5, allow_nan=False), st.just("x"), st.just(None))
offers = st.lists(st.builds(
    lambda i, kind, v, load: Offer(f"o{i}", kind, {} if v is None else {"v": v}, host(f"h{i % 3}", load)),
    st.integers(0, 99), st.sampled_from(["T", "T", "U"]), values, st.floats(0, 4, allow_nan=False)), max_size=12)


def number(v: object) -> float | None:
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else None


@settings(max_examples=300, deadline=None)
@given(offers, st.sampled_from(sorted(OPS)), st.integers(-5, 5),
       st.sampled_from(["min(v)", "max(v)", "min(host.load)", "max(v * 2 - host.load)", "first", "random"]),
       st.integers(0, 3))
def test_results_satisfy_the_constraint_and_follow_the_preference(given_offers: list[Offer], op: str, bound: int,
                                                                   prefer: str, seed: int) -> None:
    q = compile_query(f"T where v {op} {bound} prefer {prefer}")
    got = q.run(given_offers, seed)

    def ok(o: Offer) -> bool:  # the language's semantics: == and != compare any values, ordering needs numbers
        if o.type != "T" or "v" not in o.properties:
            return False
        raw, v = o.properties["v"], number(o.properties["v"])
        if op in ("==", "!="):
            return (raw == bound) == (op == "==")
        return v is not None and OPS[op](v, float(bound))

    assert all(ok(o) for o in got)
    assert sorted(map(id, got)) == sorted(id(o) for o in given_offers if ok(o))  # each matching offer, once
    keys = [q.key_of(o) for o in got]
    known = [k for k in keys if k is not None]
    assert keys[:len(known)] == known  # those without a key come last
    if q.order is Order.MIN:
        assert known == sorted(known)
    elif q.order is Order.MAX:
        assert known == sorted(known, reverse=True)
    elif q.order is Order.FIRST:
        assert got == [o for o in given_offers if ok(o)]
    assert got == q.run(given_offers, seed)  # deterministic, random included
