"""The one entry-point loader says which of the three things went wrong, and drivers and components use it."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from drd import entrypoints
from drd.entrypoints import EntryPointError
from drd.errors import DrdError


@pytest.fixture
def modules(tmp_path: Path) -> Iterator[Path]:
    (tmp_path / "ep_good.py").write_text("class Thing:\n    pass\n", encoding="utf-8")
    (tmp_path / "ep_broken.py").write_text("import no_such_dependency_here\n", encoding="utf-8")
    (tmp_path / "ep_raises.py").write_text("raise RuntimeError('boom at import')\n", encoding="utf-8")
    sys.path.insert(0, str(tmp_path))
    yield tmp_path
    sys.path.remove(str(tmp_path))
    for name in ("ep_good", "ep_broken", "ep_raises"):
        sys.modules.pop(name, None)


def test_a_good_entry_point_loads_its_class(modules: Path) -> None:
    assert entrypoints.load("ep_good:Thing").__name__ == "Thing"


@pytest.mark.parametrize(("entry", "message"), [
    ("ep_good.Thing", "expected 'package.module:Name', got 'ep_good.Thing'"),
    ("ep_missing:Thing", "no module ep_missing (for ep_missing:Thing)"),
    ("ep_broken:Thing", "module ep_broken failed to import: No module named 'no_such_dependency_here'"),
    ("ep_raises:Thing", "module ep_raises failed to import: RuntimeError: boom at import"),
    ("ep_good:Other", "module ep_good has no Other (for ep_good:Other)"),
])
def test_each_failure_says_what_went_wrong(modules: Path, entry: str, message: str) -> None:
    with pytest.raises(EntryPointError) as failed:
        entrypoints.load(entry)
    assert str(failed.value) == message
    assert isinstance(failed.value, DrdError) and failed.value.kind == "component"


def test_a_driver_whose_module_is_missing_names_its_device(modules: Path) -> None:
    from drd.hosts import Device
    from drd.hw.drivers import DriverError, load_driver

    device = Device("r1.drive", "r1", "Drive", "custom")
    with pytest.raises(DriverError) as failed:
        load_driver(device, "r1", {})
    assert str(failed.value) == ("device r1.drive (type Drive, driver 'custom'): no module components.custom.drive "
                                 "(for components.custom.drive:CustomDrive); see docs/drivers.md to add a driver")
