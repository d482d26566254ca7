"""`hosts.yaml`: the single resource configuration file (ERSP), loaded strictly into the resource model.

One file says which hosts form the cluster, what hardware each carries (RCs), how that hardware is
grouped into robots (ARCs) and the static dependencies between robots (`carrier`). Moving from the
simulator to real hardware changes `driver:` entries only, so everything a driver swap could break
is checked here, before any daemon starts: every problem is collected and raised once, as a
`HostsError`, so a broken file is fixed in one pass. `parse_hosts` is pure; `load_hosts` reads the
file and `check_files` looks at the security files the daemon will need. See docs/hosts.md.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from enum import Enum, StrEnum
from pathlib import Path
from typing import Any, TypeVar

import yaml

from drd.config import ConfigError, ConfigProblem, ConfigReader, StrictLoader, display_path, read_config_text, read_yaml
from drd.manifests import got, is_number, show  # one YAML dialect, one wording
from drd.rcm.model import Aggregate, Unit
from dsl.ast import parse_duration
from dsl.catalog import Catalog, ComponentType, Kind, Limit, possessive
from dsl.errors import did_you_mean
from dsl.limits import Limits

DEFAULT_LEASE = 3.0
#: Seconds beyond two leases a restarted controller waits for the hosts with devices before it resumes its missions.
RESUME_GRACE = 5.0
#: Finished missions a controller keeps for `status` and `stop` (each is its statechart and its records' facts,
#: tens of KB): 3,800 kept made a status reply outgrow the transport.
DEFAULT_HISTORY, MAX_HISTORY = 100, 1000
#: A name (of the cluster, a host, a robot): a part of bus keys, file names and messages, so short and plain.
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}", re.ASCII)
#: Device ids may be dotted (`scout1.wheels`): a robot's own devices are prefixed with its id.
_DEVICE_ID = re.compile(r"[A-Za-z_]\w{0,63}(?:\.[A-Za-z_]\w{0,63}){0,3}", re.ASCII)
ENDPOINT = re.compile(r"(tcp|udp)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?):([0-9]+)", re.ASCII)
_E = TypeVar("_E", bound=Enum)


class Role(StrEnum):
    CONTROLLER = "controller"
    """Runs the Resource Controller Manager and the Mission Executive; exactly one host has it."""
    WORKER = "worker"
    """Runs components (behaviors and the drivers of its devices)."""
    SIMULATOR = "simulator"
    """Runs the simulator component that `sim` drivers talk to; at most one host has it."""
    ROUTER = "router"
    """Its daemon runs a zenoh router in-process: with routers, the other daemons and the clients connect to the
    routers only (a star per router, routers meshed), not to each other (docs/daemon.md, topologies)."""


class SecurityMode(StrEnum):
    NONE = "none"
    """An open cluster: for a laptop or an isolated test network only."""
    PASSWORD = "password"
    """zenoh user/password authentication with access control."""
    TLS = "tls"
    """zenoh TLS with mutual authentication from a CA, a certificate and a key."""


#: The keys each security mode requires (and allows) besides `mode`: they name files, except `user`.
SECURITY_KEYS: Mapping[SecurityMode, tuple[str, ...]] = {
    SecurityMode.NONE: (),
    SecurityMode.PASSWORD: ("user", "password_file"),
    SecurityMode.TLS: ("ca", "cert", "key"),
}
_TOP_KEYS = ("cluster", "hosts")
#: What a `driver:` may be: the name of a package under `components/`, or of one `cluster.drivers` maps to a package
#: (so never a path, a module or a pasted blob).
DRIVER_NAME = re.compile(r"[a-z][a-z0-9_]{0,39}")
#: A Python package a driver lives in (`cluster.drivers`): dotted identifiers, never a path.
_PACKAGE = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}(\.[A-Za-z_][A-Za-z0-9_]{0,63}){0,7}")
_CLUSTER_KEYS = ("name", "security", "lease", "placement", "world", "history", "store", "limits", "drivers")
_LIMITS_KEYS = ("instances", "compile")
_STORE_KEYS = ("etcd",)
#: An etcd member's client URL (its HTTP JSON gateway; TLS to etcd is not supported yet).
_ETCD_URL = re.compile(r"http://[A-Za-z0-9.\-]+:(\d{1,5})")
#: The simulated world when hosts.yaml names none (`sim` drivers need one: worlds/NAME.yaml).
DEFAULT_WORLD = "corridor"
_HOST_KEYS = ("endpoint", "roles", "cores", "drivers", "simulator", "devices", "robots")
_SIMULATOR_KEYS = ("ros2", "listen", "domain_id")
_DEVICE_KEYS = ("type", "driver", "options", "driver_options", "capacity", "slice")
_ROBOT_KEYS = ("type", "carrier", "parts", "properties")
_SECURITY_ALLOWED = ("mode", *dict.fromkeys(k for keys in SECURITY_KEYS.values() for k in keys), "open", "roles",
                     "per_host")
#: The roles of `cluster.security.roles`, most powerful first (docs/security.md).
ACCESS_ROLES = ("daemon", "operator", "observer")
_PLACEMENT_KEYS = ("cpu", "memory", "instances", "affinity")
#: The range and unit of every number hosts.yaml itself defines (device options and robot properties declare theirs
#: in their manifests, `limits:`): a value outside is refused at load with the file, the key and the range.
RANGES: Mapping[str, Limit] = {
    "lease": Limit(0.1, 600.0, duration=True),  # below a control period of the network, grants would flap
    "slice": Limit(0.2, 86_400.0, duration=True),  # two control cycles, as a mission's `for` (dsl.checker.MIN_SLICE)
    "capacity": Limit(1, 1_000_000),
    "cores": Limit(1, 4096, "cores"),
    "history": Limit(1, MAX_HISTORY, "missions"),
    "placement": Limit(0, 1000),  # a weight: relative, so a bound only refuses nonsense
    "instances": Limit(1, 100_000, "instances"),  # a multiplicity's most (`dsl.limits`)
    "compile": Limit(1.0, 600.0, duration=True),  # the controller's budget to compile a submitted mission
    "domain_id": Limit(0, 232),  # a ROS domain id (ROS 2's own bound, from DDS port arithmetic)
}
_SCALARS: Mapping[str, Any] = {"int": int, "float": (int, float), "bool": bool, "str": str}


@dataclass(frozen=True, slots=True)
class Security:
    """How peers authenticate. Only parsed and checked here; the daemon configures zenoh from it."""

    mode: SecurityMode = SecurityMode.NONE
    user: str | None = None
    password_file: str | None = None
    ca: str | None = None
    cert: str | None = None
    key: str | None = None
    #: Who may do what (`ACCESS_ROLES` -> user names, or certificate common names with `tls`); empty: every
    #: authenticated peer may do everything, as a daemon.
    roles: Mapping[str, tuple[str, ...]] = field(default_factory=dict, hash=False)
    #: With mode none: the operator means it to run open beyond loopback (a daemon refuses otherwise).
    open: bool = False
    #: Each daemon authenticates as its own host's name (mode password: a line of the password file each; mode tls:
    #: its certificate's common name) and may then speak only for its own host (`drd.daemon.acl`).
    per_host: bool = False

    def role_of(self, name: str) -> str | None:
        """The role of a user (or certificate name): `daemon` for the daemons' own user, None when unknown."""
        if name == self.user:
            return "daemon"
        return next((role for role in ACCESS_ROLES if name in self.roles.get(role, ())), None)

    @property
    def files(self) -> dict[str, str]:
        """The files the mode needs, by key: what `check_files` looks at."""
        named = {k: getattr(self, k) for k in SECURITY_KEYS[self.mode] if k != "user"}
        return {k: v for k, v in named.items() if v}


