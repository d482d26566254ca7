"""Elementary behaviors: components with an explicit lifecycle, driven by the executive.

The lifecycle follows py_trees' split: `setup` once with the context (parameters,
resources, emit), `start` on entry, `step` each control cycle (non-blocking, returns a
`Status`), `suspend`/`resume` when the Resource Controller Manager takes a resource away
and gives it back, `terminate` on exit whatever the reason, and `shutdown` once when the
instance is dropped for good (a state entered again reuses it until then). A component that raises fails
its state (an `error` trigger), never the executive.

A component may also say what its state is (`snapshot`: plain data) and take it back (`restore`, between
`setup` and `start`) when its instance is entered again somewhere else: moved to another host (`missionctl
migrate`), placed again after its host was lost, or entered again by a new controller after a restart or a
failover. `restore(None)` tells it its state is lost: it was restarted.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from drd.errors import ComponentFailure


class Status(StrEnum):
    RUNNING = "running"
    """Still working; step again next cycle."""
    SUCCESS = "success"
    """Finished well: the state completes (completion transitions may fire)."""
    FAILURE = "failure"
    """Finished badly: the state fails (`on error` transitions may fire)."""


class StatusError(ComponentFailure):
    """A `step` returned something that is not a `Status`: its state fails with this reason as it is."""

    said = True


def step_status(value: object, component: str) -> Status:
    """What a step's return value means, by one rule in a dry-run and on a cluster (where it arrives as its `str`):
    a `Status`, or a `Status`'s own string value (`"success"`: a `StrEnum` equals it); anything else fails the
    state (StatusError), as a forgotten `return` (None) must not read as `RUNNING` for ever."""
    if isinstance(value, Status):
        return value
    if isinstance(value, str) and value in _BY_VALUE:
        return _BY_VALUE[value]
    raise StatusError(f"{component}.step returned {value!s}, not a Status "
                      "(return Status.RUNNING, Status.SUCCESS or Status.FAILURE)")


_BY_VALUE = {s.value: s for s in Status}


@dataclass
class Services:
    """What the runtime lends a component besides its devices, by name and type (no drivers, no simulator: a
    component reaches hardware only through its devices)."""

    #: input name -> an ancestor's shared datum it is bound to (the one object: a proxy sends it and brings back
    #: its changes)
    shared: dict[str, Any] = field(default_factory=dict)
    #: update(resource, key, value): the Static Dependency Database (a launched Scout's `carrier`)
    dependencies: Callable[[str, str, object], None] | None = None
    #: () -> (x, y, heading): the robot's pose, for a component given no Drive, when the runtime has one
    odometry: Callable[[], tuple[float, float, float]] | None = None


@dataclass
class Context:
    """What a component instance may use: its parameters, resources and the mission's events."""

    path: str
    params: Mapping[str, Any]
    resources: Mapping[str, str]  # need name -> resource id (unit or aggregate part)
    emit: Callable[..., None]  # emit(name, **fields)
    log: Callable[[str], None]
    now: Callable[[], float]
    outputs: dict[str, Any] = field(default_factory=dict)
    #: input name -> its value, as the mission bound it (`dsl.dataflow`): a sibling's output (current before each
    #: step), or an ancestor's shared datum (the one object, which the component may change)
    inputs: dict[str, Any] = field(default_factory=dict)
    services: Services = field(default_factory=Services)
    devices: Mapping[str, Any] = field(default_factory=dict)  # need name -> its device, through the gate
    #: need name -> `drd.runtime.ownership.Binding` (unit, robot part, the holder and the epoch it is bound at):
    #: what a proxy of a component running elsewhere forwards to the devices' host.
    bindings: Mapping[str, Any] = field(default_factory=dict)
    rank: tuple[int, int] = (0, 0)  # (-priority, declaration order): how its setpoints rank in a cycle


class Component:
    """Base class of every elementary behavior. Override what you need; defaults do nothing."""

    _context: Context | None = None

    @property
    def ctx(self) -> Context:
        """The context `setup` was given (its parameters, resources, devices, inputs); always there once set up,
        so a component never tests for None."""
        if self._context is None:
            raise RuntimeError(f"{type(self).__name__}: its context is used before setup()")
        return self._context

    def setup(self, ctx: Context) -> None:
        """Once, before start: keep the context, open drivers."""
        self._context = ctx

    @property
    def is_set_up(self) -> bool:
        return self._context is not None

    def device(self, need: str) -> Any:
        """The driver behind one of this component's needs, through its interface (drd.hw)."""
        try:
            return self.ctx.devices[need]
        except KeyError:
            raise LookupError(f"{self.ctx.path}: no device for need {need!r} "
                              f"(have: {', '.join(self.ctx.devices) or 'none'})") from None

    def update_dependency(self, resource: str, key: str, value: object) -> None:
        """Change the Static Dependency Database (a launched Scout: `carrier` becomes "")."""
        update = self.ctx.services.dependencies
        if update is None:
            raise LookupError(f"{self.ctx.path}: no dependency database in this context")
        update(resource, key, value)

    def input(self, name: str) -> Any:
        """The value of one of the inputs the manifest declares (`door`), as the mission bound it, or None (an
        optional input bound to nothing, or an output not produced yet). A component never reads a sibling or an
        ancestor's data by name: the mission says which datum an input reads."""
        return self.ctx.inputs.get(name)

    def start(self) -> None:
        """On entry, just in time."""

    def step(self, now: float) -> Status:
        """One control cycle; must return quickly."""
        return Status.RUNNING

    def suspend(self) -> None:
        """A resource was taken away: stop actuating."""

    def resume(self) -> None:
        """The resource is back."""

    def snapshot(self) -> Mapping[str, Any] | None:
        """This instance's state as plain data (JSON: str, numbers, bool, None, lists, string-keyed dicts), small
        (at most `MAX_SNAPSHOT` bytes encoded), enough for `restore` to go on where it was; None (the default):
        "my state cannot be restored". Called after `start` and every few steps while it runs (a copy travels
        only when it changed), and once more when it is moved: it must not change anything."""
        return None

    def restore(self, state: Mapping[str, Any] | None) -> None:
        """Before `start`, after `setup`, when this instance is entered again elsewhere (moved, placed again after
        its host was lost, or re-entered by a new controller): `state` is its last `snapshot`, or None when
        that is lost (it is restarted, and told so). `start` follows: it goes on from the state given here
        instead of starting afresh. The default ignores it (the component starts afresh)."""

    def terminate(self, status: Status) -> None:
        """On exit, whatever the reason (success, failure, or stopped while RUNNING)."""

    def shutdown(self) -> None:
        """Once, when the instance is dropped for good (its mission ended, or its host forgot it): release what
        `setup` acquired (files, sockets, threads). A state entered again before that reuses the instance, so
        `terminate` is the end of one entry, this the end of the object; nothing is called after it."""


#: The largest snapshot (bytes, encoded as JSON) that travels or is journaled; a larger one is dropped, and said so.
MAX_SNAPSHOT = 64 * 1024

#: How the executive finds component classes by name.
Registry = Mapping[str, Callable[[], Component]]
