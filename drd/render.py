"""A dry-run as a picture: the world, who went where, where the Scouts ended up and what they saw.

`render(world, report, path)` draws one `DryRun` over its `World`, to scale, and writes a PNG, SVG or
PDF chosen by the file's suffix. The world comes from the same frozen records the simulator runs
(`drd.sim.model`), and the light map is sampled through `World.light`, so the picture cannot disagree
with the simulation about where it is dark. Trajectories are the report's ground-truth tracks; doors
found and detections are the behaviors' own estimates, drawn where the robots believed them to be.

matplotlib is imported inside `render` (Agg, through a bare `Figure`, never pyplot), so importing drd
stays fast and no global figure state is touched. The same input gives the same bytes: SVG ids are
salted with a constant and no file carries a date. Every artist a test may look for has a `gid`
(`door-open-door_n1`, `scout-scout1-placed`, ...), which the SVG writes as its element id.
"""

from __future__ import annotations

import bisect
import math
import os
import stat
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol

from drd.sim.model import RANGER_RADIUS, DoorState, Room, World

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from matplotlib.text import Annotation, Text
    from matplotlib.transforms import Bbox

__all__ = ["SUPPORTED_SUFFIXES", "RunReport", "figure", "render"]

#: The formats `render` writes, by file suffix.
SUPPORTED_SUFFIXES = (".png", ".svg", ".pdf")
#: No dates (nor versions) in any file, so the same run renders to the same bytes.
_METADATA: dict[str, dict[str, Any]] = {
    "png": {"Software": None}, "svg": {"Date": None, "Creator": None},
    "pdf": {"CreationDate": None, "ModDate": None, "Creator": None, "Producer": None},
}

#: Faster than this (m/s) between two trail points, a Scout is in the air: it rolls at 0.3 m/s at most,
#: and a launch or a jump moves it at several m/s. The trail does not record the phase, so speed tells it.
AIRBORNE_SPEED = 1.0

_Track = Sequence[tuple[float, float, float]]

# One palette for the whole picture: each kind of thing has its own hue, and red/green mean doors only.
WALL = "#1d2330"
OPEN_DOOR = "#2e9e44"
CLOSED_DOOR = "#d32f2f"
BLOCKED_DOOR = "#8e3b00"
OBSTACLE = "#8d6e63"
ROOM_FILL = "#dfe7f2"
RANGERS = ("#1f4e9c", "#4aa3df", "#3f2f9e", "#2a7f9e")  # shades of blue: Rangers are one kind of thing
INTRUDER = "#c2185b"
DETECTION = "#ffc107"
DOOR_FOUND = "#00a0b0"
#: One colour per Scout, none of them a hue used above (blue Ranger, red/green doors, magenta people...).
SCOUTS = ("#f28e2b", "#7b4fc4", "#1a9e77", "#a0522d", "#9aa51c", "#79706e", "#e15f99", "#4e79a7")
SUCCESS, FAILURE = "#2e7d32", "#c62828"
#: The light map's colours: dark corners a deep slate, rooms (0.6-0.7) a light grey, lit corridors white.
LIGHT_COLOURS = ((0.0, "#262a40"), (0.3, "#6e7490"), (0.6, "#d3d6e0"), (1.0, "#ffffff"))

Z_LIGHT, Z_ROOM, Z_OBSTACLE, Z_INTRUDER, Z_RANGER, Z_SCOUT, Z_WALL, Z_DOOR, Z_MARK, Z_LABEL = range(10)


class RunReport(Protocol):
    """What the picture reads of a `drd.dryrun.DryRun`, which satisfies this as it is.

    A protocol rather than the class, so this module depends on the world model only: type-checking it
    does not pull in the executive and the runtime.
    """

    @property
    def mission(self) -> str: ...
    @property
    def outcome(self) -> str | None: ...
    @property
    def reason(self) -> str: ...
    @property
    def sim_time(self) -> float: ...
    @property
    def doors(self) -> list[dict[str, Any]]: ...
    @property
    def scouts(self) -> list[dict[str, Any]]: ...
    @property
    def detections(self) -> list[dict[str, Any]]: ...
    @property
    def tracks(self) -> dict[str, list[tuple[float, float, float]]]: ...
    @property
    def injections(self) -> list[dict[str, Any]]: ...
    def holds(self) -> list[dict[str, Any]]: ...


#: How far a Scout's view is drawn (m): its camera sees farther (10 m), but a wedge that long would cover the room.
VIEW_REACH = 2.5


def render(world: World, report: RunReport, path: Path, *, title: str | None = None,
           views: Mapping[str, tuple[float, float]] | None = None, types: Mapping[str, str] | None = None) -> None:
    """Draw `report` (a `DryRun`) over `world` and write it to `path` (PNG, SVG or PDF, by suffix). `views`: where
    each Scout looked at the end (robot -> heading, its camera's field of view, radians), drawn as a wedge. `types`:
    each robot's type (robot id -> type, as the hosts file says), which the legend names its robots by.

    Raises:
        ValueError: the suffix is not one of `SUPPORTED_SUFFIXES` (checked before anything is drawn).
        OSError: the file cannot be written.
    """
    path = Path(path)
    fmt = _format(path)
    import matplotlib

    with matplotlib.rc_context(_STYLE):
        fig = figure(world, report, title=title, views=views, types=types)
        _write_whole(fig, path, format=fmt, dpi=150, metadata=_METADATA[fmt])