@dataclass(frozen=True, slots=True)
class Placement:
    """Weights of the Load Balancer's policy: a host's score is the weighted sum of its loads, less `affinity`
    times its share of the devices the instance's mission state uses (docs/placement.md)."""

    cpu: float = 1.0
    memory: float = 0.5
    instances: float = 0.2
    affinity: float = 0.2


@dataclass(frozen=True, slots=True)
class Store:
    """Where the controller keeps its missions: its own SQLite journal (no `etcd`), or a replicated etcd cluster
    (its members' client URLs), which also elects the one acting controller among several (issue #16)."""

    etcd: tuple[str, ...] = ()

    @property
    def replicated(self) -> bool:
        return bool(self.etcd)


@dataclass(frozen=True, slots=True)
class Device:
    """One RC on one host. `id` is qualified by the host (`ranger1.drive`), so it is unique in the cluster.

    `capacity` is set exactly for sharable types (the manifest's capacity unless overridden).
    """

    id: str
    host: str
    type: str
    driver: str
    options: Mapping[str, object] = field(default_factory=dict, hash=False)
    capacity: float | None = None
    slice: float | None = None  # minimum time slice when a need sets none (exclusive devices only)
    #: How its driver reaches the hardware (`driver_options:`, over the host's `drivers: {<driver>: ...}`): plain
    #: values the driver class checks itself (`check_options`), never device properties (docs/ros2.md).
    driver_options: Mapping[str, object] = field(default_factory=dict, hash=False)

    @property
    def sharable(self) -> bool:
        return self.capacity is not None


@dataclass(frozen=True, slots=True)
class Robot:
    """One ARC instance. `parts` maps part names to qualified device ids; `properties` include `carrier`."""

    id: str
    host: str
    type: str
    parts: Mapping[str, str] = field(default_factory=dict, hash=False)
    properties: Mapping[str, object] = field(default_factory=dict, hash=False)

    @property
    def carrier(self) -> str | None:
        """The robot carrying this one (a Scout's Ranger), the usual static dependency."""
        value = self.properties.get("carrier")
        return value if isinstance(value, str) else None


@dataclass(frozen=True, slots=True)
class Serving:
    """How the simulator host also serves the world it runs (`hosts.<name>.simulator`): with `ros2`, every simulated
    robot as a ROS 2 robot over rmw_zenoh on a zenoh router listening on `listen`, in ROS domain `domain_id`
    (`drd.sim.ros2`, docs/ros2.md), so the cluster's `ros2` drivers reach it as they reach real robots."""

    ros2: bool = False
    listen: str = ""
    domain_id: int = 0


@dataclass(frozen=True, slots=True)
class Host:
    """A computer of the cluster: where its daemon listens, what it does, and its hardware."""

    name: str
    endpoint: str
    roles: tuple[Role, ...]
    cores: int | None = None
    devices: tuple[Device, ...] = ()
    robots: tuple[Robot, ...] = ()
    serving: Serving = Serving()  # the simulator host's `simulator:` options


