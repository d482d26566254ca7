"""Component hosting: the elementary behaviors of one mission, their contexts, devices and lifecycle calls.

A component is set up once per instance path (py_trees' `setup`) and started on every entry of its state
(`initialise`); a state re-entered in a loop keeps its object. Its devices are `BoundDevice`s over the
bindings the resource client made, so every command it sends goes through the device's gate with the path and
epoch it was bound with. Component code is not ours to trust: whatever it raises fails its own state (through
`on_failure`), never the executive.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any

from drd.errors import COMPONENT_RAISES, ComponentFailure, logged, raised
from drd.runtime import records as rec
from drd.runtime.component import Component, Context, Registry, Services, Status
from drd.runtime.emits import check_emit
from drd.runtime.ownership import Arbiter, Binding, BoundDevice
from drd.runtime.resources import BindingError, ResourceClient
from drd.runtime.tree import ACTIVE, Node

_FINAL_STATUS = {"success": Status.SUCCESS, "failure": Status.FAILURE}
_RUNNING = Status.RUNNING


class ComponentHost:
    """The components of one mission: who is running (in entry order, the order they are stepped), and calls."""

    def __init__(self, registry: Registry, resources: ResourceClient, arbiter: Arbiter, clock: Callable[[], float],
                 services: Mapping[str, Any], *, notify: Callable[[rec.Record], None],
                 emit: Callable[..., None], on_failure: Callable[[Node, str], None],
                 rank: Mapping[str, int], origin: Callable[[], float] = lambda: 0.0) -> None:
        self.registry = registry
        self.resources = resources
        self.arbiter = arbiter
        self.now = clock
        self.origin = origin  # the world's start on `clock`: components see the world's time (`world_now`)
        self.services = services
        self.notify = notify
        self.emit = emit
        self.on_failure = on_failure
        self.rank = rank  # state id -> declaration order (a later layer subsumes an earlier one)
        self.running: dict[Node, None] = {}  # leaves with a started component, in entry order
        self._made: dict[str, tuple[Component, Context, _Bindings]] = {}  # per instance path, reused on re-entry
        self._previous: dict[tuple[str, str], Any] = {}  # (path, input) -> a `last(...)` input's next value
        self._lagging: dict[Node, None] = {}  # running leaves with `last(...)` inputs
        #: units of hosts whose daemon died (a dry-run's `kill`) -> why a component bound to one cannot run
        self.dead: dict[str, str] = {}
        self._failed_with: dict[str, str] = {}  # leaf path -> the words its failure was logged with, until it leaves

    def active(self) -> Iterator[tuple[Node, Component]]:
        """The components stepped in this cycle, in order (active ones only)."""
        for node in self.running:
            comp = node.component
            if node.phase is ACTIVE and comp is not None:
                yield node, comp

    def start(self, node: Node, restore: list[Any] | None = None) -> None:
        """Set the leaf's component up (first entry of this path only) and start it. Its needs are bound the first
        time it (or its proxy) asks for one: most components of most states never do, and nothing is built for
        nobody. `restore` (`[state]`, a leaf entered again after its controller was lost): given to the
        component's `restore` before it starts (state None: its state is lost, it is restarted)."""
        made = self._made.get(node.path)
        if made is not None:
            comp, ctx, lazy = made
            lazy.reset(node)  # the same views, bound again for this entry when first read
            ctx.params, ctx.outputs = dict(node.scope), {}
        else:
            lazy = _Bindings(self, node)
            resources, devices, bindings = lazy.view(0), lazy.view(1), lazy.view(2)
            rank = (-node.state.priority, self.rank.get(node.state.id, 0))
            name = node.state.component or ""
            factory = self.registry.get(name)
            if factory is None:
                self.on_failure(node, f"no implementation of component {name} is available")
                return
            path = node.path
            ctx = Context(path, dict(node.scope), resources, self._emitter(path, name),
                          lambda text: self.notify(rec.Log(self.now(), path, text)),
                          self.world_now, devices=devices,
                          services=Services(dependencies=self.services.get("dependencies")),
                          bindings=bindings, rank=rank)
            try:
                comp = factory()
                comp.setup(ctx)
            except COMPONENT_RAISES as e:  # component code is not ours to trust
                self.failed(node, e)
                return
            self._made[node.path] = (comp, ctx, lazy)
        why = self._dead_binding(lazy)
        if why is not None:  # as a start on a host that is down fails on a cluster
            self.notify(rec.Log(self.now(), node.path, why))
            self.on_failure(node, why)
            return
        node.component, node.context = comp, ctx
        if node.state.inputs:
            self.read_inputs(node, entry=True)
        try:
            if restore is not None:
                comp.restore(restore[0])
            comp.start()
        except COMPONENT_RAISES as e:  # component code is not ours to trust
            self.failed(node, e)
            return
        self.running[node] = None

    def die(self, units: Mapping[str, str]) -> list[tuple[Node, str]]:
        """The daemon that served these units died (unit -> why): the running leaves bound to one, each with why,
        are gone without a last call (their process died with it); until `revive`, a leaf bound to one fails as it
        starts. On a cluster a component runs where its devices are (`drd.cluster.remote.RemoteComponent._resolve`)."""
        self.dead.update(units)
        found = []
        for node in list(self.running):
            made = self._made.get(node.path)
            why = None if made is None or node.component is None else self._dead_binding(made[2])
            if why is not None:
                self.running.pop(node, None)
                node.component = None
                self.notify(rec.Log(self.now(), node.path, why))  # as a cluster's call to the dead host logs it
                found.append((node, why))
        return found

    def revive(self, units: Iterable[str]) -> None:
        """The host of these units is back: components bound to them start again."""
        for unit in units:
            self.dead.pop(unit, None)

    def _dead_binding(self, lazy: _Bindings) -> str | None:
        """Why a component of these bindings cannot run (bound to a unit of a dead host), or None (bound now if it
        was not yet, only while some host is dead)."""
        if not self.dead:
            return None
        try:
            bindings: Mapping[str, Binding] = lazy.get(2)
        except BindingError:  # a need no longer held: it fails at its first call anyway
            return None
        return next((self.dead[b.unit] for b in bindings.values() if b.unit in self.dead), None)

    def _emitter(self, path: str, component: str) -> Callable[..., None]:
        """The `emit` of a component instance: checked against its manifest's `events` (`drd.runtime.emits`) when
        the catalog is known (`services["catalog"]`), so a refused emit raises in the component's call and fails
        its state, naming the component, the event and the field."""
        catalog = self.services.get("catalog")
        ct = catalog.get(component) if catalog is not None else None
        if ct is None:
            return lambda ev, /, **f: self.emit(ev, path, **f)
        declared = ct.events

        def emit(ev: str, /, **fields: Any) -> None:
            self.emit(ev, path, **check_emit(component, declared, ev, fields))
        return emit

    def read_inputs(self, node: Node, entry: bool = False) -> None:
        """Set a leaf's inputs as the mission bound them (`dsl.dataflow`): on entry every one (a shared datum is
        the ancestor's own object, in `services["shared"]` too, so a proxy sends it and brings its changes
        back), before each step the siblings' outputs, as they are now (a `last(...)` one as it was when this
        component last stepped)."""
        ctx = node.context
        if ctx is None:
            return
        shared = ctx.services.shared
        for b in node.state.inputs:
            if b.shared:
                if entry:
                    anc = _ancestor(node, b.state)
                    value = anc.scope.get(b.field) if anc is not None else None
                    ctx.inputs[b.name] = value
                    if isinstance(shared, dict):
                        shared[b.name] = value
            elif not b.last:
                ctx.inputs[b.name] = _output(node, b.state, b.field)
            else:  # as it was at the end of the previous cycle (`end_cycle`): that breaks a cycle of feeds
                ctx.inputs[b.name] = None if entry else self._previous.get((node.path, b.name))
                if entry:
                    self._lagging[node] = None

    @property
    def lagging(self) -> bool:
        """Whether some running component reads a `last(...)` input."""
        return bool(self._lagging)

    def end_cycle(self) -> None:
        """Every component has stepped: keep what the `last(...)` inputs will read at the next cycle."""
        for node in list(self._lagging):
            if node.component is None or node not in self.running:
                del self._lagging[node]
                continue
            for b in node.state.inputs:
                if b.last and not b.shared:
                    self._previous[(node.path, b.name)] = _output(node, b.state, b.field)

    def world_now(self) -> float:
        """The time components see: the world's, from 0 when it began, in a dry-run as on a cluster (whose
        executive's clock goes on across worlds: users audit 22, #2)."""
        return self.now() - self.origin()

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
        said = self._failed_with.pop(node.path, None)
        try:
            comp.terminate(_FINAL_STATUS.get(status, _RUNNING))
        except COMPONENT_RAISES as e:  # the node is leaving anyway: just say so, unless its failure just did (a
            if _words(e) != said:  # call to a dead host fails its step and its terminate alike: cluster audit 20, #6)
                self.notify(rec.Log(self.now(), node.path, _words(e)))

    def shutdown(self) -> None:
        """The mission ended: every instance made is dropped for good (`Component.shutdown`, once each); what one
        raises is only logged."""
        made, self._made = self._made, {}
        for path, (comp, _ctx, _lazy) in made.items():
            try:
                comp.shutdown()
            except COMPONENT_RAISES as e:  # component code is not ours to trust
                self.notify(rec.Log(self.now(), path, _words(e, " in shutdown")))

    def call(self, node: Node, fn: Callable[[], Any], fail: bool = True) -> bool:
        """Call component code; an exception fails the node (unless `fail` is False), never the executive."""
        try:
            fn()
            return True
        except COMPONENT_RAISES as e:  # component code is not ours to trust
            if fail:
                self.failed(node, e)
            else:
                self.notify(rec.Log(self.now(), node.path, _words(e)))
            return False

    def failed(self, node: Node, e: BaseException) -> None:
        """`node` fails with what `e` says: a component's own exception located in its code, a reason already said
        (`ComponentFailure.said`) or the runtime's refusal to bind a need (`BindingError`) as it is."""
        why = str(e) if _said(e) else raised(e)
        self._failed_with[node.path] = words = _words(e)
        self.notify(rec.Log(self.now(), node.path, words))
        self.on_failure(node, why)

    def command_failed(self, owner: object, e: Exception) -> None:
        """A driver raised on the winning setpoint of a cycle: its proposer (a node) fails."""
        if isinstance(owner, Node):
            self.failed(owner, e)

    def bind(self, node: Node) -> tuple[dict[str, str], dict[str, BoundDevice], dict[str, Binding]]:
        """A leaf's bindings (made now, at its holders' current grants), the resources and the devices they give.

        Raises:
            BindingError: a need leads to a holder that does not hold it now (released, lost).
        """
        bindings = self.resources.bind(node)
        issuer = self.resources.holder(node)
        rank = (-node.state.priority, self.rank.get(node.state.id, 0))
        def holds(robot: str) -> bool:  # a robot it is bound to (a launch moves only a Scout it holds); unbound,
            return any(robot in (b.unit, b.robot) for b in bindings.values())  # the device's own epoch refuses

        devices = {need: BoundDevice(b, issuer, self.arbiter, rank, node, self.now, holds)
                   for need, b in bindings.items() if b.driver is not None}
        return {need: b.unit for need, b in bindings.items()}, devices, bindings


