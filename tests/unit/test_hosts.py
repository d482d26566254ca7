"""hosts.yaml: the shipped configurations load, become the RCM's resources, and every bad config says why."""

from __future__ import annotations

import copy
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from drd.hosts import (
    Cluster,
    Device,
    HostsError,
    HostsProblem,
    Placement,
    Role,
    Security,
    SecurityMode,
    check_files,
    load_hosts,
    parse_hosts,
)
from drd.rcm import Aggregate, Granted, NeedRequest, Request, ResourceManager, Unit
from dsl.catalog import Catalog, ComponentType, Kind

ROOT = Path(__file__).resolve().parents[2]

# ---------------------------------------------------------------- the shipped files


def test_corridor_hosts_load(catalog: Catalog) -> None:
    cluster = load_hosts(ROOT / "hosts.yaml", catalog)
    assert (cluster.name, cluster.lease, cluster.placement) == ("corridor", 3.0, Placement(1.0, 0.5, 0.2))
    assert cluster.security == Security(SecurityMode.NONE)
    assert [h.name for h in cluster.hosts] == ["controller", "ranger1"]
    assert cluster.controller is cluster.host("controller")
    assert cluster.controller.roles == (Role.CONTROLLER,)
    assert cluster.world == "corridor"
    ranger1 = cluster.host("ranger1")
    assert ranger1.roles == (Role.WORKER, Role.SIMULATOR)  # the simulator beside the devices it serves
    assert [r.id for r in ranger1.robots] == ["ranger1", *(f"scout{i}" for i in range(1, 7))]
    assert {r.carrier for r in ranger1.robots if r.type == "Scout"} == {"ranger1"}
    assert {d.driver for d in cluster.devices} == {"sim"}
    assert all(h.endpoint.startswith("tcp/127.0.0.1:") for h in cluster.hosts)


def test_two_rangers_hosts_load(catalog: Catalog) -> None:
    cluster = load_hosts(ROOT / "hosts.two_rangers.yaml", catalog)
    carriers = {r.id: r.carrier for r in cluster.robots if r.type == "Scout"}
    assert carriers == {"scout1": "ranger1", "scout2": "ranger1", "scout3": "ranger1",
                        "scout4": "ranger2", "scout5": "ranger2", "scout6": "ranger2"}
    assert all(r.host == r.carrier for r in cluster.robots if r.type == "Scout")  # their drivers run there
    assert len({h.endpoint for h in cluster.hosts}) == 3


def test_resources_are_units_then_aggregates(catalog: Catalog) -> None:
    resources = load_hosts(ROOT / "hosts.yaml", catalog).resources()
    units = {r.id: r for r in resources if isinstance(r, Unit)}
    aggregates = {r.id: r for r in resources if isinstance(r, Aggregate)}
    assert len(units) == 5 + 6 * 3 and len(aggregates) == 7
    assert resources.index(units["ranger1.scout6.camera"]) < resources.index(aggregates["ranger1"])
    assert units["ranger1.radio"] == Unit("ranger1.radio", "RadioChannel", sharable=True, capacity=10.0,
                                          properties={"range": 30.0, "driver": "sim"}, host="ranger1")
    assert units["ranger1.drive"] == Unit("ranger1.drive", "Drive", properties={"max_speed": 0.8, "driver": "sim"},
                                          host="ranger1", slice=60.0)
    assert aggregates["ranger1"].parts == {"drive": "ranger1.drive", "ranges": "ranger1.ranges",
                                           "camera": "ranger1.camera", "launcher": "ranger1.launcher"}
    assert aggregates["ranger1"].properties == {"battery": 1.0, "magazine": 6}
    scout = aggregates["scout3"]
    assert (scout.type, scout.host, scout.properties) == ("Scout", "ranger1", {"battery": 1.0, "carrier": "ranger1"})
    assert scout.parts == {"wheels": "ranger1.scout3.wheels", "foot": "ranger1.scout3.foot",
                           "camera": "ranger1.scout3.camera", "radio": "ranger1.radio"}
    assert all(set(a.units) <= units.keys() for a in aggregates.values())