@dataclass(frozen=True, slots=True)
class Cluster:
    """The whole file, checked. `source` names the file in problems found later (`check_files`)."""

    name: str
    security: Security
    lease: float
    placement: Placement
    hosts: tuple[Host, ...]
    source: str = "hosts.yaml"
    world: str = DEFAULT_WORLD  # the world its `sim` drivers live in (worlds/NAME.yaml), unless a command says
    history: int = DEFAULT_HISTORY  # finished missions the controller keeps (status, stop); older ones are dropped
    store: Store = Store()  # the controllers' journal: SQLite on the one controller, or etcd for several
    limits: Limits = Limits()  # what a mission may create and cost to compile (`dsl.limits`)
    #: Driver name -> the Python package its classes are in, for drivers outside drd (`cluster.drivers`; the
    #: default for `driver: X` is `components.X`: docs/drivers.md).
    drivers: Mapping[str, str] = field(default_factory=dict, hash=False)

    @property
    def controller(self) -> Host:
        """The (first) host with the RCM and the Mission Executive: the one controller, or with a replicated store
        the first of the controllers, one of which is elected to act (`controllers`)."""
        return next(h for h in self.hosts if Role.CONTROLLER in h.roles)

    @property
    def resume_grace(self) -> float:
        """Seconds a controller started again waits for the hosts with devices before it resumes the journal's
        missions (two leases and RESUME_GRACE): on a cluster, and in a dry-run's `restart`."""
        return 2 * self.lease + RESUME_GRACE

    @property
    def controllers(self) -> list[Host]:
        """Every host with the controller role (several only with a replicated `store`)."""
        return [h for h in self.hosts if Role.CONTROLLER in h.roles]

    def host(self, name: str) -> Host:
        """The host called `name`; KeyError names the known hosts."""
        for h in self.hosts:
            if h.name == name:
                return h
        raise KeyError(f"no host {name!r} in {self.source} (hosts: {', '.join(h.name for h in self.hosts)})")

    @property
    def devices(self) -> tuple[Device, ...]:
        return tuple(d for h in self.hosts for d in h.devices)

    @property
    def robots(self) -> tuple[Robot, ...]:
        return tuple(r for h in self.hosts for r in h.robots)

    def types(self) -> dict[str, str]:
        """Each robot's type, by its id."""
        return {r.id: r.type for r in self.robots}

    def resources(self) -> list[Unit | Aggregate]:
        """Units then aggregates, as `drd.runtime.pool.ResourcePool.add` takes them.

        A unit's properties are its device options plus `driver`, so `where` clauses can select
        on them; an exclusive unit gets the manager's default capacity of 1.
        """
        units: list[Unit | Aggregate] = [
            Unit(d.id, d.type, sharable=d.sharable, capacity=1.0 if d.capacity is None else d.capacity,
                 properties={**d.options, "driver": d.driver}, host=d.host, slice=d.slice)
            for d in self.devices
        ]
        return units + [Aggregate(r.id, r.type, r.parts, r.properties, r.host) for r in self.robots]


HostsProblem = ConfigProblem


class HostsError(ConfigError):
    """The resource configuration has problems; carries all of them."""


# ---------------------------------------------------------------- parsing (pure)


def parse_hosts(data: object, source: str, catalog: Catalog) -> Cluster:
    """Check the YAML data of a hosts file against the catalog and build the cluster.

    Raises:
        HostsError: with every problem found, once the whole file has been read.
    """
    return _parse(data, source, catalog)


def _parse(data: object, source: str, catalog: Catalog | None) -> Cluster:
    parser = _Parser(source, catalog)
    cluster = parser.cluster(data)
    if parser.problems or cluster is None:
        raise HostsError(parser.problems)
    return cluster