def _write_whole(fig: Any, path: Path, **options: Any) -> None:
    """Draw `fig` beside `path`, then put it in its place: a picture cut short (a Ctrl-C, a full disk) is never
    left at `path`, and one already there stays whole (cli audit 24, #1). A link stays a link (the file it names is
    replaced); the file keeps its mode; one with hard links, a device or a pipe, or one whose folder takes no file
    beside it (a name too long, a folder not writable) is written in place, as before."""
    real = Path(os.path.realpath(path))
    try:
        old: os.stat_result | None = real.stat()
    except FileNotFoundError:
        old = None
    if old is not None and (old.st_nlink > 1 or not stat.S_ISREG(old.st_mode)):  # its other names would keep the
        fig.savefig(path, **options)  # old picture; a device or a pipe (/dev/full in the disk-full tests) is
        return  # written as it is: replacing it would replace the device node
    part = real.with_name(f".{real.name}.{os.getpid()}.part")
    try:
        try:
            fig.savefig(part, **options)
        except OSError:
            if part.exists():  # it failed while writing (a full disk): so would the file itself
                raise
            fig.savefig(path, **options)  # no file could be made beside it: in place
            return
        if old is not None:
            os.chmod(part, stat.S_IMODE(old.st_mode))
        os.replace(part, real)
    finally:
        part.unlink(missing_ok=True)


#: Text stays text in SVG (searchable, selectable, small); ids are salted with a constant, not at random.
_STYLE: dict[Any, Any] = {"svg.fonttype": "none", "svg.hashsalt": "drd-render", "font.family": "DejaVu Sans",
                          "font.size": 9}


def figure(world: World, report: RunReport, *, title: str | None = None,
           views: Mapping[str, tuple[float, float]] | None = None, types: Mapping[str, str] | None = None) -> Figure:
    """The picture `render` writes, laid out and with its labels placed (or left out), as a matplotlib `Figure`:
    for a caller that measures it (where the legend and title lie, which labels were kept) rather than saves it."""
    import matplotlib

    with matplotlib.rc_context(_STYLE):
        fig = _figure(world)
        ax = fig.add_subplot()
        labels = _Labels()
        doors = door_states(world, report)
        _draw_world(ax, world, doors, labels)
        _note_injected_doors(ax, world, report, labels)
        _draw_tracks(ax, world, report, labels)
        _draw_time_marks(ax, world, report, labels)
        _draw_views(ax, world, report, views or {})
        _draw_findings(ax, world, report, labels)
        _frame(fig, ax, world)
        _legend(fig, world, report, doors, bool(views), _kinds(world, types or {}))
        sub = _title(ax, world, report, title)
        _place_labels(fig, ax, labels, sub)
    return fig


def _format(path: Path) -> str:
    """The output format named by the suffix; fail early, with the choices, on anything else."""
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise ValueError(f"cannot render to {path.name!r}: unsupported suffix {suffix or '(none)'!r}; "
                         f"use one of {', '.join(SUPPORTED_SUFFIXES)}")
    return suffix[1:]



# ----------------------------------------------------------------------------------------- the frame


def _figure(world: World) -> Figure:
    """A figure shaped like the world, so equal aspect leaves no wide empty bands. The plot fits 12 in wide and
    `MAX_PLOT_HEIGHT` tall (a building of many wings stacked north to south gets a tall page, not a thin strip in a
    landscape one), and the figure is at least `MIN_WIDTH` wide so the legend and title fit inside it."""
    from matplotlib.figure import Figure

    x0, y0, x1, y1 = _extent(world)
    w, h = x1 - x0, y1 - y0
    scale = 12.0 / max(w, h * 12.0 / MAX_PLOT_HEIGHT, 1e-9)
    return Figure(figsize=(max(MIN_WIDTH, w * scale + 1.6), h * scale + 2.0), layout="constrained")


#: The tallest plot (in): 9 in kept every world of a few wings as it was; taller worlds get up to this.
MAX_PLOT_HEIGHT = 18.0
#: The narrowest figure (in): the title's first line and a legend of two rows fit in it.
MIN_WIDTH = 9.0
#: Legend columns per inch of figure width: a column of the legend needs about 2.4 in.
_LEGEND_COLUMN = 2.4


def _extent(world: World) -> tuple[float, float, float, float]:
    """The world's bounds with a margin, so walls on the edge are not cut in half."""
    x0, y0, x1, y1 = world.bounds
    m = max(0.6, 0.02 * max(x1 - x0, y1 - y0))
    return (x0 - m, y0 - m, x1 + m, y1 + m)


def _frame(fig: Figure, ax: Axes, world: World) -> None:
    """Metres on both axes at the same scale, quiet grey axes, and a slim light-level bar as tall as the plot."""
    x0, y0, x1, y1 = _extent(world)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)", color="#555555")
    ax.set_ylabel("y (m)", color="#555555")
    ax.tick_params(colors="#555555", labelsize=8)
    for spine in ax.spines.values():
        spine.set_color("#bbbbbb")
    if ax.images:
        bar = fig.colorbar(ax.images[0], cax=ax.inset_axes((1.01, 0.0, 0.012, 1.0)))
        bar.set_label("light (0 dark, 1 bright)", color="#555555")
        bar.ax.tick_params(labelsize=8, colors="#555555")
        bar.outline.set_visible(False)