def test_resources_feed_the_resource_manager(catalog: Catalog) -> None:
    """All six Scouts hold the one shared radio at once; the carrier is there for `where` clauses."""
    rcm = ResourceManager()
    for r in load_hosts(ROOT / "hosts.yaml", catalog).resources():
        rcm.add_unit(r, 0.0) if isinstance(r, Unit) else rcm.add_aggregate(r, 0.0)
    carried = NeedRequest("scout", "Scout", where=lambda c, _: c.properties.get("carrier") == "ranger1")
    decisions = [d for i in range(6) for d in rcm.request(Request(f"room[{i}]", 1, (carried,)), 0.0)]
    assert [type(d) for d in decisions] == [Granted] * 6
    assert sorted(d.assignment["scout"] for d in decisions if isinstance(d, Granted)) == [
        f"scout{i}" for i in range(1, 7)]


# ---------------------------------------------------------------- every check, one message each

DELETE = object()


def base() -> dict[str, Any]:
    """The smallest valid file: a controller and one Ranger host carrying one Scout."""
    return {
        "cluster": {"name": "lab"},
        "hosts": {
            "ctl": {"endpoint": "tcp/127.0.0.1:7447", "roles": ["controller"]},
            "r1": {
                "endpoint": "tcp/127.0.0.1:7448",
                "roles": ["worker"],
                "devices": {
                    "drive": {"type": "Drive", "driver": "sim"},
                    "ranges": {"type": "RangeSensor", "driver": "sim"},
                    "camera": {"type": "Camera", "driver": "sim", "options": {"resolution": 640}},
                    "launcher": {"type": "Launcher", "driver": "sim"},
                    "radio": {"type": "RadioChannel", "driver": "sim"},
                    "s1.wheels": {"type": "Drive", "driver": "sim"},
                    "s1.foot": {"type": "Jump", "driver": "sim"},
                    "s1.camera": {"type": "Camera", "driver": "sim"},
                },
                "robots": {
                    "r1": {"type": "Ranger", "properties": {"battery": 1.0, "magazine": 1},
                           "parts": {"drive": "drive", "ranges": "ranges", "camera": "camera", "launcher": "launcher"}},
                    "s1": {"type": "Scout", "carrier": "r1", "parts": {
                        "wheels": "s1.wheels", "foot": "s1.foot", "camera": "s1.camera", "radio": "radio"}},
                },
            },
        },
    }


def edit(**changes: object) -> Callable[[dict[str, Any]], object]:
    """Set (or DELETE) values at `/`-separated paths of `base()`; `/` because device ids have dots."""
    def apply(data: dict[str, Any]) -> object:
        for path, value in changes.items():
            *parents, last = path.split("/")
            node = data
            for p in parents:
                node = node[p]
            if value is DELETE:
                del node[last]
            else:
                node[last] = copy.deepcopy(value)
        return data
    return apply


def second_ranger_host(data: dict[str, Any]) -> object:
    data["hosts"]["r2"] = copy.deepcopy(data["hosts"]["r1"]) | {"endpoint": "tcp/127.0.0.1:7449"}
    return data


TLS = {"mode": "tls", "ca": "ca.pem", "cert": "c.pem", "key": "k.pem"}
S1 = "hosts/r1/robots/s1"
S1_PARTS = {"wheels": "s1.wheels", "foot": "s1.foot", "camera": "s1.camera", "radio": "radio"}
NOT_A_NAME = "is not a name (letters, digits and _, not starting with a digit)"