class _Parser(ConfigReader):
    """Collects problems; each reader reports what is wrong and returns a safe value to go on with.

    Without a catalog, only what joining the cluster needs is read (`load_endpoints`): the hosts'
    `devices` and `robots` are skipped, unread, so the hosts come out without hardware.
    """

    def __init__(self, source: str, catalog: Catalog | None) -> None:
        super().__init__(source)
        self.catalog = catalog
        self.refs: list[tuple[str, str, str]] = []  # (key, type, id): checked once every resource is known

    # -- the sections

    def cluster(self, data: object) -> Cluster | None:
        if not isinstance(data, dict):
            self.fail("", f"expected a mapping with keys cluster and hosts, got {got(data)}")
            return None
        self.keys(data, "", _TOP_KEYS, required=_TOP_KEYS)
        c = self.mapping(data.get("cluster", {}), "cluster")
        self.keys(c, "cluster", _CLUSTER_KEYS, required=("name",) if c is data.get("cluster") else ())
        name = self.name(c["name"], "cluster.name") if "name" in c else None
        security = self.security(c.get("security", {"mode": "none"}), "cluster.security")
        lease = self.duration(c["lease"], "cluster.lease", RANGES["lease"]) if "lease" in c else DEFAULT_LEASE
        placement = self.placement(c.get("placement", {}), "cluster.placement")
        world = self.name(c["world"], "cluster.world") if "world" in c else DEFAULT_WORLD
        history = self.history(c["history"], "cluster.history") if "history" in c else DEFAULT_HISTORY
        store = self.store(c["store"], "cluster.store") if "store" in c else Store()
        limits = self.limits(c["limits"], "cluster.limits") if "limits" in c else Limits()
        drivers = self.driver_packages(c["drivers"], "cluster.drivers") if "drivers" in c else {}
        hosts = tuple(self.host(n, h, p) for n, h, p in self.entries(data.get("hosts", {}), "hosts"))
        if data.get("hosts") == {}:
            self.fail("hosts", "expected at least one host")
        self.check_cluster(hosts, store)
        return Cluster(name or "", security, lease, placement, hosts, self.source, world or DEFAULT_WORLD, history,
                       store=store, limits=limits, drivers=drivers)

    def driver_packages(self, value: object, key: str) -> dict[str, str]:
        """`{serial: acme_drivers.serial}`: the Python package of each driver kept outside drd (importable: on the
        daemons' PYTHONPATH); `sim` is drd's own."""
        out: dict[str, str] = {}
        for driver, package in self.mapping(value, key).items():
            where = f"{key}.{driver}"
            if not isinstance(driver, str) or not DRIVER_NAME.fullmatch(driver):
                self.fail(where, "expected a driver's name: lowercase letters, digits and _, at most 40")
            elif driver == "sim":
                self.fail(where, "sim is drd's own driver (the simulator's): name another")
            elif not isinstance(package, str) or not _PACKAGE.fullmatch(package):
                self.fail(where, f"expected a Python package name such as acme_drivers.serial, got {got(package)}")
            else:
                out[str(driver)] = package
        return out

    def limits(self, value: object, key: str) -> Limits:
        """`{instances: 5000, compile: 30s}`: raise (or lower) what a mission may create and cost to compile."""
        data = self.mapping(value, key)
        self.keys(data, key, _LIMITS_KEYS)
        default = Limits()
        instances = self.number(data["instances"], f"{key}.instances", RANGES["instances"], integer=True) \
            if "instances" in data else None
        budget = self.duration(data["compile"], f"{key}.compile", RANGES["compile"]) if "compile" in data else None
        return Limits(instances or default.instances, budget or default.compile_seconds)

    def store(self, value: object, key: str) -> Store:
        """`{etcd: [http://HOST:PORT, ...]}`: the etcd members' client URLs (each once)."""
        data = self.mapping(value, key)
        self.keys(data, key, _STORE_KEYS, required=_STORE_KEYS if data is value else ())
        urls = data.get("etcd")
        if "etcd" not in data:
            return Store()
        if not isinstance(urls, list) or not urls:
            self.fail(f"{key}.etcd", "expected a non-empty list of etcd client URLs (http://HOST:PORT), got"
                      f" {got(urls)}")
            return Store()
        good: list[str] = []
        for i, url in enumerate(urls):
            m = _ETCD_URL.fullmatch(url) if isinstance(url, str) else None
            if m is None or not 0 < int(m.group(1)) < 65536:
                self.fail(f"{key}.etcd[{i}]", f"expected an etcd client URL http://HOST:PORT, got {got(url)}")
            elif url in good:
                self.fail(f"{key}.etcd[{i}]", f"{url} is listed twice")
            else:
                good.append(url)
        return Store(tuple(good)) if len(good) == len(urls) else Store()

    def history(self, value: object, key: str) -> int:
        if isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= MAX_HISTORY:
            return value
        self.fail(key, f"expected a count of finished missions to keep, {RANGES['history'].text}, got {got(value)}")
        return DEFAULT_HISTORY

    def security(self, value: object, key: str) -> Security:
        data = self.mapping(value, key)
        self.keys(data, key, _SECURITY_ALLOWED, required=("mode",) if data is value else ())
        mode = self.choice(data["mode"], f"{key}.mode", SecurityMode, "mode") if "mode" in data else None
        if mode is None:
            return Security()
        for k in _SECURITY_ALLOWED[1:-3]:
            if k in data and k not in SECURITY_KEYS[mode]:
                self.fail(f"{key}.{k}", f"does not apply to mode {mode}")
            elif k not in data and k in SECURITY_KEYS[mode]:
                self.fail(f"{key}.{k}", f"required for mode {mode}")
        per_host = data.get("per_host", False)
        roles = self.access_roles(data["roles"], f"{key}.roles", mode, per_host is True) if "roles" in data else {}
        is_open = data.get("open", False)
        if "open" in data and (mode is not SecurityMode.NONE or not isinstance(is_open, bool)):
            self.fail(f"{key}.open", "only `open: true` with mode none: an open cluster on a network, on purpose")
        if "per_host" in data and (mode is SecurityMode.NONE or not isinstance(per_host, bool)):
            self.fail(f"{key}.per_host", "only `per_host: true` with mode password or tls (each daemon its own"
                                         " identity: its host's name as its user, or as its certificate's name)")
        return Security(mode, **{k: self.text(data[k], f"{key}.{k}") for k in SECURITY_KEYS[mode] if k in data},
                        roles=roles, open=is_open is True, per_host=per_host is True)

    def access_roles(self, value: object, key: str, mode: SecurityMode,
                     per_host: bool = False) -> dict[str, tuple[str, ...]]:
        """`roles: {operator: [alice], observer: [bob]}`: each name in one role only; `none` has no identities."""
        if mode is SecurityMode.NONE:
            self.fail(key, "roles need identities: use mode password (user names) or tls (certificate names)")
            return {}
        data = self.mapping(value, key)
        self.keys(data, key, ACCESS_ROLES)
        out: dict[str, tuple[str, ...]] = {}
        seen: dict[str, str] = {}
        for role in ACCESS_ROLES:
            names = data.get(role, [])
            if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
                self.fail(f"{key}.{role}", "expected a list of names")
                continue
            for n in names:
                if n in seen:
                    self.fail(f"{key}.{role}", f"{n} is already a{'n' if seen[n][0] in 'aeiou' else ''} {seen[n]}")
                seen[n] = role
            out[role] = tuple(names)
        if mode is SecurityMode.TLS and not out.get("daemon") and not per_host:
            self.fail(f"{key}.daemon", "with tls, list the daemons' certificate names: they may do everything")
        return out

    def placement(self, value: object, key: str) -> Placement:
        data = self.mapping(value, key)
        self.keys(data, key, _PLACEMENT_KEYS)
        weights = {k: self.number(data[k], f"{key}.{k}", RANGES["placement"]) for k in _PLACEMENT_KEYS if k in data}
        placement = Placement(**{k: v for k, v in weights.items() if v is not None})
        if not any((placement.cpu, placement.memory, placement.instances)):
            self.fail(key, "at least one weight must be positive")
        return placement

    def host(self, name: str, data: dict[Any, Any], key: str) -> Host:
        self.keys(data, key, _HOST_KEYS, required=("endpoint", "roles"))
        endpoint = self.endpoint(data["endpoint"], f"{key}.endpoint") if "endpoint" in data else ""
        roles = self.roles(data["roles"], f"{key}.roles") if "roles" in data else ()
        cores = self.number(data["cores"], f"{key}.cores", RANGES["cores"], integer=True) if "cores" in data else None
        serving = self.serving(data["simulator"], f"{key}.simulator", roles) if "simulator" in data else Serving()
        if self.catalog is None:
            return Host(name, endpoint, roles, cores, serving=serving)
        raw = data.get("devices", {})
        shared = self.driver_settings(data.get("drivers", {}), f"{key}.drivers")
        devices = [self.device(name, d, v, p, shared) for d, v, p in self.entries(raw, f"{key}.devices", _DEVICE_ID)]
        # Broken entries still count (typeless), so the parts naming them are not reported again;
        # with no usable `devices` mapping at all (None), parts are not looked up.
        local = {str(k): Device(f"{name}.{k}", name, "", "") for k in raw} if isinstance(raw, dict) else None
        if local is not None:
            local.update({d.id.removeprefix(f"{name}."): d for d in devices})
        users: dict[str, str] = {}  # device -> the first `part of robot` using it
        robots = [self.robot(name, r, v, p, local, users) for r, v, p in self.entries(data.get("robots", {}),
                                                                                    f"{key}.robots")]
        return Host(name, endpoint, roles, cores, tuple(devices), tuple(robots), serving)

    def serving(self, value: object, key: str, roles: Sequence[Role]) -> Serving:
        """`simulator: {ros2: true, listen: tcp/HOST:PORT, domain_id: 0}`: only on the simulator's host; `listen` is
        required with `ros2` (the robots' router needs a port of its own, not a guess that may be a daemon's)."""
        data = self.mapping(value, key)
        self.keys(data, key, _SIMULATOR_KEYS)
        if Role.SIMULATOR not in roles:
            self.fail(key, "only the host with the role simulator serves the world: add simulator to its roles")
        ros2 = data.get("ros2", False)
        if not isinstance(ros2, bool):
            self.fail(f"{key}.ros2", f"expected true or false, got {got(ros2)}")
            ros2 = False
        listen = self.endpoint(data["listen"], f"{key}.listen") if "listen" in data else ""
        if ros2 and "listen" not in data:
            self.fail(key, "ros2: true needs listen: the endpoint of the robots' zenoh router (e.g. tcp/0.0.0.0:7447),"
                           " which the ros2 drivers' endpoint names")
        domain = self.number(data["domain_id"], f"{key}.domain_id", RANGES["domain_id"], integer=True) \
            if "domain_id" in data else 0
        return Serving(ros2, listen, domain or 0)

    def driver_settings(self, value: object, key: str) -> dict[str, dict[str, object]]:
        """A host's `drivers:`: per driver name, the `driver_options` every device of that driver starts from."""
        out: dict[str, dict[str, object]] = {}
        for driver, options in self.mapping(value, key).items():
            if self.name(driver, f"{key}.{driver}") is not None:
                out[str(driver)] = self.plain(options, f"{key}.{driver}")
        return out

    def plain(self, value: object, key: str) -> dict[str, object]:
        """A mapping of plain YAML values (what a driver's options are): no check of the keys, the driver's own."""
        data = self.mapping(value, key)
        for k in data:
            if not isinstance(k, str):
                self.fail(f"{key}.{k}", f"a key is a name, got {got(k)}")
        for path, v in _floats(data, key):
            if not math.isfinite(v):
                self.fail(path, f"{v} is not a finite number")
        return {str(k): v for k, v in data.items()}

    def device(self, host: str, local_id: str, data: dict[Any, Any], key: str,
               shared: Mapping[str, Mapping[str, object]] | None = None) -> Device:
        self.keys(data, key, _DEVICE_KEYS, required=("type", "driver"))
        t = self.component(data["type"], f"{key}.type", Kind.RC) if "type" in data else None
        driver = self.name(data["driver"], f"{key}.driver") if "driver" in data else None
        options = self.values(t, data.get("options", {}), f"{key}.options") if t else {}
        capacity = t.capacity if t and t.sharable else None
        if t and "capacity" in data:
            if not t.sharable:
                self.fail(f"{key}.capacity", f"{t.name} is not sharable; only a sharable device has a capacity")
            else:
                count = self.number(data["capacity"], f"{key}.capacity", RANGES["capacity"], integer=True)
                capacity = capacity if count is None else float(count)
        slice_ = None
        if "slice" in data:
            if t and t.sharable:
                self.fail(f"{key}.slice", f"{t.name} is sharable: it is never taken away, so it has no time slice")
            else:
                slice_ = self.duration(data["slice"], f"{key}.slice", RANGES["slice"])
        own = self.plain(data["driver_options"], f"{key}.driver_options") if "driver_options" in data else {}
        wiring = {**(shared or {}).get(driver or "", {}), **own}
        # An empty type was reported already: parts using the device are then not checked again.
        return Device(f"{host}.{local_id}", host, t.name if t else "", driver or "", options, capacity, slice_,
                      wiring)

    def robot(self, host: str, rid: str, data: dict[Any, Any], key: str, local: Mapping[str, Device] | None,
              users: dict[str, str]) -> Robot:
        self.keys(data, key, _ROBOT_KEYS, required=("type", "parts"))
        t = self.component(data["type"], f"{key}.type", Kind.ARC) if "type" in data else None
        if t is None:
            return Robot(rid, host, "")
        parts = self.parts(t, data["parts"], f"{key}.parts", rid, local, users) if "parts" in data else {}
        properties = self.values(t, data.get("properties", {}), f"{key}.properties")
        if "carrier" in data:  # the usual static dependency gets a key of its own
            if "carrier" in properties:
                self.fail(f"{key}.carrier", "given twice, also in properties")
            properties.update(self.values(t, {"carrier": data["carrier"]}, key))
        return Robot(rid, host, t.name, parts, properties)

    def parts(self, t: ComponentType, value: object, key: str, rid: str, local: Mapping[str, Device] | None,
              users: dict[str, str]) -> dict[str, str]:
        """Part name -> qualified device id: every part of the type, each a device of this host of its type."""
        data = self.mapping(value, key)
        if data is not value:
            return {}  # not a mapping: reported, and every part would be reported missing again
        self.keys(data, key, tuple(t.parts))
        out = {}
        for part, wanted in t.parts.items():
            path = f"{key}.{part}"
            if part not in data:
                self.fail(path, f"required part missing (a {wanted})")
                continue
            name = self.name(data[part], path, _DEVICE_ID)
            device = local.get(name) if local is not None and name else None
            if local is not None and name and device is None:
                self.fail(path, f"unknown device {name!r} on this host{_hint(name, local, 'it has no devices')}")
            if name is None or device is None or not device.type:
                continue
            out[part] = device.id
            if device.type != wanted:
                self.fail(path, f"{name} is a {device.type}, expected a {wanted}")
            elif not device.sharable and name in users:
                self.fail(path, f"{name} is already the {users[name]}; only a sharable device can serve several")
            else:
                users.setdefault(name, f"{part} of {rid}")
        return out

    def values(self, t: ComponentType, value: object, key: str) -> dict[str, object]:
        """Property values as the manifest of `t` declares them (device options, robot properties)."""
        out: dict[str, object] = {}
        for name, v in self.mapping(value, key).items():
            path, type_ = f"{key}.{name}", t.properties.get(str(name))
            if type_ is None:
                self.fail(path, f"unknown property of {t.name}{_hint(str(name), t.properties, 'it declares none')}")
            elif type_ in _SCALARS:
                if isinstance(v, bool) == (type_ == "bool") and isinstance(v, _SCALARS[type_]):
                    out[name] = float(v) if type_ == "float" else v
                    self.within(t, str(name), out[name], path)
                else:
                    self.fail(path, f"expected {type_}, got {got(v)}")
            elif type_ == "duration":
                out[name] = self.duration(v, path)
                self.within(t, str(name), out[name], path)
            elif isinstance(v, str):
                out[name] = v
                self.refs.append((path, type_, v))
            else:
                self.fail(path, f"expected the id of a {type_}, got {got(v)}")
        return out

    def within(self, t: ComponentType, name: str, value: object, path: str) -> None:
        """A numeric value inside the range its manifest declares (`limits`), else a problem naming the range."""
        limit = t.limits.get(name)
        if isinstance(value, int | float) and not isinstance(value, bool):
            why = (limit or _FINITE).refuses(value)
            if why:
                self.fail(path, f"{why} ({possessive(t.name)} manifest, {t.source})")

    def check_cluster(self, hosts: Sequence[Host], store: Store | None = None) -> None:
        """Across hosts: one controller (several with a replicated store, which elects the one acting), at most one
        simulator, distinct endpoints and robot ids, references."""
        for role, exactly in ((Role.CONTROLLER, True), (Role.SIMULATOR, False)):
            having = [h.name for h in hosts if role in h.roles]
            if role is Role.CONTROLLER and store is not None and store.replicated:
                having = having[:1]  # standbys: etcd elects the one that acts
            for other in having[1:]:
                several = ("; several controllers need a replicated store to elect the one that acts"
                           " (cluster.store: {etcd: [http://HOST:PORT, ...]}, docs/hosts.md)"
                           if role is Role.CONTROLLER else "")
                self.fail(f"hosts.{other}.roles", f"{role} is already a role of host {having[0]};"
                          f" a cluster has {'exactly' if exactly else 'at most'} one {role}{several}")
            if exactly and not having and hosts:
                self.fail("hosts", f"no host has the role {role}; exactly one must")
        endpoints: dict[str, str] = {}
        robots: dict[str, Robot] = {}
        for h in hosts:
            if h.endpoint and endpoints.setdefault(h.endpoint, h.name) != h.name:
                self.fail(f"hosts.{h.name}.endpoint", f"{h.endpoint} is already the endpoint of host"
                          f" {endpoints[h.endpoint]}")
        for h in hosts:
            if h.serving.listen and h.serving.listen in endpoints:
                self.fail(f"hosts.{h.name}.simulator.listen", f"{h.serving.listen} is the endpoint of host"
                          f" {endpoints[h.serving.listen]}'s daemon: the robots' router needs a port of its own")
            for r in h.robots:
                if robots.setdefault(r.id, r) is not r:
                    self.fail(f"hosts.{h.name}.robots.{r.id}", f"duplicate robot id, also on host {robots[r.id].host}")
        types = {d.id: d.type for h in hosts for d in h.devices} | {r.id: r.type for r in robots.values()}
        for key, type_, value in self.refs:  # none without a catalog: hardware was not read
            assert self.catalog is not None
            target = self.catalog.get(type_)
            if target is None or not target.is_resource:
                self.fail(key, f"{type_} is not a resource type; it cannot be configured here")
            elif types.get(value) == "":
                continue  # a robot or device whose type is wrong, reported already
            elif value not in types:
                same = [i for i, ty in types.items() if ty == type_]
                self.fail(key, f"no {type_} called {value!r}{_hint(value, same, '')}")
            elif types[value] != type_:
                self.fail(key, f"{value} is a {types[value]}, expected a {type_}")

    # -- typed readers

    def describe(self, value: object) -> str:
        return got(value)

    def key_hint(self, key: str, allowed: Sequence[str]) -> str:
        return _hint(key, allowed, "none allowed here")

    def entries(self, value: object, key: str, pattern: re.Pattern[str] = _NAME,
                ) -> Iterator[tuple[str, dict[Any, Any], str]]:
        """The (name, mapping, key path) of each well-formed entry of a mapping of named sections."""
        for k, v in self.mapping(value, key).items():
            path = f"{key}.{k}"
            if self.name(k, path, pattern) is not None and self.mapping(v, path) is v:
                yield k, v, path

    def name(self, value: object, key: str, pattern: re.Pattern[str] = _NAME) -> str | None:
        text = self.text(value, key)
        if text and not pattern.fullmatch(text):
            dots = ", in parts joined by dots" if pattern is _DEVICE_ID else ""
            plain = pattern.fullmatch(re.sub(r"\w{65,}", lambda m: m.group()[:64], text))
            self.fail(key, f"{show(text)} is too long for a name (at most 64 characters{' a part' if dots else ''})"
                      if plain else f"{show(text)} is not a name (letters, digits and _, not starting with a digit"
                                    f"{dots})")
        return text if pattern.fullmatch(text) else None

    def number(self, value: object, key: str, limit: Limit, integer: bool = False) -> Any:
        """A number inside its declared range (`RANGES`), else a problem naming the range; None then."""
        if not is_number(value, integer):
            self.fail(key, f"expected {'an integer' if integer else 'a number'} ({limit.text}), got {got(value)}")
            return None
        why = limit.refuses(value)  # type: ignore[arg-type]
        if why:
            self.fail(key, why)
            return None
        return value if integer else float(value)  # type: ignore[arg-type]

    def choice(self, value: object, key: str, enum: type[_E], what: str) -> _E | None:
        options = [str(m.value) for m in enum]
        if isinstance(value, str) and value in options:
            return enum(value)
        self.fail(key, f"unknown {what} {show(value)}{_hint(str(value), options, '')}")
        return None

    def roles(self, value: object, key: str) -> tuple[Role, ...]:
        if not isinstance(value, list) or not value:
            self.fail(key, f"expected a non-empty list of roles, got {'an empty list' if value == [] else got(value)}")
            return ()
        roles = [r for r in (self.choice(v, key, Role, "role") for v in value) if r]
        for r in sorted({r for r in roles if roles.count(r) > 1}):
            self.fail(key, f"{r} is listed twice")
        return tuple(dict.fromkeys(roles))

    def endpoint(self, value: object, key: str) -> str:
        text = self.text(value, key)
        problem = endpoint_problem(text) if text else None
        if problem is not None:
            self.fail(key, problem if problem.startswith("port") else f"{problem}, got {text!r}")
        return text if text and problem is None else ""

    def duration(self, value: object, key: str, limit: Limit | None = None) -> float:
        """A duration literal (`3s`, `500ms`; a bare number's unit would be a guess), positive and inside `limit`."""
        seconds = parse_duration(value) if isinstance(value, str) else None
        if seconds is None or (limit is None and seconds <= 0):
            what = (f"a duration such as 3s or 500ms ({limit.text})" if limit
                    else "a positive duration such as 3s or 500ms")
            self.fail(key, f"expected {what}, got {got(value)}")
            return DEFAULT_LEASE
        if limit is not None and (why := limit.refuses(seconds)):
            self.fail(key, why)
            return DEFAULT_LEASE
        return seconds

    def component(self, value: object, key: str, kind: Kind) -> ComponentType | None:
        """The catalog type `value` names, if it is of `kind` (an rc for devices, an arc for robots)."""
        name = self.text(value, key)
        assert self.catalog is not None  # hardware is read only with a catalog
        t = self.catalog.get(name)
        if t is not None and t.kind is kind and not t.abstract:
            return t
        if t is not None and t.abstract:  # `Robot`, `Sensor`: properties for the types that extend them
            concrete = [n for n in self.catalog.names(kind) if name in self.catalog.supertypes(n)]
            self.fail(key, f"{name} is abstract: name one of its types ({', '.join(concrete) or 'none'})")
        elif t is not None:
            self.fail(key, f"{name} is {_A[t.kind]}, expected {_A[kind]}")
        elif name:
            self.fail(key, f"unknown type {name!r}{_hint(name, self.catalog.names(kind), '')}")
        return None


