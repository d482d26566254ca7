"""Partial-order plans: precedence graphs, cycles, and the orders the runtime follows.

`plan { A < B; A < C }` only states precedence. By default the system picks one total
order consistent with it, breaking ties by the order the steps first appear in the plan
(so the result is stable and the author can predict it); `plan concurrent` starts each step as soon as all its
predecessors are done. networkx does the graph work.
"""

from __future__ import annotations

from collections.abc import Sequence

import networkx as nx

from dsl import ast


def plan_graph(plan: ast.Plan) -> nx.DiGraph:
    """Steps as nodes (with their rank, the order of their first appearance in the plan, and first span),
    precedences as edges."""
    g: nx.DiGraph = nx.DiGraph()
    for chain in plan.chains:
        for step in chain:
            if step.name not in g:
                g.add_node(step.name, rank=g.number_of_nodes(), span=step.span)
        for a, b in zip(chain, chain[1:], strict=False):
            if not g.has_edge(a.name, b.name):
                g.add_edge(a.name, b.name, span=b.span)
    return g


def find_cycle(g: nx.DiGraph) -> list[str] | None:
    """One cycle as the list of its steps, starting at the earliest declared, or None."""
    try:
        edges = nx.find_cycle(g)
    except nx.NetworkXNoCycle:
        return None
    steps = [u for u, _ in edges]
    first = min(range(len(steps)), key=lambda i: g.nodes[steps[i]]["rank"])
    return steps[first:] + steps[:first]


def total_order(g: nx.DiGraph) -> list[str]:
    """A topological order; among ready steps, the one that appears first in the plan goes first."""
    return list(nx.lexicographical_topological_sort(g, key=lambda n: g.nodes[n]["rank"]))


def predecessors(g: nx.DiGraph) -> dict[str, tuple[str, ...]]:
    """For `plan concurrent`: each step's direct predecessors, in declaration order."""
    return {n: tuple(sorted(g.predecessors(n), key=lambda p: g.nodes[p]["rank"])) for n in g.nodes}


def respects(order: Sequence[str], g: nx.DiGraph) -> bool:
    """True when `order` puts every step after all of its predecessors."""
    pos = {n: i for i, n in enumerate(order)}
    return all(pos[a] < pos[b] for a, b in g.edges)