def _title(ax: Axes, world: World, report: RunReport, title: str | None) -> Text:
    """One line naming the mission and its outcome (green or red), one with the time and the counts (returned: the
    labels left out at the figure's scale are said under it)."""
    counts = [f"{_n(len(rows), noun)}{what}" for rows, noun, what in (
        (report.doors, "door", " found"), (report.scouts, "robot", " launched"), (report.detections, "detection", ""))
        if rows]  # the standard components' events: a mission of other components has none to count
    stats = "  ·  ".join([f"sim time {report.sim_time:.1f} s", *counts])
    sub = ax.set_title(stats, loc="left", fontsize=10, color="#444444", pad=8)
    head = ax.annotate(f"{title or report.mission} in {world.name}", xy=(0, 1), xycoords=sub,
                       xytext=(0, 4), textcoords="offset points", va="bottom", fontsize=14, fontweight="bold",
                       color=WALL)
    outcome = report.outcome or "unfinished"
    mark = ax.annotate(f"  {outcome}", xy=(1, 0), xycoords=head, va="bottom", fontsize=14, fontweight="bold",
                       color=SUCCESS if outcome == "success" else FAILURE, gid="outcome")
    if report.reason:
        ax.annotate(f"  {report.reason}", xy=(1, 0), xycoords=mark, va="bottom", fontsize=10, color="#666666",
                    gid="reason")
    return sub


def _n(count: int, noun: str) -> str:
    return f"{count} {noun}{'' if count == 1 else 's'}"


# ----------------------------------------------------------------------------------------- the building


#: The door state each door injection leaves behind (`open` leaves a blocked door blocked).
_INJECTED_STATE = {"block": DoorState.BLOCKED, "close": DoorState.CLOSED, "open": DoorState.OPEN}


def door_states(world: World, report: RunReport) -> dict[str, DoorState]:
    """Each door as the run left it: the world's state, changed by `--inject` block/close/open in time order."""
    states = {d.id: d.state for d in world.doors}
    for _, target, new in _door_changes(world, report):
        states[target] = new
    return states


def _door_changes(world: World, report: RunReport) -> list[tuple[float, str, DoorState]]:
    """(time, door, new state) of every injection that changed a door (opening a blocked door does not)."""
    states = {d.id: d.state for d in world.doors}
    out = []
    for inj in report.injections:
        new, target = _INJECTED_STATE.get(str(inj.get("action"))), str(inj.get("target"))
        if new is not None and target in states and states[target] is not DoorState.BLOCKED and states[target] != new:
            states[target] = new
            out.append((float(inj["at"]), target, new))
    return out


def _note_injected_doors(ax: Axes, world: World, report: RunReport, labels: _Labels) -> None:
    """A label at each door an injection changed: what and when (`blocked at 60 s`)."""
    centres = {d.id: d.center for d in world.doors}
    for i, (at, target, new) in enumerate(_door_changes(world, report)):
        x, y = centres[target]
        verb = {DoorState.BLOCKED: "blocked", DoorState.CLOSED: "closed", DoorState.OPEN: "opened"}[new]
        labels.add(ax, x, y, f"{verb} at {at:.0f} s", CLOSED_DOOR, gid=f"injection-{i}")


def _draw_world(ax: Axes, world: World, doors: dict[str, DoorState], labels: _Labels) -> None:
    """The building, back to front: light, rooms, obstacles, walls, then doors on top of their gaps."""
    from matplotlib.patches import Rectangle

    _draw_light(ax, world)
    by_room: dict[str, list[tuple[float, float]]] = {}
    for door in world.doors:  # once, not every door for every room (quadratic at fleet size)
        if door.room is not None:
            by_room.setdefault(door.room, []).append(door.center)
    for room in world.rooms:
        _draw_room(ax, world, room, by_room.get(room.id, []), labels)
    for i, o in enumerate(world.obstacles):
        ax.add_patch(Rectangle((o.x0, o.y0), o.x1 - o.x0, o.y1 - o.y0, facecolor=OBSTACLE, edgecolor="#4e342e",
                               hatch="////", linewidth=0.8, alpha=0.85, zorder=Z_OBSTACLE, gid=f"obstacle-{i}"))
    for i, wall in enumerate(world.walls):
        ax.plot([wall.a[0], wall.b[0]], [wall.a[1], wall.b[1]], color=WALL, linewidth=3.2,
                solid_capstyle="projecting", zorder=Z_WALL, gid=f"wall-{i}")
    for door in world.doors:
        _draw_door(ax, door.id, door.a, door.b, doors[door.id])


def _draw_light(ax: Axes, world: World) -> None:
    """The light map as a shaded background, sampled from `World.light` on a grid of at most 240 cells a side
    (smoothed when drawn: the light has no sharp edges but room walls, which are drawn over it)."""
    import numpy as np
    from matplotlib.colors import LinearSegmentedColormap

    x0, y0, x1, y1 = _extent(world)
    step = max(x1 - x0, y1 - y0) / 240
    nx, ny = max(2, round((x1 - x0) / step)), max(2, round((y1 - y0) / step))
    xs = [x0 + (i + 0.5) * (x1 - x0) / nx for i in range(nx)]
    ys = [y0 + (j + 0.5) * (y1 - y0) / ny for j in range(ny)]
    grid = np.array([[world.light(x, y) for x in xs] for y in ys])
    cmap = LinearSegmentedColormap.from_list("drd-light", list(LIGHT_COLOURS))
    ax.imshow(grid, origin="lower", extent=(x0, x1, y0, y1), cmap=cmap, vmin=0.0, vmax=1.0,
              interpolation="bilinear", zorder=Z_LIGHT, gid="light")


