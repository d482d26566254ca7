"""The daemon's bus messages: announcements, views of the cluster, the trader and the name service.

Every message is versioned and schema-checked on receipt (`drd.bus.message`); a change to a field
bumps its version (docs/bus.md). Times called `at`, `since` or `started` are wall-clock seconds
since the epoch, so that an operator can compare them with their own clock; ages and delays are
seconds. `None` means "not known yet" (no load report received, for example).
"""

from __future__ import annotations

from typing import Any

from drd.bus import Message, message
from drd.cluster.instances import InstanceInfo


@message("drd.daemon.announce", 1)
class Announcement(Message):
    """What a daemon tells the others about itself: published when it starts, when it changes, and
    again whenever another daemon joins (so a newcomer learns everything without a request).

    `components` are the component types its host can run (its devices cover their needs);
    `services` maps the names of the daemon services it hosts to their keys (the name service);
    `config` is a digest of its hosts file, so a host started with a different file is noticed.
    """

    host: str
    cluster: str
    pid: int
    started: float
    roles: list[str]
    components: list[str]
    instances: list[InstanceInfo]
    services: dict[str, str]
    config: str


@message("drd.daemon.leaving", 1)
class Leaving(Message):
    """Published by a daemon that stops cleanly, just before its token goes: "stopped", not "lost"."""

    host: str
    reason: str


@message("drd.daemon.view-request", 2)
class ViewRequest(Message):
    """Asks a daemon for part of its view; `events` bounds how many recent events come back; `after` and `count`
    ask a page of a list that can grow with the cluster (the components' instances: `drd.paging`)."""

    events: int = 50
    after: int = 0
    count: int = 0


@message("drd.daemon.host", 1)
class HostInfo(Message):
    """One host as the answering daemon sees it. `state` is `up`, `down`, or `unresponsive` (down because it went
    silent while its link stayed open: frozen, partitioned or overloaded)."""

    name: str
    state: str
    since: float | None
    reason: str
    endpoint: str
    roles: list[str]
    cpu: float | None
    memory: float | None
    load1: float | None
    instances: int
    report_age: float | None
    devices: list[str]
    robots: list[str]
    pid: int | None


@message("drd.daemon.event", 1)
class ClusterEvent(Message):
    """Something the answering daemon noticed: `up`, `down`, `config-mismatch`, `resources-added`..."""

    at: float
    kind: str
    host: str
    detail: str


@message("drd.daemon.hosts", 1)
class HostsReply(Message):
    """The hosts of the cluster (every configured one, up or down) and the recent events."""

    cluster: str
    answered_by: str
    at: float
    hosts: list[HostInfo]
    events: list[ClusterEvent]


@message("drd.daemon.components", 2)
class ComponentsReply(Message):
    """Component types with the hosts (up) that can run them, running instances, and daemon services. In pages
    (`drd.paging`): one cursor over the instances then the services, `next` the cursor to ask after (0: the last)."""

    cluster: str
    answered_by: str
    types: dict[str, list[str]]
    instances: list[InstanceInfo]
    services: list[InstanceInfo]
    next: int = 0


@message("drd.daemon.lookup", 1)
class Lookup(Message):
    """Name service: where does the instance or service called `name` answer?"""

    name: str


@message("drd.daemon.location", 1)
class Location(Message):
    """The name service's answer: the host and the key prefix of `name`."""

    name: str
    kind: str
    host: str
    key: str


@message("drd.daemon.trader-request", 2)
class TraderRequest(Message):
    """A trader query (`Camera where resolution >= 640 prefer min(host.load)`), `seed` for `prefer random`; `after`
    and `count` ask a page of the offers (`drd.paging`)."""

    query: str
    seed: int = 0
    after: int = 0
    count: int = 0


