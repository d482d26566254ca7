"""A rig for one elementary behavior against the simulator: real drivers, a real Context.

    rig = Rig()                                     # worlds/corridor.yaml + hosts.yaml, seed 1
    comp = rig.start(FollowCorridor, needs={"drive": ("ranger1", "drive"), "ranges": ("ranger1", "ranges")},
                     params={"speed": 0.4})
    status = rig.run(comp, until=20.0)              # steps sim and component at 10 Hz

`needs` maps each need name to `(robot id, part)`; the rig grants those devices to the component and hands it
each robot part through `Component.device(need)`, behind the device's gate, exactly as the runtime does
(commands run at once: no other component competes for them).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from drd.hosts import load_hosts
from drd.hw.drivers import drivers_for
from drd.manifests import load_catalog
from drd.runtime.component import Component, Context, Status
from drd.runtime.ownership import Binding, BoundDevice, LocalGates
from drd.sim.physics import Simulation
from drd.sim.world import load_world

ROOT = Path(__file__).resolve().parents[1]


class Rig:
    def __init__(self, world: str = "corridor", hosts: str = "hosts.yaml", host: str = "ranger1", seed: int = 1):
        self.catalog = load_catalog()
        self.cluster = load_hosts(ROOT / hosts, self.catalog)
        self.sim = Simulation(load_world(ROOT / "worlds" / f"{world}.yaml"), seed=seed)
        self.drivers = drivers_for(self.cluster, host, self.sim, catalog=self.catalog)
        self.events: list[tuple[str, dict[str, Any]]] = []
        self.logs: list[str] = []
        self.inputs: dict[str, Any] = {}  # the component's inputs, as a mission would bind them

    def start(self, cls: type[Component], needs: dict[str, tuple[str, str]], params: dict[str, Any] | None = None,
              path: str = "M/Test", inputs: dict[str, Any] | None = None,
              robots: dict[str, str] | None = None) -> Component:
        """Set up and start one component, with defaults from its manifest and `params` over them; `inputs` join
        the rig's (what a mission would bind its declared inputs to); `robots`: needs bound to a whole robot (the
        Scout a LaunchScout throws: a launcher moves only a Scout its behavior holds)."""
        self.inputs.update(inputs or {})
        spec = self.catalog.get(cls.__name__)
        defaults = {p.name: p.default for p in spec.params if not p.required} if spec else {}
        resources = {need: self.cluster_part(robot, part) for need, (robot, part) in needs.items()}
        held = {*resources.values(), *(robots or {}).values()}
        resources.update(robots or {})
        gates = LocalGates.of(self.drivers.devices, self.drivers.robots)
        issuer = f"rig/{path}"
        devices = {}
        for need, (robot, part) in needs.items():
            unit = resources[need]
            gates.grant(unit, issuer, 1, self.sim.time)
            gate, driver = gates.bound(unit, robot, part) or (None, None)
            binding = Binding(need, unit, issuer, 1, gate, driver, robot, part)
            devices[need] = BoundDevice(binding, issuer, None, (0, 0), None, lambda: self.sim.time, held.__contains__)
        ctx = Context(path, {**defaults, **(params or {})}, resources,
                      lambda name, **fields: self.events.append((name, fields)), self.logs.append,
                      lambda: self.sim.time, devices=devices, inputs=self.inputs)
        comp = cls()
        comp.setup(ctx)
        comp.start()
        return comp

    def cluster_part(self, robot: str, part: str) -> str:
        return next(r.parts[part] for r in self.cluster.robots if r.id == robot)

    def run(self, comp: Component, until: float, period: float = 0.1) -> Status:
        """Step the simulation and the component at `1/period` Hz until it finishes or `until`."""
        status = Status.RUNNING
        while self.sim.time < until:
            self.sim.step(period)
            status = comp.step(self.sim.time)
            if status is not Status.RUNNING:
                break
        comp.terminate(status)
        return status
