"""Who may move a device: the gate in front of each driver, and the per-cycle arbiter that fences before it picks.

The Resource Controller Manager grants units; the gate of a device is told each grant and each end of one. A
command (a method the driver declares in `SETPOINTS` or `ACTIONS`, `drd.hw.commands`) reaches the driver only if
it comes
from the behavior subtree that holds the device's current grant, at that grant's epoch:

- the *issuer* is the component's path, qualified by its mission (`<mission>/<path>`); it must be the holder's
  path or lie below it (`under`);
- the epoch is the one the component was bound with (`Binding`): a component bound under an older grant, or
  unbound (suspended, released, exiting), carries a stale epoch or none and is refused.

Every command that reaches a gate gives one `drd.runtime.records.Command` (accepted or not, and why not) to the
gate's sink. A device whose authority ends (its holder's grant ends, the grant passes to another holder, or the
component whose setpoint is in force is unbound) is brought to a safe stop at once (`STOP`, Drive: `stop`,
zero velocity), reported as a `drd.runtime.records.Halted` record: a robot never keeps moving on the word of a
behavior that may no longer drive it.

Setpoints (`set_velocity`, `stop`) are multiplexed per control cycle by an `Arbiter`: the proposals that pass
their gate compete, the highest rank wins (priority, then the behavior declared last), and only the winner is
executed, fenced again at that moment. Actions (`launch`, `jump`) run at once, fenced, and return their result;
a refused action raises `NotHolder` in the component.

Pure logic over drivers the caller built: no bus, no clock (times are passed in), no threads.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from drd.hw.commands import DriverSpec, declared, spec_of
from drd.hw.interfaces import HardwareError
from drd.runtime import records as rec

Sink = Callable[[rec.Record], None]
#: Whether the issuer of a command holds a robot (by id): what an action that moves another robot is checked with.
Holds = Callable[[str], bool]


class NotHolder(HardwareError):
    """A command from a behavior that does not hold the device's current grant (or not at its epoch)."""


def under(path: str, holder: str) -> bool:
    """Whether `path` is `holder` or lies in its subtree (`M/R[1]/Watch` is under `M/R[1]`, not under `M/R`)."""
    return path == holder or path.startswith(holder + "/")


