"""The resources the executive knows, as the Resource Controller Manager's candidates and as
values expressions can read (`ranger.battery`, `scout.carrier == ranger`)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping

from drd.rcm import Aggregate, Candidate, ReleaseReason, ResourceManager
from drd.runtime.broker import ResourceBroker


class ResourceView(Mapping[str, object]):
    """A resource as an expression sees it: its properties, `id`, `host` and parts.

    It compares equal to its id, so `scout.carrier == ranger` holds when the Scout's
    `carrier` property names that Ranger.
    """

    __slots__ = ("_cand", "_pool")

    def __init__(self, cand: Candidate, pool: ResourcePool):
        self._cand = cand
        self._pool = pool

    @property
    def id(self) -> str:
        return self._cand.id

    def _data(self) -> dict[str, object]:
        c = self._cand
        data: dict[str, object] = {"id": c.id, "host": c.host, **self._pool.properties(c.id)}
        if isinstance(c, Aggregate):
            for part, unit in c.parts.items():
                data[part] = self._pool.view(unit)
        return data

    def __getitem__(self, key: str) -> object:
        c = self._cand
        if key == "id":
            return c.id
        if key == "host":
            return c.host
        if isinstance(c, Aggregate) and key in c.parts:
            return self._pool.view(c.parts[key])
        return self._pool.properties(c.id)[key]  # KeyError for an unknown property, as a mapping should

    def __iter__(self) -> Iterator[str]:
        return iter(self._data())

    def __len__(self) -> int:
        return len(self._data())

    def __eq__(self, other: object) -> bool:
        if isinstance(other, ResourceView):
            return other.id == self.id
        if isinstance(other, str):
            return other == self.id
        return NotImplemented

    def __hash__(self) -> int:
        return hash(self.id)

    def __repr__(self) -> str:
        return f"<{self._cand.type} {self.id}>"

    def __str__(self) -> str:
        return self.id


class ResourcePool:
    """Every unit and aggregate by id, kept in step with the manager (hot-plug, properties)."""

    def __init__(self, rcm: ResourceManager | ResourceBroker):
        self.broker = rcm if isinstance(rcm, ResourceBroker) else ResourceBroker(rcm)
        self.candidates: dict[str, Candidate] = {}
        self._props: dict[str, dict[str, object]] = {}

    def add(self, resources: Iterable[Candidate], now: float) -> None:
        """Register units before the aggregates that use them (decisions go to the broker's listeners)."""
        for c in sorted(resources, key=lambda c: isinstance(c, Aggregate)):
            self.candidates[c.id] = c
            self._props[c.id] = dict(c.properties)
            self.broker.add(c, now)

    def remove_host(self, host: str, now: float) -> None:
        """Forget a vanished host's resources; the manager frees their grants."""
        for rid in [rid for rid, c in self.candidates.items() if c.host == host]:
            del self.candidates[rid]
        self.broker.remove_host(host, now)

    def remove(self, resource_ids: Iterable[str], now: float, reason: ReleaseReason = "resource lost") -> None:
        """Forget resources that vanished (a lost robot); the manager frees their grants."""
        ids = set(resource_ids)
        for rid in ids & self.candidates.keys():
            del self.candidates[rid]
        self.broker.remove(ids, now, reason)

    def set_property(self, rid: str, key: str, value: object, now: float) -> None:
        """Change the Static Dependency Database (a launched Scout leaves its magazine)."""
        self._props.setdefault(rid, {})[key] = value
        self.broker.set_property(rid, key, value, now)

    def properties(self, rid: str) -> dict[str, object]:
        return self._props.get(rid, {})

    def view(self, rid: str) -> ResourceView | None:
        c = self.candidates.get(rid)
        return ResourceView(c, self) if c is not None else None

    def units(self, rid: str) -> tuple[str, ...]:
        c = self.candidates.get(rid)
        if isinstance(c, Aggregate):
            return c.units
        return (rid,) if c is not None else ()

    def part(self, rid: str, part: str | None) -> str:
        """The id of `part` of aggregate `rid` (or `rid` itself when no part is named)."""
        c = self.candidates.get(rid)
        if part is None or not isinstance(c, Aggregate):
            return rid
        return c.parts.get(part, rid)

    def count(self, type_name: str, pred: Callable[[object], bool] | None) -> int:
        """How many known resources of a type satisfy `pred` (for `count(Type where ...)`)."""
        n = 0
        for c in self.candidates.values():
            if c.type == type_name and (pred is None or pred(ResourceView(c, self))):
                n += 1
        return n
