"""Driver loading: `hosts.yaml`'s `driver:` entries choose each device's implementation, imported lazily.

A device of RC type `T` with `driver: X` is implemented by the class at:

- `sim`: the entry point of `T`'s manifest (`components/T/manifest.yaml`, e.g.
  `components.sim.range_sensor:SimRangeSensor`), which must lie under `components.sim`;
- any other `X`: `components.X.<t>:<Xcap>T`, where `<t>` is `T` in snake_case and `<Xcap>` is `X` in
  CamelCase: `driver: serial` for a `Drive` is `components.serial.drive:SerialDrive`; or, when hosts.yaml's
  `cluster.drivers` names a package for `X` (a driver kept outside drd), `<package>.<t>:<Xcap>T`.

The class is constructed as `cls(device, robot_id, backend)`, where `backend` is `services[X]`: the
`Simulation` for `sim`, whatever the host provides under that name otherwise (None if nothing). A
module is imported on first use only (importlib), so a host imports just the drivers its hosts.yaml
names.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from drd import entrypoints
from drd.entrypoints import EntryPointError
from drd.errors import HardwareFailure
from drd.hosts import DRIVER_NAME, Cluster, Device
from drd.hw.commands import DriverDeclarationError, conforms, declared, spec_of
from drd.hw.interfaces import INTERFACES
from drd.manifests import show
from dsl.catalog import Catalog

log = logging.getLogger(__name__)

if TYPE_CHECKING:  # the simulator (pymunk) is imported only by hosts that run sim drivers
    from drd.sim import Simulation

__all__ = ["SIM", "DriverError", "HostDrivers", "driver_entry_point", "drivers_for", "load_driver"]

SIM = "sim"


class DriverError(HardwareFailure):
    """A device's driver cannot be found or built; the message names device, driver and module."""


def _snake(name: str) -> str:
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).lower()


def _camel(name: str) -> str:
    return "".join(part[:1].upper() + part[1:] for part in re.split(r"[_\-]", name) if part)




def driver_entry_point(device: Device, catalog: Catalog | None = None, packages: Mapping[str, str] | None = None
                       ) -> str:
    """`module:Class` implementing `device` (see the module docstring); reads the catalog for `sim` only.
    `packages` (hosts.yaml `cluster.drivers`) names the package of a driver kept outside drd."""
    if not DRIVER_NAME.fullmatch(device.driver):
        raise DriverError(f"{show(device.driver)} is not a driver's name: lowercase letters, digits and _, at most 40"
                          " (the package under components/, e.g. sim or ros2)")
    if device.driver != SIM:
        package = (packages or {}).get(device.driver) or f"components.{device.driver}"
        return f"{package}.{_snake(device.type)}:{_camel(device.driver)}{device.type}"
    if catalog is None:
        from drd.manifests import load_catalog
        catalog = load_catalog()
    t = catalog.get(device.type)
    entry = t.entry_point if t is not None else None
    if entry is None:  # drd's types name theirs under components.sim; a user's own device type, its own module
        raise DriverError(f"device {device.id}: driver {SIM!r} is the class its {device.type} manifest names in"
                          " entry_point, and it names none")
    return entry


def load_driver(device: Device, robot_id: str, services: Mapping[str, Any]) -> object:
    """Import (first use only) and build the driver of `device` for robot `robot_id`.

    `services` holds the backends by driver name (`"sim"`: the Simulation) and optionally `"catalog"` and
    `"packages"` (the cluster's `drivers:`, for drivers kept outside drd).

    Raises:
        DriverError: the module or class is missing, the backend is missing, or construction failed.
    """
    entry = driver_entry_point(device, services.get("catalog"), services.get("packages"))
    where = f"device {device.id} (type {device.type}, driver {show(device.driver)})"
    try:
        cls = entrypoints.load(entry)
    except EntryPointError as e:
        raise DriverError(f"{where}: {e}; see docs/drivers.md to add a driver") from e
    if not callable(cls):
        raise DriverError(f"{where}: {entry} is not a class")
    backend = services.get(device.driver)
    if device.driver == SIM and backend is None:
        raise DriverError(f"{where}: the sim driver needs a Simulation in services['sim'], got {backend!r}")
    try:
        driver = cls(device, robot_id, backend)
    except DriverError:
        raise
    except Exception as e:
        raise DriverError(f"{where}: {entry} could not be built for {robot_id}: {e}") from e
    interface = INTERFACES.get(device.type)
    try:
        spec_of(driver)
        gaps = conforms(cls, interface) if interface is not None else []
    except DriverDeclarationError as e:
        raise DriverError(f"{where}: {e} (see docs/drivers.md: declaring commands)") from None
    if gaps:
        raise DriverError(f"{where}: {entry} lacks {gaps[0]} (see docs/drivers.md)")
    return driver