@message("drd.daemon.trader-reply", 2)
class TraderReply(Message):
    """The matching offers, best first: each `{id, type, host, load, properties, live}`; `live` maps the properties
    that are the cluster's live state (not hosts.yaml's) to their age in seconds. In pages, as `ComponentsReply`."""

    query: str
    offers: list[dict[str, Any]]
    next: int = 0  # the page after (`drd.paging`); 0: the last
    answered_by: str = ""


@message("drd.daemon.live", 1)
class LiveReport(Message):
    """The acting controller's live view of the robots, every load period (`drd.daemon.load.live_robots`): robot id ->
    the properties its Static Dependency Database changed from hosts.yaml (a launched Scout's `carrier`) and, while a
    world runs, the `x`, `y`, `heading` and `battery` its drivers' odometry reported. Every daemon merges them over
    hosts.yaml's in its trader's offers (`drd.daemon.view`)."""

    host: str
    at: float
    robots: dict[str, dict[str, Any]]


@message("drd.daemon.status", 1)
class DaemonStatus(Message):
    """One daemon about itself: process, bus counters, rejected messages and unreachable peers."""

    host: str
    cluster: str
    pid: int
    started: float
    uptime: float
    roles: list[str]
    rss: int
    load_period: float
    lease: float
    bus: dict[str, int]
    rejected: dict[str, int]
    unreachable: dict[str, str]


@message("drd.rcm.unit", 1)
class UnitInfo(Message):
    """A Resource Controller in the manager: who holds it, who waits for its type, its fencing epoch."""

    id: str
    type: str
    host: str
    sharable: bool
    capacity: float
    load: float
    epoch: int
    holders: list[str]
    queue: list[str]
    properties: dict[str, Any]
    offline: bool = False  # its host is down or did not answer a call: granted to no one new, its holders keep it


@message("drd.rcm.robot", 1)
class RobotInfo(Message):
    """An Aggregate Resource Controller (a robot) in the manager and who holds it."""

    id: str
    type: str
    host: str
    parts: dict[str, str]
    holders: list[str]


@message("drd.rcm.blocker", 1)
class BlockerInfo(Message):
    """Who stands in a waiter's way: a holder with what it holds of the waiter's claims (need -> resource id), or a
    better-placed waiter (`waiting`, nothing held) served first."""

    holder: str
    holds: dict[str, str]
    waiting: bool = False


@message("drd.rcm.waiter", 2)
class WaiterInfo(Message):
    """A request waiting in the manager's queue, in service order. Its rank is (`mission_priority`, `priority`):
    the mission's priority decides first. `where`: need -> its `where` as written (needs without one are absent);
    `blocked_by`: who is in its way now; `offline`: the hosts of units it claims that are offline."""

    holder: str
    priority: int
    mission: str
    needs: dict[str, str]
    mission_priority: int = 1
    where: dict[str, str] = {}
    blocked_by: list[BlockerInfo] = []
    offline: list[str] = []  # hosts whose robots it could take are offline (down, or did not answer): it waits for them


@message("drd.rcm.resources-request", 1)
class ResourcesRequest(Message):
    """Asks the controller for a page of its manager (`drd.paging`): the items after cursor `after`, `count` at
    most (0: the default)."""

    after: int = 0
    count: int = 0


@message("drd.rcm.resources", 4)
class ResourcesReply(Message):
    """The controller's Resource Controller Manager: units, robots, the queue, hosts whose
    resources will be removed (`removing`: host -> seconds left of the lease) unless they come back, and
    the configured hosts that are not up (`hosts`: host -> `down` or `unresponsive`, as `HostInfo.state`).

    In pages (`drd.paging`): units by id, then robots by id, then the queue in service order, one cursor over the
    three; `next` is the cursor to ask after (0: the last page), `layout` a number that changes when units or robots
    come or go (a client that sees it change between pages starts again)."""

    cluster: str
    answered_by: str
    units: list[UnitInfo]
    robots: list[RobotInfo]
    queue: list[WaiterInfo]
    removing: dict[str, float]
    hosts: dict[str, str] = {}  # an empty dict of its own for each message, as msgspec copies it
    next: int = 0
    layout: int = 0
