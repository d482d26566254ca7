"""`--render` of a building of many wings (scale audit D2): a tall page shaped like the building, wide enough for
the legend and title, rather than 12 x 9 in whatever the world."""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drd.render import MIN_WIDTH, render
from drd.sim.building import Building, world
from drd.sim.world import parse_world


@dataclass
class Report:
    """A run that has not started: only the world is drawn (what `RunReport` reads)."""

    mission: str = "Corridor"
    outcome: str | None = None
    reason: str = ""
    sim_time: float = 0.0
    doors: list[dict[str, Any]] = field(default_factory=list)
    scouts: list[dict[str, Any]] = field(default_factory=list)
    detections: list[dict[str, Any]] = field(default_factory=list)
    tracks: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)
    injections: list[dict[str, Any]] = field(default_factory=list)

    def holds(self) -> list[dict[str, Any]]:
        return []


def png_size(path: Path) -> tuple[int, int]:
    width, height = struct.unpack(">II", path.read_bytes()[16:24])
    return int(width), int(height)


def test_a_ten_wing_building_gets_a_tall_page_wide_enough_for_its_legend(tmp_path: Path) -> None:
    w = parse_world(world(Building(10, 19)), "worlds/b.yaml")
    render(w, Report(), tmp_path / "b.png")
    width, height = png_size(tmp_path / "b.png")
    assert width >= MIN_WIDTH * 150 * 0.95  # was 1050 px: the legend ran off both edges
    assert height > 1.5 * width  # the building is tall (wings stacked north to south), and so is the page