BAD: list[tuple[str, Callable[[dict[str, Any]], object], list[str]]] = [
    ("not-a-mapping", lambda d: [d],
     ["expected a mapping with keys cluster and hosts, got a list"]),
    ("unknown-top-key", edit(host={}), ["host: unknown key (did you mean hosts?)"]),
    ("missing-hosts", edit(hosts=DELETE), ["hosts: required key missing"]),
    ("no-hosts", edit(hosts={}), ["hosts: expected at least one host"]),
    ("cluster-not-mapping", edit(cluster="lab"), ["cluster: expected a mapping, got str 'lab'"]),
    ("cluster-name-missing", edit(**{"cluster/name": DELETE}), ["cluster.name: required key missing"]),
    ("cluster-name-bad", edit(**{"cluster/name": "my lab"}), [f"cluster.name: 'my lab' {NOT_A_NAME}"]),
    ("cluster-unknown-key", edit(**{"cluster/leas": "3s"}), ["cluster.leas: unknown key (did you mean lease?)"]),
    ("security-mode-unknown", edit(**{"cluster/security": {"mode": "tsl"}}),
     ["cluster.security.mode: unknown mode 'tsl' (did you mean tls?)"]),
    ("security-mode-missing", edit(**{"cluster/security": {}}), ["cluster.security.mode: required key missing"]),
    ("security-password-incomplete", edit(**{"cluster/security": {"mode": "password", "user": "drd"}}),
     ["cluster.security.password_file: required for mode password"]),
    ("security-none-with-files", edit(**{"cluster/security": {"mode": "none", "cert": "c.pem"}}),
     ["cluster.security.cert: does not apply to mode none"]),
    ("security-unknown-key", edit(**{"cluster/security": TLS | {"certs": "x"}}),
     ["cluster.security.certs: unknown key (did you mean cert?)"]),
    ("security-empty-file", edit(**{"cluster/security": TLS | {"key": ""}}),
     ["cluster.security.key: expected a non-empty string, got str ''"]),
    ("lease-number", edit(**{"cluster/lease": 3}),
     ["cluster.lease: expected a duration such as 3s or 500ms (100ms..10min), got int 3"]),
    ("lease-zero", edit(**{"cluster/lease": "0s"}), ["cluster.lease: 0s is out of range: 100ms..10min"]),
    ("lease-long", edit(**{"cluster/lease": "1h"}), ["cluster.lease: 1h is out of range: 100ms..10min"]),
    ("lease-huge", edit(**{"cluster/lease": "1e400s"}),
     ["cluster.lease: expected a duration such as 3s or 500ms (100ms..10min), got str '1e400s'"]),
    ("history-zero", edit(**{"cluster/history": 0}),
     ["cluster.history: expected a count of finished missions to keep, 1..1000 missions, got int 0"]),
    ("placement-unknown-key", edit(**{"cluster/placement": {"cpus": 1}}),
     ["cluster.placement.cpus: unknown key (did you mean cpu?)"]),
    ("placement-negative", edit(**{"cluster/placement": {"memory": -1}}),
     ["cluster.placement.memory: -1 is out of range: 0..1000"]),
    ("placement-nan-inf", edit(**{"cluster/placement": {"cpu": float("nan"), "memory": float("inf")}}),
     ["cluster.placement.cpu: nan is not a finite number (expected 0..1000)",
      "cluster.placement.memory: inf is not a finite number (expected 0..1000)"]),
    ("placement-not-a-number", edit(**{"cluster/placement": {"cpu": "high"}}),
     ["cluster.placement.cpu: expected a number (0..1000), got str 'high'"]),
    ("placement-all-zero", edit(**{"cluster/placement": {"cpu": 0, "memory": 0, "instances": 0.0}}),
     ["cluster.placement: at least one weight must be positive"]),
    ("host-name-bad", edit(**{"hosts/ranger-2": {}}), [f"hosts.ranger-2: 'ranger-2' {NOT_A_NAME}"]),
    ("host-not-mapping", edit(**{"hosts/r2": "tcp/127.0.0.1:7449"}),
     ["hosts.r2: expected a mapping, got str 'tcp/127.0.0.1:7449'"]),
    ("host-unknown-key", edit(**{"hosts/r1/endpiont": "x"}),
     ["hosts.r1.endpiont: unknown key (did you mean endpoint?)"]),
    ("host-endpoint-missing", edit(**{"hosts/r1/endpoint": DELETE}), ["hosts.r1.endpoint: required key missing"]),
    ("endpoint-syntax", edit(**{"hosts/r1/endpoint": "127.0.0.1:7448"}),
     ["hosts.r1.endpoint: expected tcp/HOST:PORT or udp/HOST:PORT, got '127.0.0.1:7448'"]),
    ("endpoint-port", edit(**{"hosts/r1/endpoint": "udp/[::1]:70000"}),
     ["hosts.r1.endpoint: port 70000 is out of range (1 to 65535)"]),
    ("endpoint-duplicate", edit(**{"hosts/r1/endpoint": "tcp/127.0.0.1:7447"}),
     ["hosts.r1.endpoint: tcp/127.0.0.1:7447 is already the endpoint of host ctl"]),
    ("role-unknown", edit(**{"hosts/r1/roles": ["workr"]}),
     ["hosts.r1.roles: unknown role 'workr' (did you mean worker?)"]),
    ("roles-empty", edit(**{"hosts/r1/roles": []}),
     ["hosts.r1.roles: expected a non-empty list of roles, got an empty list"]),
    ("role-twice", edit(**{"hosts/r1/roles": ["worker", "worker"]}), ["hosts.r1.roles: worker is listed twice"]),
    ("no-controller", edit(**{"hosts/ctl/roles": ["worker"]}),
     ["hosts: no host has the role controller; exactly one must"]),
    ("two-controllers", edit(**{"hosts/r1/roles": ["controller", "worker"]}),
     ["hosts.r1.roles: controller is already a role of host ctl; a cluster has exactly one controller; several"
      " controllers need a replicated store to elect the one that acts (cluster.store: {etcd: [http://HOST:PORT,"
      " ...]}, docs/hosts.md)"]),
    ("two-simulators", edit(**{"hosts/ctl/roles": ["controller", "simulator"], "hosts/r1/roles": ["simulator"]}),
     ["hosts.r1.roles: simulator is already a role of host ctl; a cluster has at most one simulator"]),
    ("world-not-a-name", edit(**{"cluster/world": "../etc"}), [f"cluster.world: '../etc' {NOT_A_NAME}"]),
    ("cores-zero", edit(**{"hosts/ctl/cores": 0}), ["hosts.ctl.cores: 0 is out of range: 1..4096 cores"]),
    ("cores-float", edit(**{"hosts/ctl/cores": 1.5}),
     ["hosts.ctl.cores: expected an integer (1..4096 cores), got float 1.5"]),
    ("cores-nan", edit(**{"hosts/ctl/cores": float("nan")}),
     ["hosts.ctl.cores: expected an integer (1..4096 cores), got float nan"]),
    ("devices-not-mapping", edit(**{"hosts/r1/devices": ["drive"]}),
     ["hosts.r1.devices: expected a mapping, got a list"]),
    ("device-id-bad", edit(**{"hosts/r1/devices/s1..x": {"type": "Drive", "driver": "sim"}}),
     [f"hosts.r1.devices.s1..x: 's1..x' {NOT_A_NAME[:-1]}, in parts joined by dots)"]),
    ("device-not-mapping", edit(**{"hosts/r1/devices/drive": "Drive"}),
     ["hosts.r1.devices.drive: expected a mapping, got str 'Drive'"]),
    ("device-type-typo", edit(**{"hosts/r1/devices/camera/type": "Camra"}),
     ["hosts.r1.devices.camera.type: unknown type 'Camra' (did you mean Camera?)"]),
    ("device-type-arc", edit(**{"hosts/r1/devices/camera/type": "Ranger"}),
     ["hosts.r1.devices.camera.type: Ranger is an arc, expected an rc"]),
    ("device-type-behavior", edit(**{"hosts/r1/devices/camera/type": "Watch"}),
     ["hosts.r1.devices.camera.type: Watch is a behavior, expected an rc"]),
    ("device-driver-missing", edit(**{"hosts/r1/devices/drive/driver": DELETE}),
     ["hosts.r1.devices.drive.driver: required key missing"]),
    ("device-driver-bad", edit(**{"hosts/r1/devices/drive/driver": "my driver"}),
     [f"hosts.r1.devices.drive.driver: 'my driver' {NOT_A_NAME}"]),
    ("device-unknown-key", edit(**{"hosts/r1/devices/drive/option": {}}),
     ["hosts.r1.devices.drive.option: unknown key (did you mean options?)"]),
    ("option-unknown", edit(**{"hosts/r1/devices/camera/options": {"resolutoin": 640}}),
     ["hosts.r1.devices.camera.options.resolutoin: unknown property of Camera (did you mean resolution?)"]),
    ("option-type", edit(**{"hosts/r1/devices/camera/options": {"resolution": "640", "fov": True}}),
     ["hosts.r1.devices.camera.options.resolution: expected int, got str '640'",
      "hosts.r1.devices.camera.options.fov: expected float, got bool True"]),
    ("capacity-exclusive", edit(**{"hosts/r1/devices/drive/capacity": 2}),
     ["hosts.r1.devices.drive.capacity: Drive is not sharable; only a sharable device has a capacity"]),
    ("slice-sharable", edit(**{"hosts/r1/devices/radio/slice": "10s"}),
     ["hosts.r1.devices.radio.slice: RadioChannel is sharable: it is never taken away, so it has no time slice"]),
    ("slice-not-a-duration", edit(**{"hosts/r1/devices/drive/slice": 60}),
     ["hosts.r1.devices.drive.slice: expected a duration such as 3s or 500ms (200ms..24h), got int 60"]),
    ("slice-negative", edit(**{"hosts/r1/devices/drive/slice": "-1s"}),
     ["hosts.r1.devices.drive.slice: expected a duration such as 3s or 500ms (200ms..24h), got str '-1s'"]),
    ("slice-too-long", edit(**{"hosts/r1/devices/drive/slice": "25h"}),
     ["hosts.r1.devices.drive.slice: 25h is out of range: 200ms..24h"]),
    ("capacity-zero", edit(**{"hosts/r1/devices/radio/capacity": 0}),
     ["hosts.r1.devices.radio.capacity: 0 is out of range: 1..1000000"]),
    ("capacity-fraction", edit(**{"hosts/r1/devices/radio/capacity": 2.5}),
     ["hosts.r1.devices.radio.capacity: expected an integer (1..1000000), got float 2.5"]),
    ("capacity-huge", edit(**{"hosts/r1/devices/radio/capacity": 10**400}),
     ["hosts.r1.devices.radio.capacity: an integer of 401 digits is out of range: 1..1000000"]),
    ("option-nan", edit(**{"hosts/r1/devices/camera/options": {"fov": float("nan")}}),
     ["hosts.r1.devices.camera.options.fov: nan is not a finite number (expected 1..360 degrees) (Camera's manifest,"
      " components/Camera/manifest.yaml)"]),
    ("driver-option-inf", edit(**{"hosts/r1/devices/drive/driver_options": {"gains": [1.0, float("-inf")]}}),
     ["hosts.r1.devices.drive.driver_options.gains[1]: -inf is not a finite number"]),
    ("robot-id-bad", edit(**{"hosts/r1/robots/scout 2": {}}), [f"hosts.r1.robots.scout 2: 'scout 2' {NOT_A_NAME}"]),
    ("robot-unknown-key", edit(**{f"{S1}/carier": "r1"}),
     ["hosts.r1.robots.s1.carier: unknown key (did you mean carrier?)"]),
    ("robot-type-unknown", edit(**{"hosts/r1/robots/r1/type": "Rangr"}),
     ["hosts.r1.robots.r1.type: unknown type 'Rangr' (did you mean Ranger?)"]),
    ("robot-type-rc", edit(**{"hosts/r1/robots/r1/type": "Drive"}),
     ["hosts.r1.robots.r1.type: Drive is an rc, expected an arc"]),
    ("parts-missing", edit(**{f"{S1}/parts": DELETE}), ["hosts.r1.robots.s1.parts: required key missing"]),
    ("parts-not-mapping", edit(**{f"{S1}/parts": ["s1.wheels"]}),
     ["hosts.r1.robots.s1.parts: expected a mapping, got a list"]),
    ("part-missing", edit(**{"hosts/r1/robots/r1/parts/launcher": DELETE}),
     ["hosts.r1.robots.r1.parts.launcher: required part missing (a Launcher)"]),
    ("part-unknown", edit(**{"hosts/r1/robots/r1/parts/lancher": "launcher"}),
     ["hosts.r1.robots.r1.parts.lancher: unknown key (did you mean launcher?)"]),
    ("part-unknown-device", edit(**{f"{S1}/parts/wheels": "s1.wheel"}),
     ["hosts.r1.robots.s1.parts.wheels: unknown device 's1.wheel' on this host (did you mean s1.wheels?)"]),
    ("part-wrong-type", edit(**{f"{S1}/parts/wheels": "s1.camera"}),
     ["hosts.r1.robots.s1.parts.wheels: s1.camera is a Camera, expected a Drive"]),
    ("part-shared-exclusive", edit(**{"hosts/r1/robots/s2": {"type": "Scout", "parts": S1_PARTS}}),
     [f"hosts.r1.robots.s2.parts.{p}: s1.{p} is already the {p} of s1; only a sharable device can serve several"
      for p in ("wheels", "foot", "camera")]),
    ("property-unknown", edit(**{"hosts/r1/robots/r1/properties/batery": 1.0}),
     ["hosts.r1.robots.r1.properties.batery: unknown property of Ranger (did you mean battery?)"]),
    ("property-type", edit(**{"hosts/r1/robots/r1/properties": {"battery": "full", "magazine": 6.0}}),
     ["hosts.r1.robots.r1.properties.battery: expected float, got str 'full'",
      "hosts.r1.robots.r1.properties.magazine: expected int, got float 6.0"]),
    ("battery-above-full", edit(**{"hosts/r1/robots/r1/properties/battery": 3}),
     ["hosts.r1.robots.r1.properties.battery: 3 is out of range: 0..1 (Ranger's manifest,"
      " components/Ranger/manifest.yaml)"]),
    ("magazine-negative", edit(**{"hosts/r1/robots/r1/properties/magazine": -1}),
     ["hosts.r1.robots.r1.properties.magazine: -1 is out of range: 0..100 (Ranger's manifest,"
      " components/Ranger/manifest.yaml)"]),
    ("carrier-unknown", edit(**{f"{S1}/carrier": "r2"}),
     ["hosts.r1.robots.s1.carrier: no Ranger called 'r2' (did you mean r1?)"]),
    ("carrier-wrong-type", edit(**{f"{S1}/carrier": "s1"}),
     ["hosts.r1.robots.s1.carrier: s1 is a Scout, expected a Ranger"]),
    ("carrier-not-an-id", edit(**{f"{S1}/carrier": 1}),
     ["hosts.r1.robots.s1.carrier: expected the id of a Ranger, got int 1"]),
    ("carrier-undeclared", edit(**{"hosts/r1/robots/r1/carrier": "r1"}),
     ["hosts.r1.robots.r1.carrier: unknown property of Ranger (expected one of battery, magazine)"]),
    ("carrier-twice", edit(**{f"{S1}/properties": {"carrier": "r1"}}),
     ["hosts.r1.robots.s1.carrier: given twice, also in properties"]),
    ("robot-duplicate", second_ranger_host,
     ["hosts.r2.robots.r1: duplicate robot id, also on host r1",
      "hosts.r2.robots.s1: duplicate robot id, also on host r1"]),
]


