"""`missionctl` commands against a running cluster: run, stop, hosts, status, components, resources, query.

Each joins the cluster's bus through `drd.daemon.client.ClusterClient`: with `--config hosts.yaml`
(the default) it connects to every host's endpoint with the cluster's security settings; with
`--connect ENDPOINT` to the endpoints given. When no daemon answers within `--timeout`, the command
fails with exit code 2 and one line naming the endpoints it tried.
"""

from __future__ import annotations

import functools
import inspect
import json
import math
import re
import signal
import time
import typing
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from dataclasses import asdict
from pathlib import Path
from types import FrameType
from typing import IO, TYPE_CHECKING, Any

import typer
from rich.text import Text
from typer.core import TyperCommand
from typer.models import CommandInfo, OptionInfo

from drd.cli.arrivals import SignalArrivals
from drd.cli.common import (
    INTERNAL,
    INVALID,
    OK,
    VERSION_CALLBACKS,
    distinct_files,
    duration_text,
    err,
    fail,
    fail_all,
    open_trace,
    out,
    print_json,
    shorten,
    wrap_cut,
)

if TYPE_CHECKING:
    from rich.console import RenderableType
    from rich.table import Table

    from drd.daemon.client import ClusterClient
    from drd.dryrun import DryRun
    from drd.record import Recorder
    from dsl.checker import Program

from drd.cli.options import (
    MAX_PRIORITY,
    MAX_SPEED,
    MAX_WAIT,
    ConfigOption,
    ConnectOption,
    JsonOption,
    TimeoutOption,
    UntilOption,
)


def register(app: typer.Typer) -> None:
    """Add the cluster commands to `missionctl`."""
    app.command("hosts")(hosts)
    app.command("status")(status)
    app.command("components")(components)
    app.command("resources")(resources)
    app.command("query")(query)
    app.command("run")(run)
    app.command("stop")(stop)


# --- the fast path of the read-only commands ------------------------------------------------------

#: Commands `fast_command` may run without typer: read-only, options only, run often (and by scripts).
FAST_COMMANDS = ("hosts", "status", "components", "resources")
_PLAIN_NUMBER = {int: re.compile(r"0|[1-9][0-9]*"), float: re.compile(r"[0-9]+(?:\.[0-9]+)?")}
#: OptionInfo fields that change only the help text; any other field set makes an option "not plain".
_COSMETIC = frozenset({"default", "param_decls", "help", "min", "max", "show_default", "metavar", "rich_help_panel",
                       "hidden"})


def fast_command(app: typer.Typer, argv: Sequence[str],
                 commands: Sequence[str] = FAST_COMMANDS) -> Callable[[], object] | None:
    """The call of `missionctl COMMAND ...` when `argv` is a plain, valid use of a fast command; else None.

    Typer 0.29 checks every parameter through pydantic, whose first import costs about 0.25 s: a
    quarter of a `missionctl status`. For the commands of `commands` this parses the options
    itself, reading them (names, defaults, minimums, types) from the command's typer signature,
    so nothing is declared twice. It accepts only what it is sure typer would accept with the same
    values: `--help`, an unknown or repeated option, a value that is not a plain number, a number
    out of its range, an option typer would treat specially (env var, callback, parser...) all
    return None, and typer then parses, answers or refuses as always (the same help, the same errors).
    """
    callback = app.registered_callback
    if (not argv or argv[0] not in commands or app.info.context_settings
            or callback is not None and callback.callback not in VERSION_CALLBACKS):
        return None
    fn = _registered(app, argv[0])
    spec = _option_spec(fn) if fn is not None else None
    if fn is None or spec is None:
        return None
    kwargs = {name: info.default for name, (info, _) in spec.values()}
    seen: set[str] = set()
    args = list(argv[1:])
    while args:
        word = args.pop(0)
        flag, eq, inline = word.partition("=") if word.startswith("--") else (word, "", "")
        if flag not in spec:
            return None
        name, (info, kind) = spec[flag]
        if kind is bool:
            if eq or name in seen:
                return None
            kwargs[name] = True
        else:
            if eq:
                text = inline
            elif args:
                text = args.pop(0)
            else:
                return None
            value = _plain_value(text, kind.__args__[0] if kind in (list[str], list[Path]) else kind, info.min,
                                 info.max)
            if value is None:
                return None
            if kind in (list[str], list[Path]):
                kwargs[name] = [*(kwargs[name] or []), value]
                seen.add(name)
                continue
            if name in seen:
                return None
            kwargs[name] = value
        seen.add(name)
    return functools.partial(fn, **kwargs)


def _registered(app: typer.Typer, name: str) -> Callable[..., object] | None:
    """The callback registered as command `name`, if its registration sets nothing typer treats specially."""
    plain = vars(CommandInfo())
    for info in reversed(app.registered_commands):  # a name registered twice: typer keeps the last
        callback = info.callback
        if callback is None or (info.name or callback.__name__.replace("_", "-")) != name:
            continue
        settings = {k: v for k, v in vars(info).items() if k not in ("name", "callback", "cls", "help", "short_help",
                                                                      "epilog", "hidden", "rich_help_panel")}
        if info.cls not in (None, TyperCommand) or any(plain.get(k) != v for k, v in settings.items()):
            return None
        return callback
    return None


@functools.cache
def _option_spec(fn: Callable[..., object]) -> dict[str, tuple[str, tuple[OptionInfo, Any]]] | None:
    """Each option word of `fn` -> (parameter, (its OptionInfo, its type)); None if a parameter is not plain."""
    plain = vars(OptionInfo())
    hints = typing.get_type_hints(fn)
    spec: dict[str, tuple[str, tuple[OptionInfo, Any]]] = {}
    for name, param in inspect.signature(fn).parameters.items():
        info, kind = param.default, hints.get(name)
        if not isinstance(info, OptionInfo) or kind not in (bool, str, int, float, Path, list[str],
                                                                           list[Path]):
            return None
        if any(plain.get(k) != v for k, v in vars(info).items() if k not in _COSMETIC):
            return None
        if kind is bool and (info.default is not False or info.min is not None):
            return None
        decls = info.param_decls or ()
        if not decls or any("/" in d or not d.startswith("-") or " " in d for d in decls):
            return None
        for word in decls:
            spec[word] = (name, (info, kind))
    return spec


def _plain_value(text: str, kind: Any, minimum: float | None, maximum: float | None = None) -> Any:
    """`text` as typer would convert it to `kind`, or None when unsure (typer then decides)."""
    if not text or text.startswith("-"):
        return None
    if kind in _PLAIN_NUMBER:
        if not _PLAIN_NUMBER[kind].fullmatch(text):
            return None
        value = kind(text)
        if minimum is not None and value < minimum or maximum is not None and value > maximum:
            return None  # out of range: typer says so
        return value
    return Path(text) if kind is Path else text


@contextmanager
def cluster_client(config: Path, connect: list[str] | None, timeout: float,
                   to: str = "") -> Iterator[ClusterClient]:
    """A client of the cluster, or a clean exit 2; request errors become one-line errors too. `to`: what the
    command does that only an operator may (`run a mission`...): refused here, before the cluster is asked, to a
    user whose role (`cluster.security.roles`) does not allow it; the daemons refuse it anyway."""
    from drd.bus import BusError, MalformedMessage, RemoteError
    from drd.daemon.client import ClientError, ClusterClient

    endpoints, options, name, prefer = _endpoints(config, connect, to)
    try:
        client = ClusterClient.connect(endpoints, cluster=name, options=options, timeout=timeout, prefer=prefer)
    except ClientError as e:
        hint = ("is a drd listening there? A cluster with security needs --config (for its credentials)" if connect
                else f"start the daemons with `drd start --host NAME --config {config}`; if they run, check that this"
                     f" file's cluster name ({name}) and credentials are theirs (the daemons ignore a client of another"
                     " cluster, and refuse one without the password)")
        fail(str(e), hint=hint)
    try:
        yield client
    except RemoteError as e:
        fail(e.reason)
    except MalformedMessage as e:  # our own request breaks the bus's rules (a mission file whose JSON is over 1 MiB)
        fail(f"cannot send this request: {e.reason}", hint="a request travels as one bus message of at most 1 MiB"
             " of JSON (docs/bus.md): a mission's source is sent whole")
    except (ClientError, BusError) as e:
        fail(str(e))
    finally:
        client.close()


def _endpoints(config: Path, connect: list[str] | None,
               to: str = "") -> tuple[list[str], dict[str, Any], str | None, list[str]]:
    """(endpoints, zenoh options, cluster name, preferred daemons) from --connect or the hosts file (whose roles
    must allow this user `to` do what it asks, if anything)."""
    from drd.hosts import HostsError, endpoint_problem, load_endpoints

    for endpoint in connect or ():  # the hosts file's rule, before zenoh (whose error quotes Rust source paths)
        if (problem := endpoint_problem(endpoint)) is not None:
            fail(f"--connect {endpoint}: {problem}", hint="e.g. --connect tcp/127.0.0.1:7447")
    if connect:  # a zenoh client of the first that answers (a router or a peer routes for it), the next if it fails
        return list(connect), {"mode": "client"}, None, []
    from drd.daemon.security import SecurityError, transport

    if not config.is_file():
        what = "is a folder, not a hosts file" if config.is_dir() else "is not a regular file" if config.exists() \
            else "no such file"  # a folder is not "no such file" (cli audit 24, #7)
        fail(f"{config}: {what} (looked at {config.absolute()})", hint="pass --config FILE, or --connect tcp/HOST:PORT")
    try:
        cluster = load_endpoints(config)  # endpoints, roles and security: no hardware, so no component catalog
        tr = transport(cluster)
    except (HostsError, SecurityError) as e:
        fail_all(e.problems)
    _may(cluster.security, tr.identity, to)
    prefer = [cluster.controller.name] + [h.name for h in cluster.hosts if h.name != cluster.controller.name]
    return tr.entry_points(), {**tr.options, "mode": tr.client_mode()}, cluster.name, prefer


def query_error(reason: str) -> str:
    """One error for an invalid query: the daemon's rendered reason (the query, then a caret under the column and
    the message) under "invalid query:", its lines kept together so the caret stays under its column, as text and
    as `--json`'s `error` (they were three "problems" there, the message not in `error`)."""
    return f"invalid query:\n{reason}" if "\n" in reason else f"invalid query: {reason}"