@dataclass
class HostDrivers:
    """One host's drivers: by device id, and for each robot its parts (part name -> driver)."""

    devices: dict[str, object] = field(default_factory=dict)
    robots: dict[str, dict[str, object]] = field(default_factory=dict)

    def close(self) -> None:
        """Close every driver that holds something (a ROS 2 driver's publishers and subscriptions): a host builds
        them again for each world, and a daemon that stops leaves nothing running."""
        every = {id(d): d for d in [*self.devices.values(), *(d for parts in self.robots.values()
                                                              for d in parts.values())]}
        for driver in every.values():
            close = getattr(driver, "close", None)
            if callable(close):
                try:
                    close()
                except Exception:  # one driver's failure to close must not keep the others open
                    log.warning("could not close driver %r", driver, exc_info=True)


def drivers_for(cluster: Cluster, host_name: str, sim: Simulation | None = None,
                services: Mapping[str, Any] | None = None, catalog: Catalog | None = None) -> HostDrivers:
    """Build the drivers of host `host_name`'s devices.

    Each device is driven for the robot that uses it; a device several robots share (the radio) is
    keyed under their common carrier if they have one, and each robot gets a driver of its own for
    its part. A device no robot names is driven for the host itself.
    """
    host = cluster.host(host_name)
    backends: dict[str, Any] = dict(services or {})
    if sim is not None:
        backends[SIM] = sim
    if cluster.drivers:
        backends["packages"] = cluster.drivers
    if catalog is not None:
        backends["catalog"] = catalog
    elif "catalog" not in backends and any(d.driver == SIM for d in host.devices):
        from drd.manifests import load_catalog
        backends["catalog"] = load_catalog()
    users: dict[str, list[str]] = {}
    for robot in host.robots:
        for device_id in robot.parts.values():
            users.setdefault(device_id, []).append(robot.id)
    carriers = {r.id: r.carrier for r in host.robots}
    out = HostDrivers()
    for device in host.devices:
        ids = users.get(device.id, [])
        common = {carriers[r] for r in ids}
        carrier = next(iter(common)) if len(common) == 1 else None
        owner = ids[0] if len(ids) == 1 else carrier if carrier is not None else ids[0] if ids else host.name
        out.devices[device.id] = load_driver(device, owner, backends)
    devices = {d.id: d for d in host.devices}
    for robot in host.robots:
        parts: dict[str, object] = {}
        for part, device_id in robot.parts.items():
            if device_id not in devices:  # a part on another host: that host drives it
                continue
            shared = len(users[device_id]) > 1
            parts[part] = load_driver(devices[device_id], robot.id, backends) if shared else out.devices[device_id]
        out.robots[robot.id] = parts
    return out


def check_driver_classes(cluster: Cluster, host: str, catalog: Catalog | None = None) -> list[str]:
    """Every driver class `host`'s devices name, imported and its declaration checked, without building one:
    what `drd start` (for its host) and `missionctl dry-run` (for every host: they all run in its process) refuse
    before anything starts, each problem naming the hosts file's key."""
    problems = []
    for device in cluster.host(host).devices:
        key = f"{cluster.source}: hosts.{host}.devices.{device.id.removeprefix(host + '.')}.driver"
        try:
            cls = entrypoints.load(driver_entry_point(device, catalog, cluster.drivers))
            if not isinstance(cls, type):
                raise DriverError(f"{device.driver}: not a class")
            declared(cls)
        except (DriverError, EntryPointError, DriverDeclarationError) as e:
            problems.append(f"{key}: {e}")
            continue
        interface = INTERFACES.get(device.type)
        problems += [f"{key}: {device.driver} driver of a {device.type} lacks {gap}"
                     for gap in (conforms(cls, interface) if interface is not None else [])]
        check = getattr(cls, "check_options", None)  # a driver that reads `driver_options` checks them itself
        if callable(check):
            where = f"{cluster.source}: hosts.{host}.devices.{device.id.removeprefix(host + '.')}"
            problems += [f"{where}.{p}" for p in check(device)]
    return problems