def _said(e: BaseException) -> bool:
    """A reason already said in words (a remote component's failure, its host's loss; a refused binding): not an
    exception of the component's own code, to be located in it."""
    return (isinstance(e, ComponentFailure) and e.said) or isinstance(e, BindingError)


def _words(e: BaseException, when: str = "") -> str:
    """What the log says of `e`: a reason already said as it is (never "component raised ... at drd's own line"),
    else the component's exception located in its code (`drd.errors.logged`)."""
    return str(e) if _said(e) else logged(e, when)


class _Bindings:
    """A leaf's resources, devices and bindings, made the first time any of them is read."""

    __slots__ = ("_host", "_node", "_value")

    def __init__(self, host: ComponentHost, node: Node) -> None:
        self._host, self._node = host, node
        self._value: tuple[dict[str, str], dict[str, BoundDevice], dict[str, Binding]] | None = None

    def reset(self, node: Node) -> None:
        """A new entry of the same path: bind again, for `node`, when next read."""
        self._node, self._value = node, None

    def get(self, which: int) -> Mapping[str, Any]:
        if self._value is None:
            self._value = self._host.bind(self._node)
        return self._value[which]

    def view(self, which: int) -> Mapping[str, Any]:
        return _LazyMap(self, which)


class _LazyMap(Mapping[str, Any]):
    __slots__ = ("_bindings", "_which")

    def __init__(self, bindings: _Bindings, which: int) -> None:
        self._bindings, self._which = bindings, which

    def __getitem__(self, key: str) -> Any:
        return self._bindings.get(self._which)[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._bindings.get(self._which))

    def __len__(self) -> int:
        return len(self._bindings.get(self._which))


def _ancestor(node: Node, state: str) -> Node | None:
    """The nearest ancestor of `node` that is an instance of `state`."""
    anc = node.parent
    while anc is not None and anc.state.id != state:
        anc = anc.parent
    return anc


def _output(node: Node, producer: str, field: str) -> Any:
    """Output `field` of the sibling state `producer` of `node` or of one of its ancestors: its value now if the
    producer runs (a port), else the value it finished with, else None."""
    anc = _ancestor(node, producer.rsplit("/", 1)[0])
    if anc is None:
        return None
    for child in anc.children:
        if child.state.id == producer and child.phase is ACTIVE:
            value = _live(child, field)
            if value is not None:
                return value
    return anc.outputs.get(producer.rsplit("/", 1)[1], {}).get(field)


def _live(node: Node, field: str) -> Any:
    """`field` as a running subtree has it now: a running leaf's output, else a finished child's."""
    if node.context is not None and field in node.context.outputs:
        return node.context.outputs[field]
    for child in node.children:
        if child.phase is ACTIVE:
            value = _live(child, field)
            if value is not None:
                return value
    for outputs in node.outputs.values():
        if isinstance(outputs, dict) and field in outputs:
            return outputs[field]
    return None
