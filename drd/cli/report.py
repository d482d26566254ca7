"""How a run is shown as text: a dry-run's (or a cluster run's) report, its live progress line, and a plan's
preview of the start. Pure rendering of the data the run produced, so every command shows a run the same way."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.text import Text

from drd.cli.common import out, shorten, wrap_cut
from drd.explain import natural
from dsl.statechart import StateKind

if TYPE_CHECKING:
    from collections.abc import Callable

    from rich.console import Console, RenderableType
    from rich.table import Table

    from drd.dryrun import DryRun
    from drd.executive import Executive
    from drd.preview import Preview
    from drd.sim.physics import Simulation


def progress_view(sim: Simulation, executive: Executive, width: int = 100) -> Text:
    """One live line: sim time, who holds what and who waits (counts first: they are the figures at fleet size),
    then the active behaviors, each leaf name once with how many run it (`LocateDarkCorner x40`), cut to `width`."""
    active = [n.path.rsplit("/", 1)[-1] for m in executive.missions.values() for n in m.active()
              if n.state.kind is StateKind.LEAF]
    snap = executive.broker.snapshot()
    holds = [f"{_short(h)}→{'+'.join(d['assignment'].values())}" for h, d in snap["holds"].items() if d["assignment"]]
    waiting = [_short(w["holder"]) for w in snap["queue"]]
    return live_line(sim.time, active, holds, waiting, width)


def live_line(at: float, active: list[str], holds: list[str], waiting: list[str], width: int = 100) -> Text:
    """The live line from its parts: `sim T s  holds N (…)  waiting M (…)  active Name xK, …`, cut to `width`; the
    examples in parentheses only while they fit beside the counts."""
    def some(items: list[str], most: int, sep: str) -> str:
        return f" ({sep.join(items[:most])}{', …' if len(items) > most else ''})" if items else ""

    counted: dict[str, int] = {}
    for name in active:
        counted[name] = counted.get(name, 0) + 1
    names = ", ".join(f"{n} x{k}" if k > 1 else n for n, k in counted.items()) or "—"
    head = f"{at:7.1f} s  "

    def line(examples: bool) -> Text:
        return Text.assemble(("sim ", "dim"), head, ("holds ", "dim"),
                             f"{len(holds)}" + (some(holds, 4, "; ") if examples else ""), ("  waiting ", "dim"),
                             f"{len(waiting)}" + (some(waiting, 3, ", ") if examples else ""), ("  active ", "dim"),
                             names)

    shown = line(len(holds) + len(waiting) <= 6)  # a small team: who holds and who waits, while the line fits
    if len(shown.plain) > width:  # the active behaviors before the examples
        shown = line(False)
    shown.truncate(width, overflow="ellipsis")
    return shown


def _short(holder: str) -> str:
    """`CorridorSurveillance-1/CorridorSurveillance/RoomSurveillance[2]` -> `RoomSurveillance[2]`."""
    return holder.rsplit("/", 1)[-1]


def print_report(r: DryRun, several: bool = False, console: Console | None = None) -> None:
    """A dry-run's (or a cluster run's) report as text, fitted to the console's width: on a terminal long lines
    wrap there, to a file or a pipe they stay whole (for grep); tables fit the width either way."""
    console = console or out
    for part in report_view(r, several, console.width):
        console.print(part, soft_wrap=not console.is_terminal)


def report_view(r: DryRun, several: bool = False, width: int = 80) -> list[RenderableType]:
    """The report, most telling first: the outcome and why (the failure chain down to each failed leaf, or what a
    stopped run left active and waiting), then the timeline, holds, waits, the mission's log and its facts.
    Paths are relative to the mission and cut from the middle to fit `width` (80 columns stay readable)."""
    root = r.mission
    colour = "green" if r.outcome == "success" else "red"
    # several missions, or a cluster run (another terminal may run the same mission): the id tells them apart
    who = f"{r.mission_id or r.mission} (priority {r.priority})" if several else (
        r.mission_id or r.mission) if r.on_cluster else r.mission
    lost = r.degraded()
    if lost:  # a success that lost instances on the way says so in its first line
        colour = "yellow"
    head = f"  {r.reason}".rstrip() + (f"  degraded: {len(lost)} instance{'s' if len(lost) > 1 else ''} failed"
                                       if lost else "")
    parts: list[RenderableType] = [Text.assemble(("mission ", "bold"), who, "  ", (f"{r.outcome}", f"bold {colour}"),
                                                 head)]
    parts += [Text(f"  {_relative(d['path'], root)} failed at {d['at']:.1f} s: {d['reason']}", style="yellow")
              for d in lost]
    factor = r.real_time_factor  # one decimal below 10x: "4x (4x asked: could not keep up)" read as a contradiction
    pace = f"{factor:.1f}x real time" if factor < 9.95 else f"{factor:.0f}x real time"
    if not r.kept_up:  # say so, rather than leave the operator to compare with what they asked
        pace += f" ({r.speed:g}x asked: the {'cluster' if r.on_cluster else 'machine'} could not keep up)"
    away = f" ({r.away:.1f} s of it without a controller)" if r.away else ""
    parts.append(Text(f"sim time {r.sim_time:.1f} s · wall time {r.wall_time:.2f} s{away}"
                      + (f" · {pace}" if r.paced else "") if r.wall_time > 0
                      else f"sim time {r.sim_time:.1f} s"))
    parts += _why_view(r, width)
    for row in r.injections:
        parts.append(Text.assemble(("not injected " if row.get("skipped") else "injected ", "bold yellow"),
                                   f"at {row['at']:.1f} s: {row['effect']}"))
    path_width = max(20, width - 36)

    def rel(path: str, room: int = path_width) -> str:
        return shorten(_relative(path, root), room)

    parts += _tables(r, rel, width)
    logs = r.logs()
    if logs:
        parts.append(Text(f"log: {len(logs)} line{'s' if len(logs) != 1 else ''}", style="bold"))
        for row in logs[:LOG_LINES]:
            parts += _log_lines(row["at"], rel(row["path"], max(16, width // 3)), str(row["text"]), width)
        if len(logs) > LOG_LINES:
            parts.append(Text(f"  … and {len(logs) - LOG_LINES} more (--json or --trace have them all)", style="dim"))
    parts += _events_lines(r.events(), root, width)
    for title, rows in (("doors found", r.doors), ("robots launched", r.scouts), ("intruders detected", r.detections)):
        if not rows:  # the standard components' events: a mission of other components says nothing of them
            continue
        parts.append(Text(f"{title}: {len(rows)}", style="bold"))
        for fact in rows[:FACTS]:
            text = ", ".join(_fact(k, v, root) for k, v in fact.items())
            parts += [Text(("  " if i == 0 else "    ") + line)
                      for i, line in enumerate(wrap_cut(text, width - 4, WRAPPED_LINES))]
        if len(rows) > FACTS:
            parts.append(Text(f"  … and {len(rows) - FACTS} more (--json has them all)", style="dim"))
    return parts


def _events_lines(events: list[dict[str, Any]], root: str, width: int) -> list[Text]:
    """The report's `events` section: each event name the run emitted, how many times, and its first."""
    if not events:
        return []
    total = sum(e["count"] for e in events)
    out = [Text(f"events: {total} ({len(events)} kind{'s' if len(events) != 1 else ''})", style="bold")]
    for e in events[:FACTS]:
        first = ", ".join(_fact(k, v, root) for k, v in e["fields"].items())
        text = (f"{e['name']} x{e['count']}, first at {e['at']:.1f} s by {_relative(e['by'], root)}"
                + (f": {first}" if first else ""))
        out += [Text(("  " if i == 0 else "    ") + line) for i, line in enumerate(wrap_cut(text, width - 4,
                                                                                           WRAPPED_LINES))]
    if len(events) > FACTS:
        out.append(Text(f"  … and {len(events) - FACTS} more (--json has them all)", style="dim"))
    return out