def _may(security: Any, who: str, to: str) -> None:
    """Refuse (exit 2) a user (password) or certificate (tls) whose role does not allow what the command does;
    nothing without roles. The daemons refuse it anyway, but with tls by dropping it: it would wait for nothing."""
    from drd.hosts import SecurityMode

    if not security.roles or not who:
        return
    tls = security.mode is SecurityMode.TLS
    what = f"certificate {who}" if tls else f"user {who}"
    role = security.role_of(who)
    if role is None:
        fail(f"{what} has no role in the hosts file (cluster.security.roles): the daemons refuse it",
             hint="ask for one, or " + ("use a certificate whose common name has one (cluster.security.cert)" if tls
                                        else "set DRD_USER to a user that has one"))
    if to and role == "observer":
        fail(f"{what} is an observer: it may watch the cluster (status, hosts, resources, a mission's"
             f" records), not {to}", hint="an operator may: " + (
                 "use an operator's certificate (cluster.security.cert)" if tls else "set DRD_USER to one"))


# --- commands --------------------------------------------------------------------------------------


def hosts(config: Path = ConfigOption, connect: list[str] = ConnectOption, as_json: bool = JsonOption,
          timeout: float = TimeoutOption) -> int:
    """The cluster's hosts: up or down, since when and why, with their load."""
    with cluster_client(config, connect, timeout) as client:
        reply = client.hosts(deadline=client.budget)
    data = [asdict(h) for h in reply.hosts]
    if as_json:
        print_json({"cluster": reply.cluster, "answered_by": reply.answered_by, "hosts": data})
    else:
        out.print(_hosts_table(data, reply.at))
    return OK


def status(config: Path = ConfigOption, connect: list[str] = ConnectOption, as_json: bool = JsonOption,
           timeout: float = TimeoutOption,
           watch: bool = typer.Option(False, "--watch", "-w", help="Refresh until Ctrl-C (JSON: one line each)."),
           interval: float = typer.Option(1.0, "--interval", min=0.1, max=MAX_WAIT,
                                          help="Seconds between refreshes with --watch."),
           events: int = typer.Option(20, "--events", min=0, help="How many recent events to show."),
           explain: bool = typer.Option(False, "--explain", help="Every placement decision of every mission, each "
                                        "with its hosts' scores and the hosts filtered and why (default: the last "
                                        "few of the running missions, one line each; --json has them all).")) -> int:
    """One view of the cluster: hosts, instances, resources, missions (with where their movable instances were
    placed, and why) and recent events."""
    with cluster_client(config, connect, timeout) as client:
        if not watch:
            data = client.status(events, deadline=client.budget)
            if as_json:
                print_json(status_json(data))
            else:
                out.print(status_view(data, explain=explain))
            return OK
        _watch((lambda: status_json(client.status(events))) if as_json else lambda: client.status(events), as_json,
               interval, explain)
    return OK


def status_json(data: dict[str, Any]) -> dict[str, Any]:
    """`status --json`: each mission in the shape `run --json` and `stop --json` give it, its waiting nodes told why
    (`with_waits`)."""
    data = with_waits(data)
    missions = data.get("missions")
    return data if missions is None else {**data, "missions": [mission_json(m) for m in missions]}


def with_waits(data: dict[str, Any]) -> dict[str, Any]:
    """The status with each node of a mission's tree that stands in the manager's queue told why (`waiting_for`:
    its needs with their `where`, its rank, mission priority first, and who blocks it with what they hold): a
    mission's own status says only `waiting`, the manager knows the rest. Pure; adds, never renames."""
    resources, missions = data.get("resources"), data.get("missions")
    if not resources or not missions:
        return data
    queue = {str(w["holder"]): w for w in resources.get("queue", [])}
    if not queue:
        return data

    def mark(node: dict[str, Any], mission: str) -> dict[str, Any]:
        found = queue.get(f"{mission}/{node.get('path')}")
        node = {**node, "children": [mark(c, mission) for c in node.get("children") or []]}
        if found is not None:
            node["waiting_for"] = {"needs": found["needs"], "where": found.get("where", {}),
                                   "mission_priority": found.get("mission_priority", 1),
                                   "priority": found["priority"], "blocked_by": found.get("blocked_by", []),
                                   "offline": found.get("offline", [])}
        return node

    return {**data, "missions": [{**m, "tree": mark(m["tree"], str(m.get("id")))} if isinstance(m.get("tree"), dict)
                                 else m for m in missions]}


def waits_text(why: dict[str, Any]) -> tuple[str, str]:
    """A node's `waiting_for` in words, (what it needs, who is in its way): (`for ranger: Ranger where ranger.id ==
    "ranger2" (mission priority 3, priority 1)`, `blocked by CamHog-91/HoldEast (ranger: ranger2)`), the count first
    when several block it (`blocked by 3: A (ranger: ranger2), ...`): a cut line still says how many."""
    wheres = why.get("where") or {}
    needs = ", ".join(f"{n}: {t}" + (f" where {wheres[n]}" if n in wheres else "") for n, t in why["needs"].items())
    text = f"for {needs} (mission priority {why['mission_priority']}, priority {why['priority']})"
    blockers = [holder_label(b["holder"], several=True) + (" (waiting first)" if b.get("waiting") else
                                                           f" ({', '.join(f'{k}: {v}' for k, v in b['holds'].items())})"
                                                           if b.get("holds") else "")
                for b in why.get("blocked_by") or []]
    blockers += [f"host {host} (offline: down, or it did not answer)" for host in why.get("offline") or []]
    count = f" {len(blockers)}:" if len(blockers) > 1 else ""
    return text, (f"blocked by{count} {', '.join(blockers)}" if blockers else "")


#: How many lines each part of why a node waits (its need, who blocks it) may take below the node in `status`.
WHY_LINES = 2


def why_lines(why: tuple[str, str], width: int) -> list[str]:
    """Why a node waits, on lines of at most `width` below it: its need, then who blocks it on a line of its own,
    each wrapped to `WHY_LINES` lines and cut with `…` past them. The blocker starts a line, so its name shows at 80
    columns however long the need's `where` is."""
    return [line for part in why if part for line in wrap_cut(part, width, WHY_LINES)]


def holder_label(holder: str, room: int = 0, several: bool = True) -> str:
    """A manager holder (`NightGuard-9515067/NightGuard/GuardPost`) in at most `room` characters (0: whole): with
    several missions its mission id and its path below the mission's root (`NightGuard-9515067/GuardPost`), cut so
    that what tells two holders apart stays, the id's tail and the leaf (`Nig…-9515067/GuardPost`); with one mission
    the path below the root alone."""
    steps = holder.split("/", 2)
    if len(steps) < 3:
        return shorten(holder, room) if room else holder
    mission, rest = steps[0], steps[2]
    if not several:
        return shorten(rest, room) if room else rest
    label = f"{mission}/{rest}"
    if not room or len(label) <= room:
        return label
    leaf = rest.rsplit("/", 1)[-1]
    rest = shorten(rest, max(len(leaf), room - len(mission) - 1))
    left = room - len(rest) - 1
    if left >= len(mission):
        return f"{mission}/{rest}"
    name, dash, tail = mission.rpartition("-")
    tail = dash + tail if dash else mission[-max(1, left - 1):]
    head = name[:max(0, left - len(tail) - 1)]
    return f"{head}…{tail}/{rest}"


def components(config: Path = ConfigOption, connect: list[str] = ConnectOption, as_json: bool = JsonOption,
               timeout: float = TimeoutOption) -> int:
    """Component types with the hosts that can run them, running instances and the daemons' services."""
    with cluster_client(config, connect, timeout) as client:
        reply = client.components()
    if as_json:
        print_json({"types": reply.types, "instances": [asdict(i) for i in reply.instances],
                    "services": [asdict(s) for s in reply.services]})
        return OK
    from rich.table import Table

    table = Table(title="component types (hosts up that can run them)", title_justify="left")
    table.add_column("type")
    table.add_column("hosts")
    for name, where in reply.types.items():
        table.add_row(name, ", ".join(where))
    out.print(table)
    for title, rows in (("instances", reply.instances), ("services", reply.services)):
        t = Table(title=title, title_justify="left")
        for col in ("name", "component", "host", "state", "pid", "key"):
            t.add_column(col)
        for i in rows:  # an instance as `missionctl migrate` takes it: <mission>/<path>
            t.add_row(f"{i.mission}/{i.name}" if i.mission else i.name, i.component, i.host, i.state,
                      str(i.pid or "—"), i.key)
        out.print(t if rows else Text(f"{title}: none", style="dim"))
    return OK


def resources(config: Path = ConfigOption, connect: list[str] = ConnectOption, as_json: bool = JsonOption,
              timeout: float = TimeoutOption) -> int:
    """The Resource Controller Manager: each resource with its holders, queue and fencing epoch."""
    with cluster_client(config, connect, timeout) as client:
        reply = client.resources(deadline=client.budget)
    data = {"units": [asdict(u) for u in reply.units], "robots": [asdict(r) for r in reply.robots],
            "queue": [asdict(w) for w in reply.queue], "removing": reply.removing, "hosts": reply.hosts}
    if as_json:
        print_json(data)
    else:
        from rich.console import Group

        out.print(Group(*_resources_view(data)))
    return OK


def query(text: str = typer.Argument(..., metavar="QUERY", show_default=False,
                                     help="TYPE [where EXPR] [prefer min(EXPR)|max(EXPR)|random|first]"),
          config: Path = ConfigOption, connect: list[str] = ConnectOption, as_json: bool = JsonOption,
          timeout: float = TimeoutOption,
          seed: int = typer.Option(0, "--seed", help="Seed of `prefer random`.")) -> int:
    """Ask the trader: `Camera where resolution >= 640 prefer min(host.load)`. A type matches its subtypes too
    (`Robot`: Rangers and Scouts). A robot's carrier, pose (x, y, heading) and battery are live where the cluster
    knows them; --json lists those under `live`, each with its age in seconds."""
    from drd.bus import RemoteError

    with cluster_client(config, connect, timeout) as client:
        try:
            reply = client.query(text, seed)
        except RemoteError as e:
            if e.reason.startswith("handler "):  # the daemon's failure, not the query's (wire audit 25, D3)
                fail(f"the daemon could not answer the query: {e.reason}", INTERNAL)
            fail(query_error(e.reason))
    if as_json:
        print_json(reply.offers)
        return OK
    from rich.table import Table

    table = Table(title=offers_title(len(reply.offers), text), title_justify="left")
    for col in ("id", "type", "host", "load", "properties"):
        table.add_column(col)
    for o in reply.offers:
        live = o.get("live") or {}
        props = ", ".join(f"{k}={shown_property(v)}" + (f" (live, {live[k]:.1f} s)" if k in live else "")
                          for k, v in o["properties"].items())
        table.add_row(o["id"], o["type"], str(o["host"]), _pct(o["load"] * 100 if o["load"] is not None else None),
                      props)
    out.print(table)
    return OK


