"""`ResourcePool.having` (the narrowing of a `where` join) against the plain filter it speeds up (hypothesis).

Its index of positions per candidates tuple must keep the candidates' order and drop exactly those whose
stored property names another resource, also after properties change between two calls.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from drd.rcm import Aggregate, Candidate, ResourceManager, Unit
from drd.runtime.pool import ResourcePool

IDS = [f"s{i}" for i in range(8)]
VALUES = st.sampled_from(["r1", "r2", None, 3])


def plain(pool: ResourcePool, cands: tuple[Candidate, ...], prop: str, value: str) -> list[Candidate]:
    """The filter as stated: a candidate stays unless its own `prop` is a string other than `value`."""
    kept = []
    for c in cands:
        own = pool.properties(c.id).get(prop)
        if not isinstance(own, str) or own == value or (isinstance(c, Aggregate) and prop in c.parts):
            kept.append(c)
    return kept


@settings(max_examples=200, deadline=None)
@given(st.lists(VALUES, min_size=8, max_size=8), st.lists(st.tuples(st.sampled_from(IDS), VALUES), max_size=6),
       st.sampled_from(["r1", "r2", "r3"]))
def test_having_is_the_plain_filter(carriers: list[object], changes: list[tuple[str, object]], value: str) -> None:
    pool = ResourcePool(ResourceManager())
    units: list[Candidate] = [Unit(rid, "Scout", properties={"carrier": c} if c is not None else {})
                              for rid, c in zip(IDS, carriers, strict=True)]
    agg = Aggregate("a1", "Scout", {"carrier": "s0"}, {"carrier": "r9"})
    pool.add([*units, agg], 0.0)
    cands = tuple(sorted([*units, agg], key=lambda c: c.id))
    assert pool.having(cands, "carrier", value) == plain(pool, cands, "carrier", value)
    for now, (rid, carrier) in enumerate(changes, 1):
        pool.set_property(rid, "carrier", carrier, float(now))
        for v in ("r1", "r2", value):
            assert pool.having(cands, "carrier", v) == plain(pool, cands, "carrier", v)
            assert pool.having(list(cands), "carrier", v) == plain(pool, cands, "carrier", v)
