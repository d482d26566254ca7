"""`--render` of a building of many wings (scale audit D2): a tall page shaped like the building, wide enough for
the legend and title, rather than 12 x 9 in whatever the world."""

from __future__ import annotations

import dataclasses
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from matplotlib.artist import Artist
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.transforms import Bbox

from drd.render import MIN_WIDTH, figure, render
from drd.sim.building import Building, world
from drd.sim.model import World
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


def crowded(w: World) -> Report:
    """Every Scout of the building rolled a few centimetres from its Ranger: 190 ids where 10 can be read."""
    tracks = {}
    for ranger in w.rangers:
        for k, sid in enumerate(ranger.magazine):
            tracks[sid] = [(0.0, ranger.x, ranger.y), (30.0, ranger.x + 0.05 * k, ranger.y + 0.02 * k)]
    return Report(sim_time=30.0, tracks=tracks, reason="sim time limit of 30 s reached")


def inside(fig: Figure, artist: Artist) -> bool:
    box, page = artist.get_window_extent(), fig.bbox
    return bool(page.x0 - 1 <= box.x0 and box.x1 <= page.x1 + 1 and page.y0 - 1 <= box.y0 and box.y1 <= page.y1 + 1)


@pytest.mark.parametrize("wings", [1, 10])
def test_the_legend_and_the_title_lie_within_the_image(wings: int) -> None:
    w = parse_world(world(Building(wings, 19)), "worlds/b.yaml")
    fig = figure(w, crowded(w))
    ax = fig.axes[0]
    assert fig.legends and inside(fig, fig.legends[0])
    stats = next(c for c in ax.get_children() if isinstance(c, Text) and c.get_text() == ax.get_title("left"))
    head = [t for t in ax.texts if t.get_gid() in {"outcome", "reason"} or t.get_text().endswith(f" in {w.name}")]
    assert len(head) == 3 and all(inside(fig, t) for t in [stats, *head])


def test_labels_are_thinned_at_fleet_size_and_the_title_says_how_many() -> None:
    w = parse_world(world(Building(10, 19)), "worlds/b.yaml")
    fig = figure(w, crowded(w))
    ids = [t for t in fig.axes[0].texts if str(t.get_gid()).startswith("scout-label-")]
    assert 0 < len(ids) < len(w.scout_ids) // 2  # 190 Scouts; a broken renderer keeps every one
    boxes = [t.get_window_extent() for t in ids]
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            both = Bbox.intersection(a, b)
            assert both is None or both.width * both.height <= 0.15 * a.width * a.height
    left_out = len(w.scout_ids) - len(ids)
    assert f"not drawn at this scale: {left_out} Scout ids" in fig.axes[0].get_title("left")


def test_a_small_world_keeps_every_label() -> None:
    w = parse_world(world(Building(1, 3)), "worlds/b.yaml")
    fig = figure(w, crowded(w))
    texts = {t.get_text() for t in fig.axes[0].texts}
    assert {*w.scout_ids, *(r.id for r in w.rooms)} <= texts
    assert "Scout ids" not in fig.axes[0].get_title("left") and "room names" not in fig.axes[0].get_title("left")


def test_carrier_index_agrees_with_a_scan_of_the_magazines() -> None:
    """`World.carrier` is a dict built once (check_hosts asks per robot); it must answer as the scan did."""
    w = parse_world(world(Building(3, 5)), "worlds/b.yaml")
    for rid in [*w.scout_ids, *(r.id for r in w.rangers), "nobody"]:
        assert w.carrier(rid) == next((r.id for r in w.rangers if rid in r.magazine), None)
    assert w.carrier(w.rangers[2].magazine[0]) == w.rangers[2].id
    again = dataclasses.replace(w, rangers=w.rangers[:1])  # a new record: its own index, not the old one's
    assert again.carrier(w.rangers[2].magazine[0]) is None


def test_the_legend_names_the_teams_own_robot_types() -> None:
    """Users audit 12, D10: a Rover and Drone team's picture said "Ranger path" and "Scout flight"."""
    w = parse_world(world(Building(1, 4)), "worlds/b.yaml")
    types = {**{r.id: "Rover" for r in w.rangers}, **dict.fromkeys(w.scout_ids, "Drone")}

    def labels(fig: Figure) -> list[str]:
        return [t.get_text() for t in fig.legends[0].get_texts()]

    own = labels(figure(w, crowded(w), types=types))
    assert "Rover path (start ○)" in own and "Drone flight" in own and "Drone rolling, placed" in own
    assert not any("Ranger" in label or "Scout" in label for label in own), own
    assert "Ranger path (start ○)" in labels(figure(w, crowded(w)))  # no types known (a replay): the bodies' names