_RECORD_OPTION = typer.Option(None, "--record", show_default=False,
                              help="Record the run as an MCAP file: the mission's records and active states, the"
                                   " hosts' load and liveliness, placements, the robots' poses and sensor readings"
                                   " (from the simulator's host, or on real robots from each robot's host),"
                                   " `missionctl replay`, docs/recording.md.")
_FOXGLOVE_OPTION = typer.Option(None, "--foxglove", show_default=False, metavar="[HOST:PORT]",
                                help="Serve the run live to Foxglove (its WebSocket protocol), the channels of"
                                     " --record, on HOST:PORT only; `--foxglove` alone: 127.0.0.1:8765.")


def run(mission: Path = typer.Argument(..., help="The mission file.", show_default=False),
        config: Path = ConfigOption, connect: list[str] = ConnectOption,
        world: str = typer.Option("", "--world", "-w", show_default=False,
                                  help="The simulator's world (a name under worlds/) [default: the controller's"
                                       " hosts.yaml cluster.world, else corridor]."),
        speed: float = typer.Option(1.0, "--speed", min=0.01, max=MAX_SPEED,
                                    help="Run at most this multiple of real time."),
        until: float = UntilOption,
        seed: int = typer.Option(0, "--seed", help="Seed of the simulation."),
        param: list[str] = typer.Option([], "--param", "-p", show_default=False,
                                        help="NAME=VALUE: start the mission's variable NAME at VALUE (repeatable)."),
        priority: int | None = typer.Option(None, "--priority", "-P", min=1, max=MAX_PRIORITY, show_default=False,
                                     help="The mission's priority against the missions running with it (1 the"
                                          " highest) [default: its `mission ... priority`, else 1]."),
        trace: Path | None = typer.Option(None, "--trace", show_default=False,
                                   help="Write every record of the mission as JSON lines to this file"
                                        " (docs/trace.md)."),
        record: Path | None = _RECORD_OPTION, foxglove: str | None = _FOXGLOVE_OPTION,
        detach: bool = typer.Option(False, "--detach", "-d", help="Print the mission id and return at once."),
        as_json: bool = typer.Option(False, "--json", help="Print the report as JSON."),
        timeout: float = TimeoutOption) -> int:
    """Run a mission on the cluster: the controller compiles and runs it; exit 0 if it succeeds, 1 if it fails,
    2 if it is invalid. A mission started while others run joins them: they share the team by priority."""
    from drd.cli.common import MISSION_FAILED
    from drd.daemon.missions import RunMission
    from drd.dryrun import summary
    from dsl.params import ParamError, parse_assignments

    source, imports, aliases = _mission_source(mission)
    try:
        params = parse_assignments(param)
    except ParamError as e:
        fail(str(e))
    trace_out, recorder = _outputs((mission, config, list(imports)), trace, record, foxglove, detach)
    wait = max(timeout, 15.0)
    request = RunMission(source, str(mission), world, speed, until, seed, params or None, priority,
                         give_up_at=time.time() + wait - 0.5,  # the reply must still reach us after it
                         imports=imports, aliases=aliases or None)
    with cluster_client(config, connect, timeout, to="run a mission") as client:
        watch = _RecordWatch(client, trace_out, recorder, worlds=(config.absolute().parent,))
        try:
            with _interrupt_once() as interrupts:  # from before `follow` to the end of the stop a Ctrl-C starts
                report = _run_and_follow(client, watch, request, wait, detach, as_json, interrupts)
        finally:
            watch.close()
            if trace_out is not None:
                trace_out.close()
    if report is None:  # detached
        return OK
    report.on_cluster = True
    if recorder is not None:
        _scouts_ended(report, recorder)
        recorder.end([summary(report)], report.sim_time)
    if as_json:
        print_json(report.to_dict(), default=str)
    else:
        from drd.cli.report import print_report

        print_report(report)
    return OK if report.outcome == "success" else MISSION_FAILED


#: A diagnostic's first line and a note's, as `dsl.errors.Diagnostic.render` writes them (the controller's reply
#: carries its diagnostics rendered).
_HEADER = re.compile(r"(?P<file>.+):(?P<line>\d+):(?P<column>\d+): (?P<severity>error|warning): (?P<message>.*)")
_NOTE = re.compile(r"  note: (?P<file>.+):(?P<line>\d+):(?P<column>\d+): (?P<message>.*)")


def located(rendered: str) -> dict[str, Any]:
    """A diagnostic the controller sent rendered, in `validate --json`'s shape (`Diagnostic.to_dict`) as far as its
    text says: file, line, column, severity, message, hint, notes (a refusal with no location: its message only)."""
    lines = rendered.splitlines() or [""]
    head = _HEADER.fullmatch(lines[0])
    hint = next((line.removeprefix("  hint: ") for line in lines[1:] if line.startswith("  hint: ")), None)
    if head is None:
        return {"severity": "error", "message": rendered, "hint": hint, "notes": []}
    notes = [{"message": n["message"], "file": n["file"], "line": int(n["line"]), "column": int(n["column"])}
             for n in map(_NOTE.fullmatch, lines[1:]) if n is not None]
    return {"severity": head["severity"], "message": head["message"], "file": head["file"],
            "line": int(head["line"]), "column": int(head["column"]), "hint": hint, "notes": notes}


def _structured(request: Any, diagnostics: Sequence[str]) -> list[dict[str, Any]]:
    """The controller's diagnostics as `validate --json` gives them (`Diagnostic.to_dict`: with `code`, `end_line`,
    `end_column`): this client's own compile of what it sent, when it renders the very same text (the same
    components here as there); else what the rendered text says (`located`)."""
    from drd.daemon.missions import render
    from drd.errors import DrdError
    from drd.manifests import load_catalog
    from dsl import compile_text

    try:
        mine = compile_text(request.source, load_catalog(), request.file or "<mission>", imports=request.imports or {},
                            aliases=request.aliases)
    except DrdError:  # this client's components do not load: the controller's words alone
        return [located(text) for text in diagnostics]
    if render(list(mine.diagnostics), dict(mine.sources)) == list(diagnostics):
        return [d.to_dict() for d in mine.diagnostics]
    return [located(text) for text in diagnostics]


def _refused(request: Any, diagnostics: Sequence[str], as_json: bool) -> typing.NoReturn:
    """The controller found the mission invalid: its diagnostics as it rendered them, or under `--json` one JSON
    error with them located, as `validate --json` and `dry-run --json` give it; exit 2."""
    file = request.file
    if as_json:
        found = _structured(request, diagnostics)
        first = next((d for d in found if d["severity"] == "error"), found[0] if found else None)
        where = f"{first['file']}:{first['line']}:{first['column']}: " if first and "file" in first else ""
        fail(f"{file}: invalid: {where}{first['message'] if first else 'refused'}", INVALID, diagnostics=found)
    for text in diagnostics:
        err.print(Text(text))
    err.print(Text.assemble(("✗ ", "bold red"), f"{file}: invalid, not run"))
    raise typer.Exit(INVALID)


def _scouts_ended(report: DryRun, recorder: Recorder) -> None:
    """Where each launched Scout ended, as a dry-run's report says it (`x`, `y`): its last pose the recorder
    wrote (the simulator's host told this client every pose it recorded); a Scout never seen keeps none."""
    for scout in report.scouts:
        where = recorder.where(str(scout.get("scout")))
        if where is not None:
            scout.update(x=round(where[0], 2), y=round(where[1], 2))


def _robot_ids(config: Path) -> list[str]:
    """The robots of the hosts file, when this client's components read it (else none: their lasers are then
    advertised when first seen)."""
    from drd.errors import DrdError
    from drd.hosts import load_hosts
    from drd.manifests import load_catalog

    try:
        return [r.id for r in load_hosts(config, load_catalog()).robots]
    except (DrdError, OSError):
        return []


def _outputs(inputs: tuple[Path, Path, list[str]], trace: Path | None, record: Path | None, foxglove: str | None,
             detach: bool) -> tuple[IO[str] | None, Recorder | None]:
    """The `--trace` file and the recorder of `--record` and `--foxglove`, which need the records as they come;
    neither may be an input (`inputs`: the mission, the hosts file, the files the mission imports) or the other
    (`distinct_files`)."""
    mission, hosts, imported = inputs
    distinct_files({"the mission file": [mission], "the hosts file": [hosts],
                    "a file the mission imports": [Path(name) for name in imported]},
                   {"--trace": trace, "--record": record})
    if (trace is not None or record is not None or foxglove is not None) and detach:
        given = "--trace" if trace is not None else "--record" if record is not None else "--foxglove"
        fail(f"{given} needs the records as they come: it cannot be used with --detach")
    return open_trace(trace), live_recorder(record, foxglove, _robot_ids(hosts) if foxglove else ())


def _run_and_follow(client: ClusterClient, watch: _RecordWatch, request: Any, wait: float,
                    detach: bool, as_json: bool, interrupts: list[float]) -> DryRun | None:
    """Submit the mission, then follow it to its end (None when detached: its id is printed, under `--json` as an
    object). Ctrl-C before the controller took it stops nothing; after, it stops the mission and the report says
    how it ended. The report's pace is the world's: a mission that joins a running world runs at its speed."""
    from drd.daemon.missions import RunReply, run_key

    began = time.monotonic()
    reply: RunReply | None = None
    try:
        with _deferred_interrupt() as interrupted:  # a Ctrl-C or SIGTERM before `follow` would leave it unseen
            answer = client.bus.call(run_key(client.cluster), request, timeout=wait)
            if not isinstance(answer, RunReply):
                fail(f"the controller answered a {type(answer).TYPE}")
            if not answer.ok:
                _refused(request, answer.diagnostics, as_json)
            reply = answer
            if detach:
                if as_json:
                    print_json({"mission": reply.mission, "id": reply.mission, "world": reply.world,  # `id` as in
                                "speed": reply.speed, "priority": reply.priority})  # status --json
                else:
                    out.print(reply.mission)
                return None
            watch.started(reply)
            err.print(Text.assemble(("▶ ", "bold green"), f"mission {reply.mission} started on the cluster (world "
                                    f"{reply.world}, {reply.speed:g}x real time, priority {reply.priority})"))
            if reply.speed != request.speed:  # it joined a world another mission opened, which keeps its pace
                err.print(Text(f"  --speed {request.speed:g} not applied: the running world {reply.world} goes at "
                               f"{reply.speed:g}x, set by the mission that opened it", style="yellow"))
        if interrupted:
            interrupts.append(time.monotonic())  # held until now: its second delivery is the same Ctrl-C
            raise Terminated if signal.SIGTERM in interrupted else KeyboardInterrupt
        with _terminate_as_interrupt():
            report = watch.follow(reply.mission, request.until / reply.speed + 120.0, reply.base, began)
        report.speed = reply.speed
        return report
    except KeyboardInterrupt as e:  # the operator's Ctrl-C stops the mission, not just this command
        if reply is None:  # before the controller took it: nothing runs
            raise
        if isinstance(e, Terminated):
            _ignore_sigterm()  # a SIGTERM held while submitting: the next must not cut the stop short either
        return _stop_on_interrupt(client, watch, reply.mission, reply.base, began,
                                  "SIGTERM" if isinstance(e, Terminated) else "Ctrl-C")


