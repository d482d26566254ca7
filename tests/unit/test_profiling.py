"""`DRD_PROFILE` is read in one place: a Sampler profiles its blocks only when asked, and writes where told."""

from __future__ import annotations

import pstats
from pathlib import Path

import pytest

from drd.profiling import Sampler


def busy() -> int:
    return sum(i * i for i in range(2000))


def test_unset_it_profiles_nothing_and_writes_nothing(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv("DRD_PROFILE", raising=False)
    monkeypatch.chdir(tmp_path)
    sampler = Sampler("controller", every=1)
    with sampler.run():
        busy()
    sampler.dump()
    assert sampler.profile is None and list(tmp_path.iterdir()) == []


def test_set_it_writes_a_readable_profile_every_n_blocks(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("DRD_PROFILE", str(tmp_path / "p"))
    sampler = Sampler("ranger1", every=3)
    for _ in range(2):
        with sampler.run():
            busy()
    assert not (tmp_path / "p.ranger1").exists()
    with sampler.run():
        busy()
    stats = pstats.Stats(str(tmp_path / "p.ranger1"))
    assert any(func[2] == "busy" and calls[0] == 3 for func, calls in stats.stats.items())  # type: ignore[attr-defined]
