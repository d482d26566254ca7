"""The all-or-nothing matcher: assign a candidate to every need of a request, or fail.

Needs are solved in their declared order so that a `where` can look at the candidates chosen for
the earlier needs (`scout.carrier == ranger`); when a later need fails, the search backtracks over
the earlier choices. Candidates are tried in a stable order (by id) so the same state always gives
the same assignment. A `where` may offer `narrow(candidates, chosen)`: the candidates, in order, outside
of which it is never true (`drd.runtime.resources.Where`: the Scouts of the chosen Ranger); only those are tried.
How much of each unit may be taken is a parameter (`room`): the manager passes
what is free for this request, and the capacity alone to ask whether a request can *ever* be met.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from itertools import islice
from types import MappingProxyType
from typing import Protocol

from drd.rcm.model import Candidate, NeedRequest, Unit, units_of

#: Tolerance on capacity sums, so 0.1 + 0.2 of a 0.3 channel fits.
EPS = 1e-9


class Catalog(Protocol):
    """What the solver needs to know about the registered resources."""

    def candidates(self, type: str) -> Iterable[Candidate]:
        """The candidates of a unit or aggregate type, in a stable order."""
        ...

    def unit(self, unit_id: str) -> Unit:
        """A registered unit."""
        ...

    def demand(self, candidate: Candidate, need: NeedRequest) -> Mapping[str, float]:
        """What `candidate` takes of each of its units for `need` (see `demand_of`); read-only."""
        ...


@dataclass(frozen=True, slots=True)
class Solution:
    """One full assignment: need -> candidate, what each need takes of each unit, and the sums."""

    chosen: Mapping[str, Candidate]
    demand: Mapping[str, Mapping[str, float]]
    totals: Mapping[str, float]  # unit -> quantity over all needs, in need order

    @property
    def assignment(self) -> dict[str, str]:
        return {need: candidate.id for need, candidate in self.chosen.items()}

    @property
    def units(self) -> tuple[str, ...]:
        """Every unit taken, once, in need order."""
        return tuple(self.totals)


def demand_of(catalog: Catalog, candidate: Candidate, need: NeedRequest) -> dict[str, float]:
    """What a candidate takes of each of its units: exclusive units whole, sharable ones by quantity."""
    demand: dict[str, float] = {}
    for unit_id in units_of(candidate):
        unit = catalog.unit(unit_id)
        demand[unit_id] = need.quantity if unit.sharable else unit.capacity
    return demand


def solutions(
    needs: Sequence[NeedRequest],
    catalog: Catalog,
    room: Callable[[str], float],
    given: Mapping[str, Candidate] | None = None,
) -> Iterator[Solution]:
    """Every assignment of the needs that fits in `room`, in stable order (lazily).

    `room(unit_id)` is how much of the unit this request may take; it is asked at most once per
    unit and search. `given` pre-binds names that `where` may read but that are not asked for (the
    needs a resumed holder already gave back). Within one request an exclusive unit is taken once
    and sharable quantities add up.
    """
    chosen: dict[str, Candidate] = dict(given or {})
    view = MappingProxyType(chosen)
    demands: dict[str, Mapping[str, float]] = {}
    used: dict[str, float] = {}
    rooms: dict[str, float] = {}

    def fits(demand: Mapping[str, float]) -> bool:
        for unit_id, quantity in demand.items():
            limit = rooms.get(unit_id)
            if limit is None:
                limit = rooms[unit_id] = room(unit_id)
            if used.get(unit_id, 0.0) + quantity > limit + EPS:
                return False
        return True

    def leaf() -> Solution:
        totals: dict[str, float] = {}
        for demand in demands.values():
            for unit_id, quantity in demand.items():
                totals[unit_id] = totals.get(unit_id, 0.0) + quantity
        return Solution({need.name: chosen[need.name] for need in needs}, dict(demands), totals)

    def search(index: int) -> Iterator[Solution]:
        need = needs[index]
        last = index == len(needs) - 1  # leaves are yielded here: no generator per candidate
        candidates = catalog.candidates(need.type)
        narrow = getattr(need.where, "narrow", None)
        if narrow is not None:  # a `where` that can rule candidates out wholesale (a join on an earlier need)
            candidates = narrow(candidates, view)
        for candidate in candidates:
            demand = catalog.demand(candidate, need)
            # Capacity first: it is cheap, and `where` may be arbitrary compiled mission code.
            if not fits(demand) or (need.where is not None and not need.where(candidate, view)):
                continue
            chosen[need.name] = candidate
            demands[need.name] = demand
            if last:
                yield leaf()
            else:
                for unit_id, quantity in demand.items():
                    used[unit_id] = used.get(unit_id, 0.0) + quantity
                yield from search(index + 1)
                for unit_id, quantity in demand.items():
                    used[unit_id] -= quantity
            del chosen[need.name], demands[need.name]

    return search(0) if needs else iter((leaf(),))


def first_solution(
    needs: Sequence[NeedRequest],
    catalog: Catalog,
    room: Callable[[str], float],
    given: Mapping[str, Candidate] | None = None,
) -> Solution | None:
    """The first assignment in stable order, or None."""
    return next(solutions(needs, catalog, room, given), None)


def alternatives(
    needs: Sequence[NeedRequest],
    catalog: Catalog,
    given: Mapping[str, Candidate] | None = None,
    limit: int = 256,
) -> tuple[list[Solution], bool]:
    """Every assignment possible on an empty system (capacity only), up to `limit`.

    Returns the assignments and whether the list was cut. The union of their units is what a
    waiting request claims: the units it may end up needing, which lower-priority requests must
    leave alone.
    """
    found = list(islice(solutions(needs, catalog, lambda u: catalog.unit(u).capacity, given), limit + 1))
    return found[:limit], len(found) > limit


def diagnose(
    needs: Sequence[NeedRequest],
    catalog: Catalog,
    given: Mapping[str, Candidate] | None = None,
) -> tuple[str, str] | None:
    """Why the needs can never be met on the known units, as (need name, reason); None if they can.

    Names the first need whose prefix of the request has no assignment, so with dependent needs the
    message points at the dependent one (`scout`), not at the one it depends on.
    """

    def capacity(unit_id: str) -> float:
        return catalog.unit(unit_id).capacity

    if first_solution(needs, catalog, capacity, given) is not None:
        return None
    for index, need in enumerate(needs):
        if first_solution(needs[: index + 1], catalog, capacity, given) is not None:
            continue
        typed = list(catalog.candidates(need.type))
        if not typed:
            return need.name, f"no {need.type} is known"
        if index == 0 and need.where is None:
            return need.name, f"quantity {need.quantity:g} exceeds the capacity of every {need.type}"
        earlier = ", ".join(n.name for n in needs[:index])
        suffix = f" together with {earlier}" if earlier else ""
        return need.name, f"no {need.type} satisfies the constraint{suffix}"
    return needs[-1].name, "the needs cannot all be met at once"  # pragma: no cover - defensive
