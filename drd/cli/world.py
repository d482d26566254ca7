"""`missionctl world generate --wings N --scouts M --out DIR`: a generated building and its hosts file.

Writes `DIR/hosts.yaml` and `DIR/worlds/<name>.yaml` (the hosts file's `cluster.world` names it, so `missionctl
dry-run MISSION --hosts DIR/hosts.yaml` finds it), from `drd.sim.building` (the geometry, pure). Both files are
checked by the loaders every command uses before anything is written, and existing files are kept unless
`--force`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer
import yaml
from rich.text import Text

from drd.cli.common import OK, catalog, err, fail, fail_all, print_json
from drd.cli.options import ComponentsOption

if TYPE_CHECKING:
    from drd.sim.building import Building

world_app = typer.Typer(help="Generate worlds for dry-runs.", no_args_is_help=True, add_completion=False,
                        rich_markup_mode=None)


def register(app: typer.Typer) -> None:
    """Add `world` (and its `generate`) to `missionctl`."""
    app.add_typer(world_app, name="world")


@world_app.command("generate")
def generate(
    wings: int = typer.Option(..., "--wings", help="How many wings (corridors), each with one Ranger.",
                              show_default=False),
    scouts: int = typer.Option(19, "--scouts", help="Scouts per Ranger (each wing has as many open doors)."),
    out_dir: Path = typer.Option(..., "--out", "-o", help="The folder to write hosts.yaml and worlds/NAME.yaml in "
                                                          "(made if missing).", show_default=False),
    force: bool = typer.Option(False, "--force", help="Overwrite files that exist."),
    as_json: bool = typer.Option(False, "--json", help="Say what was written as JSON."),
    components: list[Path] = ComponentsOption,
) -> int:
    """Write a building of N wings (a corridor each, rooms on both sides, one Ranger with its Scouts, one
    intruder) and the matching hosts file, for `missionctl dry-run MISSION --hosts DIR/hosts.yaml`."""
    from drd.hosts import HostsError, parse_hosts
    from drd.sim.building import Building, BuildingError, counted, hosts, world
    from drd.sim.world import WorldError, parse_world

    try:
        b = Building(wings, scouts)
    except BuildingError as e:
        fail(str(e))
    say = _progress(b, as_json)
    world_data, hosts_data = world(b), hosts(b)
    world_file, hosts_file = out_dir / "worlds" / f"{b.name}.yaml", out_dir / "hosts.yaml"
    try:  # what every command will load, checked before anything is written
        say(f"checking the world ({len(world_data['rooms'])} rooms, {len(world_data['doors'])} doors)")
        parse_world(world_data, str(world_file))
        say(f"checking the hosts file ({b.robots} robots)")
        parse_hosts(hosts_data, str(hosts_file), catalog(components))
    except (WorldError, HostsError) as e:  # a generator bug, said plainly rather than written out
        fail_all(e.problems)
    existing = [str(p) for p in (hosts_file, world_file) if p.exists()]
    if existing and not force:
        fail(f"{', '.join(existing)}: exists", hint="pass --force to overwrite, or another --out")
    if out_dir.exists() and not out_dir.is_dir():
        fail(f"--out {out_dir}: not a folder")
    texts = {world_file: _header(f"A generated building ({b.wings} wings x {b.scouts} Scouts), for "
                                 f"{hosts_file.name} beside worlds/; docs/worlds.md.") + _yaml(world_data),
             hosts_file: _header(f"{b.robots} robots on {b.wings} Ranger hosts, every driver sim, for "
                                 f"worlds/{world_file.name}; docs/hosts.md.") + _yaml(hosts_data)}
    _fits(b, texts)
    try:
        world_file.parent.mkdir(parents=True, exist_ok=True)
        for path, text in texts.items():
            say(f"writing {path}")
            path.write_text(text, encoding="utf-8")
    except OSError as e:
        fail(f"cannot write to {out_dir}: {e.strerror or e}")
    summary = {"world": str(world_file), "hosts": str(hosts_file), "name": b.name, "wings": b.wings,
               "scouts_per_wing": b.scouts, "rangers": b.wings, "scouts": b.wings * b.scouts, "robots": b.robots,
               "corridor_m": b.length}
    if as_json:
        print_json(summary)
    else:
        err.print(Text.assemble(("✓ ", "bold green"), f"wrote {hosts_file} and {world_file}: "
                                                       f"{counted(b.wings, 'wing')}, {b.robots} robots"))
        err.print(f"  run it: missionctl dry-run missions/corridor_surveillance.mission --hosts {hosts_file}")
    return OK


def _fits(b: Building, texts: Mapping[Path, str]) -> None:
    """Refuse (exit 2, nothing written) a building whose files are larger than what every command reads
    (`drd.config.MAX_CONFIG_BYTES`): they were written, and then refused by `dry-run` and `plan` (scale audit 11,
    D1: from about 400 wings of 19 Scouts)."""
    from drd.config import MAX_CONFIG_BYTES

    for path, text in texts.items():
        size = len(text.encode("utf-8"))
        if size > MAX_CONFIG_BYTES:
            most = max(1, b.wings * MAX_CONFIG_BYTES // size)
            fail(f"{path} would be {size / 2**20:.1f} MiB, more than the {MAX_CONFIG_BYTES // 2**20} MiB every command"
                 f" reads: {b.wings} wings of {b.scouts} Scouts is too large; nothing was written",
                 hint=f"at most about {most} wings of {b.scouts} Scouts (fewer Scouts a wing allow more wings)")


#: From this many robots, generation takes seconds (about 1 s per 1,000 robots, docs/design.md), so each step is
#: said on stderr as it starts.
PROGRESS_FROM = 2000


def _progress(b: Building, as_json: bool) -> Callable[[str], None]:
    """What says each step of a long generation on stderr (nothing under --json, nor for a small building)."""
    if as_json or b.robots < PROGRESS_FROM:
        return lambda _: None
    return lambda step: err.print(f"  {b.name}: {step}…", style="dim", highlight=False)


def _header(text: str) -> str:
    return f"# Generated by `missionctl world generate`. {text}\n"


def _yaml(data: Any) -> str:
    """Block style for the structure, flow style for points and small mappings: a file a person can read."""
    return str(yaml.dump(data, Dumper=_DUMPER, sort_keys=False, default_flow_style=None, width=120,
                         allow_unicode=True))


#: libyaml's emitter when PyYAML has it: the same text as the pure-Python SafeDumper (compared in
#: tests/e2e/test_world_generate_progress.py), 2.4 times faster on a 100-wing building.
_DUMPER: type[yaml.SafeDumper] = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
