"""The picture, as a newcomer asked (issue #13): each Scout's camera view and heading where it watched, time marks
along the paths, sightings in the colour of the Scout that saw them, and one summary label per Scout instead of
one per sighting."""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from drd.dryrun import DryRun, run
from drd.hosts import load_hosts
from drd.render import render, scout_colours, seers_of, time_step
from drd.sim.world import World, load_world
from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import ROOT

SVG = "{http://www.w3.org/2000/svg}"


@pytest.fixture(scope="module")
def corridor() -> World:
    return load_world(ROOT / "worlds" / "corridor.yaml")


@pytest.fixture(scope="module")
def report(corridor: World, catalog: Catalog) -> DryRun:
    chart = compile_file(ROOT / "missions" / "corridor_surveillance.mission", catalog).statechart
    assert chart is not None
    result = run(chart, load_hosts(ROOT / "hosts.yaml", catalog), corridor, catalog)
    assert result.outcome == "success" and len(result.detections) > 20
    return result


@pytest.fixture(scope="module")
def svg(corridor: World, report: DryRun, tmp_path_factory: pytest.TempPathFactory) -> ET.Element:
    path = tmp_path_factory.mktemp("views") / "run.svg"
    views = {s: (math.pi / 4 * i, math.radians(90)) for i, s in enumerate(corridor.scout_ids)}
    render(corridor, report, path, views=views)
    return ET.parse(path).getroot()


def group(root: ET.Element, gid: str) -> ET.Element:
    return next(e for e in root.iter(f"{SVG}g") if e.get("id") == gid)


def texts(root: ET.Element) -> list[str]:
    return ["".join(t.itertext()).strip() for t in root.iter(f"{SVG}text")]


def test_each_sighting_is_the_colour_of_the_scout_that_saw_it(corridor: World, report: DryRun,
                                                              svg: ET.Element) -> None:
    seers = seers_of(corridor, report)
    assert None not in seers and len(set(seers)) >= 2  # every one told, and by more than one Scout
    holds = {h["path"]: h["resources"]["scout"] for h in report.holds() if "scout" in h["resources"]}
    for d, seer in zip(report.detections, seers, strict=True):
        room = d["by"].rsplit("/", 1)[0]  # RoomSurveillance[k]: the instance that held that Scout
        assert holds[room] == seer
    colours = scout_colours(corridor)
    for i, seer in enumerate(seers):
        assert f"fill: {colours[str(seer)]}" in ET.tostring(group(svg, f"detection-{i}"), encoding="unicode")


def test_one_label_per_scout_says_how_many_and_when(corridor: World, report: DryRun, svg: ET.Element) -> None:
    words = texts(svg)
    seers = seers_of(corridor, report)
    for seer in sorted({str(s) for s in seers}):
        times = [d["at"] for d, s in zip(report.detections, seers, strict=True) if s == seer]
        n = len(times)
        when = f"{min(times):.0f} s" if round(min(times)) == round(max(times)) else \
            f"{min(times):.0f}–{max(times):.0f} s"  # one time is said once
        assert f"{seer}: {n} sighting{'s' if n > 1 else ''}, {when}" in words, words
    assert not [w for w in words if re.fullmatch(r"\d+ s", w) and w not in {f"{k * 20} s" for k in range(10)}]


def test_each_placed_scout_shows_its_view_and_heading(report: DryRun, svg: ET.Element) -> None:
    ids = {e.get("id") for e in svg.iter() if e.get("id")}
    for scout in {s["scout"] for s in report.scouts}:
        assert {f"scout-{scout}-view", f"scout-{scout}-heading"} <= ids
    assert "Scout's camera view, heading" in texts(svg)


def test_time_marks_along_the_paths(report: DryRun, svg: ET.Element) -> None:
    assert time_step(report.sim_time) == 20 and time_step(45) == 5 and time_step(3600) == 600
    ids = {e.get("id") for e in svg.iter() if e.get("id")}
    ranger = sorted(int(i.rsplit("-", 1)[1]) for i in ids if re.fullmatch(r"time-ranger1-\d+", str(i)))
    assert ranger[:4] == [20, 40, 60, 80]  # the Ranger drove on: a mark every 20 s until it stopped
    words = texts(svg)
    assert all(f"{t} s" in words for t in ranger)


def test_no_view_without_the_cameras(corridor: World, report: DryRun, tmp_path: Path) -> None:
    render(corridor, report, tmp_path / "plain.svg")
    root = ET.parse(tmp_path / "plain.svg").getroot()
    assert not [e for e in root.iter() if str(e.get("id", "")).endswith("-view")]
