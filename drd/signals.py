"""What a signal handler may do: set an event, never wait for one's lock.

Python runs a handler in the main thread, between two bytecodes of whatever it was doing. `Event.set` takes the
event's lock, which is not reentrant: if the main thread held it at that moment (inside `stop.wait()`, or inside
the `set` of a first signal's handler when a second signal came), the handler waited for itself for ever. `drd sim`
was seen so (reverify audit 7, D-f: a second SIGTERM while the first handler was in `Event.set`), deaf to any
further SIGTERM. `set_soon` sets the event from a new thread started by `_thread` (which takes no lock the
interrupted code could hold): the handler returns at once, and the event is set as soon as its lock is free.
"""

from __future__ import annotations

import _thread
import threading

__all__ = ["set_soon"]


def set_soon(event: threading.Event) -> None:
    """`event.set()` from a signal handler: at once if it is set already, else from a thread of its own."""
    if not event.is_set():  # reads a flag: no lock
        _thread.start_new_thread(event.set, ())
