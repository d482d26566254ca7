"""Every module that defines drd's bus messages, in one list: what a decoder can know does not depend on
what its process happened to import.

A message class is defined beside the code that sends it (`@message` in its module), but which (type, version)
pairs a process can decode is decided here: the first time a decoder meets a type it does not know, it loads
every module of `MESSAGE_MODULES` once (`load`) before refusing. `tests/unit/test_message_catalog.py` reads the
source tree and fails when a module defines a message and is not listed, so a new message module cannot be
forgotten.
"""

from __future__ import annotations

import functools
import importlib

#: The modules that define bus messages (`@message`), in import order.
MESSAGE_MODULES: tuple[str, ...] = (
    "drd.bus.messages",
    "drd.executive_messages",
    "drd.daemon.messages",
    "drd.daemon.missions",
    "drd.daemon.migrate",
    "drd.cluster.workers",
    "drd.cluster.gates",
    "drd.cluster.instances",
    "drd.cluster.remote",
    "drd.sim.service",
)


@functools.cache
def load() -> None:
    """Import every message module (once per process: Python's import lock makes a second caller wait)."""
    for name in MESSAGE_MODULES:
        importlib.import_module(name)
