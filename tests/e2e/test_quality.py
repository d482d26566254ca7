"""The code stays as clean as the issue asks: ruff over the tree, mypy --strict over every package."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.skipif(shutil.which("ruff") is None, reason="ruff is not installed (pip install -e '.[test]')")
def test_ruff_is_clean() -> None:
    r = subprocess.run(["ruff", "check", "."], cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 0, r.stdout + r.stderr


def test_mypy_strict_on_every_package() -> None:
    pytest.importorskip("mypy", reason="mypy is not installed (pip install -e '.[test]')")
    r = subprocess.run([sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True, timeout=300,
                       check=False)
    assert r.returncode == 0, r.stdout + r.stderr


def test_dsl_does_no_io_outside_the_loader() -> None:
    """dsl/ is pure: only dsl/loader.py reads files; nothing prints or imports rich."""
    for path in (ROOT / "dsl").glob("*.py"):
        text = path.read_text()
        assert "import rich" not in text and "from rich" not in text, path.name
        assert "print(" not in text, path.name
        if path.name != "loader.py":
            for pattern in (r"(?<![\w.])open\(", r"\.read_bytes\(", r"\bPath\(", r"\bsubprocess\b", r"os\.environ"):
                assert not re.search(pattern, text), f"{path.name} matches {pattern}"


#: Benchmarks that need the `bench` extra (`pip install -e '.[bench]'`: the peers they compare against).
NEEDS_BENCH_EXTRA = {"runtime.py": "sismic"}


@pytest.mark.parametrize("bench", sorted(p.name for p in (ROOT / "bench").glob("*.py") if not p.name.startswith("_")))
def test_every_benchmark_starts(bench: str) -> None:
    """Each benchmark still imports what it uses and parses its options (moved helpers once broke one unseen);
    none is run here: `--help` only."""
    if bench in NEEDS_BENCH_EXTRA:
        pytest.importorskip(NEEDS_BENCH_EXTRA[bench], reason=f"bench/{bench} needs pip install -e '.[bench]'")
    r = subprocess.run([sys.executable, str(ROOT / "bench" / bench), "--help"], cwd=ROOT, capture_output=True,
                       text=True, timeout=120, check=False)
    assert r.returncode == 0 and r.stdout.startswith("usage:"), r.stdout + r.stderr
