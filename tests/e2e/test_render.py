"""The dry-run picture: valid files, the things it promises to draw, and the same bytes for the same run."""

from __future__ import annotations

import dataclasses
import re
import struct
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from drd.dryrun import DryRun, run
from drd.hosts import load_hosts
from drd.render import SUPPORTED_SUFFIXES, _phases, render
from drd.sim.world import World, load_world, parse_world
from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import ROOT

SVG = "{http://www.w3.org/2000/svg}"
#: Two made-up sightings near intruder1's path, 0.3 m apart, by no Scout: two stars, one label for both.
DETECTIONS = [{"at": 21.3, "by": "Watch", "area": 0.1, "x": 16.9, "y": 2.1},
              {"at": 22.0, "by": "Watch", "area": 0.1, "x": 17.1, "y": 1.9}]


@pytest.fixture(scope="module")
def corridor() -> World:
    return load_world(ROOT / "worlds" / "corridor.yaml")


@pytest.fixture(scope="module")
def report(corridor: World, catalog: Catalog) -> DryRun:
    """The corridor mission's first 40 s (a door or two found, a Scout in the air), plus two detections."""
    chart = compile_file(ROOT / "missions" / "corridor_surveillance.mission", catalog).statechart
    assert chart is not None
    result = run(chart, load_hosts(ROOT / "hosts.yaml", catalog), corridor, catalog, until=40)
    return dataclasses.replace(result, detections=DETECTIONS + result.detections)