def _draw_room(ax: Axes, world: World, room: Room, doors: list[tuple[float, float]], labels: _Labels) -> None:
    """A light tint over the room and its id in its brightest corner, away from dark corners and its `doors`."""
    from matplotlib.patches import Rectangle

    ax.add_patch(Rectangle((room.x0, room.y0), room.x1 - room.x0, room.y1 - room.y0, facecolor=ROOM_FILL,
                           edgecolor="none", alpha=0.35, zorder=Z_ROOM, gid=f"room-{room.id}"))
    x, y, ha, va = _label_corner(world, room, doors)
    name = ax.text(x, y, room.id, ha=ha, va=va, fontsize=11, fontweight="bold", color="#3a4256", zorder=Z_LABEL,
                   gid=f"room-label-{room.id}")
    labels.rooms.append((name, room))


def _label_corner(world: World, room: Room, doors: Sequence[tuple[float, float]]) -> tuple[float, float, str, str]:
    """The inner corner to write a room's name in: the brightest, then the farthest from the room's `doors` (their
    centres, which the caller indexes by room once)."""
    inset = min(0.3, (room.x1 - room.x0) / 4, (room.y1 - room.y0) / 4)
    corners = [(room.x0 + inset, room.y1 - inset, "left", "top"), (room.x1 - inset, room.y1 - inset, "right", "top"),
               (room.x0 + inset, room.y0 + inset, "left", "bottom"),
               (room.x1 - inset, room.y0 + inset, "right", "bottom")]

    def score(c: tuple[float, float, str, str]) -> tuple[float, float]:
        near = min((math.dist((c[0], c[1]), d) for d in doors), default=0.0)
        return (round(world.light(c[0], c[1]), 2), near)

    return max(corners, key=score)  # max keeps the first of equals: deterministic


def _draw_door(ax: Axes, door_id: str, a: tuple[float, float], b: tuple[float, float], state: DoorState) -> None:
    """An open door is its wall's gap with a thin green bar; a closed door a thick red bar, a blocked one brown."""
    xs, ys = [a[0], b[0]], [a[1], b[1]]
    if state is DoorState.OPEN:
        ax.plot(xs, ys, color=OPEN_DOOR, linewidth=2.0, linestyle=(0, (2, 1.2)), solid_capstyle="butt",
                zorder=Z_DOOR, gid=f"door-open-{door_id}")
        ax.plot(xs, ys, linestyle="none", marker="|", markersize=9, markeredgewidth=2.2, color=OPEN_DOOR,
                zorder=Z_DOOR, gid=f"door-open-jambs-{door_id}")
    else:
        colour = CLOSED_DOOR if state is DoorState.CLOSED else BLOCKED_DOOR
        ax.plot(xs, ys, color=colour, linewidth=5.0, solid_capstyle="butt", zorder=Z_DOOR,
                gid=f"door-{state.value}-{door_id}")


# ----------------------------------------------------------------------------------------- who went where


def _draw_tracks(ax: Axes, world: World, report: RunReport, labels: _Labels) -> None:
    """Intruders first (dotted, under everything), then each Ranger, then each Scout, each in its own colour."""
    for intruder in world.intruders:
        seen = report.tracks.get(intruder.id)
        track = seen or [(w.t, w.x, w.y) for w in intruder.path]  # no track: the path the world file plans
        end = seen[-1] if seen else (report.sim_time, *intruder.position(report.sim_time))
        lap = [p for p in track if p[0] <= intruder.path[-1].t] if intruder.loop else track
        _draw_intruder(ax, intruder.id, lap or track, end, labels)
    for i, ranger in enumerate(world.rangers):
        track = report.tracks.get(ranger.id) or [(0.0, ranger.x, ranger.y)]
        _draw_ranger(ax, ranger.id, track, RANGERS[i % len(RANGERS)], labels)
    on_floor = {s.id: [(0.0, s.x, s.y)] for s in world.scouts}
    for i, scout_id in enumerate(world.scout_ids):
        trail = report.tracks.get(scout_id) or on_floor.get(scout_id)  # neither: still in its magazine
        if trail:
            _draw_scout(ax, scout_id, trail, SCOUTS[i % len(SCOUTS)], labels)


def _draw_intruder(ax: Axes, intruder_id: str, path: _Track, end: tuple[float, float, float],
                   labels: _Labels) -> None:
    """A dotted path (one lap of a looping one), and the person where the run left them, labelled with their id."""
    ax.plot([p[1] for p in path], [p[2] for p in path], color=INTRUDER, linewidth=1.4, linestyle=(0, (1, 2)),
            alpha=0.8, zorder=Z_INTRUDER, gid=f"intruder-{intruder_id}")
    ax.plot([end[1]], [end[2]], marker="o", markersize=7, markerfacecolor="white", markeredgecolor=INTRUDER,
            markeredgewidth=1.8, linestyle="none", zorder=Z_MARK, gid=f"intruder-{intruder_id}-end")
    labels.add(ax, end[1], end[2], intruder_id, INTRUDER, gid=f"intruder-label-{intruder_id}")