def _mission_source(mission: Path) -> tuple[str, dict[str, str], dict[str, str]]:
    """The mission's text, those of the files it imports and their other names (read here, beside it: the controller
    compiles what it is sent, never a file of its own disk), once it is known to be a mission file."""
    from dsl.loader import import_aliases, imported_texts

    if not mission.exists():
        fail(f"{mission}: no such file (looked at {mission.absolute()})")
    program = _not_a_mission(mission)  # a folder too: "is a directory", as validate says
    # the text the loader read (once, with its checks), whose imports these are
    return program.sources[program.main], imported_texts(program), import_aliases(program)


def _not_a_mission(mission: Path) -> Program:
    """Refuse here, before asking the cluster, a file that is no mission at all (a hosts file, a README, an empty
    or comment-only file) or whose imports cannot be read, as `validate` and `dry-run` do; the controller checks the
    rest. The program read, with the texts of its imports."""
    from dsl.errors import Reporter
    from dsl.loader import load_file

    report = Reporter()
    program = load_file(mission, report)
    early = [d for d in report.diagnostics if d.code in ("not-a-mission", "empty", "io", "encoding")]
    if early:
        from drd.cli.common import fail_diagnostics

        fail_diagnostics(early, program.sources)
    return program


@contextmanager
def _deferred_interrupt() -> Iterator[list[int]]:
    """Hold a Ctrl-C (SIGINT) or a SIGTERM until the block ends; the list yielded has the signals that came."""
    got: list[int] = []
    try:
        previous = {signum: signal.signal(signum, lambda n, frame: got.append(n))
                    for signum in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:  # not the main thread: nothing to defer
        yield got
        return
    try:
        yield got
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


class Terminated(KeyboardInterrupt):
    """A SIGTERM to an attached `missionctl run`: handled as its Ctrl-C (the mission stops, the report and the
    trace are written), where the default action killed the client and left the mission driving with an empty
    trace (safety audit 8)."""


@contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """While the block runs, a SIGTERM raises `Terminated` in the main thread, as a Ctrl-C raises its interrupt.
    From the first on, later SIGTERMs are ignored until the process exits (`_ignore_sigterm`): the caller stops the
    mission and writes the report, then the process ends."""
    def terminated(signum: int, frame: FrameType | None) -> None:
        _ignore_sigterm()
        raise Terminated

    with _signal_handled(signal.SIGTERM, terminated, kept=lambda: False):
        yield


@contextmanager
def _signal_handled(signum: int, handler: Callable[[int, FrameType | None], None],
                    kept: Callable[[], bool]) -> Iterator[None]:
    """`handler` for `signum` while the block runs (in the main thread: elsewhere nothing changes), and the previous
    one back after it unless `kept()` says a stop under way needs it still, or the handler replaced itself."""
    try:
        previous = signal.signal(signum, handler)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        if not kept() and signal.getsignal(signum) is handler:
            signal.signal(signum, previous)


def _ignore_sigterm() -> None:
    """Ignore SIGTERM from now on: the stop a first one started must not be cut short by the next. timeout(1),
    a shell's job control and process managers send several (to the process, then to its group), and the second
    one's default action killed the client mid-stop: no report, the trace cut, the mission left driving (cluster
    audit 10, D2). A manager that must end it sends SIGKILL; the stop is bounded (5 s to ask, 15 s to follow)."""
    with suppress(ValueError):  # not the main thread: nothing to change
        signal.signal(signal.SIGTERM, signal.SIG_IGN)


#: Seconds after a Ctrl-C within which another is the same one delivered twice (timeout(1) passes a SIGINT on to
#: its child, which the terminal's process group got too: cluster audit 17, D3), not the operator's second.
SAME_INTERRUPT = 1.0


@contextmanager
def _interrupt_once() -> Iterator[list[float]]:
    """While the block runs, a Ctrl-C raises KeyboardInterrupt, as Python's own handler does; from the first on,
    another within `SAME_INTERRUPT` seconds of it is the same one delivered twice and is ignored. After an interrupt
    the handler stays (as `_terminate_as_interrupt`'s SIGTERM does) for the stop that follows, where a later Ctrl-C
    gives up waiting for the report; the process ends after that, and an interrupt then is ignored: the stop is
    done, and one raised while the report is printed or the trace closed escaped every handler (the client died of
    SIGINT, exit -2). Python runs the handler when the main thread is back from a blocking call, so the second
    delivery of one Ctrl-C, held through the stop's call on a busy machine, could run it more than `SAME_INTERRUPT`
    after the first: what is compared is when each came (`SignalArrivals`). Yields the times of the interrupts taken
    (a caller that raised one itself, held while it could not be, adds its time)."""
    first: list[float] = []
    ended: list[bool] = []

    def interrupted(signum: int, frame: FrameType | None) -> None:
        came = arrivals.take()  # when it came, not when this runs
        if ended or first and came[-1] - first[0] < SAME_INTERRUPT:
            return
        first.append(came[-1] if first else came[0])
        raise KeyboardInterrupt

    with SignalArrivals(signal.SIGINT) as arrivals, \
            _signal_handled(signal.SIGINT, interrupted, kept=lambda: bool(first)):
        try:
            yield first
        finally:
            ended.append(True)


def _stop_on_interrupt(client: ClusterClient, watch: _RecordWatch, mission: str, base: float, began: float,
                       why: str = "Ctrl-C") -> DryRun:
    """Ask the executive to stop `mission`, then wait (bounded) for its last records, so the report says how it
    ended; a second Ctrl-C gives up waiting (the mission is stopped either way)."""
    from drd.executive_messages import MissionCommand

    err.print(Text.assemble(("■ ", "bold yellow"), f"{why}: stopping mission {mission}"))
    try:
        client.bus.call(client.keys.executive, MissionCommand("stop", mission), timeout=5.0)
        return watch.follow(mission, 15.0, base, began)
    except KeyboardInterrupt:
        fail(f"mission {mission}: stop requested, its report was not awaited (see `missionctl status`)", code=1)
    except typer.Exit:
        raise
    except Exception as e:  # the controller may be the reason the operator pressed Ctrl-C
        fail(unconfirmed_stop(mission, str(e), watch.away_since is not None), code=1)


def unconfirmed_stop(mission: str, why: str, away: bool) -> str:
    """What a Ctrl-C whose stop the controller did not confirm leads to: with no controller the stop is lost, and
    its next start resumes the mission from the journal with nobody attached; the command that ends it for good."""
    then = ("the controller is away, so the stop is lost: when it starts again it resumes the mission, with nobody"
            if away else "if the controller is away the stop is lost: when it starts again it resumes the mission,"
            " with nobody")
    return (f"mission {mission}: could not confirm the stop ({why}); {then} attached. Once it is back, end it for"
            f" good with `missionctl stop {mission}` (`missionctl status` shows it)")


def stop(mission: str = typer.Argument("", help="The mission id (default: the one running).", show_default=False),
         every: bool = typer.Option(False, "--all", help="Stop every running mission."),
         config: Path = ConfigOption, connect: list[str] = ConnectOption, as_json: bool = JsonOption,
         timeout: float = TimeoutOption) -> int:
    """Stop a running mission (its behaviors are terminated, its resources released). Without an id it stops the
    one mission that runs; with several running it names them and stops none (`--all` stops them all). A mission
    that had already ended is not stopped: it says so, with its outcome (exit 0: it does not run)."""
    with cluster_client(config, connect, timeout, to="stop a mission") as client:
        missions = stop_missions(client, mission, every, timeout)
    ended = [m for m in missions if m.get("already_ended")]
    if as_json:
        print_json({"stopped": [mission_json(m) for m in missions if m not in ended],
                    "ended": [mission_json(m) for m in ended]})
        return OK
    if not missions:
        out.print("no mission is running: nothing to stop")
    for m in missions:
        how = f"{m.get('outcome') or 'running'} {m.get('reason') or ''}".rstrip()
        out.print(f"{m.get('id')}: had already ended ({how}): nothing to stop" if m in ended
                  else f"{m.get('id')}: {how}")
    return OK


def offers_title(count: int, text: str) -> str:
    """The header of `missionctl query`: `1 offer for Camera`, `7 offers for Camera`."""
    return f"{count} offer{'' if count == 1 else 's'} for {text}"


def mission_json(status: dict[str, Any]) -> dict[str, Any]:
    """A mission's status as `stop --json` and `status --json` give it: `mission` its name and `id` its id, times
    rounded as the reports round them (`report_time`), as `run --json` gives them: one shape for a script to read."""
    from drd.dryrun import report_time

    shown = dict(status)
    if isinstance(shown.get("id"), str):
        shown["mission"] = mission_name(shown["id"])
    for key in ("time", "started"):
        if isinstance(shown.get(key), int | float) and not isinstance(shown.get(key), bool):
            shown[key] = report_time(shown[key])
    return shown


def stop_missions(client: Any, mission: str, every: bool, timeout: float) -> list[dict[str, Any]]:
    """Ask the executive to stop `mission`, or every mission (`every`), or the only one running (none given): the
    status of each mission stopped. Refuses (exit 2, naming them) to guess between several running missions: a
    bare `missionctl stop` must never stop the wrong one."""
    from drd.executive_messages import MissionCommand, MissionStatus

    targets = [mission]
    if not mission:
        running = [str(m.get("id")) for m in client.missions() if m.get("outcome") is None]
        if not running:  # `--all` asks anyway: a controller resuming its journal says it cannot stop those yet
            if every:  # (cluster audit 26, D1: "nothing to stop", then the journal's mission ran)
                client.bus.call(client.keys.executive, MissionCommand("stop", ""), timeout=max(timeout, 5.0))
            return []
        if len(running) > 1 and not every:
            fail(f"{len(running)} missions run ({', '.join(running)}): say which to stop",
                 hint=f"missionctl stop {running[0]}, or missionctl stop --all", running=running)
        targets = running if every else running[:1]
    stopped: list[dict[str, Any]] = []
    for target in targets:
        reply = client.bus.call(client.keys.executive, MissionCommand("stop", target), timeout=max(timeout, 5.0))
        if isinstance(reply, MissionStatus):
            stopped += [m for m in reply.missions if m.get("id") == target]
    return stopped


def progress_line(sim_time: float, active: list[str], width: int = 80, phases: Mapping[str, str] | None = None) -> Text:
    """`missionctl run`'s line each second: the sim time (the executive's, so it moves even when no record comes)
    and the leaves entered, by phase (`active`, `suspended`, `waiting`: a leaf takes the phase of its nearest node,
    itself or above, that `phases` marks), fitted to `width`: a preempted mission must not read as running."""
    leaves = [p for p in active if not any(q.startswith((p + "/", p + "[")) for q in active)]
    marks = phases or {}
    groups: dict[str, list[str]] = {}
    for leaf in leaves:
        groups.setdefault(_phase_of(leaf, marks), []).append(leaf.rsplit("/", 1)[-1])
    text = Text.assemble(("sim ", "dim"), f"{sim_time:7.1f} s")
    room = max(10, width - len(text) - 1)
    for phase in [p for p in ("active", "suspended", "waiting") if p in groups] or ["active"]:
        names = ", ".join(groups.get(phase, [])[:6]) or "—"
        if len(groups.get(phase, [])) > 6:
            names += f" +{len(groups[phase]) - 6}"
        room -= len(phase) + 3
        if len(names) > max(6, room):
            names = names[:max(6, room) - 1] + "…"
        room -= len(names)
        text.append_text(Text.assemble(("  ", ""), (f"{phase} ", "dim" if phase == "active" else "bold yellow"),
                                       names))
    return text


def _phase_of(path: str, phases: Mapping[str, str]) -> str:
    """The phase of the nearest node, `path` or above it, that is marked (suspended or waiting), else `active`."""
    node = path
    while node:
        if node in phases:
            return str(phases[node])
        node = node.rsplit("/", 1)[0] if "/" in node else ""
    return "active"


def track_phase(phases: dict[str, str], record: Any) -> None:
    """Keep `phases` (path -> `waiting` or `suspended`) up to date with one record of the mission: a node waits from
    its `waiting` to its `granted`, is suspended from its `suspended` to its `resumed`; an exit ends both, and a
    restore (after a controller loss) all of them: every state is entered afresh, with no `resumed` (a node
    suspended before the loss was shown suspended for ever, though it ran again)."""
    from drd.runtime import records as rec

    if isinstance(record, rec.Restored):
        phases.clear()
    elif isinstance(record, rec.Waiting):
        phases.setdefault(record.path, "waiting")
    elif isinstance(record, rec.Suspended):
        phases[record.path] = "suspended"
    elif isinstance(record, rec.Granted) and phases.get(record.path) == "waiting" or isinstance(
            record, rec.Resumed | rec.Exited):
        phases.pop(record.path, None)


#: Seconds a client waits, once it lost the controller, for the mission to be there again (a restarted controller
#: resumes it once the hosts are back: up to two leases and a few seconds after its start).
RESUME_PATIENCE = 60.0


#: On a pipe or a file, seconds before an unchanged progress line is written again (it still says the run lives).
PIPE_REPEAT = 30.0


class ProgressGate:
    """Which of `missionctl run`'s progress lines to write: each one on a terminal; on a pipe or a file only a line
    that changed, or the same one after `PIPE_REPEAT` s. While the controller was away (its sim time still), a log
    got the same line once a second."""

    def __init__(self, terminal: bool, repeat: float = PIPE_REPEAT) -> None:
        self.terminal = terminal
        self.repeat = repeat
        self.last = ""
        self.at = -math.inf

    def due(self, line: str, now: float) -> bool:
        """Whether to write `line` at `now` (monotonic seconds); a line written is remembered."""
        if self.terminal:
            return True
        if line == self.last and now - self.at < self.repeat:
            return False
        self.last, self.at = line, now
        return True


class _RecordWatch:
    """The records of the cluster's missions, from the moment `missionctl run` subscribed; then a report."""

    #: Seconds between progress lines (and between asking the executive how the mission is).
    every = 1.0

    def __init__(self, client: ClusterClient, trace: IO[str] | None = None, recorder: Recorder | None = None,
                 worlds: Sequence[Path] = ()) -> None:
        import queue

        from drd.executive_messages import MissionRecord

        self.client = client
        self.trace = trace  # --trace: the followed mission's records, as docs/trace.md lines
        self.recorder = recorder  # --record: the same records, into an MCAP file
        self.queue: queue.Queue[object] = queue.Queue()
        self.seen: dict[str, tuple[DryRun, dict[str, None]]] = {}  # mission -> (its report so far, active paths)
        self.phases: dict[str, dict[str, str]] = {}  # mission -> its nodes waiting or suspended (`track_phase`)
        self.away_since: float | None = None  # when the controller stopped answering (None: it answers)
        self.behind = False  # the controller came back: the records it sent before we heard it are still to fetch
        self.seqs: set[int] = set()  # the numbers of the records followed (a record caught up twice counts once)
        self.last_seq = 0
        #: the last record heard before the controller went away: the catch-up starts there, not at the newest
        #: record heard since (the resumed controller's live records may come before the catch-up, and its
        #: first ones, `restored` among them, before this client's subscription reached it)
        self.heard_before = 0
        #: live records that came while the controller was away or before the catch-up: taken with it, in `seq`
        #: order (a resumed mission's first live records would otherwise go before the old ones caught up)
        self.held: list[Any] = []
        self.away_total = 0.0  # seconds the controller did not answer, over the run (a restart, a failover)
        self.resumed: dict[str, Any] | None = None  # the mission's `resumed` as the controller last said it
        self.gate = ProgressGate(err.is_terminal)  # on a pipe, a progress line only when it changed
        self.view: _ClusterView | None = None
        self.priority = 1  # the started mission's, as the controller said it (`started`)
        self.worlds = tuple(worlds)  # where the mission's world is found, before drd's own (beside the hosts file)

        def on_record(sample: Any) -> None:
            if isinstance(sample.payload, MissionRecord):
                self.queue.put(sample.payload)
        self.sub = client.bus.subscribe(f"drd/{client.cluster}/mission/*/record", on_record)

    def started(self, reply: Any) -> None:
        """The controller started the mission (`RunReply`): what the client sees of the cluster goes into the
        recording from now on (`_ClusterView`)."""
        self.priority = reply.priority
        if self.recorder is not None and self.view is None:
            self.view = _ClusterView(self.client, self.recorder, reply, self.worlds)

    def close(self) -> None:
        self.sub.close()
        if self.view is not None:
            self.view.close()
        if self.recorder is not None and self.recorder.closed is False and not self.seen:
            self.recorder.close()  # nothing followed (refused, or an error): an empty but valid file

    def follow(self, mission: str, limit: float, base: float = 0.0, began: float | None = None) -> DryRun:
        """Print progress until the mission's `finished` record (or its outcome in the status); the report."""
        import queue

        from drd.dryrun import DryRun
        from drd.runtime import records as rec

        if mission not in self.seen:  # a second follow (after a Ctrl-C) goes on with what the first received
            self.seen[mission] = (DryRun(mission_name(mission), None, "", 0.0, 0.0, priority=self.priority,
                                         mission_id=mission), {})
        result, active = self.seen[mission]
        phases = self.phases.setdefault(mission, {})  # path -> waiting or suspended (`track_phase`)
        start = time.monotonic()
        next_print = next_poll = start + self.every
        finished = None
        clock = 0.0  # the mission's time as the executive last said it (records may not come for a long while)
        while finished is None:
            now = time.monotonic()
            if now - start > limit:
                fail(f"mission {mission} did not finish within {limit:.0f} s", code=1)
            try:
                msg: Any = self.queue.get(timeout=0.2)
            except queue.Empty:
                msg = None
            if msg is not None and msg.mission == mission and (self.away_since is not None or self.behind):
                self.held.append(msg)  # taken in order once caught up (`_catch_up`)
            elif msg is not None and msg.mission == mission and msg.seq not in self.seqs:
                self.seqs.add(msg.seq)
                self.last_seq = max(self.last_seq, msg.seq)
                r = self._take(msg, result, base)
                track_phase(phases, r)
                if isinstance(r, rec.Entered):
                    active[r.path] = None
                elif isinstance(r, rec.Exited):
                    active.pop(r.path, None)
                elif isinstance(r, rec.Finished):
                    finished = (r.outcome, r.reason)
                    if self.view is not None:  # what the shared world reads after it is not this mission's
                        self.view.ended_at = r.at
            now = time.monotonic()
            if now >= next_poll and finished is None:  # a missed record must not hang us: ask the executive
                next_poll = now + self.every
                clock, finished = self._polled(mission, result, base, clock)
            if now >= next_print and finished is None:
                next_print = now + self.every
                self._progress(max(result.sim_time, clock), list(active), phases, now)
        result.outcome, result.reason = finished
        result.wall_time = time.monotonic() - (start if began is None else began)
        result.away = self.away_total
        return result


    def _polled(self, mission: str, result: Any, base: float, clock: float) -> tuple[float, tuple[str, str] | None]:
        """The mission's time as the executive says it, and its (outcome, reason) once it ended: then the records
        still in flight (or held for a catch-up that did not come) are taken first, in order."""
        finished = None
        for m in self._missions(mission):
            if m.get("id") == mission and isinstance(m.get("time"), int | float):
                clock = max(clock, float(m["time"]) - base)
            if m.get("id") == mission and m.get("outcome"):
                time.sleep(0.5)  # the records in flight come first
                if self.held:
                    self._requeue(mission, [])
                while not self.queue.empty():
                    extra: Any = self.queue.get()
                    if extra.mission == mission and extra.seq not in self.seqs:
                        self.seqs.add(extra.seq)
                        self._take(extra, result, base)
                finished = (m["outcome"], m.get("reason") or "")
                # no `finished` record says when it ended: the executive's time does (a mission that could not be
                # resumed after its controller's loss ended with none, and its report said 0.0 s; cluster audit 10)
                result.sim_time = max(result.sim_time, clock)
        return clock, finished

    def _progress(self, sim_time: float, active: list[str], phases: dict[str, str], now: float) -> None:
        """The progress line, when due: each second on a terminal, on a pipe only when it changed (`ProgressGate`);
        and the trace so far on disk, whatever ends this process."""
        if self.trace is not None:
            self.trace.flush()
        line = progress_line(sim_time, active, err.width, phases)
        if self.gate.due(line.plain, now):
            err.print(line)

    def _missions(self, mission: str) -> list[dict[str, Any]]:
        """The executive's missions; none while the controller does not answer (it may be restarting: a
        controller started again resumes its missions from its journal), said once when it goes and comes back."""
        from drd.bus import RemoteError
        from drd.errors import BusFailure

        try:
            missions = self.client.missions(mission)  # this one only: a long history is not asked each second
        except RemoteError:  # it answered, with a refusal: busy (a large mission's first cycle), not away
            return []
        except BusFailure:
            if self.away_since is None:
                self.away_since = time.monotonic()
                self.heard_before = self.last_seq
                err.print(Text.assemble(("⚠ ", "bold yellow"), "the controller does not answer: waiting for it (a"
                                        " standby takes over, or the controller started again, and resumes the"
                                        " mission from its journal)"))
            return []
        if self.away_since is not None:
            if not any(m.get("id") == mission for m in missions):  # back, but not resumed yet (it waits for the
                if time.monotonic() - self.away_since < RESUME_PATIENCE:  # hosts first): keep waiting a while
                    return missions
                fail(f"mission {mission}: the controller came back without it (it kept no journal of it): see"
                     " `missionctl status`", code=1)
            away, self.away_since = self._away(mission, missions), None
            self.away_total += away
            # "resumed" only once its `restored` record says so (`_take`): a controller that was frozen past the
            # lease carries on with a mission whose hosts stopped it, which then ends, saying why
            err.print(Text.assemble(("▶ ", "bold green"), f"the controller is back after {away:.1f} s"))
            self.behind = True
        if self.behind:  # until the executive answered: it may be busy with the resumed mission's first cycles
            self.behind = not self._catch_up(mission)
        self.resumed = _resumed(mission, missions)
        return missions

    def _away(self, mission: str, missions: list[dict[str, Any]]) -> float:
        """How long `mission` had no controller: as the controller that resumed it says (`resumed.paused`, what
        `missionctl status` shows), or, when it was not resumed since (a controller frozen, not restarted), as this
        client timed it, from its first unanswered poll to the first answered one."""
        resumed = _resumed(mission, missions)
        if resumed is not None and resumed != self.resumed and isinstance(resumed.get("paused"), int | float):
            return float(resumed["paused"])
        return time.monotonic() - (self.away_since or time.monotonic())

    def _catch_up(self, mission: str) -> bool:
        """The records of `mission` sent while this client could not hear the controller (it resumed the mission
        before this session found it again), from the executive's own copy; duplicates are dropped by `follow`.
        Whether the executive answered."""
        from drd.errors import BusFailure

        try:
            records = self.client.records(mission, self.heard_before)  # page by page (`drd.paging`)
        except BusFailure:
            return False  # the live records go on (held); the next poll asks again
        self._requeue(mission, records)
        return True

    def _requeue(self, mission: str, records: list[Any]) -> None:
        """`records` caught up, the live ones held and those still queued, into the queue once each, in `seq` order
        (the same thread takes them: nothing else reads the queue)."""
        import queue

        pending, self.held = [*self.held, *records], []
        while True:
            try:
                pending.append(self.queue.get_nowait())
            except queue.Empty:
                break
        by_seq = {r.seq: r for r in pending if r.mission == mission}
        for seq in sorted(by_seq):
            self.queue.put(by_seq[seq])

    def _take(self, msg: Any, result: Any, base: float) -> Any:
        """One record of the followed mission: into its report (and the trace file); the record, or None."""
        from drd.dryrun import facts, report_time
        from drd.runtime import records as rec

        if self.trace is not None:
            line = {"kind": msg.kind, "at": report_time(msg.at - base), "path": msg.path, **_rebased(msg.data, base),
                    "mission": msg.mission, "seq": msg.seq}
            self.trace.write(json.dumps(line, separators=(",", ":"), default=str) + "\n")
        r = _record(msg, rec, base)
        if isinstance(r, rec.Restored):
            err.print(Text.assemble(("▶ ", "bold green"), f"mission {msg.mission} resumed from its state at"
                                    f" {r.since:.1f} s"))
        if r is not None:
            if self.recorder is not None:
                self.recorder.record(msg.mission, r, msg.seq)  # as the trace line has it
            result.records.append(r)
            facts(result, r)
            result.sim_time = max(result.sim_time, r.at)
        return r


def shown_property(value: Any) -> str:
    """A property as the query table shows it: a float to 3 decimals (a live pose is a float of the physics, whose
    17 digits say nothing to a reader; --json keeps them)."""
    if not isinstance(value, float):
        return str(value)
    text = f"{value:.3f}".rstrip("0").rstrip(".")
    return "0" if text == "-0" else text


def live_recorder(record: Path | None, foxglove: str | None, robots: Sequence[str] = (),
                  waits: bool = False) -> Recorder | None:
    """The recorder of `--record FILE` and `--foxglove [HOST:PORT]` (None when neither is asked), or a clear exit;
    `robots`: those whose laser the live view advertises from its start; `waits`: the run waits for a first viewer
    (a dry-run's, `Recorder.wait_for_viewer`), which the line saying where it is served says."""
    if record is None and foxglove is None:
        return None
    from drd.record import FIRST_VIEWER, Recorder, RecordingError

    try:
        recorder = Recorder(record, serve=None if foxglove is None else live_address(foxglove), robots=robots)
    except RecordingError as e:
        fail(str(e))
    if recorder.port is not None:
        host = live_address(foxglove or "")[0]
        host = f"[{host}]" if ":" in host else host
        waiting = f"; the run waits up to {FIRST_VIEWER:g} s for a first viewer" if waits else ""
        err.print(Text.assemble(("● ", "bold green"), f"live view on ws://{host}:{recorder.port} (Foxglove: Open"
                                f" connection, Foxglove WebSocket; layout docs/foxglove-layout.json){waiting}"))
    return recorder


def live_address(text: str) -> tuple[str, int]:
    """`HOST:PORT`, `:PORT` or `PORT` (the host then loopback's 127.0.0.1), or a clear exit."""
    from drd.record import LIVE_DEFAULT

    host, _, port = text.rpartition(":") if ":" in text else ("", "", text)
    host = host.strip("[]") or LIVE_DEFAULT[0]
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        fail(f"--foxglove {text!r}: expected HOST:PORT (such as 127.0.0.1:8765) or a port")
    return host, int(port)


#: Pages of readings asked for at most in one round (`_ClusterView._observe`): a client far behind catches up over
#: several rounds rather than holding up the others.
MAX_PAGES = 8


class _ClusterView:
    """`run --record`/`--foxglove`: the cluster as this client sees it, into the recording (`drd.record`): each
    host's load reports as they come (`/drd/hosts/load`); asked every `every` s in a thread of its own, the hosts
    (up or down) and where each component instance runs, when they change (`/drd/hosts`, `/drd/placements`), and
    from the simulator's host the robots' poses (`/drd/tf`; a Scout in a magazine as its Ranger's frame) and what
    their sensors read (scans, camera frames, light, launches and landings, doors: the dry-run's channels); on real
    robots (no simulator host), the same from each host that has robots (`host/<name>/robots`: its drivers' poses
    and scans, `drd.cluster.observe`). Times are the mission's (the recorder's latest record time; the simulator's,
    or each host's, time less its offset)."""

    #: Seconds (wall) between two requests for the poses, and between two for the hosts and placements.
    every, hosts_every = 0.2, 1.0

    def __init__(self, client: ClusterClient, recorder: Recorder, reply: Any, worlds: Sequence[Path] = ()) -> None:
        import threading

        from drd.bus.messages import LoadReport

        self.client, self.recorder, self.base = client, recorder, float(reply.base)
        self.said: dict[str, Any] = {}  # what was last written on each channel (only changes are written)
        self.world = self._world(str(reply.world), worlds)
        self.offset: float | None = None  # mission time = simulator time + offset (None: not known yet)
        self.cursor = 0  # the simulator host's next reading to ask for (`drd.sim.observe.Observations`)
        self.ended_at = math.inf  # the mission's `finished` (mission time): nothing after it is recorded
        from drd.daemon.missions import NO_WORLD

        self.real = str(reply.world) == NO_WORLD  # real robots: each host with robots says what its drivers read
        self.robot_hosts: list[str] = []  # the hosts up with robots (from `_hosts`)
        self.hosts_read: dict[str, tuple[int, float]] = {}  # host -> (its next reading, mission time - its time)

        def on_load(sample: Any) -> None:
            if isinstance(sample.payload, LoadReport):
                recorder.json("/drd/hosts/load", recorder.now, asdict(sample.payload))

        self.sub = client.bus.subscribe(client.keys.loads, on_load)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, name="drd-record-cluster", daemon=True)
        self.thread.start()

    def _world(self, name: str, worlds: Sequence[Path]) -> Any:
        """The mission's world as this client has it, beside its hosts file or drd's own (for the scene, and the
        robots to ask about)."""
        from drd.sim.service import world_file
        from drd.sim.world import WorldError, load_world

        try:
            world = load_world(world_file(name, worlds))
        except (ValueError, WorldError, OSError):
            return None
        self.recorder.scene(world)
        return world

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=5.0)
        self.sub.close()

    def _loop(self) -> None:
        from drd.errors import BusFailure

        next_hosts = 0.0
        while not self.stop.is_set():
            steps = [self._observe]
            if time.monotonic() >= next_hosts:
                next_hosts = time.monotonic() + self.hosts_every
                steps += [self._hosts, self._placements]
            for step in steps:
                try:
                    step()
                except (BusFailure, ValueError, KeyError, TypeError):
                    pass  # a host or the simulator that does not answer now: asked again next time
            self.recorder.flush(self.recorder.now)
            self.stop.wait(self.every)

    def _changed(self, topic: str, value: Any, extra: dict[str, Any] | None = None) -> None:
        """Write `value` (and `extra`) on `topic` if `value` is not what was written last."""
        if self.said.get(topic) != value:
            self.said[topic] = value
            self.recorder.json(topic, self.recorder.now, {"at": self.recorder.now, **value, **(extra or {})})

    def _hosts(self) -> None:
        """Each host up or down (since when, why), its roles, instances, robots and devices; and the cluster's
        events not yet written (a host that came, went, or disagrees)."""
        reply = self.client.hosts(events=20)
        hosts = [{**{k: v for k, v in asdict(h).items() if k in ("name", "state", "reason", "roles", "instances",
                                                                "robots", "devices")},
                  "since": None if h.since is None else round(h.since, 1)} for h in reply.hosts]
        seen = self.said.setdefault("events", set())
        events = [asdict(e) for e in reply.events if (e.at, e.kind, e.host) not in seen]
        seen.update((e["at"], e["kind"], e["host"]) for e in events)
        if events:  # something happened: written even if the hosts look the same again
            self.said.pop("/drd/hosts", None)
        self._changed("/drd/hosts", {"hosts": hosts}, {"answered_by": reply.answered_by, "events": events})
        self.robot_hosts = [h["name"] for h in hosts if h["robots"] and h["state"] == "up"]

    def _placements(self) -> None:
        instances = sorted((asdict(i) for i in self.client.components().instances),
                           key=lambda i: (str(i["mission"]), str(i["name"])))
        self._changed("/drd/placements", {"instances": [{k: i[k] for k in ("name", "component", "host", "mission",
                                                                         "state")} for i in instances]})

    def _observe(self) -> None:
        """Every robot's pose, and what the sensors read since the last time, from the simulator's host, page by
        page (`drd/<cluster>/world`, which every role may read: a closed cluster's observer records them too)."""
        from drd.bus import RemoteError
        from drd.record import INTRUDER
        from drd.sim.observe import replay
        from drd.sim.service import WorldObservation, WorldObserve, world_key

        if self.world is None:
            if self.real:
                self._observe_robots()
            return
        seen: WorldObservation | None = None
        for _ in range(MAX_PAGES):
            try:
                reply = self.client.bus.call(world_key(self.client.cluster), WorldObserve(self.cursor),
                                             timeout=self.client.timeout)
            except RemoteError:  # no world runs yet (or any more): asked again next time
                return
            if not isinstance(reply, WorldObservation):
                return
            seen = reply
            if self.offset is None:
                self.offset = self._calibrate(reply.time)
            for reading in reply.readings:  # those of the world before this mission began, or after it ended, are
                if 0.0 <= float(reading.get("at", 0.0)) + self.offset <= self.ended_at:  # not its own (records
                    replay(reading, self.recorder, self.offset)  # audit 26, D5: seconds of another mission's)
            self.cursor = reply.next
            if not reply.more:
                break
        if seen is None or self.offset is None:
            return
        poses = {rid: (v[0], v[1], v[2]) for rid, v in seen.poses.items()}
        poses.update({INTRUDER + iid: (v[0], v[1], 0.0) for iid, v in seen.intruders.items()})
        at = seen.time + self.offset
        if at > self.ended_at:
            return
        self.recorder.transforms(at, poses, dict(seen.carried))
        self.recorder.land(at)

    def _observe_robots(self) -> None:
        """Real robots: each host with robots, its robots' poses now and its drivers' scans since the last time
        (`host/<name>/robots`, read-only, every role's, as the simulator's world is); the poses into one `/drd/tf`
        message a round (each host's clock less its own offset: hosts' clocks need not agree)."""
        from drd.bus import RemoteError
        from drd.errors import BusFailure
        from drd.sim.observe import replay
        from drd.sim.service import WorldObservation, WorldObserve

        poses: dict[str, tuple[float, float, float]] = {}
        latest: float | None = None
        for host in self.robot_hosts:
            cursor, offset = self.hosts_read.get(host, (0, math.nan))
            for _ in range(MAX_PAGES):
                try:
                    reply = self.client.bus.call(self.client.keys.robots(host), WorldObserve(cursor),
                                                 timeout=self.client.timeout)
                except (RemoteError, BusFailure):  # a host that does not answer now: asked again next time
                    break
                if not isinstance(reply, WorldObservation):
                    break
                if math.isnan(offset):
                    offset = self._real_offset(reply.time)
                for reading in reply.readings:  # those from before this mission began are not its own
                    if float(reading.get("at", 0.0)) + offset >= 0.0:
                        replay(reading, self.recorder, offset)
                cursor = reply.next
                if not reply.more:
                    poses.update({rid: (v[0], v[1], v[2]) for rid, v in reply.poses.items()})
                    latest = max(latest if latest is not None else -math.inf, reply.time + offset)
                    break
            self.hosts_read[host] = (cursor, offset)
        if latest is not None and latest >= 0.0 and poses:
            self.recorder.transforms(latest, poses, {})

    def _real_offset(self, host_time: float) -> float:
        """The mission's time less a host's clock, on real robots: the executive's time asked right after the
        host's (real time, not rounded: the hosts' clocks count in no control periods)."""
        from drd.executive_messages import MissionCommand, MissionStatus

        status = self.client.bus.call(self.client.keys.executive_status, MissionCommand("status"),
                                      timeout=self.client.timeout)
        if not isinstance(status, MissionStatus):
            raise ValueError("the executive did not say its time")
        return status.time - self.base - host_time

    def _calibrate(self, sim_time: float) -> float:
        """The mission's time less the simulator's (the executive's clock is the simulator's plus an offset, and a
        mission's records count from its start): the executive's time asked right after the simulator's, rounded
        to the control period (both count in whole periods)."""
        from drd.executive_messages import MissionCommand, MissionStatus

        status = self.client.bus.call(self.client.keys.executive_status, MissionCommand("status"),
                                      timeout=self.client.timeout)
        if not isinstance(status, MissionStatus):
            raise ValueError("the executive did not say its time")
        return round((status.time - self.base - sim_time) / 0.1) * 0.1