@dataclass(slots=True)
class DeviceGate:
    """The door in front of one device: its current holders (qualified paths, each with its grant's epoch; one
    for an exclusive device) and the issuer whose setpoint is in force."""

    device: str
    driver: object
    spec: DriverSpec
    sink: Callable[[str, rec.Record], None]  # (mission, record): records go to the mission they concern
    holders: dict[str, int] = field(default_factory=dict)
    commander: str | None = None  # qualified path of the issuer of the setpoint in force
    kind: str = ""  # its RC type (Drive, Jump...): how a command moves the robot
    robot: str = ""  # the robot it moves ("" for a device several robots share)
    guard: Guard | None = None  # the constraints in force (`drd.runtime.constraints.ConstraintGuard`)
    # why the setpoint in force stops once the command a constraint refused is recorded (`admit`, `_record`)
    stopping: str = ""

    def verdict(self, issuer: str, epoch: int | None) -> str:
        """Why `issuer` may not command now ("" if it may)."""
        if epoch is None:
            return "not bound to a grant (suspended, released or exiting)"
        for holder, held in self.holders.items():
            if under(issuer, holder):
                return "" if held == epoch else f"epoch {epoch} is not the grant's ({held})"
        if not self.holders:
            return "nobody holds the device"
        return f"not under the holder {_path(next(iter(self.holders)))}"

    def admit(self, issuer: str, epoch: int | None, method: str, args: tuple[Any, ...], kwargs: Mapping[str, Any],
              at: float, holds: Holds | None = None) -> str:
        """Why this command may not go ("" if it may): the holder's authority, the robot it moves (an action the
        driver declares in `MOVES`: the issuer must hold that robot, `holds`), then the constraints in force. A
        command refused by a constraint also stops the setpoint in force (it was heading where it must not), once
        the refused command is recorded (`_record`): the `halted` it causes comes after it (records audit 18, #4)."""
        self.stopping = ""
        why = self.verdict(issuer, epoch)
        robot = self.moved(method, args, kwargs) if not why else None
        if robot is not None and (holds is None or not holds(robot)):
            why = f"it does not hold {robot}, which {method} moves"
        if not why and self.guard is not None:
            why = self.guard(self, issuer, method, args, kwargs)
            if why and self.commander is not None:
                self.stopping = why
        return why

    def moved(self, method: str, args: tuple[Any, ...], kwargs: Mapping[str, Any]) -> str | None:
        """The robot an action moves by name (`MOVES`: the Scout a launch throws), or None for any other command."""
        found = self.spec.moves.get(method)
        if found is None:
            return None
        index, name = found
        return str(args[index] if index < len(args) else kwargs.get(name, ""))

    def execute(self, driver: object, issuer: str, epoch: int | None, method: str, args: tuple[Any, ...],
                kwargs: Mapping[str, Any], at: float, holds: Holds | None = None) -> Any:
        """Fence, record, then call `driver.method` (the driver the issuer was bound with: a robot's part driver
        of a shared device). Raises NotHolder when refused, or whatever the driver raises."""
        why = self.admit(issuer, epoch, method, args, kwargs, at, holds)
        self._record(at, issuer, method, epoch, why)
        if why:
            raise NotHolder(f"{self.device}.{method} from {_path(issuer)} refused: {why}")
        result = getattr(driver, method)(*args, epoch=epoch, **kwargs)
        if method in self.spec.setpoints:  # the setpoint in force, until the next one (a stop leaves nothing moving)
            self.commander = None if method == self.spec.stop else issuer
        return result

    def refuse(self, issuer: str, epoch: int | None, method: str, why: str, at: float) -> None:
        """Record a command that never reached the driver (fenced out before the arbiter's pick)."""
        self._record(at, issuer, method, epoch, why)

    def grant(self, holder: str, epoch: int, at: float, exclusive: bool) -> None:
        """`holder` now holds the device at `epoch`; a setpoint of someone outside its subtree is stopped."""
        if exclusive:
            for old in [h for h in self.holders if h != holder]:
                del self.holders[old]
        self.holders[holder] = epoch
        if self.commander is not None and not under(self.commander, holder):
            self.halt(at, self.commander, f"the grant passed to {_path(holder)}")

    def clear(self, holder: str, at: float, reason: str) -> None:
        """`holder`'s grant of the device ended: stop what it (or its subtree) set in motion."""
        if self.holders.pop(holder, None) is None:
            return
        if self.commander is not None and under(self.commander, holder):
            self.halt(at, self.commander, f"{_path(holder)} lost the device ({reason})")

    def unbind(self, issuer: str, at: float, reason: str) -> None:
        """The component (or subtree) `issuer` may no longer command: stop its setpoint if it is the one in force."""
        if self.commander is not None and under(self.commander, issuer):
            self.halt(at, self.commander, reason)

    def orphan(self, at: float, reason: str) -> None:
        """Nobody may hold the device any more (its controller is gone): every grant ends and the device stops,
        so no command passes until a controller grants it again."""
        self.holders.clear()
        self.halt(at, self.commander or "/", reason)

    def halt(self, at: float, whose: str, reason: str) -> None:
        """Bring the device to its safe stop (when it has one), outside any grant; the setpoint in force ends."""
        self.commander = None
        if self.spec.stop is None:
            return
        error = ""
        try:
            getattr(self.driver, self.spec.stop)(epoch=None)
        except Exception as e:  # the device may be gone with its robot: say so, never raise into the runtime
            error = f"{type(e).__name__}: {e}"
        mission, path = _split(whose)
        self.sink(mission, rec.Halted(at, path, self.device, self.spec.stop, reason, error))

    def _record(self, at: float, issuer: str, method: str, epoch: int | None, why: str) -> None:
        mission, path = _split(issuer)
        self.sink(mission, rec.Command(at, path, self.device, method, epoch, not why, why))
        if self.stopping:
            stopping, self.stopping = self.stopping, ""
            if self.commander is not None:
                self.halt(at, self.commander, stopping)


#: A gate's guard: (gate, issuer, method, args, kwargs) -> why the command may not go, "" if it may.
Guard = Callable[[DeviceGate, str, str, tuple[Any, ...], Mapping[str, Any]], str]


def _split(qualified: str) -> tuple[str, str]:
    """(mission, path) of a qualified path `<mission>/<path>`."""
    mission, _, path = qualified.partition("/")
    return mission, path


def _path(qualified: str) -> str:
    return _split(qualified)[1]


class Gates(Protocol):
    """What the runtime tells the devices' gates, wherever they are (in process, or on a device's host)."""

    def grant(self, device: str, holder: str, epoch: int, at: float) -> None:
        """`holder` (qualified) holds `device` at `epoch`."""
        ...

    def clear(self, device: str, holder: str, at: float, reason: str) -> None:
        """`holder`'s grant of `device` ended."""
        ...

    def unbind(self, device: str, issuer: str, at: float, reason: str) -> None:
        """`issuer` (a component or a subtree, qualified) may no longer command `device`."""
        ...

    def settle(self) -> None:
        """Whatever was told is done, and recorded, when this returns (gates on other hosts: their replies)."""
        ...