def _draw_ranger(ax: Axes, ranger_id: str, track: _Track, colour: str, labels: _Labels) -> None:
    """A solid line from a hollow start marker to the Ranger's body (to scale) with an arrow for its heading."""
    from matplotlib.patches import Circle

    xs, ys = [p[1] for p in track], [p[2] for p in track]
    ax.plot(xs, ys, color=colour, linewidth=1.8, alpha=0.9, solid_joinstyle="round", zorder=Z_RANGER,
            gid=f"ranger-{ranger_id}")
    ax.plot(xs[:1], ys[:1], marker="o", markersize=8, markerfacecolor="white", markeredgecolor=colour,
            markeredgewidth=2, linestyle="none", zorder=Z_MARK, gid=f"ranger-{ranger_id}-start")
    ax.add_patch(Circle((xs[-1], ys[-1]), RANGER_RADIUS, facecolor=colour, edgecolor="white", linewidth=1.2,
                        zorder=Z_MARK, gid=f"ranger-{ranger_id}-end"))
    heading = _final_heading(track)
    if heading is not None:
        dx, dy = math.cos(heading), math.sin(heading)
        ax.annotate("", xy=(xs[-1] + 0.8 * dx, ys[-1] + 0.8 * dy), xytext=(xs[-1], ys[-1]),
                    arrowprops={"arrowstyle": "-|>", "color": colour, "linewidth": 1.8, "mutation_scale": 14,
                                "shrinkA": 0, "shrinkB": 0}, zorder=Z_MARK, gid=f"ranger-{ranger_id}-heading")
    labels.add(ax, xs[-1], ys[-1], ranger_id, colour, gid=f"ranger-label-{ranger_id}")


def _final_heading(track: _Track, back: float = 0.25) -> float | None:
    """The direction of the last `back` metres of a track (None for a robot that never moved)."""
    x, y = track[-1][1], track[-1][2]
    for _, px, py in reversed(track):
        if math.hypot(x - px, y - py) >= back:
            return math.atan2(y - py, x - px)
    return None


def _draw_scout(ax: Axes, scout_id: str, track: _Track, colour: str, labels: _Labels) -> None:
    """Flights dashed, rolling solid, and a filled hexagon where the Scout ended up, labelled with its id."""
    for k, (airborne, part) in enumerate(_phases(track)):
        ax.plot([p[1] for p in part], [p[2] for p in part], color=colour, linewidth=1.6 if airborne else 2.0,
                linestyle=(0, (4, 2.5)) if airborne else "solid", zorder=Z_SCOUT,
                gid=f"scout-{scout_id}-{'flight' if airborne else 'roll'}-{k}")
    x, y = track[-1][1], track[-1][2]
    ax.plot([x], [y], marker="h", markersize=11, markerfacecolor=colour, markeredgecolor="white",
            markeredgewidth=1.5, linestyle="none", zorder=Z_MARK, gid=f"scout-{scout_id}-placed")
    labels.add(ax, x, y, scout_id, colour, gid=f"scout-label-{scout_id}")


def _phases(track: _Track) -> Iterator[tuple[bool, list[tuple[float, float, float]]]]:
    """Split a trail into runs of airborne and rolling segments (by speed), each run sharing its end points."""
    run: list[tuple[float, float, float]] = list(track[:1])
    airborne: bool | None = None
    for p, q in pairwise(track):
        dist, dt = math.hypot(q[1] - p[1], q[2] - p[2]), q[0] - p[0]
        up = dist > 0 and (dt <= 0 or dist / dt > AIRBORNE_SPEED)
        if airborne is not None and up != airborne:
            yield airborne, run
            run = [p]
        airborne = up
        run.append(q)
    if airborne is not None:
        yield airborne, run


# ----------------------------------------------------------------------------------------- what they found


def _draw_findings(ax: Axes, world: World, report: RunReport, labels: _Labels) -> None:
    """Doors DetectDoor reported and MotionDetected events, where the robots estimated them: each sighting in the
    colour of the Scout that saw it, and one label per Scout saying how many and when (not one per sighting)."""
    for i, door in enumerate(report.doors):
        ax.plot([door["x"]], [door["y"]], marker="D", markersize=10, markerfacecolor="none",
                markeredgecolor=DOOR_FOUND, markeredgewidth=2.0, linestyle="none", zorder=Z_DOOR,
                gid=f"door-found-{i}")
        labels.markers.append((float(door["x"]), float(door["y"])))
    colours = scout_colours(world)
    seers = seers_of(world, report)
    groups: dict[str | None, list[tuple[float, float, float]]] = {}
    for i, (d, seer) in enumerate(zip(report.detections, seers, strict=True)):
        x, y = float(d["x"]), float(d["y"])
        ax.plot([x], [y], marker="*", markersize=14, markerfacecolor=colours.get(seer or "", DETECTION),
                markeredgecolor="#5d4037", markeredgewidth=0.9, linestyle="none", zorder=Z_MARK + 1,
                gid=f"detection-{i}")
        labels.markers.append((x, y))
        groups.setdefault(seer, []).append((float(d["at"]), x, y))
    for seer, seen in groups.items():
        times = [t for t, _, _ in seen]
        when = f"{min(times):.0f} s" if round(min(times)) == round(max(times)) else \
            f"{min(times):.0f}–{max(times):.0f} s"
        text = f"{seer + ': ' if seer else ''}{_n(len(seen), 'sighting')}, {when}"
        x, y = min(((x, y) for _, x, y in seen), key=lambda p: (p[0], p[1]))  # the leftmost: deterministic
        labels.add(ax, x, y, text, colours.get(seer or "", "#5d4037"), gid=f"detections-{seer or 'unknown'}")


def scout_colours(world: World) -> dict[str, str]:
    """Each Scout's colour, in the world's order (the same in every picture of that world)."""
    return {sid: SCOUTS[i % len(SCOUTS)] for i, sid in enumerate(world.scout_ids)}


