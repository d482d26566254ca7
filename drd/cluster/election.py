"""Which of several controller hosts acts: an election through etcd's leases, and the fence around the loser
(issue #16, failover to a standby controller).

Every host with the controller role campaigns: it holds an etcd lease of `ttl` seconds (renewed every third of it)
and tries, in one transaction, to create the key `drd/<cluster>/leader` attached to that lease, only if the key does
not exist. One succeeds; the revision of that transaction (the key's `create_revision`) is its **term**: etcd's
revisions only grow, so a later election always has a larger term, whatever the hosts' clocks say. The others stay
standbys and try again every `poll` seconds: when the leader's lease runs out (it died, froze or was cut off from
etcd), etcd deletes the key and the next standby's transaction wins.

A controller must stop acting before etcd lets another one start. `LeaseClock` is the pure rule: the lease is
trusted until the time the last renewal was *sent* plus its TTL, less a margin, by this process's monotonic clock
(etcd counts from when it received the renewal, later; a SIGSTOPped process's monotonic clock runs on). `FencedBus`
is the one place the controller's messages go out through: when the election says it no longer acts, a publication
is dropped, a request refused, a query left unanswered. Behind it two more fences hold whatever slips through (a
message checked, then sent after a freeze): workers refuse a call whose term is older than one they have seen,
and take a new term only when etcd's leader key vouches for it (`drd.cluster.terms`); the etcd journal writes only
while the leader key is still the one this controller created (`drd.journal.EtcdJournal`).
"""

from __future__ import annotations

import json
import logging
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from drd.bus import Bus, BusError, BusWrapper, Handler, Query, Queryable, Reply
from drd.bus.messages import Message
from drd.etcd import Etcd, EtcdError, created_at, get, put

log = logging.getLogger("drd.election")

STANDBY, LEADER, FENCED = "standby", "leader", "fenced"
#: Seconds cut off the lease's end as this controller reckons it: room for a renewal's own travel time.
MARGIN = 0.25
#: Seconds between a standby's attempts to become the leader (and a leader's checks of its own lease).
POLL = 0.25


def leader_key(cluster: str) -> str:
    return f"drd/{cluster}/leader"


def election_ttl(lease: float) -> int:
    """The election's lease for a cluster's `lease` (seconds): whole seconds, at least 2 (etcd's own minimum with its
    default timing). A standby takes over about this long after the acting controller died."""
    return max(2, math.ceil(lease))


@dataclass
class LeaseClock:
    """Until when this controller may act on its lease, by its own monotonic clock (see the module)."""

    margin: float = MARGIN
    until: float = 0.0

    def renewed(self, sent: float, ttl: float) -> None:
        """A renewal (or the grant) sent at `sent` was answered with `ttl` seconds."""
        self.until = max(self.until, sent + ttl - self.margin)

    def valid(self, now: float) -> bool:
        return now < self.until

    def lapse(self) -> None:
        self.until = 0.0