def mission_name(mission_id: str) -> str:
    """The mission's name in its id (`HallSentry-9539828` -> `HallSentry`: the controller names a mission
    `<name>-<number>`): a cluster run's report means by `mission` and `id` what a dry-run's does, and its paths,
    which begin with the name, are shown below it."""
    name, dash, number = mission_id.rpartition("-")
    return name if dash and name and number.isdigit() else mission_id


def _record(msg: Any, rec: Any, base: float = 0.0) -> Any:
    """A `MissionRecord` from the wire as the runtime's record (what the dry-run's report reads)."""
    from drd.dryrun import report_time

    return rec.from_dict({**_rebased(msg.data, base), "kind": msg.kind, "at": report_time(msg.at - base),
                          "path": msg.path})


#: Fields of a record that are times, as `at` is (docs/trace.md): made relative to the mission's start too.
TIME_FIELDS = ("since",)


def _rebased(data: dict[str, Any], base: float) -> dict[str, Any]:
    """A record's fields with its times relative to the mission's start, as `at`."""
    from drd.dryrun import report_time

    if not base or not any(k in data for k in TIME_FIELDS):
        return data
    return {k: report_time(v - base) if k in TIME_FIELDS and isinstance(v, int | float) else v for k, v in data.items()}


# --- rendering -------------------------------------------------------------------------------------