@pytest.mark.parametrize(("change", "expected"), [case[1:] for case in BAD], ids=[case[0] for case in BAD])
def test_bad_config_is_reported(catalog: Catalog, change: Callable[[dict[str, Any]], object],
                                expected: list[str]) -> None:
    with pytest.raises(HostsError) as e:
        parse_hosts(change(base()), "hosts.yaml", catalog)
    assert [str(p) for p in e.value.problems] == [f"hosts.yaml: {m}" for m in expected]


def test_base_config_is_valid(catalog: Catalog) -> None:
    """The table above tests one change each: the file it changes must be fine as it is."""
    cluster = parse_hosts(base(), "hosts.yaml", catalog)
    radio = next(d for d in cluster.devices if d.id == "r1.radio")
    assert radio == Device("r1.radio", "r1", "RadioChannel", "sim", {}, 10.0) and radio.sharable
    assert cluster.host("r1").cores is None and cluster.lease == 3.0


def test_all_problems_are_raised_at_once(catalog: Catalog) -> None:
    data = edit(**{"cluster/lease": "soon", "hosts/r1/devices/camera/type": "Camra", f"{S1}/carrier": "r9"})(base())
    with pytest.raises(HostsError) as e:
        parse_hosts(data, "hosts.yaml", catalog)
    keys = ["cluster.lease", "hosts.r1.devices.camera.type", "hosts.r1.robots.s1.carrier"]
    assert [p.key for p in e.value.problems] == keys
    assert str(e.value).count("\n") == 2
    assert pickle.loads(pickle.dumps(e.value)).problems == e.value.problems