@dataclass
class ElectionState:
    """The pure state of one controller host's campaign: standby, leader of `term`, or fenced (it was the leader
    and its lease ran out; it stays so until its daemon stepped down and asks to campaign again)."""

    role: str = STANDBY
    term: int = 0
    holder: str = ""  # the host acting, as last seen (this one when it leads)
    holder_term: int = 0
    reason: str = ""  # why it was fenced
    lease: LeaseClock | None = None

    def __post_init__(self) -> None:
        if self.lease is None:
            self.lease = LeaseClock()

    @property
    def clock(self) -> LeaseClock:
        assert self.lease is not None
        return self.lease

    def won(self, term: int, host: str, renewed: float, ttl: float) -> None:
        """Its transaction created the leader key at revision `term`; the lease was last renewed at `renewed`."""
        self.role, self.term, self.holder, self.holder_term, self.reason = LEADER, term, host, term, ""
        self.clock.lapse()
        self.clock.renewed(renewed, ttl)

    def saw(self, holder: str, term: int) -> bool:
        """Another controller holds the key (created at `term`): whether that is news."""
        news = (holder, term) != (self.holder, self.holder_term)
        self.holder, self.holder_term = holder, term
        return news

    def kept(self, sent: float, ttl: float) -> None:
        """A renewal sent at `sent` while leading was answered with `ttl`."""
        if self.role == LEADER:
            self.clock.renewed(sent, ttl)

    def fence(self, reason: str) -> bool:
        """The leader lost its lease (`reason`): it must not act any more. Whether it was leading."""
        if self.role != LEADER:
            return False
        self.role, self.reason = FENCED, reason
        self.clock.lapse()
        return True

    def check(self, now: float) -> bool:
        """Fence a leader whose lease ran out by its own clock (no renewal was answered in time); whether it did."""
        return self.role == LEADER and not self.clock.valid(now) and self.fence(
            "its etcd lease ran out before a renewal was answered (frozen, or cut off from etcd)")

    def acting(self, now: float, term: int | None = None) -> bool:
        """Whether it may act now (as the controller of `term`, if given)."""
        return self.role == LEADER and self.clock.valid(now) and (term is None or term == self.term)

    def standby(self) -> None:
        """Campaign again (after its daemon stepped down)."""
        self.role, self.term = STANDBY, 0
        self.clock.lapse()


