"""`missionctl migrate INSTANCE --to HOST`: move a running movable component to another host (issue #15).

The controller (`drd.daemon.migrate`) stops the instance where it runs as `moved`, takes its state along (its
snapshot) and starts it on HOST from that state: the mission's state neither fails nor restarts. INSTANCE is
`<mission>/<path>` as `missionctl components` lists it, or its path when one mission runs it. Refused with exit
code 2 and the reason: an unknown instance, a component that is not movable (its manifest says so), an unknown
host, one that is down or does not run components. An operator's command: an observer is refused.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import typer
from rich.text import Text

from drd.cli.cluster import cluster_client
from drd.cli.common import OK, fail, out
from drd.cli.options import MAX_WAIT, ConfigOption, ConnectOption, JsonOption

#: Seconds the controller may take by default: the instance is stopped on one host and started on another (a
#: first start on a host may load the component's module).
TIMEOUT = 15.0
#: The longest a move takes on the controller: stopped where it runs, started on the target (each call bounded by
#: `drd.cluster.remote.START_TIMEOUT`, 5 s), started again where it was if the target refused it. A client that
#: gives up sooner cannot say whether it moved (cluster audit 10, D3: exit 2, and it had moved).
MOVE_BOUND = 15.0


def register(app: typer.Typer) -> None:
    """Add `migrate` to `missionctl`."""
    app.command("migrate")(migrate)


def migrate(instance: str = typer.Argument(..., metavar="INSTANCE", show_default=False,
                                           help="The instance: <mission>/<path> as `missionctl components` lists"
                                                " it, or its path when one mission runs it."),
            to: str = typer.Option(..., "--to", metavar="HOST", show_default=False,
                                   help="The host to move it to: up, and one that runs components."),
            config: Path = ConfigOption, connect: list[str] = ConnectOption, as_json: bool = JsonOption,
            timeout: float = typer.Option(TIMEOUT, "--timeout", min=0.05, max=MAX_WAIT,
                                          help="Seconds to wait for the controller to move it.")) -> int:
    """Move a running movable component to another host; it goes on from its state there."""
    from drd.bus import BusTimeout
    from drd.daemon.migrate import Migrate, Migrated, migrate_key

    with cluster_client(config, connect, timeout, to="move a component") as client:
        try:
            reply = client.bus.call(migrate_key(client.cluster), Migrate(instance, to), timeout=timeout)
        except BusTimeout as e:
            if e.unreached:
                raise  # nothing took the request: the usual "no controller" error says so
            fail(f"{instance}: the controller did not answer within {timeout:g} s, so whether it moved is not known"
                 f" (a move may take up to {MOVE_BOUND:g} s when {to} is slow to start it, and is not called off)",
                 hint=f"see where it runs now with `missionctl components`, and give --timeout {MOVE_BOUND:g} or"
                      " more")
    if not isinstance(reply, Migrated):
        fail(f"the controller answered a {type(reply).TYPE}")
    state = reply.state[0] if reply.state else None  # the wire's `[state]`, as the docs give it: the state or null
    if as_json:
        out.print_json(json.dumps({**asdict(reply), "state": state}))
        return OK
    took = f"with its state {json.dumps(state)}" if state is not None else "afresh (its component keeps no state)"
    out.print(Text.assemble((f"{reply.mission}/{reply.path}", "bold"), f" ({reply.component}) moved from"
                            f" {reply.source} to {reply.host}, {took}"))
    return OK