def _watch(fetch: Callable[[], dict[str, Any]], as_json: bool, interval: float, explain: bool = False) -> None:
    """Refresh until Ctrl-C: a live view on a terminal, one JSON line per refresh with --json."""
    from rich.live import Live

    try:
        if as_json:
            while True:
                out.out(json.dumps(fetch()), highlight=False)
                time.sleep(interval)
        with Live(status_view(fetch(), explain=explain), console=out, auto_refresh=False) as live:
            while True:
                time.sleep(interval)
                live.update(status_view(fetch(), explain=explain), refresh=True)
    except KeyboardInterrupt:
        return


def status_view(data: dict[str, Any], width: int | None = None, explain: bool = False) -> RenderableType:
    """The cluster at a glance, what matters first (a terminal of 24 rows shows the top): the missions and their
    active trees, the hosts, the resources grouped by robot, then instances and recent events; long paths are cut
    from the middle to fit `width` (default: the console's)."""
    from rich.console import Group
    from rich.table import Table

    width = width or out.width
    data = with_waits(data)
    parts: list[RenderableType] = [
        Text.assemble(("cluster ", "bold"), data["cluster"], (f"  (answered by {data['answered_by']})", "dim"))]
    if data["missions"] is not None:
        parts += _missions_view(data["missions"], width, explain)
    parts.append(_hosts_table(data["hosts"], data["at"]))
    if data["resources"] is not None:
        parts += _resources_view(data["resources"], width, compact=True)
    daemon = data.get("daemon") or {}
    for host, why in daemon.get("unreachable", {}).items():
        parts.append(Text.assemble((f"{host} unreachable from {daemon['host']}: ", "bold yellow"), why))
    for what, message in data["errors"].items():
        parts.append(Text.assemble((f"{what}: ", "bold yellow"), message))
    if data["instances"]:
        t = Table(title="instances", title_justify="left")
        for col in ("name", "component", "host", "state", "pid"):
            t.add_column(col, no_wrap=True)
        rows = [(i["component"], i["host"], i["state"], str(i.get("pid") or "—")) for i in data["instances"]]
        fixed = sum(max(len(col), *(len(r[k]) for r in rows)) for k, col in enumerate(("component", "host", "state",
                                                                                          "pid"))) + 16
        for i, row in zip(data["instances"], rows, strict=True):
            t.add_row(shorten(i["name"], max(16, width - fixed)), *row)
        parts.append(t)
    else:
        parts.append(Text("instances: none", style="dim"))
    if data["events"]:
        t = Table(title="recent events", title_justify="left")
        for col in ("at", "host", "event", "detail"):
            t.add_column(col, no_wrap=col != "detail")
        for e in data["events"]:
            t.add_row(time.strftime("%H:%M:%S", time.localtime(e["at"])) + f".{int(e['at'] % 1 * 1000):03d}",
                      e["host"], e["kind"], e["detail"])
        parts.append(t)
    return Group(*parts)