class LocalGates:
    """The gates of drivers in this process (the dry-run: every host's drivers; a Creator: its host's)."""

    def __init__(self, sink: Callable[[str, rec.Record], None] = lambda mission, record: None) -> None:
        self.sink = sink
        self.gates: dict[str, DeviceGate] = {}
        self.sharable: set[str] = set()
        self.parts: dict[str, dict[str, object]] = {}  # robot -> part -> driver

    def describe(self, kinds: Mapping[str, str], robots: Mapping[str, str], guard: Guard | None) -> None:
        """What each device is (RC type) and which robot it moves, and the guard of the constraints in force."""
        for device, gate in self.gates.items():
            gate.kind, gate.robot, gate.guard = kinds.get(device, ""), robots.get(device, ""), guard

    def add(self, device: str, driver: object, sharable: bool = False) -> DeviceGate:
        gate = self.gates.get(device)
        if gate is None:
            gate = self.gates[device] = DeviceGate(device, driver, spec_of(driver), self._sink)
        if sharable:
            self.sharable.add(device)
        return gate

    def add_all(self, devices: Mapping[str, object], sharable: Iterable[str] = ()) -> None:
        shared = set(sharable)
        for device, driver in devices.items():
            self.add(device, driver, device in shared)

    def _sink(self, mission: str, record: rec.Record) -> None:
        self.sink(mission, record)

    def get(self, device: str) -> DeviceGate | None:
        return self.gates.get(device)

    def bound(self, unit: str, robot: str = "", part: str = "") -> tuple[DeviceGate, object] | None:
        """The gate of `unit` and the driver a component bound to it uses (a robot's own part driver of a shared
        device), or None when the unit is not a device here (an aggregate, a device of another host)."""
        gate = self.gates.get(unit)
        if gate is None:
            return None
        driver = self.parts.get(robot, {}).get(part) if robot and part else None
        return gate, driver if driver is not None else gate.driver

    @classmethod
    def of(cls, devices: Mapping[str, object], robots: Mapping[str, Mapping[str, object]] | None = None,
           sharable: Iterable[str] = (), sink: Callable[[str, rec.Record], None] | None = None) -> LocalGates:
        """Gates for drivers by device id (and robots' part drivers, `drd.hw.HostDrivers`)."""
        gates = cls(sink) if sink is not None else cls()
        gates.add_all(devices, sharable)
        gates.parts = {r: dict(p) for r, p in (robots or {}).items()}
        return gates

    def grant(self, device: str, holder: str, epoch: int, at: float) -> None:
        gate = self.gates.get(device)
        if gate is not None:
            gate.grant(holder, epoch, at, device not in self.sharable)

    def clear(self, device: str, holder: str, at: float, reason: str) -> None:
        gate = self.gates.get(device)
        if gate is not None:
            gate.clear(holder, at, reason)

    def unbind(self, device: str, issuer: str, at: float, reason: str) -> None:
        gate = self.gates.get(device)
        if gate is not None:
            gate.unbind(issuer, at, reason)

    def settle(self) -> None:
        """In process, everything told is done at once."""

    def orphan_all(self, at: float, reason: str) -> None:
        """Every device here loses every grant and stops (`DeviceGate.orphan`)."""
        for gate in self.gates.values():
            gate.orphan(at, reason)


class NoGates:
    """For a runtime without drivers (unit tests, cluster missions whose gates live on the devices' hosts)."""

    def grant(self, device: str, holder: str, epoch: int, at: float) -> None:
        return None

    def clear(self, device: str, holder: str, at: float, reason: str) -> None:
        return None

    def unbind(self, device: str, issuer: str, at: float, reason: str) -> None:
        return None

    def settle(self) -> None:
        return None


@dataclass(slots=True)
class Binding:
    """One need of one component instance, bound to a device (or a robot: an aggregate) under a grant.

    `epoch` is the grant's epoch while the binding is live, None once unbound (the component's subtree is
    suspended, the need released, the component exiting). `gate`/`driver` may change when a resumed grant
    names another unit of the same type."""

    need: str
    unit: str
    holder: str  # qualified path of the node holding the grant
    epoch: int | None = None
    gate: DeviceGate | None = None
    driver: object = None
    robot: str = ""
    part: str = ""


@dataclass(slots=True)
class Proposal:
    rank: tuple[int, int]  # (-priority, declaration order): the larger wins
    gate: DeviceGate
    binding: Binding
    issuer: str
    method: str
    args: tuple[Any, ...]
    kwargs: dict[str, Any]
    owner: Any  # who proposed it (the runtime's node), for error reports