def seers_of(world: World, report: RunReport) -> list[str | None]:
    """The Scout that saw each detection (None when it cannot be told): the Scout held, when it was seen, by the
    behavior that reported it or by one of its parents (`holds`); else the one launched by its parent's
    LaunchScout (the corridor mission's RoomSurveillance)."""
    scouts = set(world.scout_ids)
    holds = [(h["path"], float(h["from"]), float(h["to"]), [v for v in h["resources"].values() if v in scouts])
             for h in report.holds()]
    launched = {str(s.get("by", "")).rpartition("/")[0]: str(s.get("scout")) for s in report.scouts}
    out: list[str | None] = []
    for d in report.detections:
        by, at = str(d.get("by", "")), float(d["at"])
        held = [s for path, t0, t1, units in holds if (by == path or by.startswith(path + "/")) and t0 <= at <= t1
                for s in units]
        parent = by.rpartition("/")[0]
        out.append(held[0] if len(set(held)) == 1 else launched.get(parent) if parent else None)
    return out


def _draw_views(ax: Axes, world: World, report: RunReport, views: Mapping[str, tuple[float, float]]) -> None:
    """Each placed Scout's camera: its field of view as a wedge and its heading as an arrow, where it ended."""
    from matplotlib.patches import FancyArrowPatch, Wedge

    colours = scout_colours(world)
    for scout in sorted({str(s["scout"]) for s in report.scouts if s.get("scout") in views}):
        heading, fov = views[scout]
        track = report.tracks.get(scout)
        end = next((s for s in report.scouts if s.get("scout") == scout), {})
        x, y = (track[-1][1], track[-1][2]) if track else (float(end.get("x", 0.0)), float(end.get("y", 0.0)))
        colour = colours.get(scout, SCOUTS[0])
        a0, a1 = math.degrees(heading - fov / 2), math.degrees(heading + fov / 2)
        ax.add_patch(Wedge((x, y), VIEW_REACH, a0, a1, facecolor=colour, edgecolor=colour, alpha=0.18,
                           linewidth=1.0, zorder=Z_SCOUT, gid=f"scout-{scout}-view"))
        ax.add_patch(FancyArrowPatch((x, y), (x + math.cos(heading), y + math.sin(heading)), arrowstyle="-|>",
                                     color=colour, linewidth=1.6, mutation_scale=12, shrinkA=0, shrinkB=0,
                                     zorder=Z_MARK, gid=f"scout-{scout}-heading"))


def time_step(sim_time: float) -> float:
    """The time between two marks along the paths: a round step giving at most ten marks."""
    return next((s for s in (5.0, 10.0, 20.0, 30.0, 60.0, 120.0, 300.0, 600.0) if sim_time / s <= 10), 1800.0)


def _draw_time_marks(ax: Axes, world: World, report: RunReport, labels: _Labels) -> None:
    """A dot every `time_step` seconds along each robot's path, with the time, where it had moved since the last
    one (a robot standing still gets no pile of marks)."""
    step = time_step(report.sim_time)
    colours = {**{r.id: RANGERS[i % len(RANGERS)] for i, r in enumerate(world.rangers)}, **scout_colours(world)}
    for rid, colour in colours.items():
        track = report.tracks.get(rid) or []
        last: tuple[float, float] | None = None
        k = math.ceil(track[0][0] / step) if track else 0
        while track and k * step <= track[-1][0]:
            at = k * step
            x, y = _where(track, at)
            k += 1
            if at == 0 or (last is not None and math.hypot(x - last[0], y - last[1]) < 0.5):
                continue
            last = (x, y)
            ax.plot([x], [y], marker="o", markersize=3.5, markerfacecolor="white", markeredgecolor=colour,
                    markeredgewidth=1.2, linestyle="none", zorder=Z_MARK, gid=f"time-{rid}-{at:g}")
            labels.times.append(ax.annotate(
                f"{at:g} s", xy=(x, y), xytext=(0, -7), textcoords="offset points", ha="center", va="top",
                fontsize=6.5, color=colour, zorder=Z_LABEL, gid=f"time-label-{rid}-{at:g}"))


def _where(track: _Track, at: float) -> tuple[float, float]:
    """Where a track was at `at` (between its points, in a straight line)."""
    times = [p[0] for p in track]
    i = bisect.bisect_right(times, at)
    if i == 0:
        return track[0][1], track[0][2]
    if i == len(track):
        return track[-1][1], track[-1][2]
    (t0, x0, y0), (t1, x1, y1) = track[i - 1], track[i]
    k = 0.0 if t1 <= t0 else (at - t0) / (t1 - t0)
    return x0 + (x1 - x0) * k, y0 + (y1 - y0) * k


_Spot = tuple[float, float, Literal["left", "center", "right"], Literal["bottom", "center", "top"]]
#: Where a label may sit beside its marker, in order of preference: (dx, dy) points, alignment.
_SPOTS: tuple[_Spot, ...] = (
    (8, 5, "left", "bottom"), (8, -5, "left", "top"), (-8, 5, "right", "bottom"), (-8, -5, "right", "top"),
    (0, 10, "center", "bottom"), (0, -10, "center", "top"), (12, 0, "left", "center"), (-12, 0, "right", "center"),
    (16, 14, "left", "bottom"), (-16, -14, "right", "top"))
#: Half the size, in points, of the square a marker is taken to cover when placing labels.
_MARKER_HALF = 6.0