#: Seconds without a load report after which an up host shows as `silent` (a daemon reports every second or less).
SILENT_AFTER = 1.5


def _hosts_table(rows: list[dict[str, Any]], now: float) -> Table:
    from rich.table import Table

    table = Table(title="hosts", title_justify="left")
    for col in ("host", "state", "cpu", "mem", "load1", "inst", "since", "why"):
        table.add_column(col, no_wrap=col != "why")
    for h in rows:
        up = h["state"] == "up"
        since = "—" if h["since"] is None else _ago(now - h["since"])
        load1 = "—" if h["load1"] is None or not up else f"{h['load1']:.2f}"
        age = h.get("report_age")
        silent = up and isinstance(age, int | float) and age > SILENT_AFTER  # frozen, or its link is
        style = "green" if up else "bold yellow" if h["state"] == "unresponsive" else "bold red"
        state = Text("silent", style="bold yellow") if silent else Text(h["state"], style=style)
        why = f"no load report for {age:.1f} s (down at its lease)" if silent else h["reason"]
        table.add_row(h["name"] + ("*" if "controller" in h["roles"] else ""), state, _pct(h["cpu"] if up else None),
                      _pct(h["memory"] if up else None), load1, str(h["instances"]) if up else "—", since, why)
    table.caption = "* controller"
    table.caption_justify = "left"
    return table