_A = {Kind.BEHAVIOR: "a behavior", Kind.RC: "an rc", Kind.ARC: "an arc", Kind.DATA: "a data type"}


# ---------------------------------------------------------------- files (I/O)


def load_hosts(path: str | os.PathLike[str], catalog: Catalog) -> Cluster:
    """Read, check and convert a hosts file; relative security paths are taken from its folder.

    Raises:
        HostsError: the file is missing or unreadable, is not valid YAML (with the line), or has problems.
    """
    return _load(Path(path), catalog)


def endpoint_problem(text: str) -> str | None:
    """What is wrong with a zenoh endpoint drd listens on or connects to (None if nothing), as a hosts file's
    `endpoint` and `listen` and `drd sim --listen` are written: checked before zenoh sees it, whose own error is a
    parser's message with Rust source paths."""
    m = ENDPOINT.fullmatch(text)
    if m is None:
        return "expected tcp/HOST:PORT or udp/HOST:PORT"
    if not 0 < int(m.group(3)) < 65536:
        return f"port {m.group(3)} is out of range (1 to 65535)"
    return None


def load_endpoints(path: str | os.PathLike[str]) -> Cluster:
    """What a client needs to join the cluster, read without the component catalog: a lighter `load_hosts`.

    The cluster's name, security (paths as `load_hosts` gives them), lease and placement, and each
    host's endpoint, roles and cores, checked as `load_hosts` checks them; the hosts' devices and
    robots are not read, so each host comes out without hardware and problems there go unreported
    (the daemons, which read the whole file, report them). For `missionctl`'s cluster commands,
    which would otherwise load every component manifest only to skip the hardware.

    Raises:
        HostsError: the file is missing or unreadable, is not valid YAML, or has problems outside the hardware.
    """
    return _load(Path(path), None)


