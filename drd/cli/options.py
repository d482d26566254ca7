"""The options several commands share, one definition each, so one concept has one name and one help text
everywhere (docs/cli.md: `--config`/`-c`/`--hosts`, `--json`, `--components`/`-C`, `--connect`, `--timeout`)."""

from __future__ import annotations

from pathlib import Path

import typer

from dsl.evaluate import INT_DIGITS

#: The highest priority a command line may give: a number of at most 18 digits, as in a mission (`priority N`)
#: and a `--param` (users audit 9: `--priority 99999999999999999999` ran, and the report carried it).
MAX_PRIORITY = 10 ** INT_DIGITS - 1

ComponentsOption = typer.Option(
    None, "--components", "-C", help="Extra folder of component manifests (repeatable; also $DRD_COMPONENTS).",
    show_default=False, metavar="DIR")
ConfigOption = typer.Option(Path("hosts.yaml"), "--config", "-c", "--hosts",
                            help="The cluster's hosts file: connect to its routers (one at a time), else to every"
                                 " host, with its security settings (`--hosts` is an alias).")
ConnectOption = typer.Option(None, "--connect", show_default=False,
                             help="Connect to this endpoint instead (tcp/HOST:PORT; repeatable: one at a time, the"
                                  " next if it fails).")
JsonOption = typer.Option(False, "--json", help="Print JSON.")
#: The largest number of seconds an option takes (a day; a week of sim time for `--until`) and the largest speed:
#: `inf` and `1e308` are floats typer takes, and a wait for ever then hung a script (cli audit 24, #3, #4).
MAX_WAIT = 86400.0
MAX_SIM_TIME = 7 * 86400.0
MAX_SPEED = 1_000_000.0
UntilOption = typer.Option(1800.0, "--until", min=0.1, max=MAX_SIM_TIME,
                           help="Stop after this much sim time, in seconds.")
TimeoutOption = typer.Option(2.0, "--timeout", min=0.05, max=MAX_WAIT, help="Seconds to wait for a daemon to answer.")