#: How many doors, Scouts or detections the text report lists (the first ones; `--json` has them all).
FACTS = 20


#: How many lines a log line or a fact of the text report may wrap to (indented below its first) before `…`.
WRAPPED_LINES = 3


def _log_lines(at: float, path: str, text: str, width: int) -> list[Text]:
    """A log line of the report within `width`: its time, its (cut) path, its text wrapped below, indented under
    the path (`   26.6 s  RoomSurveilla…/ServoToGoal: blocked 1.2 m short of the goal:` / `as close as it gets`)."""
    stamp = f"{at:7.1f} s  "
    text, _, more = text.partition("\n")  # the lines after the first (a traceback, with DRD_DEBUG=1) come whole
    body = wrap_cut(f"{path}: {text}", max(20, width - len(stamp)), WRAPPED_LINES) + more.splitlines()
    first = Text(stamp, style="dim")
    if body[0].startswith(path + ":"):
        first.append(path, style="cyan")
        first.append(body[0][len(path):])
    else:
        first.append(body[0])
    return [first] + [Text(" " * len(stamp) + line) for line in body[1:]]


def _tables(r: DryRun, rel: Callable[..., str], width: int) -> list[RenderableType]:
    """The timeline, the holds and the waits, runs of instances that say the same thing folded."""
    parts: list[RenderableType] = []
    parts.append(_table("timeline", ("behavior", "entered", "exited", "status"),
                        [(rel(path), *rest) for path, *rest in collapse_instances(
                            [(row["path"], f"{row['entered']:.1f}", _t(row["exited"]), row["status"])
                             for row in r.timeline()])]))
    holds = r.holds()
    if holds:
        parts.append(_table("resource holds", ("holder", "resources", "from", "to", "ended"),
                            [(rel(h["path"], max(16, width // 3)),
                              ", ".join(f"{k}={v}" for k, v in h["resources"].items()), f"{h['from']:.1f}",
                              _t(h["to"]), h["ended"]) for h in holds]))
    else:
        parts.append(Text("resource holds: none", style="bold"))
    waits = [w for w in r.waits() if w["to"] - w["from"] >= 0.05]
    if waits:
        parts.append(_table("waits", ("waiter", "needs", "from", "to", "ended"),
                            [(rel(path, max(16, width // 3)), *rest) for path, *rest in collapse_instances(
                                [(w["path"], ", ".join(w["needs"]), f"{w['from']:.1f}", _t(w["to"]), w["ended"])
                                 for w in waits])]))
    return parts


#: How many log lines the text report shows (the JSON report has them all).
LOG_LINES = 30

#: The last instance index of a path (`RoomSurveillance[12]` in `M/RoomSurveillance[12]/Watch`).
_LAST_INDEX = re.compile(r"\[(\d+)\](?!.*\[\d+\])")

#: The fewest rows `collapse_instances` folds into one: below it, each instance keeps its row.
COLLAPSE_LEAST = 3


def collapse_instances(rows: list[tuple[str, ...]]) -> list[tuple[str, ...]]:
    """Rows (a path, then cells) with runs of consecutive instances that say the same thing folded into one:
    `Wait[0]` .. `Wait[999]`, all entered at 0.0, exited at 1.0, success, become one row `Wait[0..999] (1,000)`.
    Only instances numbered one after the other, in order, whose other cells are equal; the text report only (the
    JSON report and the trace have every instance)."""
    out: list[tuple[str, ...]] = []
    i = 0
    while i < len(rows):
        end = _same_run(rows, i)
        if end - i < COLLAPSE_LEAST:
            out.append(rows[i])
            i += 1
            continue
        path, *cells = rows[i]
        m = _LAST_INDEX.search(path)
        assert m is not None  # a run of two or more rows has an index
        first = int(m.group(1))
        out.append((f"{path[:m.start()]}[{first}..{first + end - i - 1}]{path[m.end():]} ({end - i:,})", *cells))
        i = end
    return out


def _same_run(rows: list[tuple[str, ...]], i: int) -> int:
    """Where the run of instances starting at row `i` ends (exclusive): the rows after it that differ from it only
    by their last index, which goes up by one each row."""
    def shape(row: tuple[str, ...]) -> tuple[str, str, tuple[str, ...], int] | None:
        m = _LAST_INDEX.search(row[0])
        return None if m is None else (row[0][:m.start()], row[0][m.end():], row[1:], int(m.group(1)))

    first = shape(rows[i])
    if first is None:
        return i + 1
    j = i + 1
    while j < len(rows) and (s := shape(rows[j])) is not None and s[:3] == first[:3] and s[3] == first[3] + j - i:
        j += 1
    return j


def _why_view(r: DryRun, width: int) -> list[RenderableType]:
    """Why the run ended as it did: each failed leaf with its own reason, or what a stopped run left behind."""
    root = r.mission
    room = max(20, width // 2)
    chain = r.failure_chain()
    leaves = [row for row in chain if row["leaf"] and row["path"] != root]
    parts: list[RenderableType] = []
    if leaves:
        parts.append(Text("why it failed", style="bold red"))
        for row in leaves:
            parts.append(Text.assemble("  ", (shorten(_relative(row["path"], root), room), "bold"),
                                       f": {row['reason']}"))
    active = r.still_active()
    if active:
        parts.append(Text(f"still active when it stopped: {len(active)}", style="bold yellow"))
        parts += still_active_lines(active, {w["path"]: w for w in r.waiting()}, root, width)
    return parts


#: How many blockers (or runs of instances of them) a text report names in a line before "and N more".
BLOCKERS_NAMED = 3


def still_active_lines(active: list[dict[str, Any]], waiting: dict[str, dict[str, Any]], root: str,
                       width: int) -> list[Text]:
    """One line per still-active leaf, runs of instances that say the same thing folded into one
    (`RoomSurveillance[40..189] (150)  waiting since 0.0 s for ranger: Ranger`), a waiter's blockers on the line
    below it; every line cut to `width`: a thousand waiters behind fifty holders make a few lines, not a megabyte."""
    room = max(20, width // 2)
    texts = [(row["since"], _relative(row["path"], root), f"{row['state']} since {row['since']:.1f} s",
              *_waiting_text(waiting.get(row["path"]), root)) for row in active]
    # earliest first as before, then the instances of one leaf that say the same thing in index order (to fold)
    texts.sort(key=lambda t: (t[0], natural(_LAST_INDEX.sub("[]", t[1])), t[2:], natural(t[1])))
    folded = collapse_instances([t[1:] for t in texts])
    names = [_fit_folded(path, room) for path, *_ in folded]
    pad = max(len(n) for n in names)
    lines = []
    for name, (_, state, needs, blockers) in zip(names, folded, strict=True):
        line = Text.assemble("  ", (name.ljust(pad), "bold"), f"  {state}")
        why = needs + (f", {blockers}" if blockers else "")
        if len(line) + len(why) <= width:  # on one line, as a small team's report always read
            line.append(why)
            lines.append(line)
            continue
        # below it: what it waits for, then who is in its way on lines of their own (wrapped, so that at least
        # the first blocker's whole name shows), each cut with … past two lines
        lines.append(line)
        below = [why.lstrip()] if len(why) + 3 <= width else [needs.lstrip(), blockers]
        lines += [Text(f"    {part}", style="dim") for text in below if text
                  for part in wrap_cut(text, width - 4, WHY_LINES)]
    for line in lines:
        line.truncate(width, overflow="ellipsis")
    return lines


#: How many lines what a still-active waiter waits for, and who is in its way, may each take below it.
WHY_LINES = 2

#: An instance's index or a fold's range of them in a path's first step (`RoomSurveillance[16..18]`).
_INDEX = re.compile(r"\[[0-9.]+\]$")


def _fit_folded(path: str, room: int) -> str:
    """A path `shorten`ed to `room`, the count a fold adds (` (150)`) kept whole, and the index or range of its
    first step (`[16..18]`) too: cut inside it, the row no longer says which instances it is
    (`RoomSurveilla…[16..18]/…/ServoToGoal (3)`, not `RoomSurveillance[16..18…/ServoToGoal (3)`)."""
    head, sep, count = path.rpartition(" (")
    if not sep or not count.endswith(")"):
        head, count = path, ""
    room = max(10, room - len(count) - 2) if count else room
    tail = f" ({count}" if count else ""
    cut = shorten(head, room)
    first, slash, rest = head.partition("/")
    index = _INDEX.search(first)
    if cut == head or index is None or cut.startswith(first):
        return cut + tail
    leaf = rest.rsplit("/", 1)[-1]
    middle = "/…/" if "/" in rest else "/"
    name = room - len(index.group()) - len(middle) - len(leaf) - 1  # what is left of the name before the index
    if name < 1:  # too narrow for the leaf as well: the instance and as much of its path as fits
        return (f"…{index.group()}{slash}" + shorten(rest, max(1, room - len(index.group()) - 2)))[:room] + tail
    return first[:min(name, index.start())] + "…" + index.group() + middle + leaf + tail


def _waiting_text(w: dict[str, Any] | None, root: str) -> tuple[str, str]:
    """(` for NEEDS`, `N in its way, held by A (units); B (units) and N-2 more`, or `behind C (waiting first)`): what
    a waiter waits for and who is in its way now, the latter "" when it is not waiting."""
    if w is None:
        return "", ""
    shown = w["blocked_by"]
    held = [f"{_relative(b['path'], root)} ({', '.join(b['holds'].values())})" for b in shown if b["holds"]]
    queued = [_relative(b["path"], root) for b in shown if not b["holds"]]
    more = w.get("blockers", len(shown)) - len(shown)
    who = [f"held by {'; '.join(held[:BLOCKERS_NAMED])}"] if held else []
    who += [f"behind {', '.join(queued[:BLOCKERS_NAMED])} (waiting first)"] if queued else []
    count = f"{len(shown) + more:,} in its way, " if more > 0 else ""  # first: a cut line still says how many
    return f" for {', '.join(w['needs']) or 'its resources'}", count + ", ".join(who) + (
        f" and {more:,} more" if more > 0 else "")


def _relative(path: str, root: str) -> str:
    """A path below the mission without the mission's name (the report's first line says it)."""
    return path[len(root) + 1:] if path.startswith(root + "/") else path


def _fact(key: str, value: Any, root: str) -> str:
    if isinstance(value, float):
        return f"{key}={value:.2f}"
    if key == "by" and isinstance(value, str):
        return f"{key}={_relative(value, root)}"
    return f"{key}={value}"


def _t(at: float | None) -> str:
    return "" if at is None else f"{at:.1f}"


def _table(title: str, columns: tuple[str, ...], rows: list[tuple[str, ...]]) -> Table:
    from rich.table import Table

    table = Table(title=title, title_justify="left")
    for col in columns:
        table.add_column(col)
    for row in rows:
        table.add_row(*row)
    return table


def print_preview(p: Preview, hosts_file: Path, root: str, console: Console | None = None) -> None:
    """A preview as text: holds, components and their hosts, waits, and what cannot hold."""
    from rich.table import Table

    console = console or out

    def short(path: str) -> str:
        return shorten(path.removeprefix(root + "/") if path != root else path, max(20, console.width // 3))

    def units(resources: dict[str, str]) -> str:
        return ", ".join(f"{k}={v}" for k, v in resources.items()) or "—"

    console.print(Text.assemble(("at start on cluster ", "bold"), (p.cluster, "bold"), f" ({hosts_file})",
                                (" — nothing runs", "dim")))
    if p.holds:
        t = Table(title="holds", title_justify="left")
        for col in ("behavior", "resources"):
            t.add_column(col)
        for h in p.holds:
            t.add_row(short(h["path"]), units(h["resources"]))
        console.print(t)
    if p.components:
        t = Table(title="components", title_justify="left")
        for col in ("behavior", "component", "host", "devices"):
            t.add_column(col, no_wrap=col != "devices")
        for c in p.components:
            t.add_row(short(c["path"]), c["component"], c["host"] or "—", units(c["devices"]))
        console.print(t)
    if p.waits:
        t = Table(title="waits", title_justify="left")
        for col in ("behavior", "needs", "behind"):
            t.add_column(col)
        for w in p.waits:
            behind = "; ".join(f"{short(b['path'])} ({units(b['holds'])})" if b["holds"] else short(b["path"])
                               for b in w["blocked_by"]) or "nothing grants it"
            t.add_row(short(w["path"]), ", ".join(w["needs"]), behind)
        console.print(t)
    for problem in p.problems:
        console.print(Text.assemble(("cannot hold: ", "bold red"), problem))
    if not p.problems:
        console.print(Text.assemble(("✓ ", "bold green"), "every need at start is granted or waits behind a holder"))


def print_state(state: dict[str, Any], console: Console | None = None) -> None:
    """`replay --at`: the run at one instant, each mission's active behaviors, holds and waits, then the robots."""
    from rich.table import Table

    console = console or out
    console.print(Text.assemble(("at ", "bold"), f"{state['at']:.1f} s of sim time"))
    if state.get("ends") is not None and state["at"] > state["ends"] + 1e-6:
        how = ("it was cut short, before the run ended: this is the run as far as it was recorded" if state.get("cut")
               else "this is the run as it ended")
        console.print(Text(f"  after the recording's end, at {state['ends']:.1f} s: {how}", style="yellow"))
    for m in state["missions"]:
        root = str(m["mission"])
        head = Text.assemble(("mission ", "bold"), str(m["id"]))
        if m["outcome"]:
            head.append(f"  {m['outcome']} (ended)", style="dim")
        console.print(head)
        for row in m["active"]:
            console.print(f"  {shorten(_relative(row['path'], root), 60)}  {row['state']} since {row['since']:.1f} s")
        for path, held in m["holds"].items():
            units = ", ".join(f"{k}={v}" for k, v in held.items() if "." not in k)
            console.print(Text.assemble(("  holds ", "dim"), f"{shorten(_relative(path, root), 50)}: {units}"))
    if state["robots"]:
        table = Table(title="robots", title_justify="left")
        for col in ("robot", "x", "y", "heading"):
            table.add_column(col)
        for rid, p in state["robots"].items():
            table.add_row(rid, f"{p['x']:.2f}", f"{p['y']:.2f}", f"{math.degrees(p['heading']):.0f}°")
        console.print(table)


#: Placement lines `missionctl status` shows under a running mission by default (`--explain`: all, with detail).
PLACEMENTS_SHOWN = 4


def placement_lines(mission: dict[str, Any], width: int = 80, explain: bool = False) -> list[Text]:
    """`missionctl status`: one line per placed instance of the mission (`Wait -> spare (score 10 vs ranger1 20:
    instances 10 vs 20; filtered controller: no worker role)`), by default only while it runs and at most
    `PLACEMENTS_SHOWN`; with `explain`, every one, each followed by its scored hosts' parts."""
    entries = [e for e in mission.get("placements") or [] if isinstance(e, dict)]
    if not entries or not (explain or mission.get("outcome") is None):
        return []
    shown = entries if explain else entries[-PLACEMENTS_SHOWN:]
    lines: list[Text] = []
    for e in shown:
        instance = str(e.get("instance", ""))  # below the mission's root state, as in the active tree
        name = shorten(instance.split("/", 1)[1] if "/" in instance else instance, max(16, width // 3))
        line = Text.assemble(("placement ", "dim"), name, " -> ", str(e.get("summary", "")), no_wrap=False,
                             overflow="fold")  # wrapped, never cut: the reasons come last
        if e.get("how") == "re-placed":
            line.append("  re-placed", style="yellow")
        lines.append(line)
        if explain:
            lines += _decision_detail(e.get("decision") or {})
    if len(shown) < len(entries):
        lines.append(Text(f"… {len(entries) - len(shown)} more placements (missionctl status --explain)",
                          style="dim"))
    return lines


def _decision_detail(record: dict[str, Any]) -> list[Text]:
    """Each scored host with its parts in points (`spare 12 = cpu 0 + memory 0 + instances 12`), then each filtered
    host and why."""
    out_lines = []
    for s in record.get("scored") or []:
        terms = " + ".join(f"{p['plugin']} {p['points']:.3g}" for p in s.get("parts", []) if p.get("points"))
        out_lines.append(Text(f"    {s.get('host')} {s.get('total', 0):.3g} = {terms or '0'}", style="dim"))
    for host, why in (record.get("filtered") or {}).items():
        out_lines.append(Text(f"    {host} filtered: {', '.join(why)}", style="dim"))
    left = record.get("left_out") or {}
    if any(left.values()):
        out_lines.append(Text(f"    … {left.get('scored', 0)} scored and {left.get('filtered', 0)} filtered hosts "
                              "more (the controller's log)", style="dim"))
    return out_lines
