"""The one place that reads `DRD_PROFILE`: cProfile a daemon's hot loops when a developer asks.

`DRD_PROFILE=/tmp/p drd start ...` profiles the controller's mission loop (`/tmp/p.controller`), each host's
Creator batches (`/tmp/p.<host>`) and the simulator service (`/tmp/p.sim`); read them with `python -m pstats`.
Unset, a `Sampler` costs one attribute test per run.
"""

from __future__ import annotations

import cProfile
import os
from collections.abc import Iterator
from contextlib import contextmanager


def profile_base() -> str:
    """The path prefix asked for by `DRD_PROFILE` ('' when profiling is off)."""
    return os.environ.get("DRD_PROFILE", "")


class Sampler:
    """Profiles each `run()` block into one profile, written to `<DRD_PROFILE>.<name>` every `every` blocks and
    at `dump()`."""

    def __init__(self, name: str, every: int = 200) -> None:
        base = profile_base()
        self.path = f"{base}.{name}" if base else ""
        self.every = every
        self.runs = 0
        self.profile = cProfile.Profile() if base else None

    @contextmanager
    def run(self) -> Iterator[None]:
        prof = self.profile
        if prof is None:
            yield
            return
        prof.enable()
        try:
            yield
        finally:
            prof.disable()
            self.runs += 1
            if self.runs % self.every == 0:
                prof.dump_stats(self.path)

    def dump(self) -> None:
        if self.profile is not None:
            self.profile.dump_stats(self.path)