@dataclass
class _Labels:
    """The labels beside markers, placed once the layout is known so they avoid each other and the markers; and the
    labels at fixed places (room names, time marks), kept only where they can be read."""

    movable: list[Annotation] = field(default_factory=list)
    markers: list[tuple[float, float]] = field(default_factory=list)
    #: Time marks' labels, in drawing order: each is kept only where it covers no label already kept.
    times: list[Annotation] = field(default_factory=list)
    #: Room names and the room each names: kept only where the name fits in its room at the figure's scale.
    rooms: list[tuple[Text, Room]] = field(default_factory=list)

    def add(self, ax: Axes, x: float, y: float, text: str, colour: str, *, gid: str) -> None:
        """A small label beside the marker at (x, y), on a translucent white box so it reads over any background."""
        self.movable.append(ax.annotate(
            text, xy=(x, y), xytext=_SPOTS[0][:2], textcoords="offset points", fontsize=8.5, fontweight="bold",
            color=colour, ha=_SPOTS[0][2], va=_SPOTS[0][3], zorder=Z_LABEL, gid=gid,
            bbox={"boxstyle": "round,pad=0.15", "facecolor": "white", "edgecolor": "none", "alpha": 0.75}))
        self.markers.append((x, y))


#: A label is left out when the best spot for it still has this share of its area under other labels: at fleet size
#: hundreds of ids on top of each other read as none, and a label half hidden tells nothing either.
_HIDDEN = 0.15
#: What each kind of label is called in the note saying how many were left out, by the start of its gid.
_KINDS = (("scout-label-", "Scout ids"), ("ranger-label-", "Ranger ids"), ("intruder-label-", "intruder ids"),
          ("detections-", "sighting notes"), ("injection-", "door notes"), ("room-label-", "room names"),
          ("time-label-", "time marks"))


def _place_labels(fig: Figure, ax: Axes, labels: _Labels, sub: Text) -> None:
    """Place the labels on the laid-out figure, leave out those that cannot be read at its scale, and say so under
    the title. Saying so adds a line above the plot, which shrinks it a little: the labels are then placed again on
    the final layout (the note's height does not depend on the count), so what was judged readable still is."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)  # measures text as the PNG will; the SVG and PDF writers use the same font metrics
    stats = sub.get_text()
    left_out = _place_once(fig, ax, labels)
    if left_out:
        sub.set_text(f"{stats}\n{_left_out_note(left_out)}")
        left_out = _place_once(fig, ax, labels)
        sub.set_text(f"{stats}\n{_left_out_note(left_out)}")
    for text in left_out:
        text.remove()


def _left_out_note(left_out: list[Text]) -> str:
    """`not drawn at this scale: 130 Scout ids, 40 time marks` (each kind once, in a fixed order)."""
    counts = [(sum(1 for t in left_out if str(t.get_gid()).startswith(prefix)), noun) for prefix, noun in _KINDS]
    return "not drawn at this scale: " + ", ".join(f"{n} {noun}" for n, noun in counts if n)


def _place_once(fig: Figure, ax: Axes, labels: _Labels) -> list[Text]:
    """Greedy, in drawing order: room names that fit their room; each movable label at the first spot where it covers
    no other label, room name or marker (else the least bad, or left out if that is mostly hidden); then each time
    mark's label where it covers no label kept. Returns the labels left out (hidden, for now).

    The boxes kept are bucketed in a grid of display pixels, so each test looks at its neighbours only: linear in the
    labels, where testing every box against every other was quadratic (10 s of the 14 s a 10-wing building took)."""
    every: list[Text] = [*(t for t, _ in labels.rooms), *labels.movable, *labels.times]
    for text in every:
        text.set_visible(True)
    fig.draw_without_rendering()  # runs the layout, so data-to-pixel transforms are final
    half = _MARKER_HALF * fig.dpi / 72
    words, marks, left_out = _Grid(), _Grid(), []
    for text, room in labels.rooms:
        box = _box(text.get_window_extent())
        (x0, y0), (x1, y1) = ax.transData.transform([(room.x0, room.y0), (room.x1, room.y1)])
        if box[0] < x0 - 1 or box[1] < y0 - 1 or box[2] > x1 + 1 or box[3] > y1 + 1:
            left_out.append(text)
        else:
            words.add(box)
    times = [_box(t.get_window_extent()) for t in labels.times]
    for box in times:
        words.add(box)  # avoided by the labels placed next, as before time labels could be left out
    for x, y in labels.markers:
        px, py = ax.transData.transform((x, y))
        marks.add((px - half, py - half, px + half, py + half))
    frame = _box(ax.get_window_extent())
    placed: list[_Box] = []
    for label in labels.movable:
        spot, hidden = _best_spot(label, words, marks, frame)
        _move(label, _SPOTS[spot])
        if hidden:
            left_out.append(label)
        else:
            box = _pad(_box(label.get_window_extent()), 2)
            words.add(box)
            placed.append(box)
    kept = _Grid()
    for box in placed:
        kept.add(box)
    for text, _ in labels.rooms:
        if text not in left_out:
            kept.add(_box(text.get_window_extent()))
    for text, box in zip(labels.times, times, strict=True):
        if kept.covered(box) > 0:
            left_out.append(text)
        else:
            kept.add(box)
    for text in left_out:
        text.set_visible(False)
    return left_out


def _best_spot(label: Annotation, words: _Grid, marks: _Grid, frame: _Box) -> tuple[int, bool]:
    """The spot with the least cost (the first free one), and whether the label there is mostly under other words."""
    best: tuple[float, int, float] | None = None
    for i, spot in enumerate(_SPOTS):
        _move(label, spot)
        box = _pad(_box(label.get_window_extent()), 2)
        under = words.covered(box)
        area = (box[2] - box[0]) * (box[3] - box[1])
        cost = under + marks.covered(box) + 4 * (area - _overlap(box, frame))
        if best is None or cost < best[0]:
            best = (cost, i, under / area if area > 0 else 0.0)
        if cost == 0:
            break
    assert best is not None
    return best[1], best[2] > _HIDDEN


_Box = tuple[float, float, float, float]  # x0, y0, x1, y1 in display pixels


def _box(b: Bbox) -> _Box:
    return (float(b.x0), float(b.y0), float(b.x1), float(b.y1))


def _pad(b: _Box, p: float) -> _Box:
    return (b[0] - p, b[1] - p, b[2] + p, b[3] + p)


def _overlap(a: _Box, b: _Box) -> float:
    """The area two boxes share (0 when apart)."""
    w, h = min(a[2], b[2]) - max(a[0], b[0]), min(a[3], b[3]) - max(a[1], b[1])
    return w * h if w > 0 and h > 0 else 0.0


@dataclass
class _Grid:
    """Boxes bucketed in square cells of display pixels: `covered` looks only at boxes sharing a cell with its own."""

    cell: float = 64.0
    boxes: list[_Box] = field(default_factory=list)
    cells: dict[tuple[int, int], list[int]] = field(default_factory=dict)

    def _keys(self, b: _Box) -> Iterator[tuple[int, int]]:
        c = self.cell
        for i in range(math.floor(b[0] / c), math.floor(b[2] / c) + 1):
            for j in range(math.floor(b[1] / c), math.floor(b[3] / c) + 1):
                yield (i, j)

    def add(self, b: _Box) -> None:
        self.boxes.append(b)
        for key in self._keys(b):
            self.cells.setdefault(key, []).append(len(self.boxes) - 1)

    def covered(self, b: _Box) -> float:
        """How much of `b` the boxes added cover, summed over them (pixels²), as the former full scan summed it."""
        near = {n for key in self._keys(b) for n in self.cells.get(key, ())}
        return sum(_overlap(b, self.boxes[n]) for n in sorted(near))


def _move(label: Annotation, spot: _Spot) -> None:
    label.xyann = spot[:2]
    label.set_horizontalalignment(spot[2])
    label.set_verticalalignment(spot[3])


def _kinds(world: World, types: Mapping[str, str]) -> tuple[str, str]:
    """What the legend calls the robots with a carrier's body and those with a carried one: their types (`Rover`,
    `Drone/Probe`), or the world file's words for the bodies (Ranger, Scout) when the types are not known."""
    big = "/".join(sorted({types.get(r.id, "Ranger") for r in world.rangers})) or "Ranger"
    small = "/".join(sorted({types.get(rid, "Scout") for rid in world.scout_ids})) or "Scout"
    return big, small


