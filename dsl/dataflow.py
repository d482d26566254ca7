"""Declared data flow: which datum each input of an elementary behavior reads (pure, no I/O).

A component declares typed `inputs` and `outputs` in its manifest; it never looks a sibling, an ancestor's shared
data or a parent up by name. Where the behavior is used, each input binds to what is in scope, the rule the
language already uses for resources:

1. explicitly: `AlignRanger(door: finder.door)` (a sibling's output) or `DetectDoor(visited: doors)` (a shared
   datum); `last(finder.door)` reads the value of the previous control cycle (it breaks a cycle of concurrent
   siblings feeding each other);
2. by name: a datum called like the input, of its type (an output that declares no type matches by name only);
3. by type: the one datum of the input's type.

Scope is searched level by level, nearest first: the behavior's siblings (the other children of its parent, each
with the outputs of its whole subtree) and its parent's `shared` data, then its parent's siblings and the
grandparent's shared data, and so on up to the mission. Two candidates at the nearest level that has any are an
ambiguity (a located error naming both); none, for an input that is not `optional`, is a located error too.
A sibling's output is read live: the value it has now if it runs (a port between concurrent siblings, stepped
producers first), the last one it left if it finished.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass

from dsl.catalog import InputSpec

#: The type of an output that declares fields but no data type: it binds by name only.
UNTYPED = "record"


@dataclass(frozen=True, slots=True)
class Offer:
    """A datum in scope: an output of the sibling state `state` (its name `key` in the parent), or the shared datum
    `name` declared by the state `state`."""

    state: str
    name: str
    type: str
    shared: bool
    key: str = ""

    def describe(self) -> str:
        return f"shared {self.name}: {self.type}" if self.shared else f"{self.key}.{self.name}" + (
            f" ({self.type})" if self.type != UNTYPED else "")


@dataclass(frozen=True, slots=True)
class InputBinding:
    """Input `name` of a leaf reads `field` of `state`: a sibling state's output, or the shared datum declared by
    `state` (`shared`). `last`: the previous control cycle's value."""

    name: str
    state: str
    field: str
    shared: bool
    last: bool = False


@dataclass(frozen=True, slots=True)
class Ambiguous:
    """Several data fit at the nearest level that has any."""

    offers: tuple[Offer, ...]


class Scope:
    """The data of one level of a body (its children's outputs and its shared data), indexed once by name, type and
    sibling: every child of the body looks its inputs up in it, so a body of many children costs each lookup a
    dictionary hit, not a scan of all its siblings (a 20,000-child mission compiled in quadratic time)."""

    def __init__(self, offers: Iterable[Offer], opaque: bool = False) -> None:
        self.offers = tuple(offers)
        self.opaque = opaque  # a child or datum here is unknown (a checker error): what it offers is unknown too
        self.by_name: dict[str, list[Offer]] = {}
        self.by_type: dict[str, list[Offer]] = {}
        self.by_key: dict[str, list[Offer]] = {}
        for o in self.offers:
            self.by_name.setdefault(o.name, []).append(o)
            self.by_type.setdefault(o.type, []).append(o)
            if not o.shared:
                self.by_key.setdefault(o.key, []).append(o)


@dataclass(frozen=True, slots=True)
class Level:
    """What one child sees of a `Scope`: all of it but its own outputs (`skip`, its key in the body)."""

    scope: Scope
    skip: str = ""

    def _visible(self, offers: Iterable[Offer]) -> list[Offer]:
        return [o for o in offers if o.shared or o.key != self.skip]

    def named(self, name: str) -> list[Offer]:
        return self._visible(self.scope.by_name.get(name, ()))

    def typed(self, type_: str) -> list[Offer]:
        return self._visible(self.scope.by_type.get(type_, ()))

    def outputs_of(self, key: str) -> list[Offer]:
        """The outputs of sibling `key` (none for the child itself)."""
        return [] if key == self.skip else list(self.scope.by_key.get(key, ()))

    def __iter__(self) -> Iterator[Offer]:
        return iter(self._visible(self.scope.offers))


def bind(spec: InputSpec, levels: Sequence[Level]) -> Offer | Ambiguous | None:
    """The datum input `spec` binds to, by name then by type, nearest level first (see the module doc)."""
    for level in levels:
        hits = [o for o in level.named(spec.name) if o.type in (spec.type, UNTYPED)]
        if hits:
            return hits[0] if len(hits) == 1 else Ambiguous(tuple(hits))
    for level in levels:
        hits = level.typed(spec.type)
        if hits:
            return hits[0] if len(hits) == 1 else Ambiguous(tuple(hits))
    return None


def producer_order(names: Sequence[str], feeds: Iterable[tuple[str, str]]) -> list[str] | list[str | None]:
    """`names` (concurrent siblings, in declaration order) with every producer before its consumers; `feeds` are
    (producer, consumer) edges read this cycle. A cycle returns the names on it, followed by None."""
    import networkx as nx

    graph: nx.DiGraph[str] = nx.DiGraph()
    graph.add_nodes_from(names)
    graph.add_edges_from((a, b) for a, b in feeds if a != b and a in graph and b in graph)
    try:
        rank = {n: i for i, n in enumerate(names)}
        return list(nx.lexicographical_topological_sort(graph, key=lambda n: rank[n]))
    except nx.NetworkXUnfeasible:
        cycle = [edge[0] for edge in nx.find_cycle(graph)]
        return [*cycle, None]
