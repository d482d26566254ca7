"""When each signal reached the process, which is not when Python runs its handler.

Python runs a signal's handler only once the main thread is back from a blocking call: a zenoh query holds it, so a
Ctrl-C delivered twice (`timeout` passes a SIGINT on to its child, whose terminal group got it too) can have its
second handler run seconds after the first. Its arrival is what tells the same Ctrl-C from the operator's next one.
The interpreter's C-level handler writes each signal's number to the wakeup fd the moment the signal comes, in
whichever thread takes it; a thread here reads those bytes and notes the time (`signal.set_wakeup_fd`).
"""

from __future__ import annotations

import signal
import socket
import threading
import time
from types import TracebackType

#: How long a handler waits for the reader to note its signal's arrival before taking the time it runs at instead:
#: the reader is woken by the very write that tripped the handler, so it is there first but for scheduling.
NOTED_WITHIN = 0.2


class SignalArrivals:
    """The arrival times of `signum`, in order, while the `with` block runs (in the main thread; elsewhere, or
    where another wakeup fd is set, `arrival` is the time it is asked at, as without this)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        self.times: list[float] = []
        self.taken = 0  # how many of `times` were taken
        self.noted = threading.Condition()
        self.previous: int | None = None
        self.pair: tuple[socket.socket, socket.socket] | None = None
        self.reader: threading.Thread | None = None

    def __enter__(self) -> SignalArrivals:
        read, write = socket.socketpair()
        write.setblocking(False)  # the C handler must never block
        try:
            previous = signal.set_wakeup_fd(write.fileno(), warn_on_full_buffer=False)
        except ValueError:  # not the main thread
            read.close()
            write.close()
            return self
        if previous != -1:  # someone else's (an event loop): theirs stays
            signal.set_wakeup_fd(previous)
            read.close()
            write.close()
            return self
        self.previous, self.pair = previous, (read, write)
        self.reader = threading.Thread(target=self._read, args=(read,), name="signal-arrivals", daemon=True)
        self.reader.start()
        return self

    def _read(self, read: socket.socket) -> None:
        while True:
            try:
                data = read.recv(64)
            except OSError:
                return
            if not data:
                return
            at = time.monotonic()
            with self.noted:
                self.times.extend(at for number in data if number == self.signum)
                self.noted.notify_all()

    def take(self) -> list[float]:
        """The arrivals not taken before, oldest first; for a handler, those it runs for (several deliveries before
        it ran are one call). At least one: the time it is asked at when none was noted."""
        with self.noted:
            self.noted.wait_for(lambda: len(self.times) > self.taken, timeout=NOTED_WITHIN if self.pair else 0.0)
            came, self.taken = self.times[self.taken:], len(self.times)
        return came or [time.monotonic()]

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self.pair is None:
            return
        signal.set_wakeup_fd(-1 if self.previous is None else self.previous)
        read, write = self.pair
        write.close()  # the reader's recv returns b""
        if self.reader is not None:
            self.reader.join(timeout=1.0)
        read.close()
        self.pair = None