def test_property_values_of_every_type() -> None:
    """int, float (an int widens), bool, str, duration (in seconds) and references to devices."""
    props = {"n": "int", "x": "float", "on": "bool", "label": "str", "period": "duration", "eye": "Cam"}
    catalog = Catalog.of([ComponentType("Cam", Kind.RC, properties={"fov": "float"}),
                          ComponentType("Bot", Kind.ARC, parts={"cam": "Cam"}, properties=props)])
    values = {"n": 2, "x": 1, "on": False, "label": "front", "period": "250ms", "eye": "h.cam"}
    data: dict[str, Any] = {"cluster": {"name": "c"}, "hosts": {"h": {
        "endpoint": "tcp/robot-1.local:7447", "roles": ["controller", "worker"],
        "devices": {"cam": {"type": "Cam", "driver": "usb", "options": {"fov": 70}}},
        "robots": {"b": {"type": "Bot", "parts": {"cam": "cam"}, "properties": values}}}}}
    cluster = parse_hosts(data, "hosts.yaml", catalog)
    assert cluster.robots[0].properties == {"n": 2, "x": 1.0, "on": False, "label": "front", "period": 0.25,
                                            "eye": "h.cam"}
    assert cluster.devices[0].options == {"fov": 70.0} and cluster.devices[0].capacity is None
    data["hosts"]["h"]["robots"]["b"]["properties"] |= {"on": 1, "period": "1 week", "eye": "b"}
    with pytest.raises(HostsError) as e:
        parse_hosts(data, "hosts.yaml", catalog)
    assert [str(p) for p in e.value.problems] == [
        "hosts.yaml: hosts.h.robots.b.properties.on: expected bool, got int 1",
        "hosts.yaml: hosts.h.robots.b.properties.period: expected a positive duration such as 3s or 500ms,"
        " got str '1 week'",
        "hosts.yaml: hosts.h.robots.b.properties.eye: b is a Bot, expected a Cam",
    ]