@pytest.fixture(scope="module")
def svg_file(corridor: World, report: DryRun, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("render") / "run.svg"
    render(corridor, report, path)
    return path


@pytest.fixture(scope="module")
def svg(svg_file: Path) -> ET.Element:
    return ET.parse(svg_file).getroot()


def texts(root: ET.Element) -> list[str]:
    return ["".join(t.itertext()).strip() for t in root.iter(f"{SVG}text")]


def ids(root: ET.Element) -> set[str]:
    return {e.attrib["id"] for e in root.iter() if "id" in e.attrib}


def stroke(root: ET.Element, gid: str) -> str:
    """The style of the line drawn in the group with this id."""
    group = next(e for e in root.iter(f"{SVG}g") if e.get("id") == gid)
    return next(p.attrib["style"] for p in group.iter(f"{SVG}path") if "stroke" in p.get("style", ""))


def test_png_is_a_picture_of_a_sensible_size(corridor: World, report: DryRun, tmp_path: Path) -> None:
    import matplotlib

    settings = dict(matplotlib.rcParams)
    path = tmp_path / "run.png"
    render(corridor, report, path)
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    assert 1200 <= width <= 2400 and 400 <= height < width  # the corridor is three times as long as it is deep
    assert dict(matplotlib.rcParams) == settings  # styled inside an rc_context: the caller's settings are left alone


def test_svg_labels_what_it_draws(corridor: World, report: DryRun, svg: ET.Element) -> None:
    words = texts(svg)
    for room in corridor.rooms:
        assert room.id in words
    for robot in ["ranger1", "intruder1", "intruder2", *(s["scout"] for s in report.scouts)]:
        assert robot in words
    assert report.outcome in words
    assert f"{report.mission} in corridor" in words
    assert any(w.startswith(f"sim time {report.sim_time:.1f} s") and f"{len(report.doors)} door" in w for w in words)
    assert "2 sightings, 21–22 s" in words  # one label says how many and when (drd.render: not one per sighting)
    assert {"detection-0", "detection-1", "light", "legend", "outcome", "ranger-ranger1-start"} <= ids(svg)
    assert {f"door-found-{i}" for i in range(len(report.doors))} <= ids(svg)


def test_outcome_is_coloured(svg: ET.Element) -> None:
    outcome = next(e for e in svg.iter(f"{SVG}g") if e.get("id") == "outcome")
    colour = "#2e7d32" if "success" in "".join(outcome.itertext()) else "#c62828"
    assert colour in ET.tostring(outcome, encoding="unicode")


def test_open_and_closed_doors_look_different(corridor: World, svg: ET.Element) -> None:
    assert {f"door-{d.state.value}-{d.id}" for d in corridor.doors} <= ids(svg)
    open_, closed = stroke(svg, "door-open-door_n1"), stroke(svg, "door-closed-door_n2")
    assert "#2e9e44" in open_ and "stroke-dasharray" in open_
    assert "#d32f2f" in closed and "stroke-dasharray" not in closed

    def width(style: str) -> float:
        return float(re.search(r"stroke-width: ([\d.]+)", style).group(1))  # type: ignore[union-attr]

    assert width(closed) > 2 * width(open_)


def test_same_run_same_bytes(corridor: World, report: DryRun, svg_file: Path, tmp_path: Path) -> None:
    render(corridor, report, tmp_path / "again.svg")
    assert (tmp_path / "again.svg").read_bytes() == svg_file.read_bytes()
    render(corridor, report, tmp_path / "a.pdf")
    render(corridor, report, tmp_path / "b.pdf")
    assert (tmp_path / "a.pdf").read_bytes() == (tmp_path / "b.pdf").read_bytes()
    assert (tmp_path / "a.pdf").read_bytes().startswith(b"%PDF")


@pytest.mark.parametrize("name", ["run.jpg", "run", "run.png.txt"])
def test_other_suffixes_are_refused_with_the_choices(corridor: World, report: DryRun, tmp_path: Path,
                                                      name: str) -> None:
    with pytest.raises(ValueError, match=r"\.png, \.svg, \.pdf") as e:
        render(corridor, report, tmp_path / name)
    assert name in str(e.value) and not (tmp_path / name).exists()
    assert SUPPORTED_SUFFIXES == (".png", ".svg", ".pdf")


def test_a_small_world_and_an_empty_report(tmp_path: Path) -> None:
    """No tracks, a blocked door, a Scout on the floor: drawn from the world alone; a title; an upper-case suffix."""
    world = parse_world({
        "name": "small", "walls": [{"from": [0, 1], "to": [12, 1]}, {"from": [0, -1], "to": [12, -1]}],
        "rooms": [{"id": "a", "rect": [2, 1, 6, 4]}],
        "doors": [{"id": "d_a", "at": [4, 1], "width": 1.0, "state": "blocked"}],
        "intruders": [{"id": "visitor", "path": [{"t": 0, "at": [3, 2]}, {"t": 5, "at": [5, 2]}]}],
        "rangers": [{"id": "ranger1", "at": [1, 0]}], "scouts": [{"id": "scout3", "at": [3, 3]}],
    }, "small.yaml")
    path = tmp_path / "SMALL.SVG"
    render(world, DryRun("Empty", None, "", 0.0, 0.0), path, title="Night shift")
    root = ET.parse(path).getroot()
    assert {"Night shift in small", "a", "ranger1", "scout3", "visitor", "unfinished"} <= set(texts(root))
    assert {"door-blocked-d_a", "scout-scout3-placed"} <= ids(root)
    assert "blocked door" in texts(root) and "closed door" not in texts(root)


def test_scout_trail_splits_into_flight_and_rolling() -> None:
    """A launch moves metres a second, rolling a few decimetres: the picture dashes the first, not the second."""
    trail = [(10.0, 0.0, 0.0), (10.5, 2.0, 0.0), (11.0, 4.0, 0.0), (12.0, 4.2, 0.0), (13.0, 4.4, 0.0),
             (13.1, 4.9, 0.0), (14.0, 5.0, 0.0)]
    phases = [(airborne, [p[0] for p in part]) for airborne, part in _phases(trail)]
    assert phases == [(True, [10.0, 10.5, 11.0]), (False, [11.0, 12.0, 13.0]), (True, [13.0, 13.1]),
                      (False, [13.1, 14.0])]
    assert list(_phases(trail[:1])) == []


def test_importing_drd_render_does_not_import_matplotlib() -> None:
    code = "import sys, drd.render; assert 'matplotlib' not in sys.modules, 'matplotlib imported'"
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
                       check=False)
    assert r.returncode == 0, r.stderr


def test_doors_are_drawn_as_the_injections_left_them(corridor: World, report: DryRun, tmp_path: Path) -> None:
    """`--inject 'block door_n1 at 12s'`: the picture shows door_n1 blocked, with when, not open as at the start."""
    injected = dataclasses.replace(report, injections=[
        {"at": 12.0, "action": "block", "target": "door_n1", "injection": "block door_n1 at 12s", "effect": ""},
        {"at": 20.0, "action": "open", "target": "door_n1", "injection": "open door_n1 at 20s", "effect": ""},
        {"at": 25.0, "action": "open", "target": "door_n2", "injection": "open door_n2 at 25s", "effect": ""}])
    path = tmp_path / "injected.svg"
    render(corridor, injected, path)
    root = ET.parse(path).getroot()
    assert {"door-blocked-door_n1", "door-open-door_n2"} <= ids(root)  # a blocked door stays blocked
    assert not {"door-open-door_n1", "door-closed-door_n2"} & ids(root)
    assert "blocked at 12 s" in texts(root) and "opened at 25 s" in texts(root)
    assert "opened at 20 s" not in texts(root)  # door_n1 stayed blocked
