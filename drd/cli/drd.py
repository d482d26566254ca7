"""`drd`: the Distributed Robotics Daemon's command line (one daemon per host).

The daemon itself (`drd start`) arrives with the cluster work; what a host can already
answer without it lives here.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table

from drd import __version__
from drd.cli.common import OK, ComponentsOption, catalog, out, run_app
from dsl.catalog import Kind

app = typer.Typer(help="The Distributed Robotics Daemon: one per host.", no_args_is_help=True,
                  add_completion=False, rich_markup_mode=None)


@app.command()
def components(
    kind: Kind = typer.Option(None, "--kind", "-k", help="Only this kind: behavior, rc, arc or data.",
                              show_default=False),
    as_json: bool = typer.Option(False, "--json", help="Print the catalog as JSON."),
    extra: list[Path] = ComponentsOption,
) -> int:
    """List the component types this host knows from its manifests."""
    cat = catalog(extra)
    types = sorted((t for t in cat.components.values() if kind is None or t.kind is kind),
                   key=lambda t: (t.kind.value, t.name))
    if as_json:
        out.print_json(json.dumps([{
            "name": t.name, "kind": t.kind.value, "description": t.description, "source": t.source,
            "params": [{"name": p.name, "type": p.type, "default": p.default, "required": p.required}
                       for p in t.params],
            "needs": [{"name": n.name, "type": n.type, "of": list(n.of)} for n in t.needs],
        } for t in types]))
        return OK
    table = Table(title="Component types", title_justify="left")
    for col in ("name", "kind", "parameters", "needs"):
        table.add_column(col)
    for t in types:
        params = ", ".join(f"{p.name}: {p.type}" + ("" if p.required else f" = {p.default}") for p in t.params)
        needs = ", ".join(f"{n.name}: {n.type}" for n in t.needs) or ", ".join(f"{k}: {v}" for k, v in t.parts.items())
        table.add_row(t.name, t.kind.value, params, needs)
    out.print(table)
    return OK


@app.command()
def version() -> int:
    """Print drd's version."""
    out.print(f"drd {__version__}")
    return OK


def main() -> None:
    run_app(app, "drd")
