"""The report's active leaves and their owners (drd/explain.py) against the pairwise definitions (hypothesis)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from drd.explain import _leaves, _owners

SEGMENTS = st.sampled_from(["M", "R", "R[0]", "R[1]", "R[10]", "Go", "A/B", "x"])
PATHS = st.lists(st.lists(SEGMENTS, min_size=1, max_size=4).map("/".join), max_size=30, unique=True)


@settings(max_examples=300, deadline=None)
@given(PATHS)
def test_leaves_are_the_paths_with_nothing_below(paths: list[str]) -> None:
    plain = [p for p in paths if not any(q.startswith((p + "/", p + "[")) for q in paths)]
    assert _leaves(iter(paths)) == plain


@settings(max_examples=300, deadline=None)
@given(PATHS, st.lists(SEGMENTS, min_size=1, max_size=4).map("/".join))
def test_owners_are_the_paths_a_path_is_below(others: list[str], path: str) -> None:
    for s in others:
        assert (s in _owners(path)) == path.startswith((s + "/", s + "["))