def _ago(seconds: float) -> str:
    seconds = max(0.0, seconds)
    if seconds < 120:
        return f"{seconds:.1f}s ago"
    return f"{seconds / 60:.0f}min ago" if seconds < 7200 else f"{seconds / 3600:.0f}h ago"


def _resources_view(data: dict[str, Any], width: int | None = None, compact: bool = False) -> list[RenderableType]:
    """The manager's resources grouped by robot: each robot with its holders and waiters, then its parts (`compact`:
    only those held apart from their robot), then the units of several robots (a shared radio) and of none."""
    from rich.table import Table

    width = width or out.width
    units = {u["id"]: u for u in data["units"]}
    owners: dict[str, list[str]] = {}
    for r in data["robots"]:
        for unit in r["parts"].values():
            owners.setdefault(unit, []).append(r["id"])
    columns = ("resource", "holders", "queue", "use") if compact else ("resource", "holders", "queue", "epoch", "use")
    labels = [len(r["id"]) + len(r["type"]) + 1 for r in data["robots"]] + [
        len(u) + 2 for u in units if len(owners.get(u, [])) != 1] + [
        len(part) + 2 for r in data["robots"] for part in r["parts"]]
    fixed = min(max(labels, default=8), 24) + 5 + (0 if compact else 5) + 3 * len(columns) + 1  # and the borders
    room = max(12, (width - fixed) // 2)

    everyone = [h for u in data["units"] for h in (*u["holders"], *u["queue"])] + [w["holder"] for w in data["queue"]]
    one_mission = len({h.split("/", 1)[0] for h in everyone}) <= 1
    order = {str(w["holder"]): i for i, w in enumerate(data["queue"])}

    def name(holder: str) -> str:
        """Below its mission's root when one mission holds everything, else with its mission id (`holder_label`)."""
        return holder_label(holder, room, several=not one_mission)

    def who(paths: list[str]) -> str:
        return ", ".join(name(p) for p in paths[:2]) + (f" +{len(paths) - 2}" if len(paths) > 2 else "") \
            if paths else "—"

    table = Table(title="resources by robot", title_justify="left")
    for col in columns:
        table.add_column(col, no_wrap=col in ("use", "epoch"))

    def unit_row(label: str, u: dict[str, Any]) -> None:
        cells = [label, who(u["holders"]), who(u["queue"])] + ([] if compact else [str(u["epoch"])])
        table.add_row(*cells, f"{u['load']:g}/{u['capacity']:g}")

    for r in data["robots"]:
        mine = [(part, units[unit]) for part, unit in r["parts"].items() if unit in units and len(owners[unit]) == 1]
        queue = sorted({q for _, u in mine for q in u["queue"]}, key=lambda q: (order.get(q, len(order)), q))
        label = Text.assemble((r["id"], "bold"), (f" {r['type']}", "dim"))
        table.add_row(label, who(r["holders"]), who(queue), *([""] * (len(columns) - 3)))
        for part, u in mine:
            if not compact or sorted(u["holders"]) != sorted(r["holders"]):
                unit_row(f"  {part}", u)
    shared = [u for uid, u in units.items() if len(owners.get(uid, [])) > 1]
    alone = [u for uid, u in units.items() if uid not in owners]
    for title, group in (("shared", shared), ("not in a robot", alone)):
        if group:
            table.add_row(Text(title, style="bold"), *([""] * (len(columns) - 1)))
            for u in group:
                unit_row(f"  {u['id']}", u)
    parts: list[RenderableType] = [table]
    if data["queue"]:
        parts.append(Text("waiting: " + ", ".join(
            f"{name(w['holder'])} (mission priority {w.get('mission_priority', 1)}, priority {w['priority']})"
            for w in data["queue"])))
    return parts + _leaving(data)


def _leaving(data: dict[str, Any]) -> list[RenderableType]:
    """A line for each host whose resources are leaving the manager, or left it while the host is unresponsive."""
    states = data.get("hosts") or {}
    parts: list[RenderableType] = [
        Text(f"{host} is {states.get(host, 'down')}: its resources leave the manager in {left:.1f} s", style="yellow")
        for host, left in data["removing"].items()]
    parts += [Text(f"{host} is unresponsive: its resources left the manager until it reports again", style="yellow")
              for host, state in states.items() if host not in data["removing"] and state == "unresponsive"]
    silent = sorted({str(u["host"]) for u in data["units"] if u.get("offline")} - set(data["removing"]) - set(states))
    parts += [Text(f"{host} did not answer a call: its resources are granted to no one new until it reports again",
                   style="yellow") for host in silent]
    return parts


#: How many nodes of a mission's active tree `status` shows (the rest is counted; `--json` has them all).
TREE_NODES = 12


def _missions_view(missions: list[dict[str, Any]], width: int = 80, explain: bool = False) -> list[RenderableType]:
    """Each mission with its active tree: chains of single children in one line (`RoomSurveillance[2]/
    HideInCorner/Watch`), the resources each holds beside it, then where its movable instances were placed."""
    from rich.tree import Tree

    from drd.cli.report import placement_lines

    if not missions:
        return [Text("missions: none", style="dim")]
    parts: list[RenderableType] = [Text("missions", style="bold")]
    for m in missions:
        outcome = m.get("outcome") or "running"
        colour = {"running": "cyan", "success": "green"}.get(outcome, "red")
        head = Text.assemble((str(m.get("id")), "bold"), "  ", (outcome, colour))
        if isinstance(m.get("time"), int | float) and m.get("outcome") is None:  # its own time, not the world's
            began = m.get("started")
            since = float(began) if isinstance(began, int | float) else 0.0
            head.append(f"  {duration_text(round(float(m['time']) - since, 1))}", style="dim")
        if m.get("outcome") and m.get("reason"):  # on its own lines when it does not fit, cut with `…` past
            reason = str(m["reason"])  # WHY_LINES: a long one was cut at the width, and read as whole (audit 24 #9)
            if head.cell_len + 2 + len(reason) <= width:
                head.append(f"  {reason}", style="dim")
            else:
                head.append("".join("\n" + line for line in wrap_cut(reason, max(20, width - 5), WHY_LINES)),
                            style="dim")
        resumed = m.get("resumed")
        if isinstance(resumed, dict) and isinstance(resumed.get("paused"), int | float):
            head.append(f"  resumed after its controller was lost ({float(resumed['paused']):.1f} s without one)",
                        style="yellow")
        root = m.get("tree")
        if root and m.get("outcome") is None:  # what the mission itself holds, or waits for (`needs` at its top)
            held = [str(v) for k, v in (root.get("resources") or {}).items() if "." not in k]
            if held:
                head.append("  " + ", ".join(held), style="dim")
            if isinstance(root.get("waiting_for"), dict):  # cluster audit 17, D1: "running", nothing said why
                head.append("  waiting", style="dim")
                for why in why_lines(waits_text(root["waiting_for"]), max(20, width - 1)):
                    head.append("\n" + why, style="dim")
        tree = Tree(head)
        if root and m.get("outcome") is None:
            shown = [0]
            for child in root.get("children") or []:
                _grow_active(tree, child, root.get("path", ""), 1, width, shown)
            if shown[0] > TREE_NODES:
                tree.add(Text(f"… {shown[0] - TREE_NODES} more active (missionctl status --json)", style="dim"))
        for line in placement_lines(m, width, explain):
            tree.add(line)
        parts.append(tree)
    return parts


def _grow_active(tree: Any, node: dict[str, Any], above: str, depth: int, width: int, shown: list[int]) -> None:
    """Add `node` (and its chain of single children, in one label) under `tree`; count what is left out."""
    held: list[str] = []
    waits: list[tuple[str, str]] = []
    path = str(node.get("path", ""))
    phase = str(node.get("phase", "active"))
    while True:
        held += [str(v) for k, v in (node.get("resources") or {}).items() if "." not in k]
        if isinstance(node.get("waiting_for"), dict):
            waits.append(waits_text(node["waiting_for"]))
        children = node.get("children") or []
        if len(children) != 1:
            break
        node = children[0]
        path = str(node.get("path", path))
        phase = str(node.get("phase", phase))
    rest = path[len(above):] if above and path.startswith(above) else "/" + path.rsplit("/", 1)[-1]
    # below its parent (`/FindNewDoor`), or an instance, named as its multiplicity (`RoomSurveillance[2]/Watch`)
    label = rest[1:] if rest.startswith("/") else above.rsplit("/", 1)[-1] + rest
    shown[0] += 1
    if shown[0] > TREE_NODES:
        for child in children:
            _count(child, shown)
        return
    extra = ("  " + ", ".join(held) if held else "") + (f"  {phase}" if phase != "active" else "")
    extra += "  waiting" if waits and phase != "waiting" else ""
    room = max(12, width - 4 * depth - len(extra) - 1)  # why it waits goes below: the label keeps its room
    text = Text.assemble(shorten(label, room), (extra, "dim"))
    for line in (line for why in waits for line in why_lines(why, max(20, width - 4 * depth - 1))):
        text.append("\n" + line, style="dim")
    branch = tree.add(text)
    for child in children:
        _grow_active(branch, child, path, depth + 1, width, shown)


def _count(node: dict[str, Any], shown: list[int]) -> None:
    shown[0] += 1
    for child in node.get("children") or []:
        _count(child, shown)


def _pct(value: float | None) -> str:
    return "—" if value is None else f"{value:.0f}%"


def _resumed(mission: str, missions: list[dict[str, Any]]) -> dict[str, Any] | None:
    """`mission`'s `resumed` in the executive's list (when, from what, after how long without a controller)."""
    for m in missions:
        if m.get("id") == mission and isinstance(m.get("resumed"), dict):
            return dict(m["resumed"])
    return None
