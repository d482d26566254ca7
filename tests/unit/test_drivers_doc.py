"""The worked `serial` driver of docs/drivers.md loads as written (docs audit 2: its hosts.yaml line put the port in
`options`, which a Drive does not declare, so `drd start` refused it, and its code read the port from there)."""

from __future__ import annotations

import re
import sys
import types
from pathlib import Path

import pytest

from drd.hosts import load_hosts
from drd.hw.drivers import check_driver_classes
from dsl.catalog import Catalog
from tests.conftest import ROOT

DOC = ROOT / "docs" / "drivers.md"


def test_the_worked_serial_driver_loads_and_checks_its_driver_options(tmp_path: Path, catalog: Catalog,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    text = DOC.read_text(encoding="utf-8")
    code = re.search(r'```python\n("""A Drive over a serial.*?)```', text, re.S)
    line = re.search(r"^ +(drive: \{type: Drive, driver: serial, .*\})$", text, re.M)
    assert code is not None and line is not None
    (tmp_path / "acme_drivers").mkdir()
    (tmp_path / "acme_drivers" / "__init__.py").write_text("")
    (tmp_path / "acme_drivers" / "drive.py").write_text(code.group(1))
    monkeypatch.setitem(sys.modules, "serial", types.ModuleType("serial"))  # pyserial: opened only at start
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in ("acme_drivers", "acme_drivers.drive"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    hosts = tmp_path / "hosts.yaml"
    hosts.write_text("cluster: {name: lab, drivers: {serial: acme_drivers}, security: {mode: none}}\nhosts:\n"
                     "  lab:\n    endpoint: tcp/127.0.0.1:7447\n    roles: [controller, worker]\n    devices:\n"
                     f"      {line.group(1)}\n")
    assert check_driver_classes(load_hosts(hosts, catalog), "lab", catalog) == []
    hosts.write_text(hosts.read_text().replace("{port: /dev/ttyUSB0}", "{baud: 9600, speed: 3}"))
    assert check_driver_classes(load_hosts(hosts, catalog), "lab", catalog) == [
        f"{hosts}: hosts.lab.devices.drive.driver_options.port: the serial port, e.g. /dev/ttyUSB0",
        f"{hosts}: hosts.lab.devices.drive.driver_options.speed: unknown (expected one of port, baud, wheel_base)"]