def _load(path: Path, catalog: Catalog | None) -> Cluster:
    source = display_path(path)
    data = read_yaml(path, source, HostsError)
    try:
        cluster = _parse(data, source, catalog)
    except HostsError as e:
        raise HostsError(with_lines(e.problems, path)) from None
    folder = path.absolute().parent  # `/` keeps absolute paths as they are
    files: dict[str, Any] = {k: str(folder / Path(v).expanduser()) for k, v in cluster.security.files.items()}
    return replace(cluster, security=replace(cluster.security, **files))


def check_files(cluster: Cluster) -> list[HostsProblem]:
    """The security files that are missing or unreadable: a daemon needs them before it can join."""
    problems = []
    for key, name in cluster.security.files.items():
        file = Path(name)
        if not file.is_file():
            problems.append(HostsProblem(cluster.source, f"cluster.security.{key}", f"no such file: {name}"))
        elif not os.access(file, os.R_OK):
            problems.append(HostsProblem(cluster.source, f"cluster.security.{key}", f"cannot read {name}"))
    return problems


def with_lines(problems: Iterable[HostsProblem], path: Path) -> list[HostsProblem]:
    """`problems` with the line of each key in the file (the deepest part of the key path the file has: a missing
    key points at its parent). Found only once there are problems: the file's YAML nodes are read again for them,
    so a file that loads costs nothing more. The file read again is the file loaded (a change in between only
    moves the lines)."""
    try:
        root = yaml.compose(read_config_text(path), Loader=StrictLoader)
    except (OSError, ValueError, yaml.YAMLError):
        return list(problems)
    return [p if p.line or not p.key else replace(p, line=_line(root, p.key)) for p in problems]


