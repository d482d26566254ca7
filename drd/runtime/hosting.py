"""Component hosting: the elementary behaviors of one mission, their contexts, devices and lifecycle calls.

A component is set up once per instance path (py_trees' `setup`) and started on every entry of its state
(`initialise`); a state re-entered in a loop keeps its object. Its devices are `BoundDevice`s over the
bindings the resource client made, so every command it sends goes through the device's gate with the path and
epoch it was bound with. Component code is not ours to trust: whatever it raises fails its own state (through
`on_failure`), never the executive.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Any

from drd.runtime import records as rec
from drd.runtime.component import Component, Context, Registry, Status
from drd.runtime.ownership import Arbiter, BoundDevice
from drd.runtime.resources import ResourceClient
from drd.runtime.tree import ACTIVE, Node

_FINAL_STATUS = {"success": Status.SUCCESS, "failure": Status.FAILURE}


class ComponentHost:
    """The components of one mission: who is running (in entry order, the order they are stepped), and calls."""

    def __init__(self, registry: Registry, resources: ResourceClient, arbiter: Arbiter, clock: Callable[[], float],
                 services: Mapping[str, Any], *, notify: Callable[[rec.Record], None],
                 emit: Callable[..., None], on_failure: Callable[[Node, str], None],
                 rank: Mapping[str, int]) -> None:
        self.registry = registry
        self.resources = resources
        self.arbiter = arbiter
        self.now = clock
        self.services = services
        self.notify = notify
        self.emit = emit
        self.on_failure = on_failure
        self.rank = rank  # state id -> declaration order (a later layer subsumes an earlier one)
        self.running: dict[Node, None] = {}  # leaves with a started component, in entry order
        self._made: dict[str, tuple[Component, Context]] = {}  # per instance path, reused on re-entry

    def active(self) -> Iterator[tuple[Node, Component]]:
        """The components stepped in this cycle, in order (active ones only)."""
        for node in self.running:
            comp = node.component
            if node.phase is ACTIVE and comp is not None:
                yield node, comp

    def start(self, node: Node) -> None:
        """Bind the leaf's needs, set its component up (first entry of this path only) and start it."""
        try:
            bindings = self.resources.bind(node)
        except Exception as e:  # a binding error names the need and the holder it leads to
            self.on_failure(node, str(e))
            return
        issuer = self.resources.holder(node)
        rank = (-node.state.priority, self.rank.get(node.state.id, 0))
        devices = {need: BoundDevice(b, issuer, self.arbiter, rank, node, self.now)
                   for need, b in bindings.items() if b.driver is not None}
        resources = {need: b.unit for need, b in bindings.items()}
        made = self._made.get(node.path)
        if made is not None:
            comp, ctx = made
            ctx.params, ctx.outputs = dict(node.scope), {}
            ctx.resources, ctx.devices, ctx.bindings, ctx.rank = resources, devices, bindings, rank
        else:
            name = node.state.component or ""
            factory = self.registry.get(name)
            if factory is None:
                self.on_failure(node, f"no implementation of component {name} is available")
                return
            shared: dict[str, Any] = {}
            for anc in node.ancestors():
                for k, _ in anc.state.shared:
                    shared.setdefault(k, anc.scope.get(k))
            path = node.path
            ctx = Context(path, dict(node.scope), resources,
                          lambda ev, **f: self.emit(ev, path, **f),
                          lambda text: self.notify(rec.Log(self.now(), path, text)),
                          self.now, devices=devices,
                          services={**self.services, "shared": shared, "siblings": node.parent.outputs
                                    if node.parent else {}},
                          bindings=bindings, rank=rank)
            try:
                comp = factory()
                comp.setup(ctx)
            except Exception as e:  # component code is not ours to trust
                self.failed(node, e)
                return
            self._made[node.path] = (comp, ctx)
        node.component, node.context = comp, ctx
        if not self.call(node, comp.start):
            return
        self.running[node] = None

    def step(self, node: Node, comp: Component, now: float) -> Status | None:
        """One control cycle of one component: its status, or None when it raised (its state fails)."""
        try:
            return comp.step(now)
        except Exception as e:  # component code is not ours to trust
            self.failed(node, e)
            return None

    def suspend(self, node: Node) -> None:
        comp = node.component
        if comp is not None:
            self.call(node, comp.suspend)

    def resume(self, node: Node) -> None:
        comp = node.component
        if comp is not None:
            self.call(node, comp.resume)

    def terminate(self, node: Node, status: str) -> None:
        """The component's last call; what it raises is only logged (the node is leaving anyway)."""
        comp = node.component
        if comp is None:
            return
        self.running.pop(node, None)
        self.call(node, lambda: comp.terminate(_FINAL_STATUS.get(status, Status.RUNNING)), fail=False)

    def call(self, node: Node, fn: Callable[[], Any], fail: bool = True) -> bool:
        """Call component code; an exception fails the node (unless `fail` is False), never the executive."""
        try:
            fn()
            return True
        except Exception as e:  # component code is not ours to trust
            if fail:
                self.failed(node, e)
            else:
                self.notify(rec.Log(self.now(), node.path, f"component raised {type(e).__name__}: {e}"))
            return False

    def failed(self, node: Node, e: Exception) -> None:
        why = f"component raised {type(e).__name__}: {e}"
        self.notify(rec.Log(self.now(), node.path, why))
        self.on_failure(node, why)

    def command_failed(self, owner: object, e: Exception) -> None:
        """A driver raised on the winning setpoint of a cycle: its proposer (a node) fails."""
        if isinstance(owner, Node):
            self.failed(owner, e)
