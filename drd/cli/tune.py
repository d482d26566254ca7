"""`missionctl tune INSTANCE [--cores 0,1] [--nice 5]`: core and priority assignment of a running instance.

The instance's host comes from the Component Database (the name service, `lookup`): every Creator announces
its instances. The request (`drd.cluster.workers.Tune`) goes to that host's Creator, which sets the CPU
affinity and nice level of the process running the instance (a container shares it with other instances:
the answer names them) and answers what the process runs with now. Without `--cores` or `--nice` it only
shows the current settings. An unknown instance exits with code 2 and a did-you-mean.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import typer
from rich.text import Text

from drd.cli.cluster import cluster_client
from drd.cli.common import OK, fail, out
from drd.cli.options import ConfigOption, ConnectOption, JsonOption, TimeoutOption


def register(app: typer.Typer) -> None:
    """Add `tune` to `missionctl`."""
    app.command("tune")(tune)


def parse_cores(text: str) -> list[int]:
    """`0,1` or `0-3,6` -> sorted core numbers; ValueError with a readable reason."""
    cores: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        lo, sep, hi = part.partition("-")
        try:
            first, last = (int(lo), int(hi)) if sep else (int(part), int(part))
        except ValueError:
            raise ValueError(f"{part!r} is not a core number or a range like 0-3") from None
        if first < 0 or last < first:
            raise ValueError(f"{part!r} is not a core number or a range like 0-3")
        cores.update(range(first, last + 1))
    return sorted(cores)


def tune(instance: str = typer.Argument(..., metavar="INSTANCE", show_default=False,
                                        help="The instance's name, as `missionctl components` lists it."),
         cores: str | None = typer.Option(None, "--cores", show_default=False,
                                          help="CPU cores to run on: 0,1 or 0-3 (checked against the host's)."),
         nice: int | None = typer.Option(None, "--nice", min=-20, max=19, show_default=False,
                                         help="Nice level, -20..19 (lower needs privileges on the host)."),
         config: Path = ConfigOption, connect: list[str] = ConnectOption, as_json: bool = JsonOption,
         timeout: float = TimeoutOption) -> int:
    """Set CPU affinity and nice of the process running a component instance, at run time."""
    from drd.bus import RemoteError
    from drd.cluster.workers import Tune, Tuned
    from dsl.errors import did_you_mean

    try:
        wanted = parse_cores(cores) if cores is not None else None
    except ValueError as e:
        fail(f"--cores {cores}: {e}")
    with cluster_client(config, connect, timeout, to="tune an instance") as client:
        try:
            where = client.lookup(instance)
        except RemoteError:
            known = sorted({i.name for i in client.components().instances})
            hint = did_you_mean(instance, known, 3) or next(
                (f"did you mean {k}?" for k in known if k.rsplit("/", 1)[-1] == instance), None)
            fail(f"no running instance called {instance!r}", hint=hint or (
                f"running instances: {', '.join(known)}" if known else "no instance runs now"))
        if where.kind != "instance":
            fail(f"{instance} is a daemon service, not a component instance")
        reply = client.bus.call(client.keys.tune(where.host), Tune(instance, wanted, nice), timeout=max(timeout, 2.0))
    if not isinstance(reply, Tuned):
        fail(f"{where.host} answered a {type(reply).TYPE}")
    if as_json:
        out.print_json(json.dumps(asdict(reply)))
        return OK
    verb = "tuned" if wanted is not None or nice is not None else "runs"
    out.print(Text.assemble((f"{reply.instance}", "bold"), f" {verb} on {reply.host}: pid {reply.pid}"
                            f" ({reply.process}), cores {','.join(map(str, reply.cores))}, nice {reply.nice}"))
    if reply.shared_with:
        out.print(Text(f"  its process also runs: {', '.join(reply.shared_with)}", style="yellow"))
    return OK
