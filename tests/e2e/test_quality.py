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
