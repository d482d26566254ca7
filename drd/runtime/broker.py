"""One Resource Controller Manager shared by several missions.

The manager returns its decisions to whoever called it, but a release by one mission can
grant a waiter of another. The broker calls the manager and hands every decision to every
attached listener (each interpreter keeps those naming its own holders), so several
missions share one manager by priority, in one process or behind the daemon.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Iterator
from contextlib import contextmanager
from typing import Any

from drd.rcm import Aggregate, Decision, ReleaseReason, Request, ResourceManager, Unit

DecisionListener = Callable[[Iterable[Decision]], None]


class ResourceBroker:
    def __init__(self, rcm: ResourceManager):
        self.rcm = rcm
        self.listeners: list[DecisionListener] = []
        self._kept: list[tuple[Request, float]] | None = None  # requests held back while `together` (see there)

    def attach(self, listener: DecisionListener) -> None:
        self.listeners.append(listener)

    def detach(self, listener: DecisionListener) -> None:
        if listener in self.listeners:
            self.listeners.remove(listener)

    def _publish(self, decisions: tuple[Decision, ...]) -> tuple[Decision, ...]:
        """Hand the decisions out one at a time, in the manager's order, to every listener: a release seen by one
        mission comes before the grant it made to another, in every mission's records as in the manager."""
        listeners = self.listeners
        if len(listeners) == 1:
            listeners[0](decisions)
            return decisions
        for d in decisions:
            for listener in list(listeners):
                listener((d,))
        return decisions

    def request(self, req: Request, now: float) -> tuple[Decision, ...]:
        if self._kept is not None:
            self._kept.append((req, now))
            return ()
        return self._publish(self.rcm.request(req, now))

    @contextmanager
    def together(self) -> Iterator[None]:
        """Missions entered at one instant, as one: their requests are asked when the block ends, best rank first
        (mission priority, then priority; equals in the order made). A controller resuming its missions entered
        them one by one, and the first entered took what a better one had held (safety audit 7, D2). A request
        withdrawn meanwhile (`cancel`, `release` of its holder) is never asked."""
        if self._kept is not None:
            yield
            return
        self._kept = []
        try:
            yield
        finally:
            kept, self._kept = self._kept, None
            for req, now in sorted(kept, key=lambda item: item[0].rank):  # stable: equals keep their order
                self._publish(self.rcm.request(req, now))

    def _withdraw(self, holder: str) -> None:
        if self._kept:
            self._kept = [(r, t) for r, t in self._kept if r.holder != holder and not r.holder.startswith(holder + "/")]

    def reserve(self, req: Request, now: float, at: float) -> tuple[Decision, ...]:
        return self._publish(self.rcm.reserve(req, now, at))

    def release(self, holder: str, now: float, units: Collection[str] | None = None) -> tuple[Decision, ...]:
        if units is None:
            self._withdraw(holder)
        return self._publish(self.rcm.release(holder, now, units))

    def cancel(self, holder: str, now: float) -> tuple[Decision, ...]:
        self._withdraw(holder)
        return self._publish(self.rcm.cancel(holder, now))

    def renew(self, holder: str, now: float) -> tuple[Decision, ...]:
        return self._publish(self.rcm.renew(holder, now))

    def tick(self, now: float) -> tuple[Decision, ...]:
        return self._publish(self.rcm.tick(now))

    def remove_host(self, host: str, now: float) -> tuple[Decision, ...]:
        return self._publish(self.rcm.remove_host(host, now))

    def set_host_offline(self, host: str, offline: bool, now: float) -> tuple[Decision, ...]:
        return self._publish(self.rcm.set_host_offline(host, offline, now))

    def remove(self, resource_ids: Iterable[str], now: float,
               reason: ReleaseReason = "resource lost") -> tuple[Decision, ...]:
        return self._publish(self.rcm.remove(resource_ids, now, reason))

    def set_property(self, rid: str, key: str, value: object, now: float) -> tuple[Decision, ...]:
        return self._publish(self.rcm.set_property(rid, key, value, now))

    def add(self, resource: Unit | Aggregate, now: float) -> tuple[Decision, ...]:
        if isinstance(resource, Unit):
            return self._publish(self.rcm.add_unit(resource, now))
        return self._publish(self.rcm.add_aggregate(resource, now))

    def __getattr__(self, name: str) -> Any:
        if name in _DECIDING:
            raise AttributeError(f"{name} makes decisions: add it to ResourceBroker so they are published")
        return getattr(self.rcm, name)  # queries: holders, queue, snapshot


_DECIDING = {"add_unit", "add_aggregate"}
