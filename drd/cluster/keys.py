"""The daemon's key layout on the bus, in one place (docs/daemon.md lists it).

Everything lives under `drd/<cluster>/` so two clusters can share a network. Per-host keys carry
the host's name, so a client can ask one daemon (and skip one that does not answer) instead of
waiting for every daemon on a wildcard.
"""

from __future__ import annotations

from dataclasses import dataclass

from drd.bus import join_key

#: Component Database operations every daemon answers under `host/<name>/db/<op>`.
DB_OPS = ("hosts", "components", "lookup", "query")


@dataclass(frozen=True, slots=True)
class ClusterKeys:
    """Key builders for one cluster. Host names are checked to be single chunks."""

    cluster: str

    @property
    def root(self) -> str:
        return join_key("drd", self.cluster)

    def host(self, host: str) -> str:
        """The host's liveliness token: present while its daemon runs."""
        return join_key("drd", self.cluster, "host", host)

    @property
    def hosts(self) -> str:
        """Every host token."""
        return f"{self.root}/host/*"

    def load(self, host: str) -> str:
        """The Load Reporter's publications (`LoadReport`)."""
        return f"{self.host(host)}/load"

    @property
    def loads(self) -> str:
        return f"{self.root}/host/*/load"

    def live(self, host: str) -> str:
        """The acting controller's `LiveReport`s: the robots' live properties, for every daemon's trader."""
        return f"{self.host(host)}/live"

    @property
    def lives(self) -> str:
        return f"{self.root}/host/*/live"

    def announce(self, host: str) -> str:
        """`Announcement` and `Leaving` publications."""
        return f"{self.host(host)}/announce"

    @property
    def announces(self) -> str:
        return f"{self.root}/host/*/announce"

    def ping(self, host: str) -> str:
        return f"{self.host(host)}/ping"

    def status(self, host: str) -> str:
        """The daemon's own status (`DaemonStatus`)."""
        return f"{self.host(host)}/status"

    def db(self, host: str, op: str) -> str:
        """A Component Database operation answered by the daemon of `host` (see `DB_OPS`)."""
        if op not in DB_OPS:
            raise ValueError(f"unknown database operation {op!r} (expected one of {', '.join(DB_OPS)})")
        return f"{self.host(host)}/db/{op}"

    def robots(self, host: str) -> str:
        """What the host's real drivers read (`drd.cluster.observe`: the robots' poses, their scans): read-only, open
        to every role, as the simulator's `world` is; served by a host with robots when no host is a simulator."""
        return f"{self.host(host)}/robots"

    def tune(self, host: str) -> str:
        """The Creator of `host` tuning a running instance's process (`Tune`): an operator's, apart from the
        Creator's own key, which only the controller calls."""
        return f"{self.host(host)}/tune"

    def instance(self, host: str, path: str) -> str:
        """A running component instance's liveliness token (its path's `/` are key separators)."""
        return f"{self.root}/instance/{host}/{path}"  # path: `<slot>/<instance path>` (`creator.token_slots`)

    @property
    def instances(self) -> str:
        return f"{self.root}/instance/**"

    @property
    def resources(self) -> str:
        """The controller's Resource Controller Manager view (`ResourcesReply`)."""
        return f"{self.root}/rcm/resources"

    @property
    def executive(self) -> str:
        """The controller's Mission Executive (`MissionCommand`), served by `drd.executive`."""
        return f"{self.root}/executive"

    @property
    def executive_status(self) -> str:
        """The executive's read-only side (`MissionCommand` status and records): what an observer may ask."""
        return f"{self.root}/executive/status"


def cluster_of(token_key: str) -> tuple[str, str] | None:
    """(cluster, host) of a host token key `drd/<cluster>/host/<host>`, or None for any other key."""
    parts = token_key.split("/")
    if len(parts) == 4 and parts[0] == "drd" and parts[2] == "host":
        return parts[1], parts[3]
    return None