class Arbiter:
    """The setpoints of one control cycle: fenced when proposed, the best per device run at `flush`."""

    def __init__(self, clock: Callable[[], float]) -> None:
        self.clock = clock
        # The best proposal so far per device. Public so that the runtime can skip calling `flush` in the usual
        # cycle that commanded nothing: a dict test instead of two calls.
        self.best: dict[str, Proposal] = {}

    def propose(self, p: Proposal) -> None:
        why = p.gate.admit(p.issuer, p.binding.epoch, p.method, p.args, p.kwargs, self.clock())
        if why:  # fenced before the pick: a refused command never outranks a valid one
            p.gate.refuse(p.issuer, p.binding.epoch, p.method, why, self.clock())
            return
        best = self.best.get(p.gate.device)
        if best is None or p.rank >= best.rank:
            self.best[p.gate.device] = p

    def flush(self, on_error: Callable[[Any, Exception], None]) -> int:
        """Execute the winning setpoints (fenced again: grants may have changed since); returns how many ran."""
        if not self.best:
            return 0
        winners, self.best = list(self.best.values()), {}
        now = self.clock()
        for p in winners:
            try:
                p.gate.execute(p.binding.driver, p.issuer, p.binding.epoch, p.method, p.args, p.kwargs, now)
            except NotHolder:
                continue  # recorded by the gate; a setpoint refused at the end of the cycle fails nobody
            except Exception as e:  # the driver refused it: fails its proposer, not the cycle
                on_error(p.owner, e)
        return len(winners)

    def drop(self, issuer: str, devices: Iterable[str] | None = None) -> None:
        """Forget the proposals of `issuer`'s subtree (on `devices`, or all): it was unbound before the cycle's end."""
        if not self.best:
            return
        only = None if devices is None else set(devices)
        for device in [d for d, p in self.best.items() if under(p.issuer, issuer) and (only is None or d in only)]:
            del self.best[device]

    def flush_from(self, issuer: str, on_error: Callable[[Any, Exception], None]) -> None:
        """Execute now the winning setpoints of `issuer`'s subtree (its last words before it is unbound: a
        terminating or suspended behavior's own stop), leaving the others' for the cycle's end."""
        mine = [d for d, p in self.best.items() if under(p.issuer, issuer)]
        if not mine:
            return
        now = self.clock()
        for device in mine:
            p = self.best.pop(device)
            try:
                p.gate.execute(p.binding.driver, p.issuer, p.binding.epoch, p.method, p.args, p.kwargs, now)
            except NotHolder:
                continue
            except Exception as e:
                on_error(p.owner, e)


class BoundDevice:
    """A component's handle on one device: readings go straight to the driver, commands through the gate with
    the issuer's path and the binding's epoch (setpoints by way of the arbiter, when there is one)."""

    __slots__ = ("_binding", "_issuer", "_arbiter", "_rank", "_owner", "_clock", "_holds")

    def __init__(self, binding: Binding, issuer: str, arbiter: Arbiter | None, rank: tuple[int, int], owner: Any,
                 clock: Callable[[], float], holds: Holds | None = None) -> None:
        self._binding = binding
        self._issuer = issuer
        self._arbiter = arbiter
        self._rank = rank
        self._owner = owner
        self._clock = clock
        self._holds = holds  # the robots the component holds, for an action that moves one (`DriverSpec.moves`)

    def __getattr__(self, name: str) -> Any:
        binding = self._binding
        gate, driver = binding.gate, binding.driver
        spec = gate.spec if gate is not None else declared(type(driver))  # cached per class: a hot path
        if name not in spec.names:  # a behavior reaches what the driver declares, nothing else (drd.hw.commands)
            raise AttributeError(f"{binding.unit}: {name} is neither a reading nor a command its driver declares"
                                 f" (readings: {', '.join(sorted(spec.readings)) or 'none'}; commands:"
                                 f" {', '.join(sorted(spec.commands)) or 'none'})")
        value = getattr(driver, name)
        if gate is None or name not in gate.spec.commands:
            return value  # a reading: no authority needed
        issuer, arbiter = self._issuer, self._arbiter
        if arbiter is not None and name in gate.spec.setpoints:
            rank, owner = self._rank, self._owner

            def propose(*args: Any, **kwargs: Any) -> None:
                kwargs.pop("epoch", None)  # the binding's epoch, never the component's own
                arbiter.propose(Proposal(rank, gate, binding, issuer, name, args, kwargs, owner))
            return propose

        def command(*args: Any, **kwargs: Any) -> Any:
            kwargs.pop("epoch", None)
            return gate.execute(binding.driver, issuer, binding.epoch, name, args, kwargs, self._clock(), self._holds)
        return command

    def __repr__(self) -> str:
        return f"BoundDevice({self._binding.unit!r}, epoch={self._binding.epoch})"
