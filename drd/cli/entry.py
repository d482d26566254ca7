"""The console scripts' entry points (`drd`, `missionctl`): the tool is imported inside them, so a Ctrl-C that
lands while it still imports itself (typer, rich, drd: the first few tenths of a second) ends it as one after does,
`interrupted` and exit 130, not a Python traceback (cli audit 24, #6). Nothing heavy is imported here."""

from __future__ import annotations

import sys
from typing import NoReturn

#: The exit code of a Ctrl-C before anything ran (`drd.cli.common.INTERRUPTED`; not imported: that is typer).
INTERRUPTED = 130


def _interrupted() -> NoReturn:
    """What the safety net says of a Ctrl-C (`drd.cli.common._error`), said without it: it was not imported yet."""
    if "--json" in sys.argv[1:]:
        sys.stderr.write(f'{{"error": "interrupted", "code": {INTERRUPTED}}}\n')
    else:
        sys.stderr.write("interrupted\n")
    raise SystemExit(INTERRUPTED)


def missionctl() -> None:
    try:
        from drd.cli.missionctl import main
    except KeyboardInterrupt:
        _interrupted()
    main()


def drd() -> None:
    try:
        from drd.cli.drd import main
    except KeyboardInterrupt:
        _interrupted()
    main()