class Election:
    """One controller host's campaign, on a thread of its own (see the module). `on_elected(term)` runs on a
    thread of its own when it wins (renewals go on meanwhile); `on_fenced(reason)` when it lost its lease."""

    def __init__(self, etcd: Etcd, cluster: str, host: str, ttl: int, *, on_elected: Callable[[int], None],
                 on_fenced: Callable[[str], None], clock: Callable[[], float] = time.monotonic,
                 poll: float = POLL) -> None:
        self.etcd = etcd
        self.key = leader_key(cluster)
        self.host = host
        self.ttl = max(1, int(ttl))
        self.on_elected, self.on_fenced = on_elected, on_fenced
        self.clock = clock
        self.poll = poll
        self.state = ElectionState()
        self.lease = 0  # etcd's id of this host's lease (0: none yet)
        self.granted = float(self.ttl)  # the TTL etcd granted (at least its minimum)
        self._renewed = 0.0  # when the last answered grant or renewal was sent
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._said_down = False
        self._thread = threading.Thread(target=self._loop, name=f"drd-election-{host}", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self, revoke: bool = True) -> None:
        """Stop campaigning; with `revoke`, drop the lease now, so a standby takes over at once (a clean stop)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2 * self.etcd.timeout + 1)
        if revoke and self.lease:
            try:
                self.etcd.revoke(self.lease)
            except EtcdError as e:
                log.info("could not drop the election lease (it runs out on its own): %s", e)

    def resign(self) -> None:
        """Stop acting now, before the controller's services close (a clean stop): nothing they send on closing
        gets out, nor is written, and `close` then drops the lease so a standby resumes the missions at once."""
        with self._lock:
            self.state.fence("its daemon is stopping")
            self.state.role = FENCED

    def acting(self, term: int | None = None) -> bool:
        """Whether this host is the controller now (of `term`, if given): the fence's question, asked before every
        message; also fences a leader whose lease ran out by its own clock."""
        with self._lock:
            if self.state.check(self.clock()):
                self._fenced_later()
            return self.state.acting(self.clock(), term)

    @property
    def term(self) -> int:
        return self.state.term

    @property
    def role(self) -> str:
        return self.state.role

    def standby(self) -> None:
        """Its daemon stepped down: campaign again, with a new lease."""
        with self._lock:
            self.state.standby()
            self.lease = 0

    # -- the loop ------------------------------------------------------------------------------------------------------

    def _loop(self) -> None:
        delay = 0.0
        while not self._stop.wait(delay):
            try:
                role = self.state.role
                delay = self._campaign() if role == STANDBY else self._renew() if role == LEADER else self.poll
                if self._said_down:
                    log.info("etcd answers again")
                    self._said_down = False
            except EtcdError as e:
                if not self._said_down:
                    log.warning("election: %s", e)
                    self._said_down = True
                with self._lock:
                    if self.state.check(self.clock()):
                        self._fenced_later()
                delay = self.poll
            except Exception:  # never let the campaign die silently
                log.exception("election: unexpected error")
                delay = self.poll

    def _campaign(self) -> float:
        sent = self.clock()
        if not self.lease or sent - self._renewed > self.granted / 3:
            if self.lease and self.etcd.keepalive(self.lease) > 0:
                self._renewed = sent
            else:
                self.lease, granted = self.etcd.grant(self.ttl)
                self.granted, self._renewed = float(granted), sent
        value = json.dumps({"host": self.host, "pid": os.getpid(), "lease": self.lease})
        won, revision, responses = self.etcd.txn([created_at(self.key, 0)], [put(self.key, value, self.lease)],
                                                 [get(self.key)])
        if won:
            with self._lock:
                self.state.won(revision, self.host, self._renewed, self.granted)
            log.info("elected the acting controller (term %d, etcd lease %x of %g s)", revision, self.lease,
                     self.granted)
            threading.Thread(target=self.on_elected, args=(revision,), name="drd-elected", daemon=True).start()
            return 0.0  # renew at once: the lease's clock starts from the last renewal
        kvs = (responses[0].get("response_range") or {}).get("kvs") or [] if responses else []
        if kvs:
            from drd.etcd import KeyValue

            kv = KeyValue.of(kvs[0])
            try:
                holder = str(json.loads(kv.value).get("host", "?"))
            except (ValueError, AttributeError):
                holder = "?"
            if self.state.saw(holder, kv.create_revision):
                log.info("standby controller: %s acts (term %d); taking over if its etcd lease runs out", holder,
                         kv.create_revision)
        return self.poll

    def _renew(self) -> float:
        sent = self.clock()
        ttl = self.etcd.keepalive(self.lease)
        with self._lock:
            if ttl > 0:
                self._renewed = sent
                self.state.kept(sent, ttl)
                if not self.state.check(self.clock()):
                    return min(self.granted / 3, 2 * self.poll)
            elif not self.state.fence("its etcd lease expired: another controller may act now"):
                return self.poll
            self._fenced_later()
        return self.poll

    def _fenced_later(self) -> None:
        """Tell the daemon it was fenced, on a thread of its own (called with the lock held)."""
        reason = self.state.reason
        log.warning("fenced: this controller (term %d) stops acting: %s", self.state.term, reason)
        threading.Thread(target=self.on_fenced, args=(reason,), name="drd-fenced", daemon=True).start()


class FencedBus(BusWrapper):
    """The bus of a controller that may be fenced: every publication, request and answer goes through it only while
    `acting()` says this controller acts (see the module). Closing it does not close `inner` (the daemon owns it)."""

    def __init__(self, inner: Bus, acting: Callable[[], bool], what: str = "") -> None:
        super().__init__(inner)
        self.acting = acting
        self.what = what
        self.dropped = 0  # messages it kept from going out since it was fenced

    def _refused(self) -> str:
        self.dropped += 1
        who = self.what or "this controller"
        return f"{who} no longer acts (fenced, or stopping): another controller may act now"

    def put_raw(self, key: str, data: bytes) -> None:
        if self.acting():
            self.inner.put_raw(key, data)
        else:
            self._refused()

    def request_raw(self, key: str, data: bytes | None, timeout: float = 2.0) -> list[Reply]:
        if not self.acting():
            raise BusError(self._refused())
        return self.inner.request_raw(key, data, timeout)

    def serve(self, key_expr: str, handler: Handler) -> Queryable:
        def fenced(query: Query) -> Reply | Message | None:
            if not self.acting():  # no answer at all: the acting controller's is the one a client gets
                self._refused()
                return None
            return handler(query)

        return self.inner.serve(key_expr, fenced)