def _line(node: yaml.Node | None, key: str) -> int | None:
    """The line (1-based) of `key`, a dotted path whose names may hold dots themselves (device ids: `s1.wheels`)
    and `[i]` for a list's items, under `node`."""
    line = None
    while key and node is not None:
        nxt: yaml.Node | None = None
        if isinstance(node, yaml.MappingNode):
            names = [(str(k.value), k, v) for k, v in node.value if isinstance(k, yaml.ScalarNode)]
            hits = [(n, k, v) for n, k, v in names if key == n or key.startswith((f"{n}.", f"{n}["))]
            if hits:
                name, k, nxt = max(hits, key=lambda h: len(h[0]))
                line, key = k.start_mark.line + 1, key[len(name):].removeprefix(".")
        elif isinstance(node, yaml.SequenceNode) and (m := re.match(r"\[(\d+)\]\.?", key)):
            index = int(m.group(1))
            if index < len(node.value):
                nxt = node.value[index]
                line, key = nxt.start_mark.line + 1, key[m.end():]
        node = nxt
    return line


# ---------------------------------------------------------------- small helpers


#: What every number in hosts.yaml is held to when nothing declares its range: finite (YAML writes .nan and .inf).
_FINITE = Limit()


def _floats(value: object, key: str) -> Iterator[tuple[str, float]]:
    """Every float inside plain YAML data (a driver's options), with its key path: NaN and inf are refused there too."""
    if isinstance(value, float):
        yield key, value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from _floats(v, f"{key}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _floats(v, f"{key}[{i}]")


def _hint(value: str, candidates: Iterable[str], empty: str) -> str:
    """` (did you mean X?)`, else the choices when there are few, else `empty` in parentheses."""
    options = sorted(candidates)
    hint = did_you_mean(value, options)
    if hint is None and 0 < len(options) <= 6:
        hint = f"expected one of {', '.join(options)}"
    hint = hint or empty
    return f" ({hint})" if hint else ""
