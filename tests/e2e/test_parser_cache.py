"""The mission parser's tables kept between processes (`dsl.parser.cache_tables`, `drd.cache`)."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from drd import cache
from dsl import parser

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "missions" / "corridor_surveillance.mission"
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]


@pytest.fixture
def tables_dir(tmp_path: Path) -> Iterator[Path]:
    parser.cache_tables(str(tmp_path))
    try:
        yield tmp_path
    finally:
        parser.cache_tables(None)


def test_a_parser_writes_its_tables_and_the_next_one_reads_them(tables_dir: Path) -> None:
    text = MISSION.read_text()
    expected, _ = parser.Parser().parse(text)
    files = list(tables_dir.iterdir())
    assert len(files) == 1 and files[0].name.startswith("mission-grammar-") and files[0].stat().st_size > 10_000
    written = files[0].stat().st_mtime_ns
    again, diagnostics = parser.Parser().parse(text)  # from the file: same tree, file left as it was
    assert again == expected and not diagnostics
    assert files[0].stat().st_mtime_ns == written


def test_a_damaged_table_file_is_rebuilt_and_parsing_is_unchanged(tables_dir: Path) -> None:
    parser.Parser()
    (path,) = tables_dir.iterdir()
    good = path.read_bytes()
    path.write_bytes(good[: len(good) // 2])  # a write cut short by a crash
    tree, diagnostics = parser.Parser().parse(MISSION.read_text())
    assert tree is not None and not diagnostics
    rebuilt = path.stat().st_mtime_ns
    assert path.stat().st_size > len(good) // 2  # written again, whole: the next parser reads it as it is
    parser.Parser()
    assert path.stat().st_mtime_ns == rebuilt


def test_without_a_cache_directory_nothing_is_written(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Nowhere: not the temporary folder (where lark's own `cache=True` would write), the cache home or the
    working directory, all pointed at one folder that must stay empty; the same set-up with a cache directory
    does write there, so the observation can see a write."""
    import tempfile

    for var in ("XDG_CACHE_HOME", "HOME", "TMPDIR"):
        monkeypatch.setenv(var, str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.chdir(tmp_path)
    try:
        parser.cache_tables(None)
        parser.Parser()
        assert list(tmp_path.rglob("*")) == []
        parser.cache_tables(str(tmp_path))
        parser.Parser()
        assert [p.name for p in tmp_path.iterdir()] != []
    finally:
        parser.cache_tables(None)


def test_cache_dir_is_private_to_the_user(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    directory = cache.cache_dir()
    assert directory == str(tmp_path / "drd")
    assert (tmp_path / "drd").stat().st_mode & 0o777 == 0o700
    os.chmod(tmp_path / "drd", 0o777)  # others could plant a pickle there: not used
    assert cache.cache_dir() is None
    monkeypatch.setenv("XDG_CACHE_HOME", "/proc/no-such-place")  # cannot be created: not used
    assert cache.cache_dir() is None


def test_missionctl_validate_keeps_the_tables_in_xdg_cache_home(tmp_path: Path) -> None:
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path)}
    for _ in range(2):  # the first builds and writes, the second reads
        r = subprocess.run([*MISSIONCTL, "validate", str(MISSION)], cwd=ROOT, env=env,
                           capture_output=True, text=True, timeout=60, check=False)
        assert r.returncode == 0, r.stdout + r.stderr
    assert [p.name.startswith("mission-grammar-") for p in (tmp_path / "drd").iterdir()] == [True]