def test_cluster_lookups(catalog: Catalog) -> None:
    cluster = parse_hosts(base(), "hosts.yaml", catalog)
    assert cluster.controller.name == "ctl" and cluster.host("r1").robots[1].carrier == "r1"
    with pytest.raises(KeyError, match="no host 'r9' in hosts.yaml"):
        cluster.host("r9")


# ---------------------------------------------------------------- files


def write(tmp_path: Path, text: str, name: str = "hosts.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_missing_file(catalog: Catalog, tmp_path: Path) -> None:
    with pytest.raises(HostsError) as e:
        load_hosts(tmp_path / "nowhere.yaml", catalog)
    assert e.value.problems == (HostsProblem((tmp_path / "nowhere.yaml").as_posix(), "", "no such file"),)


def test_yaml_syntax_error_has_its_line(catalog: Catalog, tmp_path: Path) -> None:
    path = write(tmp_path, "cluster:\n  name: lab\nhosts:\n  ctl: {endpoint: tcp/127.0.0.1:7447\n")
    with pytest.raises(HostsError) as e:
        load_hosts(path, catalog)
    (problem,) = e.value.problems
    assert (problem.line, str(problem)) == (5, f"{path.as_posix()}:5: invalid YAML: expected ',' or '}}',"
                                               " but got '<stream end>'")


def test_duplicate_host_is_a_yaml_error(catalog: Catalog, tmp_path: Path) -> None:
    """PyYAML would keep the second `ctl` silently; a host defined twice is a mistake."""
    host = "  ctl: {endpoint: tcp/127.0.0.1:7447, roles: [controller]}\n"
    path = write(tmp_path, f"cluster: {{name: lab}}\nhosts:\n{host}{host}")
    with pytest.raises(HostsError) as e:
        load_hosts(path, catalog)
    assert str(e.value) == f"{path.as_posix()}:4: invalid YAML: duplicate key 'ctl'"


def test_security_files_are_resolved_and_checked(catalog: Catalog, tmp_path: Path) -> None:
    (tmp_path / "certs").mkdir()
    for name in ("ca.pem", "drd.pem"):
        (tmp_path / "certs" / name).write_text("-----", encoding="utf-8")
    text = ("cluster: {name: lab, security: {mode: tls, ca: certs/ca.pem, cert: certs/drd.pem, key: certs/drd.key}}\n"
            "hosts: {ctl: {endpoint: tcp/127.0.0.1:7447, roles: [controller]}}\n")
    cluster = load_hosts(write(tmp_path, text), catalog)
    assert cluster.security.ca == str(tmp_path / "certs" / "ca.pem")  # relative to the hosts file, not the cwd
    assert check_files(cluster) == [HostsProblem(cluster.source, "cluster.security.key",
                                                 f"no such file: {tmp_path / 'certs' / 'drd.key'}")]
    assert check_files(load_hosts(ROOT / "hosts.yaml", catalog)) == []


def test_check_files_of_a_password_cluster(tmp_path: Path) -> None:
    secret = tmp_path / "secret"
    secret.write_text("pw", encoding="utf-8")
    cluster = Cluster("lab", Security(SecurityMode.PASSWORD, "drd", str(secret)), 3.0, Placement(), ())
    assert cluster.security.files == {"password_file": str(secret)} and check_files(cluster) == []
    secret.unlink()
    assert [p.key for p in check_files(cluster)] == ["cluster.security.password_file"]


def test_a_device_option_outside_its_manifests_range_is_refused_with_the_key_and_range(tmp_path: Path) -> None:
    """`beams: 1000000000` once made a dry-run reach 3.9 GB (issue #18): the manifest's limits refuse it at load."""
    from drd.hosts import HostsError, load_hosts
    from drd.manifests import load_catalog

    root = Path(__file__).resolve().parents[2]
    bad = (root / "hosts.yaml").read_text(encoding="utf-8").replace("beams: 181", "beams: 1000000000")
    bad = bad.replace("max_speed: 0.8", "max_speed: -1.0")
    (tmp_path / "hosts.yaml").write_text(bad, encoding="utf-8")
    with pytest.raises(HostsError) as refused:
        load_hosts(tmp_path / "hosts.yaml", load_catalog())
    problems = [str(p) for p in refused.value.problems]
    assert any("hosts.ranger1.devices.ranges.options.beams: 1000000000 is out of range: 3..4096" in p for p in problems)
    assert any("hosts.ranger1.devices.drive.options.max_speed: -1 is out of range: 0..20 m/s" in p for p in problems)


def test_a_manifest_limit_must_name_a_numeric_property_and_be_ordered() -> None:
    from drd.manifests import parse_manifest

    _t, problems = parse_manifest({"name": "Lidar", "kind": "rc", "entry_point": "x.y:Z", "interfaces": ["RangeSensor"],
                                   "properties": {"beams": "int", "model": "str"},
                                   "limits": {"beams": {"min": 10, "max": 5}, "model": {"max": 3}}}, "lidar.yaml")
    text = [str(p) for p in problems]
    assert "lidar.yaml: limits.beams: min 10 is above max 5" in text
    assert any(p.startswith("lidar.yaml: limits.model: limits a numeric property") for p in text)


def test_a_huge_value_is_echoed_cut_with_its_length(tmp_path: Path) -> None:
    """Issue #18: a value pasted by mistake (a megabyte) is named in one readable line, not copied whole."""
    from drd.hosts import HostsError, load_hosts
    from drd.manifests import load_catalog

    root = Path(__file__).resolve().parents[2]
    text = (root / "hosts.yaml").read_text(encoding="utf-8").replace("lease: 3s", "lease: " + "x" * 100_000)
    (tmp_path / "hosts.yaml").write_text(text, encoding="utf-8")
    with pytest.raises(HostsError) as refused:
        load_hosts(tmp_path / "hosts.yaml", load_catalog())
    [problem] = [str(p) for p in refused.value.problems if "cluster.lease" in str(p)]
    assert "(100,000 characters)" in problem and len(problem) < 300  # the value's own length
