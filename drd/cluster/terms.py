"""Which controller's term a worker's Creator takes (bus audit, defect 1).

A controller's calls carry its **term**: with etcd, the revision that created the leader key (its election,
`drd.cluster.election`); with the one controller of hosts.yaml, its daemon's start time, as its announcement and
status say it (`started`). A Creator refuses a call whose term is older than the one it adopted, so a controller
frozen while another took over cannot act when it wakes.

A term on the wire is only the caller's word, and a term adopted is kept until the daemon restarts: taking any
term as it came let one forged call (`term=9.9e15`, even with an op the Creator refused) lock the real
controller out for good. So a term greater than the adopted one is adopted only once

- the cluster vouches for it: it is the term of the controller that is live now, as the `Witness` reads it (etcd's
  leader key, or the controller daemon's own status); a term that is not is refused, and nothing changes;
- and the call carrying it was accepted (`TermFence.adopt`, called by the Creator after its checks).

`Terms` is the pure rule; `Witness` is the I/O (one etcd read or one bus query, only when a new term shows up,
not per call); `TermFence` puts them together, thread-safe, and logs refusals on the rate-limited
`drd.daemon.rejects` logger.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from drd.bus import Bus, BusError
from drd.cluster.election import leader_key
from drd.cluster.keys import ClusterKeys
from drd.etcd import Etcd
from drd.hosts import Cluster

#: Refusals are what a peer sent: `drd start` rate-limits this logger (`drd.daemon.logs.install`).
rejects = logging.getLogger("drd.daemon.rejects")

#: Seconds a term the witness did not vouch for is refused again without asking it (a flood of one forged term
#: costs one read per this long; a real new controller's term is asked at once, it is another term).
REFUSED_FOR = 1.0
#: At most this many refused terms are remembered.
MEMO = 64
#: Seconds the witness waits for etcd or for the controller's status.
WITNESS_TIMEOUT = 1.0
#: Seconds a controller's start time may be ahead of this host's clock (unsynchronized clocks): a term further in the
#: future is no controller's start time.
CLOCK_SKEW = 60.0

#: What `Witness.live` gives: the live controller's term, or None and why it is not known.
Live = tuple[float | None, str]


def show(term: float) -> str:
    """A term as it reads: etcd's revision (a whole number) with several controllers, else a start time."""
    return str(int(term)) if term == int(term) else f"{term:.3f}"


@dataclass
class Terms:
    """The pure rule (see the module): the adopted term, the last one the witness vouched for, recent refusals."""

    adopted: float = 0.0
    vouched: float = 0.0
    refused: dict[float, tuple[float, str]] = field(default_factory=dict)  # term -> (refused until, why)

    def older(self, term: float) -> bool:
        return term < self.adopted

    def known(self, term: float) -> bool:
        """Whether `term` needs no witness: the adopted one, or the one it last vouched for."""
        return term == self.adopted or (term == self.vouched and term > self.adopted)

    def memo(self, term: float, now: float) -> str:
        """Why `term` was refused a moment ago ("" if it was not, or long enough ago to ask again)."""
        hit = self.refused.get(term)
        return hit[1] if hit is not None and now < hit[0] else ""

    def answered(self, term: float, live: Live, now: float) -> str:
        """The witness's answer about `term`: "" if it vouches for it, else why it is refused (remembered)."""
        current, unknown = live
        if current is not None and term == current:
            self.vouched = term
            return ""
        if current is None:
            why = f"cannot check its term {show(term)} ({unknown})"
        elif term > current:
            why = f"term {show(term)} is no controller's: the live controller's term is {show(current)}"
        else:
            why = f"term {show(term)} is older than the live controller's, {show(current)}"
        if len(self.refused) >= MEMO:
            self.refused = {t: v for t, v in self.refused.items() if now < v[0]}
            if len(self.refused) >= MEMO:
                self.refused.clear()
        self.refused[term] = (now + REFUSED_FOR, why)
        return why

    def adopt(self, term: float) -> bool:
        """Take `term` (a call carrying it was accepted) if the witness vouched for it; whether it changed."""
        if term > self.adopted and term == self.vouched:
            self.adopted = term
            return True
        return False


