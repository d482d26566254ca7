"""A driver kept outside drd (component audit D5): hosts.yaml `cluster.drivers: {toy: PACKAGE}` makes `driver: toy`
mean `PACKAGE.<type>:Toy<Type>` instead of `components.toy...`, which a user cannot add to without editing drd's
installed tree. The package is the user's own (here written to a temporary folder put on sys.path)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from drd.hosts import HostsError, parse_hosts
from drd.hw.drivers import check_driver_classes, drivers_for
from dsl.catalog import Catalog

TOY_DRIVE = '''
from drd.hw.interfaces import Fence


class ToyDrive:
    READINGS = frozenset({"odometry", "origin", "max_speed"})
    SETPOINTS = ("set_velocity", "stop")
    STOP = "stop"

    def __init__(self, device, robot_id, backend=None):
        self.fence, self.max_speed, self.last = Fence(device.id), 0.5, (0.0, 0.0)

    def set_velocity(self, v, omega, epoch=None):
        self.fence.check(epoch)
        self.last = (v, omega)

    def stop(self, epoch=None):
        self.set_velocity(0.0, 0.0, epoch)

    def odometry(self):
        return (0.0, 0.0, 0.0)

    def origin(self):
        return (0.0, 0.0, 0.0)
'''


def hosts(drivers: Any) -> dict[str, Any]:
    return {"cluster": {"name": "yard", "drivers": drivers},
            "hosts": {"bay9": {"endpoint": "tcp/127.0.0.1:7447", "roles": ["controller", "worker"],
                               "devices": {"wheels": {"type": "Drive", "driver": "toy"}}}}}


@pytest.fixture
def package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    (tmp_path / "yardkit_drivers").mkdir()
    (tmp_path / "yardkit_drivers" / "__init__.py").write_text("")
    (tmp_path / "yardkit_drivers" / "drive.py").write_text(TOY_DRIVE)
    monkeypatch.syspath_prepend(str(tmp_path))
    return "yardkit_drivers"


def test_a_driver_outside_drd_is_found_through_cluster_drivers(catalog: Catalog, package: str) -> None:
    cluster = parse_hosts(hosts({"toy": package}), "hosts.yaml", catalog)
    assert cluster.drivers == {"toy": package}
    assert check_driver_classes(cluster, "bay9", catalog) == []
    built = drivers_for(cluster, "bay9", catalog=catalog).devices["bay9.wheels"]
    assert type(built).__module__ == "yardkit_drivers.drive" and type(built).__name__ == "ToyDrive"


def test_without_the_package_the_driver_is_looked_for_in_drd_and_not_found(catalog: Catalog, package: str) -> None:
    data = hosts({})
    del data["cluster"]["drivers"]
    cluster = parse_hosts(data, "hosts.yaml", catalog)
    [problem] = check_driver_classes(cluster, "bay9", catalog)
    assert "hosts.bay9.devices.wheels.driver" in problem and "components.toy.drive" in problem


@pytest.mark.parametrize(("drivers", "message"), [
    ({"toy": "../yardkit"}, "cluster.drivers.toy: expected a Python package name such as acme_drivers.serial"),
    ({"toy": 3}, "cluster.drivers.toy: expected a Python package name"),
    ({"sim": "yardkit"}, "cluster.drivers.sim: sim is drd's own driver"),
    ({"Toy": "yardkit"}, "cluster.drivers.Toy"),
])
def test_a_bad_driver_package_names_the_key(catalog: Catalog, drivers: Any, message: str) -> None:
    with pytest.raises(HostsError) as info:
        parse_hosts(hosts(drivers), "hosts.yaml", catalog)
    assert any(message in str(p) for p in info.value.problems), info.value.problems
