"""The one entry-point loader says which of the three things went wrong, and drivers and components use it."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from drd import entrypoints
from drd.entrypoints import EntryPointError, MissingDependency
from drd.errors import DrdError


@pytest.fixture
def modules(tmp_path: Path) -> Iterator[Path]:
    (tmp_path / "ep_good.py").write_text("class Thing:\n    pass\n", encoding="utf-8")
    (tmp_path / "ep_broken.py").write_text("import no_such_dependency_here\n", encoding="utf-8")
    (tmp_path / "ep_raises.py").write_text("raise RuntimeError('boom at import')\n", encoding="utf-8")
    (tmp_path / "ep_syntax.py").write_text("x = 1\ndef f()\n    pass\n", encoding="utf-8")
    (tmp_path / "ep_pkg").mkdir()
    (tmp_path / "ep_pkg" / "__init__.py").write_text("", encoding="utf-8")
    (tmp_path / "ep_pkg" / "comp.py").write_text("import ep_pkg.helpres\n", encoding="utf-8")  # a typo
    sys.path.insert(0, str(tmp_path))
    yield tmp_path
    sys.path.remove(str(tmp_path))
    for name in ("ep_good", "ep_broken", "ep_raises", "ep_syntax", "ep_pkg", "ep_pkg.comp"):
        sys.modules.pop(name, None)


def test_a_good_entry_point_loads_its_class(modules: Path) -> None:
    assert entrypoints.load("ep_good:Thing").__name__ == "Thing"


@pytest.mark.parametrize(("entry", "message"), [
    ("ep_good.Thing", "expected 'package.module:Name', got 'ep_good.Thing'"),
    ("ep_missing:Thing", "no module ep_missing (for ep_missing:Thing)"),
    ("ep_broken:Thing", "module ep_broken failed to import: No module named 'no_such_dependency_here'"),
    ("ep_raises:Thing", "module ep_raises failed to import: RuntimeError: boom at import (at ep_raises.py:1)"),
    # users audit 18, #5: a syntax error said `(ep_syntax.py, line 2)`: no folder, no column, no line
    ("ep_syntax:Thing", "module ep_syntax failed to import: ep_syntax.py:2:8: SyntaxError: expected ':', in `def f()`"),
    ("ep_good:Other", "module ep_good has no Other (for ep_good:Other)"),
])
def test_each_failure_says_what_went_wrong(modules: Path, entry: str, message: str) -> None:
    with pytest.raises(EntryPointError) as failed:
        entrypoints.load(entry)
    assert str(failed.value).replace(f"{modules}/", "") == message  # the module's own path, shortened here
    assert isinstance(failed.value, DrdError) and failed.value.kind == "component"


def test_a_library_the_module_imports_is_a_missing_dependency_and_its_own_package_is_not(modules: Path) -> None:
    """A host without a component's library starts without that component (drd.preflight); a module of the
    component's own package that is not there is a mistake in it, refused like any other."""
    with pytest.raises(MissingDependency) as lacking:
        entrypoints.load("ep_broken:Thing")
    assert lacking.value.dependency == "no_such_dependency_here"
    with pytest.raises(EntryPointError) as broken:
        entrypoints.load("ep_pkg.comp:Thing")
    assert not isinstance(broken.value, MissingDependency)
    assert str(broken.value) == "module ep_pkg.comp failed to import: No module named 'ep_pkg.helpres'"
    with pytest.raises(EntryPointError) as missing:
        entrypoints.load("ep_pkg.nothing:Thing")
    assert str(missing.value) == "no module ep_pkg.nothing (for ep_pkg.nothing:Thing)"
    assert not isinstance(missing.value, MissingDependency)
    with pytest.raises(EntryPointError) as missing:
        entrypoints.load("ep_good_not:Thing")  # a name another module's name starts with: still its own module
    assert str(missing.value) == "no module ep_good_not (for ep_good_not:Thing)"


def test_a_hosting_check_makes_a_missing_dependency_unavailable_and_a_dry_run_refuses_it(modules: Path) -> None:
    from drd.preflight import entry_point_check
    from dsl.catalog import Catalog, ComponentType, Kind

    broken = ComponentType("Lidar3D", Kind.BEHAVIOR, entry_point="ep_broken:Thing", source="x/Lidar3D/manifest.yaml")
    typo = ComponentType("Typo", Kind.BEHAVIOR, entry_point="ep_good:Other", source="x/Typo/manifest.yaml")
    catalog = Catalog({"Lidar3D": broken, "Typo": typo})
    hosting = entry_point_check(catalog, hosting=True)
    assert hosting.problems == ["x/Typo/manifest.yaml: entry_point: module ep_good has no Other (for ep_good:Other)"]
    assert hosting.unavailable == {"Lidar3D": "its module ep_broken needs no_such_dependency_here, which is not "
                                              "installed here (x/Lidar3D/manifest.yaml)"}
    assert hosting.warnings("lab") == [f"lab will not run Lidar3D: {hosting.unavailable['Lidar3D']}"]
    alone = entry_point_check(catalog, ["Lidar3D"])  # a dry-run runs it here: it must import
    assert alone.unavailable == {} and alone.problems == [
        "x/Lidar3D/manifest.yaml: entry_point: module ep_broken failed to import: "
        "No module named 'no_such_dependency_here'"]


def test_a_driver_whose_module_is_missing_names_its_device(modules: Path) -> None:
    from drd.hosts import Device
    from drd.hw.drivers import DriverError, load_driver

    device = Device("r1.drive", "r1", "Drive", "custom")
    with pytest.raises(DriverError) as failed:
        load_driver(device, "r1", {})
    assert str(failed.value) == ("device r1.drive (type Drive, driver 'custom'): no module components.custom.drive "
                                 "(for components.custom.drive:CustomDrive); see docs/drivers.md to add a driver")