class Witness:
    """What a worker can check of the live controller's term: etcd's leader key (its `create_revision`) when the
    cluster elects its controller, else the `started` of the hosts.yaml controller's own status."""

    def __init__(self, bus: Bus, cluster: Cluster, timeout: float = WITNESS_TIMEOUT,
                 clock: Callable[[], float] = time.time) -> None:
        self.bus = bus
        self.clock = clock  # wall time: a start time is one
        self.cluster = cluster
        self.timeout = timeout
        self._etcd: Etcd | None = None

    def live(self) -> Live:
        try:
            return self._elected() if self.cluster.store.replicated else self._started()
        except Exception as e:  # etcd or the bus failed: the term cannot be checked, so it is not taken
            return None, f"{type(e).__name__}: {e}"

    def _elected(self) -> Live:
        if self._etcd is None:
            self._etcd = Etcd(self.cluster.store.etcd, timeout=self.timeout)
        kv = self._etcd.get(leader_key(self.cluster.name))
        if kv is None:
            return None, "no controller holds etcd's leader key now"
        return float(kv.create_revision), ""

    def _started(self) -> Live:
        controller = self.cluster.controller.name
        try:
            replies = self.bus.request(ClusterKeys(self.cluster.name).status(controller), timeout=self.timeout)
        except BusError as e:
            return None, f"the controller {controller} did not say its term: {e}"
        return started_term(controller, [r.payload for r in replies], self.clock())


def started_term(controller: str, answers: list[object], now: float) -> Live:
    """The live controller's term from the answers to its status (`drd.daemon.status`, read by its fields: drd.cluster
    does not import drd.daemon). Any peer may answer on that key in an open cluster, so a term is taken only if every
    answer naming the controller says the same start time, and it is not in the future: a forged answer beside the
    real one makes the term uncheckable (refused, asked again later), never adopted."""
    said = {float(started) for a in answers if getattr(a, "host", None) == controller
            and isinstance(started := getattr(a, "started", None), float | int) and not isinstance(started, bool)}
    if not said:
        return None, f"the controller {controller} did not answer with its status"
    if len(said) > 1:
        return None, (f"{len(said)} different terms answer as the controller {controller}'s status (another peer"
                      " answers on its key): none is taken")
    term = said.pop()
    if term > now + CLOCK_SKEW:
        return None, f"the controller {controller}'s start time {show(term)} is in the future"
    return term, ""


class TermFence:
    """The Creator's fence (see the module). `live`: the witness (None: nothing to check with, a Creator without a
    bus in a test, so a term is taken on the caller's word as before)."""

    def __init__(self, host: str, live: Callable[[], Live] | None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.host = host
        self.live = live
        self.clock = clock
        self.rule = Terms()
        self._lock = threading.Lock()
        self._asking = threading.Lock()  # one witness read at a time (never under the Creator's lock)

    @property
    def term(self) -> float:
        return self.rule.adopted

    def stale(self, term: float) -> str:
        """Why a call of `term` is refused as an older controller's ("" if it is not): cheap, under the Creator's
        lock, right before the call is served."""
        with self._lock:
            adopted = self.rule.adopted
        if term >= adopted:
            return ""
        rejects.warning("creator %s: refused a call from an older controller (term %s, the current one %s)",
                        self.host, show(term), show(adopted))
        return (f"{self.host} refuses a call from an older controller (term {show(term)}; the controller of term"
                f" {show(adopted)} acts now)")

    def admit(self, term: float) -> str:
        """Why a call of `term` is refused ("" if it may be served): older than the adopted term, or new and not
        the live controller's. Changes nothing but what the witness said; may ask it (call it without locks)."""
        why = self.stale(term)
        if why:
            return why
        with self._lock:
            if self.live is None or self.rule.known(term):
                return ""
            why = self.rule.memo(term, self.clock())
        if not why:
            with self._asking:
                with self._lock:
                    if self.rule.known(term):  # another call of this term was vouched for meanwhile
                        return ""
                live = self.live()
                with self._lock:
                    why = self.rule.answered(term, live, self.clock())
        if not why:
            return ""
        rejects.warning("creator %s: refused a call of an unvouched term: %s", self.host, why)
        return f"{self.host} refuses the call: {why}"

    def adopt(self, term: float) -> None:
        """A call of `term` was accepted: later calls of older terms are refused."""
        with self._lock:
            if self.live is None and term > self.rule.adopted:
                self.rule.vouched = term  # no witness: the caller's word (a Creator without a bus)
            changed = self.rule.adopt(term)
        if changed:
            logging.getLogger("drd.cluster.creator").info("creator %s: the controller of term %s acts now",
                                                          self.host, show(term))