def _legend(fig: Figure, world: World, report: RunReport, doors: dict[str, DoorState], views: bool,
            kinds: tuple[str, str] = ("Ranger", "Scout")) -> None:
    """One entry per kind of thing (not per robot), below the plot, listing only kinds the picture shows; the
    robots named by `kinds` (`_kinds`)."""
    big, small = kinds
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    def line(colour: str, **kw: Any) -> Line2D:
        return Line2D([], [], color=colour, **kw)

    states = set(doors.values())
    scout = SCOUTS[0]
    entries: list[tuple[Any, str, bool]] = [
        (line(WALL, linewidth=3.2), "wall", bool(world.walls)),
        (line(OPEN_DOOR, linewidth=2.0, linestyle=(0, (2, 1.2))), "open door", DoorState.OPEN in states),
        (line(CLOSED_DOOR, linewidth=5.0), "closed door", DoorState.CLOSED in states),
        (line(BLOCKED_DOOR, linewidth=5.0), "blocked door", DoorState.BLOCKED in states),
        (Patch(facecolor=OBSTACLE, edgecolor="#4e342e", hatch="////"), "obstacle", bool(world.obstacles)),
        (line(RANGERS[0], linewidth=1.8, marker="o", markevery=[0], markerfacecolor="white"), f"{big} path (start ○)",
         bool(world.rangers)),
        (line(scout, linewidth=1.6, linestyle=(0, (4, 2.5))), f"{small} flight", bool(world.scout_ids)),
        (line(scout, linewidth=2.0, marker="h", markevery=[-1], markersize=9, markeredgecolor="white"),
         f"{small} rolling, placed", bool(world.scout_ids)),
        (line(INTRUDER, linewidth=1.4, linestyle=(0, (1, 2)), marker="o", markevery=[-1], markerfacecolor="white"),
         "intruder path (end ○)", bool(world.intruders)),
        (line(DOOR_FOUND, linestyle="none", marker="D", markerfacecolor="none", markeredgewidth=2.0),
         "door found", bool(report.doors)),
        (line(scout, linestyle="none", marker="*", markersize=13, markeredgecolor="#5d4037"),
         f"sighting (the colour of the {small} that saw it)", bool(report.detections)),
        (Patch(facecolor=scout, edgecolor=scout, alpha=0.3), f"{small}'s camera view, heading", views and
         bool(report.scouts)),
        (line("#555555", linestyle="none", marker="o", markersize=4, markerfacecolor="white"), "time mark",
         bool(report.tracks)),
    ]
    shown = [(h, label) for h, label, present in entries if present]
    fits = max(1, int(fig.get_figwidth() / _LEGEND_COLUMN))  # as many columns as the figure holds, so none is cut
    legend = fig.legend([h for h, _ in shown], [label for _, label in shown], loc="outside lower center",
                        ncols=max(1, min(fits, math.ceil(len(shown) / 2))), frameon=False, fontsize=9, handlelength=2.6)
    legend.set_gid("legend")
