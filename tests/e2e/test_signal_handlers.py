"""A signal handler never waits for the stop event's lock (reverify audit 7, D-f): `drd sim` hung for ever, deaf to
SIGTERM, when a second signal came while the first handler was inside `Event.set` (the lock is not reentrant, and
a handler runs in the interrupted main thread). Each case runs in a process of its own, bounded, so a handler that
deadlocks fails the test instead of hanging the suite."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import ROOT

#: The main thread holds the event's lock (as inside `Event.set` or `Event.wait`) when a SIGTERM comes: the handler
#: must return, and the event be set once the lock is free.
SCRIPT = """
import os, signal, threading
from drd.signals import set_soon
stop = threading.Event()
signal.signal(signal.SIGTERM, lambda n, f: {handler})
with stop._cond:  # what Event.set holds while it runs
    os.kill(os.getpid(), signal.SIGTERM)
    os.kill(os.getpid(), signal.SIGTERM)  # a second one, as the audit's
print("handlers returned", flush=True)
print("set" if stop.wait(10) else "never set", flush=True)
"""


def run(handler: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", SCRIPT.format(handler=handler)], cwd=ROOT, capture_output=True,
                          text=True, timeout=30, check=False)


def test_a_handler_sets_the_stop_event_even_while_its_lock_is_held() -> None:
    r = run("set_soon(stop)")
    assert r.returncode == 0 and r.stdout.split("\n")[:2] == ["handlers returned", "set"], (r.stdout, r.stderr)


def test_the_plain_set_this_replaces_deadlocks_there() -> None:
    """The scenario is real: `stop.set()` in the handler never returns (the process is killed by the bound)."""
    with pytest.raises(subprocess.TimeoutExpired):
        subprocess.run([sys.executable, "-c", SCRIPT.format(handler="stop.set()")], cwd=ROOT, capture_output=True,
                       text=True, timeout=5, check=False)
