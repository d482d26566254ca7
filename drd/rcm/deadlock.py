"""Wait-for cycles: find one with networkx, and pick the request to cancel.

All-or-nothing grants rule out hold-and-wait within one request, so a cycle needs an owner that
holds units while one of its descendants waits (holder "A" holds X, "A/child" asks for Y, while
"B" holds Y and "B/child" waits for X). The graph is built lazily from those nested waiters, with
successors computed fresh by the manager, so it never goes stale and costs nothing when no holder
has a waiting descendant.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import networkx as nx


def ancestors(path: str) -> Iterable[str]:
    """The proper prefixes of a holder path, by "/" segments: "A/B/C" -> "A", "A/B"."""
    parts = path.split("/")
    for end in range(1, len(parts)):
        yield "/".join(parts[:end])


def same_owner(a: str, b: str) -> bool:
    """Whether one holder path is the other or one of its ancestors."""
    return a == b or a.startswith(b + "/") or b.startswith(a + "/")


def find_cycle(starts: Iterable[str], successors: Callable[[str], Iterable[str]]) -> tuple[str, ...] | None:
    """A wait-for cycle reachable from `starts`, rotated to begin at its smallest node; or None."""
    import networkx as nx  # here, not at the top: only a wait that may deadlock needs it (fast CLI start-up)

    sources = sorted(set(starts))
    graph: nx.DiGraph[str] = nx.DiGraph()
    graph.add_nodes_from(sources)
    stack = list(reversed(sources))
    seen: set[str] = set()
    while stack:
        node = stack.pop()
        if node in seen:
            continue
        seen.add(node)
        for successor in successors(node):
            graph.add_edge(node, successor)
            stack.append(successor)
    try:
        edges = nx.find_cycle(graph, source=sources)
    except nx.NetworkXNoCycle:
        return None
    cycle = [edge[0] for edge in edges]
    start = cycle.index(min(cycle))
    return tuple(cycle[start:] + cycle[:start])


def choose_victim(candidates: Iterable[str], rank: Callable[[str], tuple[Any, ...]]) -> str:
    """The request to cancel: the largest `rank` = ((mission priority, priority) numbers, request order).

    That is the lowest priority and, among equals, the most recent requester: older work and more
    important work survive.
    """
    return max(candidates, key=lambda holder: (rank(holder), holder))
